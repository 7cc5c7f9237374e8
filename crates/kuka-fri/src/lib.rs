//! KUKA Sunrise FRI (Fast Robot Interface) messages, as the controller and its client exchange
//! them over UDP (the client listens on 30200 by default).
//!
//! Every send period (1-100 ms) the controller sends an `FRIMonitoringMessage`: header with a
//! sequence counter, robot info, measured joint data with the controller's time stamp, and the
//! connection info (session state, connection quality, send period, receive multiplier). The
//! client answers every `receive_multiplier`-th message with an `FRICommandMessage`; a monitoring
//! client sends only the header, echoing the controller's counter in `reflected_sequence_counter`.
//! The controller grades the connection quality from how timely those answers are, and the session
//! state follows the quality.
//!
//! The structs are written by hand from the public field layout of the FRI client SDK's protobuf
//! description (proto2, field numbers below); no KUKA file is used. Repeated doubles are encoded
//! unpacked, one tag per value, as the SDK does; the decoder accepts packed too. This is the plain
//! protobuf framing of the FRI 1.x/2.x SDKs; later SDK versions wrap the message in a length
//! prefix and a CRC, which this crate does not speak.

use prost::Message as _;

/// `message_identifier` of an LBR monitoring message.
pub const MONITORING_MESSAGE_ID: u32 = 0x0024_5142;
/// `message_identifier` of an LBR command message.
pub const COMMAND_MESSAGE_ID: u32 = 0x0003_4001;
/// Largest datagram either side accepts; the SDK's buffers are 1500 bytes.
pub const MAX_MESSAGE_BYTES: usize = 1500;
/// Longest IO name the SDK holds (a 64-byte C string).
pub const MAX_IO_NAME_BYTES: usize = 63;
/// Joints of an LBR.
pub const LBR_JOINTS: usize = 7;

