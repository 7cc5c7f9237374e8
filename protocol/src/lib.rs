//! The wire types of cobot-align's ZeroMQ links, and the only place they are defined.
//!
//! Every message is one JSON frame `{"header": {"from", "to", "type"}, "body": {...}}`, the
//! envelope of the thesis's messages (section 2.3.3). The instruction request and its ack are
//! byte-for-byte the thesis's (DESIGN.md 6.2); our additions are extra fields only (`reason` on
//! an error ack), and receivers ignore fields they do not know. The language-neutral contract
//! is in `protocol/schemas/` with golden examples in `protocol/examples/`.
//!
//! Senders validate before serialising: [`to_json`] refuses NaN or infinite numbers, which JSON
//! cannot carry and which would poison a twin downstream.

use serde::{Deserialize, Serialize};

/// Name of the IPS side in headers.
pub const IPS: &str = "ips";

/// Who the robot side is in headers: `"ros"` for UR (the thesis's ROS link), `"IiwaDrive"` for
/// the KUKA iiwa.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RobotSide {
    Ros,
    IiwaDrive,
}

impl RobotSide {
    pub fn name(self) -> &'static str {
        match self {
            RobotSide::Ros => "ros",
            RobotSide::IiwaDrive => "IiwaDrive",
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Header {
    pub from: String,
    pub to: String,
    #[serde(rename = "type")]
    pub kind: String,
}

/// `{"header": ..., "body": ...}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Envelope<B> {
    pub header: Header,
    pub body: B,
}

/// Body of instruction requests and acks.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct InstructionBody {
    pub command: String,
    pub content: String,
    /// Why a request failed (our addition; absent on the thesis's messages).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

pub type Instruction = Envelope<InstructionBody>;

/// What an instruction asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// Start mirroring the hardware state (`"content": "hwState"`).
    Start,
    /// Stop mirroring.
    Stop,
    /// Report the bridge's state (our addition).
    Status,
}

impl Command {
    pub fn name(self) -> &'static str {
        match self {
            Command::Start => "start",
            Command::Stop => "stop",
            Command::Status => "status",
        }
    }
}

/// The thesis's request: `{"header":{"from":"ips","to":<side>,"type":"instruction"},
/// "body":{"command":"start"|"stop","content":"hwState"}}`.
pub fn instruction(to: RobotSide, command: Command) -> Instruction {
    Envelope {
        header: Header {
            from: IPS.to_owned(),
            to: to.name().to_owned(),
            kind: "instruction".to_owned(),
        },
        body: InstructionBody {
            command: command.name().to_owned(),
            content: "hwState".to_owned(),
            reason: None,
        },
    }
}

/// The thesis's OK ack.
pub fn ack_ok(from: RobotSide) -> Instruction {
    ack(from, "ok", None)
}

/// The thesis's ERROR ack, with our `reason`.
pub fn ack_error(from: RobotSide, reason: impl Into<String>) -> Instruction {
    ack(from, "error", Some(reason.into()))
}

fn ack(from: RobotSide, content: &str, reason: Option<String>) -> Instruction {
    Envelope {
        header: Header {
            from: from.name().to_owned(),
            to: IPS.to_owned(),
            kind: "instruction".to_owned(),
        },
        body: InstructionBody {
            command: "ack".to_owned(),
            content: content.to_owned(),
            reason,
        },
    }
}

/// One controller sample, published on the hardware-state socket while mirroring.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HwStateBody {
    /// Joint names, in the order of the value arrays.
    pub names: Vec<String>,
    /// Joint positions, rad.
    pub position: Vec<f64>,
    /// Joint velocities, rad/s (reported by UR controllers; differentiated for the iiwa).
    pub velocity: Vec<f64>,
    /// Joint efforts where the controller gives them, in `effort_unit`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effort: Option<Vec<f64>>,
    /// "N m" (iiwa measured torque) or "A" (UR motor current).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effort_unit: Option<String>,
    /// The bridge's message counter, +1 per published sample, never reset while it runs.
    pub seq: u64,
    /// When the bridge received the sample, s since the Unix epoch.
    pub stamp: f64,
    /// The controller's own clock for the sample, s (UR: time since controller start).
    pub controller_time: f64,
    /// The controller's sample counter where it has one (FRI sequence counter).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub controller_seq: Option<u64>,
    /// UR robot mode / iiwa session state, as the controller numbers them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot_mode: Option<i32>,
    /// UR safety mode.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safety_mode: Option<i32>,
}

pub type HwState = Envelope<HwStateBody>;

pub fn hw_state(from: RobotSide, body: HwStateBody) -> HwState {
    Envelope {
        header: Header {
            from: from.name().to_owned(),
            to: IPS.to_owned(),
            kind: "hwState".to_owned(),
        },
        body,
    }
}

