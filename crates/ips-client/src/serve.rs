//! `ips serve`: the IPS side of the thesis's digital twin (DTHardwareMirror, section 2.3.3) and
//! its alignment dialog (2.3.1), as a ZeroMQ service.
//!
//! It subscribes to robot-bridge's hardware-state stream and keeps the latest joint sample; on
//! `start` it asks the bridge to mirror, on `stop` (and on exit) to stop. `get` captures the
//! latest sample as an inspection, refused when the sample is older than `max_sample_age_s`
//! (the stream stalled or the bridge lost its robot) or the tool moves faster than
//! `max_tool_speed_m_s` (a touch is taken at rest). Every change to the inspection list is
//! appended to a journal and flushed to disk before the reply (`load` replaces the list with a
//! session file's inspections in one entry), so an acknowledged inspection
//! survives a crash; a restarted service replays the journal.
//!
//! `align-cloud` aligns the session's part (or a requested mesh) to a scanner cloud file named
//! in the request, from the part's nominal pose with delta 0.1 m unless the request gives them;
//! `diagnose` diagnoses the inspections in memory with the session's robot, tool and part,
//! exactly what `save` would write. Their data are the documents of `ips align-cloud --json` and
//! `ips diagnose --json` (without `plot`), made by the same functions.
//!
//! Requests are served in turn by one thread that owns the REP socket, and `align`,
//! `align-cloud` and `diagnose` run in that thread: a `status` (or any request) arriving
//! meanwhile is answered only when the running one has finished. Measured on a shared 2-core
//! machine (`cargo bench -p ips-client --bench service_requests`, docs/BENCHMARKS.md): a
//! `diagnose` of 16 inspections takes 0.3-0.35 s when the residual needs every candidate effect
//! fitted and about 0.09 s when nothing is left to explain; an `align-cloud` of the example scan
//! (23,555 points) 0.08-0.14 s; a touch-set `align` tens of milliseconds. Those are the waits a
//! status request sees; the `ips` client waits up to 30 s. The hardware-state
//! subscription runs in its own thread and is never blocked by requests, so the live sample a
//! `get` takes after a slow request is as fresh as ever.

use std::collections::VecDeque;
use std::fs::{File, OpenOptions};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::{self, JoinHandle};
use std::time::Instant;

use align_core::registration::psa::{PsaOptions, PsaTarget, align_touches};
use nalgebra::Vector3;
use protocol::{ServiceRequest, service_reply};
use serde_json::{Value, json};

use crate::session::{Inspection, LoadedSession, SessionFile};

#[derive(Debug, Clone)]
pub struct ServeConfig {
    /// Session file giving robot, tool and part (its inspections are the starting list unless a
    /// journal exists).
    pub session: PathBuf,
    pub journal: PathBuf,
    pub rep: String,
    pub bridge_rep: String,
    pub bridge_pub: String,
    pub max_sample_age_s: f64,
    pub max_tool_speed_m_s: f64,
}

/// The latest joint state received from the bridge.
#[derive(Debug, Clone)]
struct LatestSample {
    q: Vec<f64>,
    qd: Vec<f64>,
    controller_time: f64,
    received: Instant,
}

struct State {
    template: SessionFile,
    folder: PathBuf,
    inspections: Vec<Inspection>,
    next_id: u64,
    journal: File,
    mirroring: bool,
}

