//! The alignment service's requests and replies (`ips serve`, REP, default `tcp://*:4000`), in
//! the thesis's envelope with `"type": "request"` and `"type": "reply"`.

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::envelope::{Envelope, Header, IPS, Message, ProtocolError, check_envelope_shape};
use crate::pose::Pose;
use crate::session::Inspection;

/// Name of the alignment service in headers.
pub const SERVICE: &str = "align";

/// Requests larger than this are refused unread (the largest, an align-cloud, is ~300 bytes).
pub const MAX_SERVICE_REQUEST_BYTES: usize = 64 * 1024;

/// What a service request asks for: the body, tagged by its `command`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "command", rename_all = "kebab-case")]
pub enum ServiceCommand {
    /// Mirroring, inspection count and the age of the latest joint state.
    Status,
    /// Ask the bridge to start mirroring the robot.
    Start,
    /// Ask the bridge to stop mirroring.
    Stop,
    /// Capture an inspection.
    Get(GetRequest),
    List,
    Remove(RemoveRequest),
    Reset,
    /// Point Set Alignment of the session's part to the inspections.
    Align,
    /// Point Cloud Alignment of a scanner cloud file.
    AlignCloud(Box<AlignCloudRequest>),
    Diagnose,
    /// Write the session (robot, tool, part, inspections) to `path`.
    Save(PathRequest),
    /// Replace the inspections with those of the session file at `path`.
    Load(PathRequest),
    /// The latest alignment and diagnosis this service computed (whoever asked for them) and
    /// the latest next-touch suggestion.
    Results,
}

impl ServiceCommand {
    /// Every command's name, as the `command` field spells it.
    pub const NAMES: [&'static str; 13] = [
        "status",
        "start",
        "stop",
        "get",
        "list",
        "remove",
        "reset",
        "align",
        "align-cloud",
        "diagnose",
        "save",
        "load",
        "results",
    ];

    pub fn name(&self) -> &'static str {
        match self {
            ServiceCommand::Status => "status",
            ServiceCommand::Start => "start",
            ServiceCommand::Stop => "stop",
            ServiceCommand::Get(_) => "get",
            ServiceCommand::List => "list",
            ServiceCommand::Remove(_) => "remove",
            ServiceCommand::Reset => "reset",
            ServiceCommand::Align => "align",
            ServiceCommand::AlignCloud(_) => "align-cloud",
            ServiceCommand::Diagnose => "diagnose",
            ServiceCommand::Save(_) => "save",
            ServiceCommand::Load(_) => "load",
            ServiceCommand::Results => "results",
        }
    }
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GetRequest {
    /// The controller time of the touch, s (e.g. a touch-trigger probe's signal): the sample at
    /// or just after it is captured instead of the latest.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_s: Option<f64>,
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RemoveRequest {
    /// Inspection ids.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ids: Vec<String>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PathRequest {
    /// A session file, as the service sees the path.
    pub path: String,
}

/// An `align-cloud` request; what it leaves out the service takes from its session.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct AlignCloudRequest {
    /// Scanner cloud file, as the service sees the path.
    pub cloud: String,
    /// Unit of the cloud file in metres, 0.001 for mm (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cloud_scale: Option<f64>,
    /// A part mesh to align instead of the session's part.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh: Option<String>,
    /// Unit of `mesh` in metres (only with `mesh`; default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh_scale: Option<f64>,
    /// The part pose `base_from_part` the alignment starts from (default the session part's
    /// nominal pose).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start_pose: Option<Pose>,
    /// Upper bound of the start pose's error, m: the thesis's delta (default 0.1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delta_m: Option<f64>,
    /// The thesis's SVD step instead of point-to-plane (default false).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub point_to_point: Option<bool>,
    /// Delta shrinks as cos^2 over 100 iterations (the thesis's code) instead of halving each
    /// time the pose settles (default false).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cos_squared: Option<bool>,
    /// Delta shrinks as cos over 100 iterations (the thesis's eq. 33) instead of halving each
    /// time the pose settles (default false; not with `cos_squared`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cosine: Option<bool>,
    /// No exploration of orientations around the start pose, the thesis's behaviour (default
    /// false).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub local: Option<bool>,
}

pub type ServiceRequest = Envelope<ServiceCommand>;

/// A request from IPS to the service.
pub fn service_request(command: ServiceCommand) -> ServiceRequest {
    Envelope {
        header: Header {
            from: IPS.to_owned(),
            to: SERVICE.to_owned(),
            kind: "request".to_owned(),
        },
        body: command,
    }
}

