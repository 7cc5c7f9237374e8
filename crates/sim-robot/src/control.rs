//! The control socket: one request, one reply, and no request, however malformed, ends the
//! loop. A fault test found two ways a REP socket stopped serving: a two-frame request left it
//! owing a reply it could not send (the loop then exited and the port closed), and raw TCP
//! bytes, which libzmq reads as an unversioned (ZMTP 1.0) peer's messages, left libzmq's REP
//! state machine stuck so that no later client was answered. The socket is therefore a ROUTER
//! that does REP's part itself: it reads every frame of every message, answers a REQ client's
//! request through its envelope (the frames up to the empty delimiter), and drops what no REQ
//! client sends. REQ clients see no difference.

use std::sync::Arc;
use std::sync::atomic::Ordering;

use align_core::robots::ShippedRobot;
use protocol::sim::{self, SimCommand};

use crate::motion::Trajectory;
use crate::{Shared, effects, probing};

/// Requests larger than this are refused unparsed (the largest, a `probe` or a `path` motion,
/// is a few KiB).
pub const MAX_REQUEST_BYTES: usize = 64 * 1024;

/// The most envelope frames (routing id and any proxies' hops) kept to address a reply; a
/// message with more before its delimiter is not from a REQ client and is dropped.
const MAX_ENVELOPE_FRAMES: usize = 16;

/// A request: where the reply goes, its first body frame, and how many body frames and bytes
/// came in all.
struct Received {
    /// The routing id, any hops, and the empty delimiter: sent back before the reply.
    envelope: Vec<Vec<u8>>,
    first_frame: Vec<u8>,
    frame_count: usize,
    total_bytes: usize,
}

/// What one wait on the socket gave.
enum Wait {
    Request(Received),
    /// Nothing within the receive timeout, an interruption, or a message that cannot be
    /// answered: look at the shutdown flag again.
    Nothing,
    /// The context is gone: nothing can be received again.
    Closed,
}

pub(crate) fn control_loop(socket: zmq::Socket, shared: Arc<Shared>, robot: ShippedRobot) {
    while !shared.shutdown.load(Ordering::Relaxed) {
        let received = match receive(&socket) {
            Wait::Request(received) => received,
            Wait::Nothing => continue,
            Wait::Closed => return,
        };
        let reply = answer(&received, &shared, robot);
        // A ROUTER drops a reply to a peer that has gone; nothing is left owing.
        let _ = send_reply(&socket, &received.envelope, &reply);
    }
}

/// Waits for one message and reads all its frames. Frames beyond the first body frame are
/// counted and dropped, never kept.
fn receive(socket: &zmq::Socket) -> Wait {
    let routing_id = match socket.recv_bytes(0) {
        Ok(frame) => frame,
        Err(zmq::Error::ETERM | zmq::Error::ENOTSOCK) => return Wait::Closed,
        // EAGAIN (the receive timeout), EINTR and anything else are not the socket's end.
        Err(_) => return Wait::Nothing,
    };
    let mut envelope = vec![routing_id];
    let mut delimited = false;
    let mut first_frame = None;
    let (mut frame_count, mut total_bytes) = (0_usize, 0_usize);
    // libzmq delivers a message whole, so its remaining frames are already here.
    while socket.get_rcvmore().unwrap_or(false) {
        let Ok(frame) = socket.recv_bytes(0) else {
            break;
        };
        if !delimited {
            delimited = frame.is_empty();
            if envelope.len() < MAX_ENVELOPE_FRAMES {
                envelope.push(frame);
            }
            continue;
        }
        frame_count += 1;
        total_bytes = total_bytes.saturating_add(frame.len());
        if first_frame.is_none() {
            first_frame = Some(frame);
        }
    }
    let envelope_complete = envelope.last().is_some_and(Vec::is_empty);
    if !delimited || !envelope_complete {
        // Not a REQ client's request (libzmq's REP drops these too): there is no one to
        // answer.
        return Wait::Nothing;
    }
    Wait::Request(Received {
        envelope,
        first_frame: first_frame.unwrap_or_default(),
        frame_count,
        total_bytes,
    })
}

fn send_reply(socket: &zmq::Socket, envelope: &[Vec<u8>], reply: &str) -> Result<(), zmq::Error> {
    let frames = envelope
        .iter()
        .map(Vec::as_slice)
        .chain(std::iter::once(reply.as_bytes()));
    socket.send_multipart(frames, 0)
}

fn answer(received: &Received, shared: &Shared, robot: ShippedRobot) -> String {
    if received.frame_count == 0 {
        return sim::reply_error("an empty request: a request is one frame holding a JSON object");
    }
    if received.frame_count > 1 {
        return sim::reply_error(&format!(
            "a multipart request of {} frames: a request is a single frame holding one JSON object",
            received.frame_count
        ));
    }
    if received.total_bytes > MAX_REQUEST_BYTES {
        return sim::reply_error(&format!(
            "request of {} bytes exceeds the {MAX_REQUEST_BYTES}-byte limit",
            received.total_bytes
        ));
    }
    match parse_request(&received.first_frame) {
        Ok(command) => execute(command, shared, robot),
        Err(reason) => sim::reply_error(&reason),
    }
}

