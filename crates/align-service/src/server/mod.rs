//! The alignment service behind `ips serve`: the IPS side of the thesis's digital twin
//! (DTHardwareMirror, section 2.3.3) and its alignment dialog (2.3.1), as a ZeroMQ service.
//!
//! It subscribes to robot-bridge's hardware-state stream and keeps the latest joint sample
//! ([`samples`]); on `start` it asks the bridge to mirror, on `stop` (and on exit) to stop. `get`
//! captures the latest sample as an inspection, refused when the sample is older than
//! `max_sample_age_s` (the stream stalled or the bridge lost its robot) or the tool moves faster
//! than `max_tool_speed_m_s` (a touch is taken at rest). Every change to the inspection list is
//! journaled ([`journal`]) before the reply, so an acknowledged inspection survives a crash; a
//! restarted service replays the journal. With a touch-trigger probe (`Config::trigger`), each
//! rising edge of its input captures an inspection at the edge's time without a `get`, through
//! the same journal ([`trigger`]).
//!
//! `align-cloud` aligns the session's part (or a requested mesh) to a scanner cloud file named
//! in the request; `diagnose` diagnoses the inspections in memory with the session's robot, tool
//! and part, exactly what `save` would write. Their data are the documents of `ips align-cloud
//! --json` and `ips diagnose --json` (without `plot`), made by the same [`crate::jobs`].
//!
//! Requests are served in turn by one thread that owns the REP socket ([`handlers`]), and
//! `align`, `align-cloud` and `diagnose` run in that thread: a `status` arriving meanwhile is
//! answered only when the running one has finished. Measured on a shared 2-core machine (`cargo
//! bench -p ips-client --bench service_requests`, docs/BENCHMARKS.md): a `diagnose` of 16
//! inspections takes 0.3-0.35 s when the residual needs every candidate effect fitted and about
//! 0.09 s when nothing is left to explain; an `align-cloud` of the example scan (23,555 points)
//! 0.08-0.14 s; a touch-set `align` tens of milliseconds. Those are the waits a status request
//! sees; the `ips` client waits up to 30 s. The hardware-state subscription runs in its own
//! thread and is never blocked by requests, so the live sample a `get` takes after a slow
//! request is as fresh as ever.

mod edges;
mod files;
mod handlers;
mod journal;
mod samples;
mod trigger;

pub use journal::JournalReport;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::{self, JoinHandle};

use reply_socket::ReplySocket;

use crate::BadInput;
use crate::session::{LoadedSession, parse_session_file};

/// What the service serves and where it listens.
#[derive(Debug, Clone)]
pub struct Config {
    /// Session file giving robot, tool and part (its inspections are the starting list unless a
    /// journal exists).
    pub session: PathBuf,
    pub journal: PathBuf,
    /// The service's REP endpoint, e.g. `tcp://*:4000` (`tcp://127.0.0.1:*` picks a port).
    pub rep: String,
    /// robot-bridge's instruction REP and hardware-state PUB endpoints.
    pub bridge_rep: String,
    pub bridge_pub: String,
    /// Oldest joint state a `get` accepts, s.
    pub max_sample_age_s: f64,
    /// Fastest tool a `get` accepts, m/s.
    pub max_tool_speed_m_s: f64,
    /// The only directories whose regular files `load`, `save` and `align-cloud` may name;
    /// empty means the session file's folder.
    pub data_dirs: Vec<PathBuf>,
    /// Whether the session file's inspections start a new journal's list (true) or it starts
    /// empty; an existing journal's list wins either way.
    pub keep_session_inspections: bool,
    /// The digital input a touch-trigger probe is wired to: while mirroring, each rising edge
    /// captures an inspection at the edge's time (module `trigger`). `None`: touches are
    /// captured by `get` only.
    pub trigger: Option<protocol::DigitalInput>,
}

/// Why the service could not start.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// The session (or a limit in the config) is unusable: the user's to fix.
    #[error(transparent)]
    BadInput(#[from] BadInput),
    #[error("journal '{}': {source}", path.display())]
    Journal {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("socket {endpoint}: {source}")]
    Socket {
        endpoint: String,
        source: zmq::Error,
    },
}