/// Parses a service request, naming what is wrong with it when it is not one: too large, not
/// JSON (with a hint for Python's NaN), not objects, an unknown command, or a command whose
/// fields have the wrong shape.
pub fn parse_service_request(bytes: &[u8]) -> Result<ServiceRequest, ProtocolError> {
    if bytes.len() > MAX_SERVICE_REQUEST_BYTES {
        return Err(ProtocolError::TooLarge {
            bytes: bytes.len(),
            limit: MAX_SERVICE_REQUEST_BYTES,
        });
    }
    let value: serde_json::Value = serde_json::from_slice(bytes).map_err(|error| {
        // Python's json module writes NaN and Infinity by default; serde only says "expected
        // value", which does not point at the number.
        let text = String::from_utf8_lossy(bytes);
        let hint = if text.contains("NaN") || text.contains("Infinity") {
            " (NaN and Infinity are not JSON numbers: send finite values)"
        } else {
            ""
        };
        ProtocolError::Json(format!("{error}{hint}"))
    })?;
    check_envelope_shape(&value)?;
    let command = &value["body"]["command"];
    let Some(name) = command.as_str() else {
        return Err(ProtocolError::Shape(
            "body.command must be a string naming the command".to_owned(),
        ));
    };
    if !ServiceCommand::NAMES.contains(&name) {
        return Err(ProtocolError::UnknownServiceCommand(name.to_owned()));
    }
    let name = name.to_owned();
    let request: ServiceRequest = serde_json::from_value(value).map_err(|error| {
        let message = error.to_string();
        // "missing field `path`" says less than which request needs it.
        match message
            .strip_prefix("missing field `")
            .and_then(|rest| rest.split_once('`'))
        {
            Some((field, _)) => ProtocolError::Shape(format!("{name} needs a '{field}'")),
            None => ProtocolError::Shape(format!("{name}: {message}")),
        }
    })?;
    request.validate()?;
    Ok(request)
}

impl Message for ServiceRequest {
    /// Refuses non-finite numbers, which serde_json would write as `null`: the service would
    /// then answer about a type error the sender never made.
    fn validate(&self) -> Result<(), ProtocolError> {
        match &self.body {
            ServiceCommand::Get(get) => match get.time_s {
                Some(time_s) if !time_s.is_finite() => {
                    Err(ProtocolError::NonFinite(".body.time_s".to_owned()))
                }
                _ => Ok(()),
            },
            ServiceCommand::AlignCloud(request) => {
                let scalars = [
                    ("cloud_scale", request.cloud_scale),
                    ("mesh_scale", request.mesh_scale),
                    ("delta_m", request.delta_m),
                ];
                for (name, value) in scalars {
                    if value.is_some_and(|v| !v.is_finite()) {
                        return Err(ProtocolError::NonFinite(format!(".body.{name}")));
                    }
                }
                match request.start_pose.as_ref().and_then(Pose::first_non_finite) {
                    Some(index) => Err(ProtocolError::NonFinite(format!(
                        ".body.start_pose.{index}"
                    ))),
                    None => Ok(()),
                }
            }
            _ => Ok(()),
        }
    }
}

/// The service's reply, `"type": "reply"`: `ok`, a `reason` when not, and the command's data.
/// The data is held as a JSON value so the reply has one shape whatever the command: build it
/// with [`service_reply_ok`] from the command's typed reply and read it with
/// [`ServiceReplyBody::into_data`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ServiceReplyBody {
    pub ok: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    #[serde(default, skip_serializing_if = "serde_json::Value::is_null")]
    data: serde_json::Value,
}

pub type ServiceReply = Envelope<ServiceReplyBody>;

fn reply(body: ServiceReplyBody) -> ServiceReply {
    Envelope {
        header: Header {
            from: SERVICE.to_owned(),
            to: IPS.to_owned(),
            kind: "reply".to_owned(),
        },
        body,
    }
}

/// A success carrying `data`, one of this module's reply types (or a report).
pub fn service_reply_ok<T: Serialize>(data: &T) -> Result<ServiceReply, ProtocolError> {
    let data =
        serde_json::to_value(data).map_err(|error| ProtocolError::Shape(error.to_string()))?;
    Ok(reply(ServiceReplyBody {
        ok: true,
        reason: None,
        data,
    }))
}

/// A refusal with its reason.
pub fn service_reply_error(reason: impl Into<String>) -> ServiceReply {
    reply(ServiceReplyBody {
        ok: false,
        reason: Some(reason.into()),
        data: serde_json::Value::Null,
    })
}

/// Why a reply gave no data.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReplyError {
    /// The service refused the request, with its reason.
    #[error("{0}")]
    Refused(String),
    /// The reply is not the document the request's command replies.
    #[error("the service's {command} reply is not the document: {reason}")]
    Shape { command: String, reason: String },
}

