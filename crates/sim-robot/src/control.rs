//! The control socket: one request, one reply, and no request, however malformed, ends the
//! loop. The socket is a [`ReplySocket`] (the `reply-socket` crate says why a plain REP is
//! not enough); requests are single JSON objects whose object fields are objects.

use std::sync::Arc;
use std::sync::atomic::Ordering;

use align_core::robots::ShippedRobot;
use protocol::sim::{self, SimCommand};
use reply_socket::{ReplySocket, Wait};

use crate::motion::Trajectory;
use crate::{Shared, effects, probing};

/// Requests larger than this are refused unparsed (the largest, a `probe` or a `path` motion,
/// is a few KiB).
pub const MAX_REQUEST_BYTES: usize = 64 * 1024;

pub(crate) fn control_loop(socket: ReplySocket, shared: Arc<Shared>, robot: ShippedRobot) {
    while !shared.shutdown.load(Ordering::Relaxed) {
        let request = match socket.receive() {
            Wait::Request(request) => request,
            Wait::Nothing => continue,
            Wait::Closed => return,
        };
        let reply = match request
            .single_frame(MAX_REQUEST_BYTES)
            .and_then(sim::parse_command)
        {
            Ok(command) => {
                tracing::debug!(?command, "control request");
                execute(command, &shared, robot)
            }
            Err(reason) => {
                tracing::warn!(%reason, "control request refused");
                sim::reply_error(&reason)
            }
        };
        // A reply to a client that has gone is dropped; nothing is left owing.
        let _ = socket.reply(&request, reply.as_bytes());
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