#[derive(Debug)]
pub struct ServeHandle {
    pub rep_endpoint: String,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

impl ServeHandle {
    pub fn stop(mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
    }
}

impl Drop for ServeHandle {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn socket(
    context: &zmq::Context,
    kind: zmq::SocketType,
    timeout_ms: i32,
) -> Result<zmq::Socket, String> {
    let socket = context.socket(kind).map_err(|e| e.to_string())?;
    socket.set_linger(0).map_err(|e| e.to_string())?;
    socket.set_rcvtimeo(timeout_ms).map_err(|e| e.to_string())?;
    socket.set_sndtimeo(timeout_ms).map_err(|e| e.to_string())?;
    Ok(socket)
}

/// Replays a journal: one JSON object per line, `add`, `remove` or `reset`. A torn last line
/// (a crash mid-write, never acknowledged) is ignored.
fn replay(path: &Path, inspections: &mut Vec<Inspection>) -> Result<u64, String> {
    let Ok(file) = File::open(path) else {
        return Ok(0);
    };
    let mut highest = 0;
    for line in BufReader::new(file).lines() {
        let line = line.map_err(|e| format!("journal '{}': {e}", path.display()))?;
        let Ok(entry) = serde_json::from_str::<Value>(&line) else {
            continue;
        };
        match entry["op"].as_str() {
            Some("add") => {
                if let Ok(inspection) =
                    serde_json::from_value::<Inspection>(entry["inspection"].clone())
                {
                    highest = highest.max(inspection.id.parse::<u64>().unwrap_or(0));
                    inspections.push(inspection);
                }
            }
            Some("remove") => {
                let ids: Vec<String> =
                    serde_json::from_value(entry["ids"].clone()).unwrap_or_default();
                inspections.retain(|i| !ids.contains(&i.id));
            }
            Some("reset") => inspections.clear(),
            Some("load") => {
                if let Ok(loaded) =
                    serde_json::from_value::<Vec<Inspection>>(entry["inspections"].clone())
                {
                    highest = loaded
                        .iter()
                        .filter_map(|i| i.id.parse().ok())
                        .fold(highest, u64::max);
                    *inspections = loaded;
                }
            }
            _ => {}
        }
    }
    Ok(highest)
}

impl State {
    /// Appends one journal entry and forces it to disk.
    fn journal(&mut self, entry: Value) -> Result<(), String> {
        let mut line = entry.to_string();
        line.push('\n');
        self.journal
            .write_all(line.as_bytes())
            .and_then(|()| self.journal.sync_data())
            .map_err(|e| format!("cannot write the journal: {e}"))
    }
}

pub fn start(config: &ServeConfig) -> Result<ServeHandle, String> {
    let text = std::fs::read_to_string(&config.session)
        .map_err(|e| format!("cannot read session '{}': {e}", config.session.display()))?;
    let template: SessionFile = serde_json::from_str(&text)
        .map_err(|e| format!("session '{}': {e}", config.session.display()))?;
    let folder = config.session.parent().unwrap_or(Path::new(".")).to_owned();
    // Check robot, tool and part now rather than at the first align.
    let loaded = LoadedSession::resolve(template.clone(), &folder).map_err(|e| e.0)?;
    // The service turns the robot's joint states into touches: it needs the robot.
    let Some(chain) = loaded.chain.clone() else {
        return Err(format!(
            "session '{}' has no robot: the service needs one to turn joint states into touches",
            config.session.display()
        ));
    };
    let mut inspections = Vec::new();
    let journal_exists = config.journal.exists();
    let mut highest = replay(&config.journal, &mut inspections)?;
    if !journal_exists {
        inspections = template.inspections.clone();
        highest = inspections
            .iter()
            .filter_map(|i| i.id.parse().ok())
            .max()
            .unwrap_or(0);
    }
    let journal = OpenOptions::new()
        .create(true)
        .append(true)
        .open(&config.journal)
        .map_err(|e| format!("cannot open journal '{}': {e}", config.journal.display()))?;
    let mut state = State {
        template,
        folder,
        inspections,
        next_id: highest + 1,
        journal,
        mirroring: false,
    };
    if !journal_exists {
        let initial: Vec<Value> = state
            .inspections
            .iter()
            .map(|i| json!({"op": "add", "inspection": i}))
            .collect();
        for entry in initial {
            state.journal(entry)?;
        }
    }
    let context = zmq::Context::new();
    let rep = socket(&context, zmq::REP, 100)?;
    rep.set_maxmsgsize(16 * 1024 * 1024)
        .map_err(|e| e.to_string())?;
    rep.bind(&config.rep)
        .map_err(|e| format!("{}: {e}", config.rep))?;
    let rep_endpoint = rep
        .get_last_endpoint()
        .map_err(|e| e.to_string())?
        .unwrap_or_else(|_| config.rep.clone());
    let sub = socket(&context, zmq::SUB, 100)?;
    sub.set_subscribe(b"").map_err(|e| e.to_string())?;
    sub.connect(&config.bridge_pub)
        .map_err(|e| format!("{}: {e}", config.bridge_pub))?;
    let latest: Arc<Mutex<Option<LatestSample>>> = Arc::new(Mutex::new(None));
    let history: Arc<Mutex<VecDeque<LatestSample>>> = Arc::new(Mutex::new(VecDeque::new()));
    let stop = Arc::new(AtomicBool::new(false));
    let mut threads = Vec::new();
    {
        let (latest, history, stop) =
            (Arc::clone(&latest), Arc::clone(&history), Arc::clone(&stop));
        threads.push(thread::spawn(move || {
            subscribe_loop(sub, latest, history, stop)
        }));
    }
    {
        let (latest, history, stop, config) = (
            Arc::clone(&latest),
            Arc::clone(&history),
            Arc::clone(&stop),
            config.clone(),
        );
        let tool = loaded.tool.clone();
        threads.push(thread::spawn(move || {
            let context = context;
            let mut service = Service {
                state,
                latest,
                history,
                config,
                context,
                chain,
                tool,
            };
            service.serve(rep, &stop);
            if service.state.mirroring {
                let _ = service.bridge("stop");
            }
        }));
    }
    Ok(ServeHandle {
        rep_endpoint,
        stop,
        threads,
    })
}

/// Samples kept for a get at a given controller time: 4 s at 1 kHz, 8 s at 500 Hz.
const HISTORY_SAMPLES: usize = 4096;

fn subscribe_loop(
    sub: zmq::Socket,
    latest: Arc<Mutex<Option<LatestSample>>>,
    history: Arc<Mutex<VecDeque<LatestSample>>>,
    stop: Arc<AtomicBool>,
) {
    while !stop.load(Ordering::Relaxed) {
        let Ok(bytes) = sub.recv_bytes(0) else {
            continue;
        };
        let Ok(message) = serde_json::from_slice::<protocol::HwState>(&bytes) else {
            continue;
        };
        if message.body.validate().is_err() {
            continue;
        }
        let sample = LatestSample {
            q: message.body.position,
            qd: message.body.velocity,
            controller_time: message.body.controller_time,
            received: Instant::now(),
        };
        {
            let mut history = history.lock().unwrap_or_else(|p| p.into_inner());
            // A controller restart starts its clock again: older samples would be found first.
            if history
                .back()
                .is_some_and(|last| last.controller_time > sample.controller_time)
            {
                history.clear();
            }
            history.push_back(sample.clone());
            while history.len() > HISTORY_SAMPLES {
                history.pop_front();
            }
        }
        *latest.lock().unwrap_or_else(|p| p.into_inner()) = Some(sample);
    }
}

struct Service {
    state: State,
    latest: Arc<Mutex<Option<LatestSample>>>,
    /// The last [`HISTORY_SAMPLES`] samples, for a get at a given controller time.
    history: Arc<Mutex<VecDeque<LatestSample>>>,
    config: ServeConfig,
    context: zmq::Context,
    chain: align_core::kinematics::Chain,
    tool: align_core::tool::Tool,
}

impl Service {
    fn serve(&mut self, rep: zmq::Socket, stop: &AtomicBool) {
        while !stop.load(Ordering::Relaxed) {
            let request = match rep.recv_bytes(0) {
                Ok(request) => request,
                Err(zmq::Error::EAGAIN) => continue,
                Err(_) => return,
            };
            while rep.get_rcvmore().unwrap_or(false) {
                let _ = rep.recv_bytes(0);
            }
            let (ok, reason, data) = match self.handle(&request) {
                Ok(data) => (true, None, data),
                Err(reason) => (false, Some(reason), Value::Null),
            };
            let reply = protocol::to_json(&service_reply(ok, reason, data)).unwrap_or_default();
            let _ = rep.send(reply.as_bytes(), 0);
        }
    }

