//! The bridge's threads: the back end (controller connection), the publisher (owns the PUB
//! socket) and the instruction server (owns the REP socket). A ZeroMQ socket lives in one
//! thread; the threads share only atomics, a status record and a sample channel.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::thread::{self, JoinHandle};
use std::time::Duration;

use protocol::{HwStateBody, RobotSide};

use crate::backend::{BackendConfig, OpenError, Sample};
use crate::controller::{ControllerRecord, Shared, backend_loop};
use crate::instructions::{Identity, instruction_loop};
use reply_socket::ReplySocket;

#[derive(Debug, Clone)]
pub struct Config {
    /// The controller's protocol and where to find it.
    pub backend: BackendConfig,
    /// Instruction socket (REP), e.g. "tcp://*:2000".
    pub rep: String,
    /// Hardware-state socket (PUB), e.g. "tcp://*:3000".
    pub publish: String,
}

#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    #[error(transparent)]
    Backend(#[from] OpenError),
    #[error("socket {endpoint}: {source}")]
    Socket {
        endpoint: String,
        source: zmq::Error,
    },
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
    socket.bind(endpoint).map_err(error)?;
    let bound = socket
        .get_last_endpoint()
        .map_err(error)?
        .unwrap_or_else(|_| endpoint.to_owned());
    Ok((socket, bound))
}

/// Starts the bridge and returns once its sockets are bound.
pub fn start(config: &Config) -> Result<Handle, BridgeError> {
    let settings = config.backend.settings();
    let backend = settings.open()?;
    let controller_endpoint = backend.controller_endpoint();
    let identity = Identity {
        backend_name: settings.kind().name(),
        robot_side: settings.robot_side(),
    };
    let context = zmq::Context::new();
    // A ROUTER doing REP's part (the reply-socket crate says why); REQ clients see a REP.
    let (rep, rep_endpoint) =
        ReplySocket::bind(&context, &config.rep, 100).map_err(|source| BridgeError::Socket {
            endpoint: config.rep.clone(),
            source,
        })?;
    let (publisher, pub_endpoint) = bind(&context, zmq::PUB, &config.publish)?;
    let shared = Arc::new(Shared {
        mirroring: AtomicBool::new(false),
        published: AtomicU64::new(0),
        controller: Mutex::new(ControllerRecord::default()),
    });
    let shutdown_flag = Arc::new(AtomicBool::new(false));
    let (samples_in, samples_out) = mpsc::channel::<(Sample, f64)>();
    let names = backend.joint_names();
    let effort_unit = backend.effort_unit();
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
                identity.robot_side,
            )
        }));
    }
    {
        let (shared, stop) = (Arc::clone(&shared), Arc::clone(&shutdown_flag));
        threads.push(thread::spawn(move || {
            instruction_loop(rep, shared, stop, identity)
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
    on_ready: impl FnOnce(&Handle),
    shutdown: impl FnOnce(),
) -> Result<(), BridgeError> {
    let handle = start(config)?;
    on_ready(&handle);
    shutdown();
    handle.stop();
    Ok(())
}

/// The publisher's thread: one hwState frame per sample while mirroring, numbered without gaps.
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
                digital_inputs: sample.digital_inputs,
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
