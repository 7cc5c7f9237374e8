//! The bridge's threads: the back end (controller connection), the publisher (owns the PUB
//! socket) and the instruction server (owns the REP socket). A ZeroMQ socket lives in one
//! thread; the threads share only atomics, a status record and a sample channel.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use protocol::{Command, HwStateBody, RobotSide, StatusBody};

use crate::BackendKind;
use crate::backend::{Backend, Event, LinkState, Sample};

/// Requests larger than this are refused unread (a JSON instruction is ~100 bytes).
pub const MAX_REQUEST_BYTES: usize = 64 * 1024;

#[derive(Debug, Clone)]
pub struct Config {
    pub backend: BackendKind,
    pub robot_host: String,
    pub rtde_port: u16,
    pub fri_port: u16,
    pub rep: String,
    pub publish: String,
}

#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    #[error("cannot listen for FRI on UDP port {port}: {source}")]
    Fri { port: u16, source: std::io::Error },
    #[error("socket {endpoint}: {source}")]
    Socket {
        endpoint: String,
        source: zmq::Error,
    },
}

#[derive(Debug, Default)]
struct ControllerState {
    state: &'static str,
    reason: Option<String>,
    last_sample: Option<Instant>,
    recent: std::collections::VecDeque<Instant>,
    reconnects: u64,
    link: Option<LinkState>,
    /// The controller's counter of the previous sample in this session, where it has one.
    last_controller_seq: Option<u64>,
    counts_controller_seq: bool,
    controller_samples_missed: u64,
    rejected_datagrams: Option<u64>,
}

struct Shared {
    mirroring: AtomicBool,
    published: AtomicU64,
    controller: Mutex<ControllerState>,
}