/// A running service with its bound endpoint.
#[derive(Debug)]
pub struct Handle {
    pub rep_endpoint: String,
    /// What replaying the journal found: entries, corrupt lines skipped, a torn tail cut off.
    pub journal_report: JournalReport,
    /// Where the inspection list came from, for the start-up log: the session file, the journal,
    /// or neither.
    pub inspections_note: String,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

impl Handle {
    /// Stops the service (the bridge is told to stop mirroring if it was) and waits for it.
    pub fn stop(mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
    }
}

impl Drop for Handle {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// Runs the service until `shutdown` returns (the binary's blocks until SIGINT or SIGTERM);
/// `on_ready` gets the running service (its bound REP endpoint, the journal's report) once it
/// answers requests.
pub fn run(
    config: &Config,
    on_ready: impl FnOnce(&Handle),
    shutdown: impl FnOnce(),
) -> Result<(), ServiceError> {
    let handle = start(config)?;
    on_ready(&handle);
    shutdown();
    handle.stop();
    Ok(())
}

pub(crate) fn socket(
    context: &zmq::Context,
    kind: zmq::SocketType,
    timeout_ms: i32,
    endpoint: &str,
) -> Result<zmq::Socket, ServiceError> {
    let error = |source| ServiceError::Socket {
        endpoint: endpoint.to_owned(),
        source,
    };
    let socket = context.socket(kind).map_err(error)?;
    socket.set_linger(0).map_err(error)?;
    socket.set_rcvtimeo(timeout_ms).map_err(error)?;
    socket.set_sndtimeo(timeout_ms).map_err(error)?;
    Ok(socket)
}

fn check_limits(config: &Config) -> Result<(), BadInput> {
    for (name, value) in [
        ("max_sample_age_s", config.max_sample_age_s),
        ("max_tool_speed_m_s", config.max_tool_speed_m_s),
    ] {
        if !(value.is_finite() && value > 0.0) {
            return Err(BadInput(format!(
                "{name} must be a positive number, got {value}"
            )));
        }
    }
    Ok(())
}

/// Starts the service and returns once its REP socket is bound.
pub fn start(config: &Config) -> Result<Handle, ServiceError> {
    check_limits(config)?;
    let text = std::fs::read_to_string(&config.session).map_err(|e| {
        BadInput(format!(
            "cannot read session '{}': {e}",
            config.session.display()
        ))
    })?;
    let template = parse_session_file(&text, &config.session.display().to_string())?;
    let folder = config.session.parent().unwrap_or(Path::new(".")).to_owned();
    let files = if config.data_dirs.is_empty() {
        let session_folder = if folder.as_os_str().is_empty() {
            PathBuf::from(".")
        } else {
            folder.clone()
        };
        files::FileAccess::new(&[session_folder])?
    } else {
        files::FileAccess::new(&config.data_dirs)?
    };
    // Check robot, tool and part now rather than at the first align.
    let loaded = LoadedSession::resolve(template.clone(), &folder)?;
    // The service turns the robot's joint states into touches: it needs the robot.
    let Some(chain) = loaded.chain.clone() else {
        return Err(BadInput(format!(
            "session '{}' has no robot: the service needs one to turn joint states into touches",
            config.session.display()
        ))
        .into());
    };
    let replayed = journal::replay(&config.journal)?;
    let mut journal = journal::Journal::open(&config.journal)?;
    let journal_report = replayed
        .as_ref()
        .map(|replayed| replayed.report.clone())
        .unwrap_or_default();
    let in_file = template.inspections.len();
    let (inspections, highest_id, inspections_note) = match replayed {
        Some(replayed) => {
            let note = format!(
                "{} inspection(s) replayed from the journal '{}'{}",
                replayed.inspections.len(),
                config.journal.display(),
                if in_file > 0 {
                    format!(
                        " (the session file's {in_file} are not used: the journal continues an earlier run; remove it to start from the file)"
                    )
                } else {
                    String::new()
                }
            );
            (replayed.inspections, replayed.highest_id, note)
        }
        None => {
            // A new journal starts with the session file's inspections, unless told otherwise.
            let inspections = if config.keep_session_inspections {
                template.inspections.clone()
            } else {
                Vec::new()
            };
            let note = match (in_file, config.keep_session_inspections) {
                (0, _) => "no inspections yet (a new journal)".to_owned(),
                (n, true) => format!(
                    "{n} inspection(s) from the session file start the list (--session-inspections drop starts empty)"
                ),
                (n, false) => format!(
                    "the session file's {n} inspection(s) are not used: the list starts empty"
                ),
            };
            for inspection in &inspections {
                journal
                    .append(&protocol::JournalEntry::Add {
                        inspection: inspection.clone(),
                    })
                    .map_err(|reason| ServiceError::Journal {
                        path: config.journal.clone(),
                        source: std::io::Error::other(reason),
                    })?;
            }
            let highest = journal::highest_id(&inspections);
            (inspections, highest, note)
        }
    };
    let context = zmq::Context::new();
    // A ROUTER doing REP's part (the reply-socket crate says why); REQ clients see a REP.
    let (rep, rep_endpoint) =
        ReplySocket::bind(&context, &config.rep, 100).map_err(|source| ServiceError::Socket {
            endpoint: config.rep.clone(),
            source,
        })?;
    let socket_error = |endpoint: &str| {
        let endpoint = endpoint.to_owned();
        move |source| ServiceError::Socket { endpoint, source }
    };
    let sub = socket(&context, zmq::SUB, 100, &config.bridge_pub)?;
    sub.set_subscribe(b"")
        .map_err(socket_error(&config.bridge_pub))?;
    sub.connect(&config.bridge_pub)
        .map_err(socket_error(&config.bridge_pub))?;
    let samples = Arc::new(samples::Samples::default());
    let stop = Arc::new(AtomicBool::new(false));
    let mut threads = Vec::new();
    {
        let (samples, stop) = (Arc::clone(&samples), Arc::clone(&stop));
        let mut trigger = config.trigger.map(edges::EdgeDetector::new);
        let detect = move |sample: &samples::JointSample| trigger.as_mut()?.feed(sample);
        threads.push(thread::spawn(move || {
            samples::subscribe_loop(sub, samples, detect, stop)
        }));
    }
    let mut service = handlers::Service {
        results: template.results.clone().unwrap_or_default(),
        results_serial: 0,
        alignment_serial: 0,
        diagnosis_serial: 0,
        latest_next_touch: None,
        touch_candidates: std::sync::OnceLock::new(),
        template,
        folder,
        inspections,
        next_id: highest_id + 1,
        journal,
        mirroring: false,
        samples,
        config: config.clone(),
        context,
        bridge_side: None,
        files,
        nominal_chain: chain.clone(),
        chain,
        corrections: loaded.corrections,
        tool: loaded.tool,
        part_mesh: loaded.mesh,
        base_from_part_nominal: loaded.base_from_part_nominal,
        calibration: None,
        kinematics_note: None,
    };
    {
        let stop = Arc::clone(&stop);
        threads.push(thread::spawn(move || {
            service.serve(&rep, &stop);
            service.stop_mirroring_on_exit();
        }));
    }
    Ok(Handle {
        rep_endpoint,
        journal_report,
        inspections_note,
        stop,
        threads,
    })
}