impl ServiceReplyBody {
    /// The data as the reply type of `command` (named in errors).
    pub fn into_data<T: DeserializeOwned>(self, command: &str) -> Result<T, ReplyError> {
        if !self.ok {
            return Err(ReplyError::Refused(
                self.reason.unwrap_or_else(|| "refused".to_owned()),
            ));
        }
        serde_json::from_value(self.data).map_err(|error| ReplyError::Shape {
            command: command.to_owned(),
            reason: error.to_string(),
        })
    }
}

impl Message for ServiceReply {
    fn validate(&self) -> Result<(), ProtocolError> {
        Ok(())
    }
}

/// `status`: fields in alphabetical order, as the documents have always been written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StatusReply {
    pub inspections: usize,
    /// Which kinematics turn joints into touches: the description's nominal ones, or the
    /// controller's factory calibration (with its hash); absent before the bridge was asked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kinematics: Option<String>,
    pub mirroring: bool,
    /// Counts the alignments and diagnoses the service computed: a client that shows results
    /// asks for `results` when it changes.
    #[serde(default)]
    pub results_serial: u64,
    /// Age of the latest joint state, s; null before the first.
    pub sample_age_s: Option<f64>,
    /// True when there is no joint state or it is older than the service's limit.
    pub stale: bool,
}

/// `get`: the inspection taken, and where its ball is: what an operator checks before the next
/// touch. Clients that read an [`crate::session::Inspection`] from it ignore the rest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GetReply {
    #[serde(flatten)]
    pub inspection: Inspection,
    /// The ball centre in the robot's base frame, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ball_centre_mm: Option<[f64; 3]>,
    /// The ball's signed distance from the surface of the part at its nominal pose, mm
    /// (negative inside): near zero for a touch on the part where the simulation has it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nominal_surface_distance_mm: Option<f64>,
    /// A warning about the touch, e.g. a ball far from the nominal part.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// Outward normal of the nominal part's surface nearest the ball (base frame): which face
    /// the touch was on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nominal_surface_normal: Option<[f64; 3]>,
    /// Where to touch next to learn the most about the part's pose.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub next_touch: Option<NextTouchHint>,
}

/// A suggested next touch on the part at its nominal pose, base frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NextTouchHint {
    /// The surface point to touch, mm.
    pub point_mm: [f64; 3],
    /// Outward normal of the surface there.
    pub normal: [f64; 3],
    /// Direction to move the probe in (into the surface), unit vector.
    pub approach: [f64; 3],
    /// Tilt of that direction from the inward normal, degrees (0 = head-on).
    pub tilt_deg: f64,
    /// Why this touch.
    pub reason: String,
}

/// `start` and `stop`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MirroringReply {
    pub mirroring: bool,
}

/// `list`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InspectionsReply {
    pub inspections: Vec<Inspection>,
    /// Where each inspection's ball was, as `get` and `align` place it (the kinematics in use
    /// and the session's joint corrections); inspections with joints only.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub balls: Vec<BallPlace>,
}

/// An inspection's ball in the robot's base frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BallPlace {
    pub id: String,
    /// The ball centre, mm.
    pub centre_mm: [f64; 3],
    /// The tool's axis (TCP z) at the touch: the direction the probe moved in.
    pub approach: [f64; 3],
}

/// `remove`, `reset` and `load`: how many inspections are left.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InspectionCountReply {
    pub inspections: usize,
}

/// `save`: where the session went and how many inspections it holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SavedReply {
    pub inspections: usize,
    pub path: String,
    /// The results written with the inspections (`alignment`, `diagnosis`): the last ones
    /// computed from exactly these inspections.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub results: Vec<String>,
}

/// `results`: the latest alignment and diagnosis the service computed, whoever asked for them,
/// and the next touch the latest `get` suggested.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ResultsReply {
    /// `status`'s `results_serial` when these were read.
    pub serial: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alignment: Option<LatestResult<crate::reports::AlignReport>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diagnosis: Option<LatestResult<crate::reports::DiagnoseReport>>,
    /// Cleared when inspections are removed, reset or loaded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub next_touch: Option<NextTouchHint>,
}

/// A result and whether it still describes the inspections the service holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LatestResult<T> {
    /// The inspections it was computed from.
    pub inspections: Vec<String>,
    /// True while those are exactly the service's inspections (none removed, none added).
    pub current: bool,
    /// `results_serial` when it was computed (0: read from the session file): the larger of
    /// two results' is the newer.
    pub serial: u64,
    pub report: T,
}