/// The bridge's answer to a status request.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StatusBody {
    pub backend: String,
    /// "connected", "connecting" or "lost".
    pub controller: String,
    pub mirroring: bool,
    /// Measured rate of controller samples over the last second, Hz.
    pub sample_rate_hz: f64,
    /// Age of the newest sample, s; absent before the first.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last_sample_age_s: Option<f64>,
    pub published: u64,
    /// Controller connections lost since start (gaps in the stream).
    pub reconnects: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// Controller samples never received, counted from gaps in the controller's sequence
    /// counter (FRI) within a session.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub controller_samples_missed: Option<u64>,
    /// The FRI session state the controller reports (e.g. "MONITORING_READY").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub session_state: Option<String>,
    /// The FRI connection quality the controller reports ("POOR" .. "EXCELLENT").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub connection_quality: Option<String>,
    /// Datagrams dropped as not from the controller or not its messages (FRI).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rejected_datagrams: Option<u64>,
}

pub type Status = Envelope<StatusBody>;

pub fn status(from: RobotSide, body: StatusBody) -> Status {
    Envelope {
        header: Header {
            from: from.name().to_owned(),
            to: IPS.to_owned(),
            kind: "status".to_owned(),
        },
        body,
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProtocolError {
    #[error("the message is not valid JSON: {0}")]
    Json(String),
    #[error("the message does not have the expected shape: {0}")]
    Shape(String),
    #[error("unknown message type '{0}' (expected 'instruction')")]
    UnknownType(String),
    #[error("unknown command '{0}' (expected start, stop or status)")]
    UnknownCommand(String),
    #[error("unknown content '{0}' (expected 'hwState')")]
    UnknownContent(String),
    #[error("field {0} is not a finite number")]
    NonFinite(String),
}

/// A parsed instruction request.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Request {
    pub command: Command,
    /// The `to` the sender used (the thesis's clients send "ros" or "IiwaDrive").
    pub to: String,
}

/// Parses an instruction request, naming what is wrong with it when it is not one.
pub fn parse_request(bytes: &[u8]) -> Result<Request, ProtocolError> {
    let value: serde_json::Value =
        serde_json::from_slice(bytes).map_err(|error| ProtocolError::Json(error.to_string()))?;
    let message: Instruction =
        serde_json::from_value(value).map_err(|error| ProtocolError::Shape(error.to_string()))?;
    if message.header.kind != "instruction" {
        return Err(ProtocolError::UnknownType(message.header.kind));
    }
    let command = match message.body.command.as_str() {
        "start" => Command::Start,
        "stop" => Command::Stop,
        "status" => Command::Status,
        other => return Err(ProtocolError::UnknownCommand(other.to_owned())),
    };
    if command != Command::Status && message.body.content != "hwState" {
        return Err(ProtocolError::UnknownContent(message.body.content));
    }
    Ok(Request {
        command,
        to: message.header.to,
    })
}

/// A message a sender can check before it goes on the wire.
pub trait Message: Serialize {
    /// Checks shapes and that every number is finite (serde_json would write NaN as null).
    fn validate(&self) -> Result<(), ProtocolError>;
}

impl Message for Instruction {
    fn validate(&self) -> Result<(), ProtocolError> {
        Ok(())
    }
}

impl Message for HwState {
    fn validate(&self) -> Result<(), ProtocolError> {
        self.body.validate()
    }
}

impl Message for Status {
    fn validate(&self) -> Result<(), ProtocolError> {
        let ages = [
            ("sample_rate_hz", Some(self.body.sample_rate_hz)),
            ("last_sample_age_s", self.body.last_sample_age_s),
        ];
        for (name, value) in ages {
            if value.is_some_and(|v| !v.is_finite()) {
                return Err(ProtocolError::NonFinite(format!(".body.{name}")));
            }
        }
        Ok(())
    }
}

/// Serialises a message after validating it.
pub fn to_json<T: Message>(message: &T) -> Result<String, ProtocolError> {
    message.validate()?;
    serde_json::to_string(message).map_err(|error| ProtocolError::Shape(error.to_string()))
}

impl HwStateBody {
    /// Checks what a receiver relies on: equal array lengths and finite numbers.
    pub fn validate(&self) -> Result<(), ProtocolError> {
        let count = self.names.len();
        let lengths_ok = self.position.len() == count
            && self.velocity.len() == count
            && self.effort.as_ref().is_none_or(|e| e.len() == count);
        if !lengths_ok {
            return Err(ProtocolError::Shape(format!(
                "{count} names but {} positions, {} velocities",
                self.position.len(),
                self.velocity.len()
            )));
        }
        let arrays = [
            ("position", Some(&self.position)),
            ("velocity", Some(&self.velocity)),
            ("effort", self.effort.as_ref()),
        ];
        for (name, values) in arrays {
            if let Some(index) = values.and_then(|v| v.iter().position(|x| !x.is_finite())) {
                return Err(ProtocolError::NonFinite(format!(".body.{name}[{index}]")));
            }
        }
        for (name, value) in [
            ("stamp", self.stamp),
            ("controller_time", self.controller_time),
        ] {
            if !value.is_finite() {
                return Err(ProtocolError::NonFinite(format!(".body.{name}")));
            }
        }
        Ok(())
    }
}

/// A request to the alignment service (`ips serve`, REP, default `tcp://*:4000`), in the
/// thesis's envelope with `"type": "request"`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ServiceRequestBody {
    /// status, start, stop, get, list, remove, reset, align, align-cloud, diagnose, save, load.
    pub command: String,
    /// Inspection ids (remove).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ids: Vec<String>,
    /// A session file (save, load).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub path: Option<String>,
    /// Scanner cloud file, as the service sees the path (align-cloud).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cloud: Option<String>,
    /// Unit of the cloud file in metres, 0.001 for mm (align-cloud; default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cloud_scale: Option<f64>,
    /// A part mesh to align instead of the session's part (align-cloud).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh: Option<String>,
    /// Unit of `mesh` in metres (align-cloud, only with `mesh`; default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh_scale: Option<f64>,
    /// The part pose `base_from_part` the alignment starts from (align-cloud; default the
    /// session part's nominal pose).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start_pose: Option<PoseXyzRpy>,
    /// Upper bound of the start pose's error, m: the thesis's delta (align-cloud; default 0.1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delta_m: Option<f64>,
    /// The thesis's SVD step instead of point-to-plane (align-cloud; default false).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub point_to_point: Option<bool>,
    /// Delta shrinks as cos^2 (the thesis's code) instead of cos (its eq. 33) (align-cloud;
    /// default false).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cos_squared: Option<bool>,
    /// No exploration of orientations around the start pose, the thesis's behaviour
    /// (align-cloud; default false).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub local: Option<bool>,
    /// The controller time of the touch, s (get; e.g. a touch-trigger probe's signal): the
    /// sample at or just after it is captured instead of the latest.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_s: Option<f64>,
}