/// Fields that hold objects wherever they appear at the top of a request.
const OBJECT_FIELDS: [&str; 5] = [
    "motion",
    "payload",
    "cyclic_encoder",
    "base_from_part",
    "tcp",
];

/// Parses a request after checking that objects are objects: serde's derived structs also
/// read arrays (`["hold",[0,0,0,0,0,0]]` would read as a hold motion), which no client writes.
fn parse_request(bytes: &[u8]) -> Result<SimCommand, String> {
    let value: serde_json::Value =
        serde_json::from_slice(bytes).map_err(|_| "the request is not JSON".to_owned())?;
    let Some(object) = value.as_object() else {
        return Err(format!(
            "the request must be a JSON object, got {}",
            kind_of(&value)
        ));
    };
    for field in OBJECT_FIELDS {
        match object.get(field) {
            Some(inner) if !inner.is_object() => {
                return Err(format!(
                    "'{field}' must be an object, got {}",
                    kind_of(inner)
                ));
            }
            _ => {}
        }
    }
    let waypoints = object
        .get("motion")
        .and_then(|motion| motion.get("waypoints"))
        .and_then(serde_json::Value::as_array);
    for (index, waypoint) in waypoints.into_iter().flatten().enumerate() {
        if !waypoint.is_object() {
            return Err(format!(
                "'motion.waypoints[{index}]' must be an object, got {}",
                kind_of(waypoint)
            ));
        }
    }
    sim::parse_command(bytes)
}

fn kind_of(value: &serde_json::Value) -> &'static str {
    match value {
        serde_json::Value::Null => "null",
        serde_json::Value::Bool(_) => "a boolean",
        serde_json::Value::Number(_) => "a number",
        serde_json::Value::String(_) => "a string",
        serde_json::Value::Array(_) => "an array",
        serde_json::Value::Object(_) => "an object",
    }
}

/// Carries out one well-formed command.
fn execute(command: SimCommand, shared: &Shared, robot: ShippedRobot) -> String {
    let done = || sim::reply_ok(&sim::Done {});
    match command {
        SimCommand::Status => sim::reply_ok(&status(shared, robot)),
        SimCommand::Truth => {
            let sample = shared.sample();
            sim::reply_ok(&sim::Truth {
                q: sample.true_q,
                qd: sample.qd,
                reported_q: sample.q,
                time: sample.time_s,
            })
        }
        SimCommand::TruthAt { time } => {
            if !time.is_finite() {
                return sim::reply_error("truth_at needs a finite 'time' in s");
            }
            let sample = shared.sample_at(time);
            sim::reply_ok(&sim::Truth {
                q: sample.true_q,
                qd: sample.qd,
                reported_q: sample.q,
                time,
            })
        }
        SimCommand::Motion { motion } => match motion.check(&shared.limits) {
            Ok(()) => {
                shared.set_motion(motion);
                // A scripted motion replaces any probe run.
                *shared.probe.lock().unwrap_or_else(|p| p.into_inner()) = None;
                done()
            }
            Err(reason) => sim::reply_error(&reason),
        },
        SimCommand::Effects(effects) => {
            match effects::Effects::checked(effects, shared.limits.len()) {
                Ok(effects) => {
                    *shared.effects.lock().unwrap_or_else(|p| p.into_inner()) = effects;
                    done()
                }
                Err(reason) => sim::reply_error(&reason),
            }
        }
        SimCommand::Probe(request) => match probing::start(&request, shared) {
            Ok(plan) => sim::reply_ok(&plan),
            Err(reason) => sim::reply_error(&reason),
        },
        SimCommand::Pause => {
            shared.paused.store(true, Ordering::Relaxed);
            done()
        }
        SimCommand::Resume => {
            shared.paused.store(false, Ordering::Relaxed);
            done()
        }
        SimCommand::Drop => {
            shared.drop_generation.fetch_add(1, Ordering::Relaxed);
            done()
        }
    }
}

fn status(shared: &Shared, robot: ShippedRobot) -> sim::SimStatus {
    let fri = shared
        .fri
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .as_ref()
        .map(|link| sim::FriLink {
            local_address: link.local_address.clone(),
            quality: link.quality.name().to_owned(),
            sequence: u64::from(link.sequence),
            session_state: link.session_state.name().to_owned(),
            timely_answers: link.timely_answers,
        });
    let time_s = shared.now_s();
    let at_rest = shared
        .motion
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .at_rest(time_s);
    let probe = shared
        .probe
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .as_ref()
        .map(|schedule| schedule.report(time_s, at_rest));
    sim::SimStatus {
        at_rest,
        clients: shared.clients.load(Ordering::Relaxed),
        fri,
        paused: shared.paused.load(Ordering::Relaxed),
        probe,
        robot: robot.name().to_owned(),
        time: time_s,
    }
}
