//! The request thread: one handler per [`ServiceCommand`], each returning its typed reply.

use std::panic::AssertUnwindSafe;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use align_core::guidance::{self, TakenTouch};
use align_core::kinematics::Chain;
use align_core::tool::Tool;
use nalgebra::{DVector, Vector3};
use protocol::reports::{AlignReport, CloudReport, DiagnoseReport};
use protocol::session::{Inspection, SavedResult, SessionFile, SessionResults};
use protocol::{
    AlignCloudRequest, BallPlace, Command, GetReply, InspectionCountReply, InspectionsReply,
    JournalEntry, LatestResult, MirroringReply, NextTouchHint, ProtocolError, ResultsReply,
    RobotSide, SavedReply, ServiceCommand, ServiceReply, StatusReply,
};
use reply_socket::{ReplySocket, Wait};
use serde::Serialize;
use serde::de::DeserializeOwned;

use super::files::{
    CLOUD_FILE_LIMIT_BYTES, FileAccess, MESH_FILE_LIMIT_BYTES, SESSION_FILE_LIMIT_BYTES,
};
use super::journal::{Journal, highest_id};
use super::samples::{JointSample, Samples};
use super::{Config, socket};
use crate::BadInput;
use crate::jobs::{align, cloud, diagnose};
use crate::session::{Calibration, LoadedSession, check_inspection, parse_session_file};

/// Why a request was refused; its text is the reply's `reason`.
#[derive(Debug, thiserror::Error)]
pub(crate) enum RequestError {
    /// Not a service request, or one with the wrong shape.
    #[error(transparent)]
    Malformed(#[from] ProtocolError),
    /// The request's files or data are unusable.
    #[error(transparent)]
    BadInput(#[from] BadInput),
    /// The service's state does not allow it now (a stale joint state, unknown ids, the bridge).
    #[error("{0}")]
    Refused(String),
}

impl From<String> for RequestError {
    fn from(reason: String) -> Self {
        RequestError::Refused(reason)
    }
}

type Handled<T> = Result<T, RequestError>;

pub(crate) struct Service {
    pub template: SessionFile,
    /// The session file's folder: its relative paths are relative to it.
    pub folder: PathBuf,
    pub inspections: Vec<Inspection>,
    pub next_id: u64,
    pub journal: Journal,
    pub mirroring: bool,
    pub samples: Arc<Samples>,
    pub config: Config,
    pub context: zmq::Context,
    /// How the bridge names itself in headers (`ros`, `IiwaDrive`), learnt from its status.
    pub bridge_side: Option<RobotSide>,
    /// The files requests may name.
    pub files: FileAccess,
    pub chain: Chain,
    pub tool: Tool,
    /// The part and its nominal pose, to say where each touch's ball is.
    pub part_mesh: align_core::geometry::Mesh,
    pub base_from_part_nominal: nalgebra::Isometry3<f64>,
    /// The session's declared joint corrections (`robot.joint_offsets`, ...), applied to the
    /// joints of every touch placed here as `align` applies them.
    pub corrections: crate::session::JointCorrections,
    /// The session robot's chain as its description has it (`chain` may be calibrated).
    pub nominal_chain: Chain,
    /// The controller's factory calibration, learnt from the bridge on `start`.
    pub calibration: Option<Calibration>,
    /// Which kinematics are in use, for `status`; `None` before the bridge was asked.
    pub kinematics_note: Option<String>,
    /// The last alignment and diagnosis, each with the inspections it used: `save` keeps those
    /// that still describe the inspections.
    pub results: SessionResults,
    /// Counts the alignments and diagnoses computed (`status`'s `results_serial`).
    pub results_serial: u64,
    /// `results_serial` when the alignment and the diagnosis in `results` were computed.
    pub alignment_serial: u64,
    pub diagnosis_serial: u64,
    /// The suggestion the latest `get` made, until the inspections change otherwise.
    pub latest_next_touch: Option<NextTouchHint>,
    /// Places on the nominal part a next touch may go, drawn at the first `get`.
    pub touch_candidates: std::sync::OnceLock<Vec<guidance::Candidate>>,
}

/// A suggested touch as the `get` reply carries it.
fn hint(next: guidance::NextTouch) -> NextTouchHint {
    let triple = |v: Vector3<f64>| [v.x, v.y, v.z];
    NextTouchHint {
        point_mm: triple(next.point.coords * 1e3),
        normal: triple(next.normal),
        approach: triple(next.approach),
        tilt_deg: next.tilt_rad.to_degrees(),
        reason: next.reason,
    }
}

/// A ball farther than this from the nominal part's surface is named in the `get` reply: a
/// touch of another object, or a nominal pose far off. A cell's nominal pose is usually within
/// a few millimetres of the part; 40 mm off is the example of a touch to question. The
/// demo hides its part 42 mm from the nominal pose, so its touches carry the note, rightly.
const FAR_FROM_NOMINAL_M: f64 = 0.03;

fn reply<T: Serialize>(result: Handled<T>) -> ServiceReply {
    match result.map(|data| protocol::service_reply_ok(&data)) {
        Ok(Ok(reply)) => reply,
        Ok(Err(error)) => {
            protocol::service_reply_error(format!("cannot encode the reply: {error}"))
        }
        Err(error) => protocol::service_reply_error(error.to_string()),
    }
}

/// Runs `handle` on `request`, answering with an internal error instead of unwinding through
/// the request loop when it panics: one request's bug must not take down the service and every
/// client with it. The panic itself is logged by the panic hook (stderr). Handlers journal a
/// change before they make it, so a handler that fails midway leaves the journal consistent.
pub(crate) fn guarded(request: &[u8], handle: impl FnOnce(&[u8]) -> ServiceReply) -> ServiceReply {
    match std::panic::catch_unwind(AssertUnwindSafe(|| handle(request))) {
        Ok(reply) => reply,
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| (*s).to_owned())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "a panic without a message".to_owned());
            tracing::error!(panic = %what, "internal error while handling a request");
            protocol::service_reply_error(format!(
                "internal error: {what} (a bug: the request was not carried out; the service keeps serving)"
            ))
        }
    }
}