/// A pose as the session file writes it: position x, y, z (m) and fixed-axis roll, pitch, yaw
/// (rad).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseXyzRpy {
    pub xyz: [f64; 3],
    pub rpy: [f64; 3],
}

/// The service's reply, `"type": "reply"`: `ok`, a `reason` when not, and the command's data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ServiceReplyBody {
    pub ok: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    #[serde(default, skip_serializing_if = "serde_json::Value::is_null")]
    pub data: serde_json::Value,
}

pub type ServiceRequest = Envelope<ServiceRequestBody>;
pub type ServiceReply = Envelope<ServiceReplyBody>;

/// Name of the alignment service in headers.
pub const SERVICE: &str = "align";

pub fn service_request(command: &str) -> ServiceRequest {
    Envelope {
        header: Header {
            from: IPS.to_owned(),
            to: SERVICE.to_owned(),
            kind: "request".to_owned(),
        },
        body: ServiceRequestBody {
            command: command.to_owned(),
            ids: Vec::new(),
            path: None,
            cloud: None,
            cloud_scale: None,
            mesh: None,
            mesh_scale: None,
            start_pose: None,
            delta_m: None,
            point_to_point: None,
            cos_squared: None,
            local: None,
            time_s: None,
        },
    }
}

pub fn service_reply(ok: bool, reason: Option<String>, data: serde_json::Value) -> ServiceReply {
    Envelope {
        header: Header {
            from: SERVICE.to_owned(),
            to: IPS.to_owned(),
            kind: "reply".to_owned(),
        },
        body: ServiceReplyBody { ok, reason, data },
    }
}

impl Message for ServiceReply {
    fn validate(&self) -> Result<(), ProtocolError> {
        Ok(())
    }
}

impl Message for ServiceRequest {
    /// Refuses non-finite numbers, which serde_json would write as `null`: the service would
    /// then answer about a type error the sender never made.
    fn validate(&self) -> Result<(), ProtocolError> {
        let body = &self.body;
        let scalars = [
            ("cloud_scale", body.cloud_scale),
            ("mesh_scale", body.mesh_scale),
            ("delta_m", body.delta_m),
            ("time_s", body.time_s),
        ];
        for (name, value) in scalars {
            if value.is_some_and(|v| !v.is_finite()) {
                return Err(ProtocolError::NonFinite(format!(".body.{name}")));
            }
        }
        if let Some(pose) = &body.start_pose {
            for (name, values) in [("xyz", pose.xyz), ("rpy", pose.rpy)] {
                if let Some(index) = values.iter().position(|v| !v.is_finite()) {
                    return Err(ProtocolError::NonFinite(format!(
                        ".body.start_pose.{name}[{index}]"
                    )));
                }
            }
        }
        Ok(())
    }
}