#[derive(Clone, PartialEq, prost::Message)]
pub struct MessageHeader {
    #[prost(uint32, required, tag = "1")]
    pub message_identifier: u32,
    #[prost(uint32, required, tag = "2")]
    pub sequence_counter: u32,
    #[prost(uint32, required, tag = "3")]
    pub reflected_sequence_counter: u32,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct ConnectionInfo {
    #[prost(enumeration = "SessionState", required, tag = "1")]
    pub session_state: i32,
    #[prost(enumeration = "ConnectionQuality", required, tag = "2")]
    pub quality: i32,
    /// Milliseconds between monitoring messages.
    #[prost(uint32, optional, tag = "3")]
    pub send_period_ms: Option<u32>,
    /// The client answers every n-th message.
    #[prost(uint32, optional, tag = "4")]
    pub receive_multiplier: Option<u32>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct RobotInfo {
    #[prost(int32, optional, tag = "1")]
    pub number_of_joints: Option<i32>,
    #[prost(enumeration = "SafetyState", optional, tag = "2")]
    pub safety_state: Option<i32>,
    #[prost(enumeration = "DriveState", repeated, packed = "false", tag = "5")]
    pub drive_state: Vec<i32>,
    #[prost(enumeration = "OperationMode", optional, tag = "6")]
    pub operation_mode: Option<i32>,
    #[prost(enumeration = "ControlMode", optional, tag = "7")]
    pub control_mode: Option<i32>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct JointValues {
    #[prost(double, repeated, packed = "false", tag = "1")]
    pub value: Vec<f64>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct TimeStamp {
    #[prost(uint32, required, tag = "1")]
    pub sec: u32,
    #[prost(uint32, required, tag = "2")]
    pub nanosec: u32,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct MessageMonitorData {
    /// rad.
    #[prost(message, optional, tag = "1")]
    pub measured_joint_position: Option<JointValues>,
    /// N m.
    #[prost(message, optional, tag = "2")]
    pub measured_torque: Option<JointValues>,
    /// rad; sent by FRI 1.x controllers only.
    #[prost(message, optional, tag = "3")]
    pub commanded_joint_position: Option<JointValues>,
    /// N m.
    #[prost(message, optional, tag = "4")]
    pub commanded_torque: Option<JointValues>,
    /// N m.
    #[prost(message, optional, tag = "5")]
    pub external_torque: Option<JointValues>,
    /// The IOs the Sunrise application registered for FRI (`registerIO` on its FRI
    /// configuration), each with its current value; empty when it registered none. FRI SDKs
    /// 1.13 to 2.5 all carry them at this field number (older ones have no IO).
    #[prost(message, repeated, tag = "8")]
    pub read_io_request: Vec<FriIoValue>,
    #[prost(message, optional, tag = "15")]
    pub timestamp: Option<TimeStamp>,
}

/// One IO's value as FRI reports it. The name is `"Group.Name"` as the IO configuration in
/// WorkVisual has it; booleans and digital IOs carry `digital_value`, analog ones
/// `analog_value`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct FriIoValue {
    #[prost(string, required, tag = "1")]
    pub name: String,
    #[prost(enumeration = "FriIoType", required, tag = "2")]
    pub io_type: i32,
    #[prost(enumeration = "FriIoDirection", required, tag = "3")]
    pub direction: i32,
    #[prost(uint64, optional, tag = "4")]
    pub digital_value: Option<u64>,
    #[prost(double, optional, tag = "5")]
    pub analog_value: Option<f64>,
}

impl FriIoValue {
    /// A boolean input, as a touch-trigger probe wired to the controller appears.
    pub fn boolean_input(name: &str, high: bool) -> Self {
        Self {
            name: name.to_owned(),
            io_type: FriIoType::Boolean as i32,
            direction: FriIoDirection::Input as i32,
            digital_value: Some(u64::from(high)),
            analog_value: None,
        }
    }

    /// Whether a boolean or digital IO is set (any bit); `None` for an analog IO or a value
    /// the message left out.
    pub fn is_set(&self) -> Option<bool> {
        match FriIoType::try_from(self.io_type).ok()? {
            FriIoType::Boolean | FriIoType::Digital => self.digital_value.map(|v| v != 0),
            FriIoType::Analog => None,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, prost::Enumeration)]
#[repr(i32)]
pub enum FriIoType {
    Boolean = 0,
    Digital = 1,
    Analog = 2,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, prost::Enumeration)]
#[repr(i32)]
pub enum FriIoDirection {
    Input = 0,
    Output = 1,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct Checksum {
    #[prost(int32, optional, tag = "1")]
    pub crc32: Option<i32>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct MessageEndOf {
    #[prost(int32, optional, tag = "1")]
    pub message_length: Option<i32>,
    #[prost(message, optional, tag = "2")]
    pub message_checksum: Option<Checksum>,
}

/// What the controller sends every send period. Fields this crate does not model (IPO data,
/// requested transformations) are skipped when decoding.
#[derive(Clone, PartialEq, prost::Message)]
pub struct MonitoringMessage {
    #[prost(message, required, tag = "1")]
    pub header: MessageHeader,
    #[prost(message, optional, tag = "2")]
    pub robot_info: Option<RobotInfo>,
    #[prost(message, optional, tag = "3")]
    pub monitor_data: Option<MessageMonitorData>,
    #[prost(message, optional, tag = "4")]
    pub connection_info: Option<ConnectionInfo>,
    #[prost(message, optional, tag = "15")]
    pub end_of_message_data: Option<MessageEndOf>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct MessageCommandData {
    #[prost(message, optional, tag = "1")]
    pub joint_position: Option<JointValues>,
    #[prost(message, optional, tag = "3")]
    pub joint_torque: Option<JointValues>,
}

/// What the client answers. A monitoring-only client sends the header alone.
#[derive(Clone, PartialEq, prost::Message)]
pub struct CommandMessage {
    #[prost(message, required, tag = "1")]
    pub header: MessageHeader,
    #[prost(message, optional, tag = "2")]
    pub command_data: Option<MessageCommandData>,
    #[prost(message, optional, tag = "15")]
    pub end_of_message_data: Option<MessageEndOf>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, prost::Enumeration)]
#[repr(i32)]
pub enum SessionState {
    Idle = 0,
    MonitoringWait = 1,
    MonitoringReady = 2,
    CommandingWait = 3,
    CommandingActive = 4,
}

impl SessionState {
    pub fn name(self) -> &'static str {
        match self {
            SessionState::Idle => "IDLE",
            SessionState::MonitoringWait => "MONITORING_WAIT",
            SessionState::MonitoringReady => "MONITORING_READY",
            SessionState::CommandingWait => "COMMANDING_WAIT",
            SessionState::CommandingActive => "COMMANDING_ACTIVE",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, prost::Enumeration)]
#[repr(i32)]
pub enum ConnectionQuality {
    Poor = 0,
    Fair = 1,
    Good = 2,
    Excellent = 3,
}

impl ConnectionQuality {
    pub fn name(self) -> &'static str {
        match self {
            ConnectionQuality::Poor => "POOR",
            ConnectionQuality::Fair => "FAIR",
            ConnectionQuality::Good => "GOOD",
            ConnectionQuality::Excellent => "EXCELLENT",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, prost::Enumeration)]
#[repr(i32)]
pub enum SafetyState {
    NormalOperation = 0,
    SafetyStopLevel0 = 1,
    SafetyStopLevel1 = 2,
    SafetyStopLevel2 = 3,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, prost::Enumeration)]
#[repr(i32)]
pub enum OperationMode {
    TestMode1 = 0,
    TestMode2 = 1,
    AutomaticMode = 2,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, prost::Enumeration)]
#[repr(i32)]
pub enum DriveState {
    Off = 0,
    Transitioning = 1,
    Active = 2,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, prost::Enumeration)]
#[repr(i32)]
pub enum ControlMode {
    PositionControl = 0,
    CartesianImpedance = 1,
    JointImpedance = 2,
    NoControl = 3,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FriError {
    #[error("datagram of {0} bytes exceeds the {MAX_MESSAGE_BYTES}-byte FRI limit")]
    TooLarge(usize),
    #[error("not an FRI message: {0}")]
    Decode(String),
    #[error("message identifier {found:#x} is not the expected {expected:#x}")]
    WrongIdentifier { found: u32, expected: u32 },
}

fn check_size(bytes: &[u8]) -> Result<(), FriError> {
    if bytes.len() > MAX_MESSAGE_BYTES {
        return Err(FriError::TooLarge(bytes.len()));
    }
    Ok(())
}

impl MonitoringMessage {
    /// Decodes a datagram and checks that it is an LBR monitoring message.
    pub fn decode_checked(bytes: &[u8]) -> Result<Self, FriError> {
        check_size(bytes)?;
        let message = Self::decode(bytes).map_err(|error| FriError::Decode(error.to_string()))?;
        if message.header.message_identifier != MONITORING_MESSAGE_ID {
            return Err(FriError::WrongIdentifier {
                found: message.header.message_identifier,
                expected: MONITORING_MESSAGE_ID,
            });
        }
        Ok(message)
    }

    /// Measured joint positions, rad.
    pub fn measured_positions(&self) -> Option<&[f64]> {
        self.monitor_data
            .as_ref()?
            .measured_joint_position
            .as_ref()
            .map(|values| values.value.as_slice())
    }

    /// Measured joint torques, N m.
    pub fn measured_torques(&self) -> Option<&[f64]> {
        self.monitor_data
            .as_ref()?
            .measured_torque
            .as_ref()
            .map(|values| values.value.as_slice())
    }

    /// The controller's time stamp of the sample, s.
    pub fn controller_time_s(&self) -> Option<f64> {
        let stamp = self.monitor_data.as_ref()?.timestamp.as_ref()?;
        Some(f64::from(stamp.sec) + f64::from(stamp.nanosec) * 1e-9)
    }

    pub fn session_state(&self) -> Option<SessionState> {
        let info = self.connection_info.as_ref()?;
        SessionState::try_from(info.session_state).ok()
    }

    pub fn quality(&self) -> Option<ConnectionQuality> {
        let info = self.connection_info.as_ref()?;
        ConnectionQuality::try_from(info.quality).ok()
    }

    /// Time between monitoring messages, s.
    pub fn send_period_s(&self) -> Option<f64> {
        let period_ms = self.connection_info.as_ref()?.send_period_ms?;
        (period_ms > 0).then(|| f64::from(period_ms) * 1e-3)
    }

    /// Every how many monitoring messages the client answers (1 when not stated).
    pub fn receive_multiplier(&self) -> u32 {
        self.connection_info
            .as_ref()
            .and_then(|info| info.receive_multiplier)
            .unwrap_or(1)
            .max(1)
    }
}

impl CommandMessage {
    /// The header-only answer of a monitoring client: its own counter and the controller's.
    pub fn monitoring_reply(own_sequence: u32, monitoring_sequence: u32) -> Self {
        Self {
            header: MessageHeader {
                message_identifier: COMMAND_MESSAGE_ID,
                sequence_counter: own_sequence,
                reflected_sequence_counter: monitoring_sequence,
            },
            command_data: None,
            end_of_message_data: None,
        }
    }

    /// Decodes a datagram and checks that it is an LBR command message.
    pub fn decode_checked(bytes: &[u8]) -> Result<Self, FriError> {
        check_size(bytes)?;
        let message = Self::decode(bytes).map_err(|error| FriError::Decode(error.to_string()))?;
        if message.header.message_identifier != COMMAND_MESSAGE_ID {
            return Err(FriError::WrongIdentifier {
                found: message.header.message_identifier,
                expected: COMMAND_MESSAGE_ID,
            });
        }
        Ok(message)
    }
}

/// Encodes any FRI message into a datagram.
pub fn encode(message: &impl prost::Message) -> Vec<u8> {
    message.encode_to_vec()
}