impl Service {
    pub(crate) fn serve(&mut self, rep: &ReplySocket, stop: &AtomicBool) {
        while !stop.load(Ordering::Relaxed) {
            // Between requests, at least every receive timeout (100 ms).
            self.capture_triggered();
            let request = match rep.receive() {
                Wait::Request(request) => request,
                Wait::Nothing => continue,
                Wait::Closed => return,
            };
            let started = std::time::Instant::now();
            let reply = match request.single_frame(protocol::MAX_SERVICE_REQUEST_BYTES) {
                Ok(frame) => guarded(frame, |bytes| self.handle(bytes)),
                Err(reason) => {
                    tracing::warn!(%reason, "malformed request refused");
                    protocol::service_reply_error(reason)
                }
            };
            tracing::debug!(
                ok = reply.body.ok,
                elapsed_ms = started.elapsed().as_secs_f64() * 1e3,
                reason = reply.body.reason.as_deref().unwrap_or(""),
                "request answered"
            );
            let text = protocol::to_json(&reply).unwrap_or_default();
            // A reply to a client that has gone is dropped; nothing is left owing.
            let _ = rep.reply(&request, text.as_bytes());
        }
    }

    pub(crate) fn stop_mirroring_on_exit(&mut self) {
        if self.mirroring {
            let _ = self.bridge(Command::Stop);
        }
    }

    fn handle(&mut self, bytes: &[u8]) -> ServiceReply {
        let request = match protocol::parse_service_request(bytes) {
            Ok(request) => request,
            Err(error) => {
                tracing::warn!(%error, bytes = bytes.len(), "malformed request refused");
                return reply::<()>(Err(error.into()));
            }
        };
        tracing::debug!(command = request.body.name(), "request");
        match request.body {
            ServiceCommand::Status => reply(Ok(self.status())),
            ServiceCommand::Start => reply(self.set_mirroring(true)),
            ServiceCommand::Stop => reply(self.set_mirroring(false)),
            ServiceCommand::Get(get) => reply(self.get(get.time_s)),
            ServiceCommand::List => reply(Ok(InspectionsReply {
                inspections: self.inspections.clone(),
                balls: self.balls(),
            })),
            ServiceCommand::Remove(remove) => reply(self.remove(remove.ids)),
            ServiceCommand::Reset => reply(self.reset()),
            ServiceCommand::Align => reply(self.align()),
            ServiceCommand::AlignCloud(request) => reply(self.align_cloud(&request)),
            ServiceCommand::Diagnose => reply(self.diagnose()),
            ServiceCommand::Save(save) => reply(self.save(save.path)),
            ServiceCommand::Load(load) => reply(self.load(load.path)),
            ServiceCommand::Results => reply(Ok(self.latest_results())),
        }
    }