    /// Sends the thesis's instruction to the bridge and returns its ack content.
    fn bridge(&self, command: &str) -> Result<(), String> {
        let req = socket(&self.context, zmq::REQ, 2000)?;
        req.connect(&self.config.bridge_rep)
            .map_err(|e| e.to_string())?;
        let command = if command == "start" {
            protocol::Command::Start
        } else {
            protocol::Command::Stop
        };
        let text = protocol::to_json(&protocol::instruction(protocol::RobotSide::Ros, command))
            .map_err(|e| e.to_string())?;
        req.send(text.as_bytes(), 0)
            .map_err(|e| format!("bridge unreachable: {e}"))?;
        let reply = req.recv_bytes(0).map_err(|_| {
            format!(
                "no answer from the bridge at {} within 2 s",
                self.config.bridge_rep
            )
        })?;
        let ack: protocol::Instruction =
            serde_json::from_slice(&reply).map_err(|e| format!("bad ack from the bridge: {e}"))?;
        if ack.body.content == "ok" {
            Ok(())
        } else {
            Err(format!(
                "the bridge refused: {}",
                ack.body.reason.unwrap_or_default()
            ))
        }
    }

    fn handle(&mut self, request: &[u8]) -> Result<Value, String> {
        if request.len() > 64 * 1024 {
            return Err(format!(
                "request of {} bytes exceeds the 65536-byte limit",
                request.len()
            ));
        }
        let request: ServiceRequest = serde_json::from_slice(request).map_err(|e| {
            // Python's json module writes NaN and Infinity by default; serde only says "expected
            // value", which does not point at the number.
            let text = String::from_utf8_lossy(request);
            let hint = if text.contains("NaN") || text.contains("Infinity") {
                " (NaN and Infinity are not JSON numbers: send finite values)"
            } else {
                ""
            };
            format!("not a service request: {e}{hint}")
        })?;
        match request.body.command.as_str() {
            "status" => Ok(self.status()),
            "start" => {
                self.bridge("start")?;
                self.state.mirroring = true;
                Ok(json!({"mirroring": true}))
            }
            "stop" => {
                self.bridge("stop")?;
                self.state.mirroring = false;
                Ok(json!({"mirroring": false}))
            }
            "get" => self.get(request.body.time_s),
            "list" => Ok(json!({"inspections": self.state.inspections})),
            "remove" => {
                let unknown: Vec<&String> = request
                    .body
                    .ids
                    .iter()
                    .filter(|id| !self.state.inspections.iter().any(|i| &i.id == *id))
                    .collect();
                if request.body.ids.is_empty() || !unknown.is_empty() {
                    return Err(format!(
                        "remove needs existing inspection ids; unknown: {unknown:?}"
                    ));
                }
                self.state
                    .journal(json!({"op": "remove", "ids": request.body.ids}))?;
                self.state
                    .inspections
                    .retain(|i| !request.body.ids.contains(&i.id));
                Ok(json!({"inspections": self.state.inspections.len()}))
            }
            "reset" => {
                self.state.journal(json!({"op": "reset"}))?;
                self.state.inspections.clear();
                Ok(json!({"inspections": 0}))
            }
            "align" => self.align(),
            "align-cloud" => {
                let job = crate::align_cloud::from_request(
                    &request.body,
                    &self.state.template.part,
                    &self.state.folder,
                )
                .map_err(|e| e.0)?;
                let output = crate::align_cloud::align(&job).map_err(|e| e.0)?;
                serde_json::to_value(output).map_err(|e| e.to_string())
            }
            "diagnose" => {
                // Exactly what `save` would write: the template's robot, tool and part with the
                // inspections in memory.
                let session = LoadedSession::resolve(self.session_file(), &self.state.folder)
                    .map_err(|e| e.0)?;
                let diagnosed = crate::diagnose::diagnose_session(&session).map_err(|e| e.0)?;
                serde_json::to_value(diagnosed.output(None)).map_err(|e| e.to_string())
            }
            "save" => {
                let path = request.body.path.ok_or("save needs a 'path'")?;
                let mut file = self.session_file();
                // The file may land anywhere: paths relative to the template would break.
                let absolute = |relative: &str| {
                    let joined = self.state.folder.join(relative);
                    joined
                        .canonicalize()
                        .unwrap_or(joined)
                        .display()
                        .to_string()
                };
                file.part.mesh = absolute(&file.part.mesh);
                if let Some(robot) = &mut file.robot {
                    robot.urdf = absolute(&robot.urdf);
                    for dir in robot.package_dirs.values_mut() {
                        *dir = absolute(dir);
                    }
                }
                let text = serde_json::to_string_pretty(&file).map_err(|e| e.to_string())?;
                std::fs::write(&path, text + "\n")
                    .map_err(|e| format!("cannot write '{path}': {e}"))?;
                Ok(json!({"path": path, "inspections": file.inspections.len()}))
            }
            "load" => {
                let path = request.body.path.ok_or("load needs a 'path'")?;
                let text = std::fs::read_to_string(&path)
                    .map_err(|e| format!("cannot read '{path}': {e}"))?;
                let file: SessionFile =
                    serde_json::from_str(&text).map_err(|e| format!("session '{path}': {e}"))?;
                if file.format != crate::session::FORMAT {
                    return Err(format!(
                        "session '{path}': format '{}' is not '{}'",
                        file.format,
                        crate::session::FORMAT
                    ));
                }
                // One journal entry, so a crash leaves either the old list or the new one.
                self.state
                    .journal(json!({"op": "load", "inspections": file.inspections}))?;
                self.state.next_id = file
                    .inspections
                    .iter()
                    .filter_map(|i| i.id.parse().ok())
                    .max()
                    .unwrap_or(0)
                    + 1;
                self.state.inspections = file.inspections;
                Ok(json!({"inspections": self.state.inspections.len()}))
            }
            other => Err(format!(
                "unknown command '{other}' (expected status, start, stop, get, list, remove, reset, align, align-cloud, diagnose, save or load)"
            )),
        }
    }