/// A running bridge with its bound endpoints.
#[derive(Debug)]
pub struct Handle {
    pub rep_endpoint: String,
    pub pub_endpoint: String,
    /// Where the controller's datagrams are received (FRI), e.g. "udp://0.0.0.0:30200".
    pub controller_endpoint: Option<String>,
    shutdown: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

impl Handle {
    pub fn stop(mut self) {
        self.shutdown.store(true, Ordering::Relaxed);
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
    }
}

impl Drop for Handle {
    fn drop(&mut self) {
        self.shutdown.store(true, Ordering::Relaxed);
    }
}

fn side(kind: BackendKind) -> RobotSide {
    match kind {
        BackendKind::Ur => RobotSide::Ros,
        BackendKind::Iiwa => RobotSide::IiwaDrive,
    }
}

fn bind(
    context: &zmq::Context,
    kind: zmq::SocketType,
    endpoint: &str,
) -> Result<(zmq::Socket, String), BridgeError> {
    let error = |source| BridgeError::Socket {
        endpoint: endpoint.to_owned(),
        source,
    };
    let socket = context.socket(kind).map_err(error)?;
    socket.set_linger(0).map_err(error)?;
    socket.set_rcvtimeo(100).map_err(error)?;
    socket.set_sndtimeo(1000).map_err(error)?;
    // Far above MAX_REQUEST_BYTES so an oversized request still arrives and gets a reason.
    socket.set_maxmsgsize(16 * 1024 * 1024).map_err(error)?;
    socket.bind(endpoint).map_err(error)?;
    let bound = socket
        .get_last_endpoint()
        .map_err(error)?
        .unwrap_or_else(|_| endpoint.to_owned());
    Ok((socket, bound))
}

/// Starts the bridge and returns once its sockets are bound.
pub fn start(config: &Config) -> Result<Handle, BridgeError> {
    let (backend, controller_endpoint): (Box<dyn Backend>, _) = match config.backend {
        BackendKind::Ur => (
            Box::new(crate::backend::ur::UrBackend::new(
                &config.robot_host,
                config.rtde_port,
            )),
            None,
        ),
        BackendKind::Iiwa => {
            let backend =
                crate::backend::iiwa::IiwaBackend::bind(&config.robot_host, config.fri_port)
                    .map_err(|source| BridgeError::Fri {
                        port: config.fri_port,
                        source,
                    })?;
            let endpoint = format!("udp://{}", backend.local_address());
            (Box::new(backend), Some(endpoint))
        }
    };
    let context = zmq::Context::new();
    let (rep, rep_endpoint) = bind(&context, zmq::REP, &config.rep)?;
    let (publisher, pub_endpoint) = bind(&context, zmq::PUB, &config.publish)?;
    let shared = Arc::new(Shared {
        mirroring: AtomicBool::new(false),
        published: AtomicU64::new(0),
        controller: Mutex::new(ControllerState {
            state: "connecting",
            ..ControllerState::default()
        }),
    });
    let shutdown_flag = Arc::new(AtomicBool::new(false));
    let (samples_in, samples_out) = mpsc::channel::<(Sample, f64)>();
    let names = backend.joint_names();
    let effort_unit = backend.effort_unit();
    let robot_side = side(config.backend);
    let mut threads = Vec::new();
    {
        let (shared, stop) = (Arc::clone(&shared), Arc::clone(&shutdown_flag));
        threads.push(thread::spawn(move || {
            backend_loop(backend, shared, stop, samples_in)
        }));
    }
    {
        let (shared, stop) = (Arc::clone(&shared), Arc::clone(&shutdown_flag));
        threads.push(thread::spawn(move || {
            publish_loop(
                publisher,
                shared,
                stop,
                samples_out,
                names,
                effort_unit,
                robot_side,
            )
        }));
    }
    {
        let (shared, stop) = (Arc::clone(&shared), Arc::clone(&shutdown_flag));
        let kind = config.backend;
        threads.push(thread::spawn(move || {
            instruction_loop(rep, shared, stop, kind)
        }));
    }
    Ok(Handle {
        rep_endpoint,
        pub_endpoint,
        controller_endpoint,
        shutdown: shutdown_flag,
        threads,
    })
}

/// Runs until `shutdown` is set (the binary sets it on SIGINT/SIGTERM).
pub fn run(
    config: &Config,
    shutdown: &AtomicBool,
    on_ready: impl FnOnce(&Handle),
) -> Result<(), BridgeError> {
    let handle = start(config)?;
    on_ready(&handle);
    while !shutdown.load(Ordering::Relaxed) {
        thread::sleep(Duration::from_millis(50));
    }
    handle.stop();
    Ok(())
}

fn unix_now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

fn backend_loop(
    mut backend: Box<dyn Backend>,
    shared: Arc<Shared>,
    stop: Arc<AtomicBool>,
    samples: Sender<(Sample, f64)>,
) {
    while !stop.load(Ordering::Relaxed) {
        let event = backend.next_event(Duration::from_millis(50));
        let mut controller = shared.controller.lock().unwrap_or_else(|p| p.into_inner());
        controller.rejected_datagrams = backend.rejected_datagrams().map(|(count, _)| count);
        let Some(event) = event else {
            continue;
        };
        match event {
            Event::Connecting => controller.state = "connecting",
            Event::Connected { .. } => {
                // A new session straight after the old one (a controller restarted faster than
                // the loss timeout) is a gap in the stream too.
                if controller.state == "connected" {
                    controller.reconnects += 1;
                }
                controller.state = "connected";
                controller.reason = None;
                // A new session counts from its own start.
                controller.last_controller_seq = None;
            }
            Event::Lost { reason } => {
                if controller.state == "connected" {
                    controller.reconnects += 1;
                }
                controller.state = "lost";
                controller.reason = Some(reason);
                controller.link = None;
                controller.last_controller_seq = None;
            }
            Event::Sample(sample) => {
                if let Some(seq) = sample.controller_seq {
                    controller.counts_controller_seq = true;
                    if let Some(previous) = controller.last_controller_seq {
                        controller.controller_samples_missed +=
                            seq.saturating_sub(previous).saturating_sub(1);
                    }
                    controller.last_controller_seq = Some(seq);
                }
                controller.link.clone_from(&sample.link);
                let now = Instant::now();
                controller.last_sample = Some(now);
                controller.recent.push_back(now);
                while controller
                    .recent
                    .front()
                    .is_some_and(|t| now.duration_since(*t) > Duration::from_secs(1))
                {
                    controller.recent.pop_front();
                }
                drop(controller);
                if samples.send((sample, unix_now())).is_err() {
                    return;
                }
            }
        }
    }
}

fn publish_loop(
    socket: zmq::Socket,
    shared: Arc<Shared>,
    stop: Arc<AtomicBool>,
    samples: Receiver<(Sample, f64)>,
    names: Vec<String>,
    effort_unit: Option<&'static str>,
    robot_side: RobotSide,
) {
    let mut seq = 0u64;
    while !stop.load(Ordering::Relaxed) {
        let (sample, stamp) = match samples.recv_timeout(Duration::from_millis(100)) {
            Ok(received) => received,
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => return,
        };
        if !shared.mirroring.load(Ordering::Relaxed) {
            continue;
        }
        let message = protocol::hw_state(
            robot_side,
            HwStateBody {
                names: names.clone(),
                position: sample.position,
                velocity: sample.velocity,
                effort: sample.effort,
                effort_unit: effort_unit.map(str::to_owned),
                seq,
                stamp,
                controller_time: sample.controller_time,
                controller_seq: sample.controller_seq,
                robot_mode: sample.robot_mode,
                safety_mode: sample.safety_mode,
            },
        );
        // A sample that fails validation (NaN from the controller) is dropped, never sent.
        let Ok(text) = protocol::to_json(&message) else {
            continue;
        };
        if socket.send(text.as_bytes(), 0).is_ok() {
            seq += 1;
            shared.published.fetch_add(1, Ordering::Relaxed);
        }
    }
}

fn instruction_loop(
    socket: zmq::Socket,
    shared: Arc<Shared>,
    stop: Arc<AtomicBool>,
    kind: BackendKind,
) {
    let robot_side = side(kind);
    while !stop.load(Ordering::Relaxed) {
        let request = match socket.recv_bytes(0) {
            Ok(request) => request,
            Err(zmq::Error::EAGAIN) => continue,
            Err(_) => return,
        };
        // A REQ client may send a multi-part message: drain it so the reply goes out.
        while socket.get_rcvmore().unwrap_or(false) {
            let _ = socket.recv_bytes(0);
        }
        let reply = answer(&request, &shared, kind, robot_side);
        let _ = socket.send(reply.as_bytes(), 0);
    }
}

fn answer(request: &[u8], shared: &Shared, kind: BackendKind, robot_side: RobotSide) -> String {
    let error = |reason: String| {
        protocol::to_json(&protocol::ack_error(robot_side, reason)).unwrap_or_default()
    };
    if request.len() > MAX_REQUEST_BYTES {
        return error(format!(
            "request of {} bytes exceeds the {MAX_REQUEST_BYTES}-byte limit",
            request.len()
        ));
    }
    let parsed = match protocol::parse_request(request) {
        Ok(parsed) => parsed,
        Err(reason) => return error(reason.to_string()),
    };
    let controller = shared.controller.lock().unwrap_or_else(|p| p.into_inner());
    match parsed.command {
        Command::Start => {
            if controller.state != "connected" {
                let why = controller
                    .reason
                    .clone()
                    .unwrap_or_else(|| "not connected yet".to_owned());
                return error(format!("controller {}: {why}", controller.state));
            }
            shared.mirroring.store(true, Ordering::Relaxed);
            protocol::to_json(&protocol::ack_ok(robot_side)).unwrap_or_default()
        }
        Command::Stop => {
            shared.mirroring.store(false, Ordering::Relaxed);
            protocol::to_json(&protocol::ack_ok(robot_side)).unwrap_or_default()
        }
        Command::Status => {
            let body = StatusBody {
                backend: kind.name().to_owned(),
                controller: controller.state.to_owned(),
                mirroring: shared.mirroring.load(Ordering::Relaxed),
                sample_rate_hz: controller.recent.len() as f64,
                last_sample_age_s: controller.last_sample.map(|t| t.elapsed().as_secs_f64()),
                published: shared.published.load(Ordering::Relaxed),
                reconnects: controller.reconnects,
                reason: controller.reason.clone(),
                controller_samples_missed: controller
                    .counts_controller_seq
                    .then_some(controller.controller_samples_missed),
                session_state: controller
                    .link
                    .as_ref()
                    .and_then(|link| link.session_state)
                    .map(str::to_owned),
                connection_quality: controller
                    .link
                    .as_ref()
                    .and_then(|link| link.quality)
                    .map(str::to_owned),
                rejected_datagrams: controller.rejected_datagrams,
            };
            protocol::to_json(&protocol::status(robot_side, body)).unwrap_or_default()
        }
    }
}