    fn journal(&mut self, entry: &JournalEntry) -> Handled<()> {
        self.journal.append(entry).map_err(|reason| {
            tracing::warn!(%reason, "journal write failed: the change is refused");
            RequestError::Refused(reason)
        })
    }

    /// What `save` would write: the template's robot, tool and part with the inspections in
    /// memory.
    fn session_file(&self) -> SessionFile {
        let mut file = self.template.clone();
        file.inspections = self.inspections.clone();
        let ids = self.inspection_ids();
        let results = SessionResults {
            alignment: self
                .results
                .alignment
                .clone()
                .filter(|saved| saved.inspections == ids),
            diagnosis: self
                .results
                .diagnosis
                .clone()
                .filter(|saved| saved.inspections == ids),
        };
        file.results =
            (results.alignment.is_some() || results.diagnosis.is_some()).then_some(results);
        // The controller's calibration, when one is in use, travels with the touches it made.
        if let (Some(robot), Some(calibration)) = (&mut file.robot, &self.calibration) {
            robot.kinematics = Some(calibration.to_kinematics());
        }
        file
    }

    fn status(&self) -> StatusReply {
        let age = self
            .samples
            .latest()
            .map(|s| s.received.elapsed().as_secs_f64());
        StatusReply {
            inspections: self.inspections.len(),
            kinematics: self.kinematics_note.clone(),
            mirroring: self.mirroring,
            results_serial: self.results_serial,
            sample_age_s: age,
            stale: age.is_none_or(|a| a > self.config.max_sample_age_s),
        }
    }

    fn set_mirroring(&mut self, mirroring: bool) -> Handled<MirroringReply> {
        self.bridge(if mirroring {
            Command::Start
        } else {
            Command::Stop
        })?;
        self.mirroring = mirroring;
        if mirroring {
            self.learn_kinematics();
        }
        Ok(MirroringReply { mirroring })
    }

    /// Asks the bridge which kinematics its controller reported (a UR's factory calibration)
    /// and, when they fit the session's robot, turns joints into touches with them from now on.
    /// Anything else keeps the nominal kinematics, with the reason in the log and `status`.
    fn learn_kinematics(&mut self) {
        let side = self.bridge_side.unwrap_or(RobotSide::Ros);
        let status: Result<protocol::Status, String> = self.instruct(side, Command::Status);
        let applied = match status.map(|status| status.body.kinematics) {
            Ok(Some(kinematics)) => Calibration::for_chain(&kinematics, &self.nominal_chain)
                .and_then(|calibration| {
                    let chain = calibration.apply(&self.nominal_chain)?;
                    Ok((calibration, chain))
                })
                .map_err(|reason| {
                    tracing::warn!(%reason, "the controller's calibration is not used");
                    format!("nominal (the controller's calibration does not apply: {reason})")
                }),
            Ok(None) => Err("nominal (the controller reports no calibration)".to_owned()),
            Err(reason) => Err(format!("nominal (bridge status: {reason})")),
        };
        let (calibration, chain, note) = match applied {
            Ok((calibration, chain)) => {
                let note = calibration.describe();
                (Some(calibration), chain, note)
            }
            Err(note) => (None, self.nominal_chain.clone(), note),
        };
        if calibration != self.calibration {
            tracing::info!(kinematics = %note, "kinematics for touches");
        }
        self.chain = chain;
        self.calibration = calibration;
        self.kinematics_note = Some(note);
    }

    /// Sends one of the thesis's instructions to the bridge and returns its reply (an ack, or
    /// for `status` the bridge's status), or why not.
    fn instruct<T: DeserializeOwned>(&self, to: RobotSide, command: Command) -> Result<T, String> {
        let endpoint = &self.config.bridge_rep;
        let req =
            socket(&self.context, zmq::REQ, 2000, endpoint).map_err(|error| error.to_string())?;
        req.connect(endpoint).map_err(|e| e.to_string())?;
        let text =
            protocol::to_json(&protocol::instruction(to, command)).map_err(|e| e.to_string())?;
        req.send(text.as_bytes(), 0)
            .map_err(|e| format!("bridge unreachable: {e}"))?;
        let reply = req
            .recv_bytes(0)
            .map_err(|_| format!("no answer from the bridge at {endpoint} within 2 s"))?;
        serde_json::from_slice(&reply)
            .map_err(|e| format!("bad {} reply from the bridge: {e}", command.name()))
    }