    fn session_file(&self) -> SessionFile {
        let mut file = self.state.template.clone();
        file.inspections = self.state.inspections.clone();
        file
    }

    fn status(&self) -> Value {
        let latest = self
            .latest
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone();
        let age = latest.as_ref().map(|s| s.received.elapsed().as_secs_f64());
        json!({
            "mirroring": self.state.mirroring,
            "inspections": self.state.inspections.len(),
            "sample_age_s": age,
            "stale": age.is_none_or(|a| a > self.config.max_sample_age_s),
        })
    }

    /// Captures the latest sample, or with `time_s` the first sample at or after that controller
    /// time (a touch-trigger probe's time stamp), as an inspection.
    fn get(&mut self, time_s: Option<f64>) -> Result<Value, String> {
        let latest = self
            .latest
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
            .ok_or("no joint state received yet: start mirroring first")?;
        let age = latest.received.elapsed().as_secs_f64();
        if age > self.config.max_sample_age_s {
            return Err(format!(
                "latest joint state is {age:.3} s old (limit {} s): is the bridge mirroring and the robot connected?",
                self.config.max_sample_age_s
            ));
        }
        let latest = match time_s {
            None => latest,
            Some(time_s) => self.sample_at(time_s)?,
        };
        let (base_from_flange, jacobian) = {
            self.chain
                .check_joints(&latest.q)
                .map_err(|e| e.to_string())?;
            self.chain.jacobian_unchecked(&latest.q)
        };
        // TCP velocity: flange linear velocity plus omega x (flange -> TCP lever).
        let twist = &jacobian * nalgebra::DVector::from_column_slice(&latest.qd);
        let linear = Vector3::new(twist[0], twist[1], twist[2]);
        let angular = Vector3::new(twist[3], twist[4], twist[5]);
        let lever = base_from_flange.rotation * self.tool.flange_from_tcp.translation.vector;
        let speed = (linear + angular.cross(&lever)).norm();
        if speed > self.config.max_tool_speed_m_s {
            return Err(format!(
                "the tool moves at {:.1} mm/s (limit {:.1} mm/s): take touches at rest",
                speed * 1e3,
                self.config.max_tool_speed_m_s * 1e3
            ));
        }
        let inspection = Inspection {
            id: self.state.next_id.to_string(),
            q: Some(latest.q),
            flange_pose: None,
            qd: Some(latest.qd),
            stamp: Some(latest.controller_time),
            face: None,
        };
        self.state
            .journal(json!({"op": "add", "inspection": inspection}))?;
        self.state.next_id += 1;
        self.state.inspections.push(inspection.clone());
        Ok(serde_json::to_value(&inspection).unwrap_or(Value::Null))
    }

