//! The bridge's messages: the thesis's instruction request and ack (DESIGN.md 6.2), the
//! hardware-state sample and the bridge's status.

use serde::{Deserialize, Serialize};

use crate::envelope::{Envelope, Header, IPS, Message, ProtocolError, check_envelope_shape};

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

    /// The side a header's `from` names, if it is one.
    pub fn from_name(name: &str) -> Option<Self> {
        [RobotSide::Ros, RobotSide::IiwaDrive]
            .into_iter()
            .find(|side| side.name() == name)
    }
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
    /// The controller's digital inputs sampled with this sample, one bit each (UR's
    /// `actual_digital_input_bits`: bits 0-7 DI0-7, 8-15 CI0-7, 16-17 TI0-1; see [`crate::io`]);
    /// absent when the controller does not offer them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub digital_inputs: Option<u64>,
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
    /// The calibrated DH table the controller reported on its latest connection (UR primary
    /// interface); absent when it sent none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kinematics: Option<crate::calibration::ControllerKinematics>,
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
    check_envelope_shape(&value)?;
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