    /// Asks the bridge to start or stop mirroring, addressed as the bridge names itself: a UR
    /// bridge is the thesis's "ros", an iiwa bridge "IiwaDrive". The name is learnt once from
    /// the `from` of the bridge's status reply.
    fn bridge(&mut self, command: Command) -> Result<(), String> {
        let side = match self.bridge_side {
            Some(side) => side,
            None => {
                let status: protocol::Status = self.instruct(RobotSide::Ros, Command::Status)?;
                let side = RobotSide::from_name(&status.header.from).unwrap_or(RobotSide::Ros);
                self.bridge_side = Some(side);
                side
            }
        };
        let ack: protocol::Instruction = self.instruct(side, command)?;
        if ack.body.content == "ok" {
            Ok(())
        } else {
            Err(format!(
                "the bridge refused: {}",
                ack.body.reason.unwrap_or_default()
            ))
        }
    }

    /// Captures the latest sample, or with `time_s` the first sample at or after that controller
    /// time (a touch-trigger probe's time stamp), as an inspection.
    fn get(&mut self, time_s: Option<f64>) -> Handled<GetReply> {
        let latest = self
            .samples
            .latest()
            .ok_or("no joint state received yet: start mirroring first".to_owned())?;
        let age = latest.received.elapsed().as_secs_f64();
        if age > self.config.max_sample_age_s {
            return Err(format!(
                "latest joint state is {age:.3} s old (limit {} s): is the bridge mirroring and the robot connected?",
                self.config.max_sample_age_s
            )
            .into());
        }
        let sample = match time_s {
            None => latest,
            Some(time_s) => self.samples.at(time_s)?,
        };
        self.check_at_rest(&sample)?;
        let inspection = Inspection {
            id: self.next_id.to_string(),
            q: Some(sample.q),
            flange_pose: None,
            qd: Some(sample.qd),
            stamp: Some(sample.controller_time),
            face: None,
            trigger: None,
        };
        self.journal(&JournalEntry::Add {
            inspection: inspection.clone(),
        })?;
        self.next_id += 1;
        self.inspections.push(inspection.clone());
        let reply = self.where_the_ball_is(inspection);
        self.latest_next_touch = reply.next_touch.clone();
        Ok(reply)
    }

    /// `results`: the latest alignment and diagnosis, each saying whether it still describes
    /// the inspections held, and the latest suggestion.
    fn latest_results(&self) -> ResultsReply {
        fn latest<T: Clone>(
            saved: &SavedResult<T>,
            ids: &[String],
            serial: u64,
        ) -> LatestResult<T> {
            LatestResult {
                current: saved.inspections == ids,
                serial,
                inspections: saved.inspections.clone(),
                report: saved.report.clone(),
            }
        }
        let ids = self.inspection_ids();
        ResultsReply {
            serial: self.results_serial,
            alignment: (self.results.alignment.as_ref())
                .map(|s| latest(s, &ids, self.alignment_serial)),
            diagnosis: (self.results.diagnosis.as_ref())
                .map(|s| latest(s, &ids, self.diagnosis_serial)),
            next_touch: self.latest_next_touch.clone(),
        }
    }

    /// Where the inspection's TCP (the ball's centre) was: the joints as the session's model
    /// uses them (its declared corrections applied) through the kinematics in use (the
    /// controller's calibration when it reported one), as `align` places it. `None` for an
    /// inspection given as a flange pose.
    fn base_from_tcp(&self, inspection: &Inspection) -> Option<nalgebra::Isometry3<f64>> {
        let q = inspection.q.as_ref()?;
        let q = self
            .corrections
            .corrected(q, inspection.qd.as_deref(), &self.chain);
        Some(self.tool.base_from_tcp(&self.chain.forward_unchecked(&q)))
    }

    /// `list`'s ball places.
    fn balls(&self) -> Vec<BallPlace> {
        let triple = |v: Vector3<f64>| [v.x, v.y, v.z];
        self.inspections
            .iter()
            .filter_map(|inspection| {
                let tcp = self.base_from_tcp(inspection)?;
                Some(BallPlace {
                    id: inspection.id.clone(),
                    centre_mm: triple(tcp.translation.vector * 1e3),
                    approach: triple(tcp.rotation * Vector3::z()),
                })
            })
            .collect()
    }