    /// The first recorded sample at or after controller time `time_s`, at most 50 ms after it.
    fn sample_at(&self, time_s: f64) -> Result<LatestSample, String> {
        if !time_s.is_finite() {
            return Err("get: time_s must be a finite controller time".to_owned());
        }
        let history = self.history.lock().unwrap_or_else(|p| p.into_inner());
        let found = history
            .iter()
            .find(|sample| sample.controller_time >= time_s - 1e-9);
        match found {
            Some(sample) if sample.controller_time - time_s <= 0.05 => Ok(sample.clone()),
            _ => Err(format!(
                "no joint sample at controller time {time_s:.4} s (the {} kept cover {:.4}-{:.4} s)",
                history.len(),
                history.front().map_or(f64::NAN, |s| s.controller_time),
                history.back().map_or(f64::NAN, |s| s.controller_time)
            )),
        }
    }

    fn align(&self) -> Result<Value, String> {
        let session =
            LoadedSession::resolve(self.session_file(), &self.state.folder).map_err(|e| e.0)?;
        let target = PsaTarget::new(&session.mesh)
            .with_faces(&session.faces)
            .map_err(|e| e.to_string())?;
        let options = PsaOptions {
            tip_radius_m: session.tool.tip_radius_m,
            ..PsaOptions::default()
        };
        let result = align_touches(
            &target,
            &session.touches,
            &session.base_from_part_nominal,
            &options,
        )
        .map_err(|e| format!("cannot align: {e}"))?;
        serde_json::to_value(crate::align::report(&session, &result)).map_err(|e| e.to_string())
    }
}