    /// The reply to `get`: the inspection, its ball centre, and how far that is from the part's
    /// surface at the nominal pose, with a warning when it is too far to be a touch of it.
    fn where_the_ball_is(&self, inspection: Inspection) -> GetReply {
        let next_touch = self.next_touch();
        let Some(tcp) = self.base_from_tcp(&inspection) else {
            return GetReply {
                inspection,
                ball_centre_mm: None,
                nominal_surface_distance_mm: None,
                note: None,
                nominal_surface_normal: None,
                next_touch,
            };
        };
        let centre = tcp.translation.vector;
        let in_part = self.base_from_part_nominal.inverse() * nalgebra::Point3::from(centre);
        let surface = self.part_mesh.closest_point(&in_part);
        let distance_m = surface.signed_distance - self.tool.tip_radius_m;
        let normal = self.base_from_part_nominal.rotation * surface.normal;
        let note = (distance_m.abs() > FAR_FROM_NOMINAL_M).then(|| {
            format!(
                "the ball is {:.1} mm from the nominal part's surface: probably not a touch of this part, or the nominal pose is that far off",
                distance_m * 1e3
            )
        });
        GetReply {
            inspection,
            ball_centre_mm: Some([centre.x * 1e3, centre.y * 1e3, centre.z * 1e3]),
            nominal_surface_distance_mm: Some(distance_m * 1e3),
            note,
            nominal_surface_normal: Some([normal.x, normal.y, normal.z]),
            next_touch,
        }
    }

    /// The touch that would add the most to what the inspections so far say about the part's
    /// pose, on the part at its nominal pose ([`align_core::guidance`]).
    fn next_touch(&self) -> Option<NextTouchHint> {
        let candidates = self.touch_candidates.get_or_init(|| {
            guidance::candidates(
                &self.part_mesh,
                &self.base_from_part_nominal,
                self.tool.tip_radius_m,
            )
        });
        if let Some(next) = self.separating_ambiguity(candidates) {
            return Some(next);
        }
        let taken: Vec<TakenTouch> = self
            .inspections
            .iter()
            .filter_map(|inspection| {
                let tcp = self.base_from_tcp(inspection)?;
                Some(TakenTouch {
                    ball_centre: nalgebra::Point3::from(tcp.translation.vector),
                    approach: Some(tcp.rotation * Vector3::z()),
                })
            })
            .collect();
        let next = guidance::next_touch(
            &self.part_mesh,
            &self.base_from_part_nominal,
            candidates,
            &taken,
        )?;
        Some(hint(next))
    }

    /// When the last alignment found other poses as good (and its touches are all still
    /// there), the touch that tells them apart.
    fn separating_ambiguity(&self, candidates: &[guidance::Candidate]) -> Option<NextTouchHint> {
        let saved = self.results.alignment.as_ref()?;
        let report = &saved.report;
        let ids = self.inspection_ids();
        if !report.ambiguous || !saved.inspections.iter().all(|id| ids.contains(id)) {
            return None;
        }
        let pose = |p: &protocol::Pose| align_core::pose::isometry_from_xyz_rpy(p.xyz, p.rpy);
        let alternatives: Vec<_> = report.candidates.iter().map(|c| pose(&c.pose)).collect();
        guidance::separating_touch(
            &self.part_mesh,
            &pose(&report.alignment.pose),
            &alternatives,
            candidates,
        )
        .map(hint)
    }

    /// Refuses a sample whose tool moves faster than the limit: a touch is taken at rest.
    fn check_at_rest(&self, sample: &JointSample) -> Result<(), String> {
        self.chain
            .check_joints(&sample.q)
            .map_err(|e| e.to_string())?;
        let (base_from_flange, jacobian) = self.chain.jacobian_unchecked(&sample.q);
        // TCP velocity: flange linear velocity plus omega x (flange -> TCP lever).
        let twist = &jacobian * DVector::from_column_slice(&sample.qd);
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
        Ok(())
    }

    fn remove(&mut self, ids: Vec<String>) -> Handled<InspectionCountReply> {
        let unknown: Vec<&String> = ids
            .iter()
            .filter(|id| !self.inspections.iter().any(|i| &i.id == *id))
            .collect();
        if ids.is_empty() || !unknown.is_empty() {
            return Err(
                format!("remove needs existing inspection ids; unknown: {unknown:?}").into(),
            );
        }
        self.journal(&JournalEntry::Remove { ids: ids.clone() })?;
        self.inspections.retain(|i| !ids.contains(&i.id));
        self.latest_next_touch = None;
        Ok(InspectionCountReply {
            inspections: self.inspections.len(),
        })
    }

    fn reset(&mut self) -> Handled<InspectionCountReply> {
        self.journal(&JournalEntry::Reset)?;
        self.inspections.clear();
        self.latest_next_touch = None;
        Ok(InspectionCountReply { inspections: 0 })
    }

    fn loaded_session(&self) -> Handled<LoadedSession> {
        // session_file() carries the calibration in use.
        Ok(LoadedSession::resolve(self.session_file(), &self.folder)?)
    }

    fn inspection_ids(&self) -> Vec<String> {
        self.inspections.iter().map(|i| i.id.clone()).collect()
    }

    fn align(&mut self) -> Handled<AlignReport> {
        let session = self.loaded_session()?;
        let result = align::align_session(&session, align::AlignChoices::default())?;
        let report = align::report(&session, &result);
        self.results.alignment = Some(SavedResult {
            inspections: self.inspection_ids(),
            report: report.clone(),
        });
        self.results_serial += 1;
        self.alignment_serial = self.results_serial;
        Ok(report)
    }

    fn align_cloud(&self, request: &AlignCloudRequest) -> Handled<CloudReport> {
        let mut job = cloud::from_request(request, &self.template.part, &self.folder)?;
        job.cloud = self
            .files
            .readable(&request.cloud, CLOUD_FILE_LIMIT_BYTES, "scanner cloud")?;
        if let Some(mesh) = &request.mesh {
            job.mesh = self.files.readable(mesh, MESH_FILE_LIMIT_BYTES, "mesh")?;
        }
        Ok(cloud::align(&job)?)
    }

    fn diagnose(&mut self) -> Handled<DiagnoseReport> {
        let session = self.loaded_session()?;
        let report = diagnose::diagnose_session(&session)?.report(None);
        self.results.diagnosis = Some(SavedResult {
            inspections: self.inspection_ids(),
            report: report.clone(),
        });
        self.results_serial += 1;
        self.diagnosis_serial = self.results_serial;
        Ok(report)
    }

    fn save(&self, path: String) -> Handled<SavedReply> {
        let mut file = self.session_file();
        // The file may land anywhere: paths relative to the template would break.
        let absolute = |relative: &str| {
            let joined = self.folder.join(relative);
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
        let text = serde_json::to_string_pretty(&file)
            .map_err(|e| RequestError::Refused(e.to_string()))?;
        let target = self.files.writable(&path)?;
        std::fs::write(&target, text + "\n").map_err(|e| format!("cannot write '{path}': {e}"))?;
        let results = file.results.as_ref();
        Ok(SavedReply {
            inspections: file.inspections.len(),
            path,
            results: [
                ("alignment", results.is_some_and(|r| r.alignment.is_some())),
                ("diagnosis", results.is_some_and(|r| r.diagnosis.is_some())),
            ]
            .into_iter()
            .filter(|(_, kept)| *kept)
            .map(|(name, _)| name.to_owned())
            .collect(),
        })
    }

    fn load(&mut self, path: String) -> Handled<InspectionCountReply> {
        let source = self
            .files
            .readable(&path, SESSION_FILE_LIMIT_BYTES, "session file")?;
        let text =
            std::fs::read_to_string(&source).map_err(|e| format!("cannot read '{path}': {e}"))?;
        let file = parse_session_file(&text, &path)?;
        // Checked before anything is journaled: a bad inspection in the journal would fail every
        // align after it, and every restart.
        for inspection in &file.inspections {
            check_inspection(inspection, &self.chain)
                .map_err(|error| BadInput(format!("session '{path}': {error}")))?;
        }
        // One journal entry, so a crash leaves either the old list or the new one.
        self.journal(&JournalEntry::Load {
            inspections: file.inspections.clone(),
        })?;
        self.next_id = highest_id(&file.inspections) + 1;
        self.inspections = file.inspections;
        self.latest_next_touch = None;
        Ok(InspectionCountReply {
            inspections: self.inspections.len(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reason(reply: &ServiceReply) -> Option<String> {
        reply.body.reason.clone()
    }

    #[test]
    fn a_handler_that_panics_gets_an_internal_error_reply_and_the_next_request_is_served() {
        let failed = guarded(b"{}", |_| panic!("index out of bounds: the len is 0"));
        assert!(!failed.body.ok);
        let why = reason(&failed).unwrap();
        assert!(
            why.starts_with("internal error: index out of bounds"),
            "{why}"
        );
        let formatted = guarded(b"{}", |_| panic!("{} touches", 3));
        assert!(reason(&formatted).unwrap().contains("3 touches"));
        let served = guarded(b"{}", |_| {
            protocol::service_reply_ok(&InspectionCountReply { inspections: 2 }).unwrap()
        });
        assert!(served.body.ok);
    }
}
