//! The Universal Robots Real-Time Data Exchange (RTDE) wire format, protocol versions 1 and 2,
//! from UR's published RTDE guide: both ends use it (robot-bridge as client, sim-robot as server).
//!
//! Every package is `uint16 size` (the whole package, header included), `uint8 type`, payload;
//! all numbers big-endian. A client negotiates the protocol version, asks for the controller
//! version, sets up an output recipe (variable names -> their types and a recipe id), starts, and
//! then receives one data package per controller cycle at the frequency it asked for.

use std::io::{Read, Write};

/// Package types (ASCII letters on the wire).
pub mod package {
    pub const REQUEST_PROTOCOL_VERSION: u8 = b'V';
    pub const GET_URCONTROL_VERSION: u8 = b'v';
    pub const TEXT_MESSAGE: u8 = b'M';
    pub const DATA_PACKAGE: u8 = b'U';
    pub const CONTROL_PACKAGE_SETUP_OUTPUTS: u8 = b'O';
    pub const CONTROL_PACKAGE_SETUP_INPUTS: u8 = b'I';
    pub const CONTROL_PACKAGE_START: u8 = b'S';
    pub const CONTROL_PACKAGE_PAUSE: u8 = b'P';
}

/// Largest package the format can describe (the size field is 16 bits).
pub const MAX_PACKAGE_BYTES: usize = u16::MAX as usize;

#[derive(Debug, thiserror::Error)]
pub enum RtdeError {
    #[error("connection: {0}")]
    Io(#[from] std::io::Error),
    #[error("package size {0} is smaller than its 3-byte header")]
    BadSize(u16),
    #[error("package of type '{kind}' is too short: {needed} bytes needed, {got} present")]
    Short {
        kind: char,
        needed: usize,
        got: usize,
    },
    #[error("payload of {0} bytes does not fit an RTDE package")]
    TooLarge(usize),
    #[error("unknown RTDE type name '{0}'")]
    UnknownType(String),
    #[error("text in a package is not UTF-8")]
    Text,
}

/// One package: its type and payload.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Package {
    pub kind: u8,
    pub payload: Vec<u8>,
}

impl Package {
    pub fn new(kind: u8, payload: Vec<u8>) -> Self {
        Self { kind, payload }
    }

    /// The bytes on the wire.
    pub fn encode(&self) -> Result<Vec<u8>, RtdeError> {
        let size = self.payload.len() + 3;
        if size > MAX_PACKAGE_BYTES {
            return Err(RtdeError::TooLarge(self.payload.len()));
        }
        let mut bytes = Vec::with_capacity(size);
        bytes.extend_from_slice(&(size as u16).to_be_bytes());
        bytes.push(self.kind);
        bytes.extend_from_slice(&self.payload);
        Ok(bytes)
    }

    pub fn write_to(&self, stream: &mut impl Write) -> Result<(), RtdeError> {
        stream.write_all(&self.encode()?)?;
        Ok(())
    }

    /// Reads exactly one package (blocking until it is complete or the stream fails).
    pub fn read_from(stream: &mut impl Read) -> Result<Self, RtdeError> {
        let mut header = [0u8; 3];
        stream.read_exact(&mut header)?;
        let size = u16::from_be_bytes([header[0], header[1]]);
        if size < 3 {
            return Err(RtdeError::BadSize(size));
        }
        let mut payload = vec![0u8; size as usize - 3];
        stream.read_exact(&mut payload)?;
        Ok(Self {
            kind: header[2],
            payload,
        })
    }

    fn need(&self, bytes: usize) -> Result<(), RtdeError> {
        if self.payload.len() < bytes {
            Err(RtdeError::Short {
                kind: self.kind as char,
                needed: bytes,
                got: self.payload.len(),
            })
        } else {
            Ok(())
        }
    }

    /// The payload as a single `uint8` (accepted flags, recipe ids).
    pub fn first_byte(&self) -> Result<u8, RtdeError> {
        self.need(1)?;
        Ok(self.payload[0])
    }
}

/// RTDE value types.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValueType {
    Bool,
    Uint8,
    Uint32,
    Uint64,
    Int32,
    Double,
    Vector3d,
    Vector6d,
    Vector6Int32,
    Vector6Uint32,
}

impl ValueType {
    pub fn name(self) -> &'static str {
        match self {
            ValueType::Bool => "BOOL",
            ValueType::Uint8 => "UINT8",
            ValueType::Uint32 => "UINT32",
            ValueType::Uint64 => "UINT64",
            ValueType::Int32 => "INT32",
            ValueType::Double => "DOUBLE",
            ValueType::Vector3d => "VECTOR3D",
            ValueType::Vector6d => "VECTOR6D",
            ValueType::Vector6Int32 => "VECTOR6INT32",
            ValueType::Vector6Uint32 => "VECTOR6UINT32",
        }
    }

    pub fn parse(name: &str) -> Result<Self, RtdeError> {
        Ok(match name {
            "BOOL" => ValueType::Bool,
            "UINT8" => ValueType::Uint8,
            "UINT32" => ValueType::Uint32,
            "UINT64" => ValueType::Uint64,
            "INT32" => ValueType::Int32,
            "DOUBLE" => ValueType::Double,
            "VECTOR3D" => ValueType::Vector3d,
            "VECTOR6D" => ValueType::Vector6d,
            "VECTOR6INT32" => ValueType::Vector6Int32,
            "VECTOR6UINT32" => ValueType::Vector6Uint32,
            other => return Err(RtdeError::UnknownType(other.to_owned())),
        })
    }

    /// Bytes on the wire.
    pub fn size(self) -> usize {
        match self {
            ValueType::Bool | ValueType::Uint8 => 1,
            ValueType::Uint32 | ValueType::Int32 => 4,
            ValueType::Uint64 | ValueType::Double => 8,
            ValueType::Vector3d => 24,
            ValueType::Vector6d => 48,
            ValueType::Vector6Int32 | ValueType::Vector6Uint32 => 24,
        }
    }

    /// How many numbers a value of this type holds.
    pub fn count(self) -> usize {
        match self {
            ValueType::Vector3d => 3,
            ValueType::Vector6d | ValueType::Vector6Int32 | ValueType::Vector6Uint32 => 6,
            _ => 1,
        }
    }
}

/// The type of an output variable as a UR controller reports it, or `None` (the controller
/// answers NOT_FOUND). Covers the variables UR's RTDE guide lists for outputs, including every
/// one ur_rtde's receive interface asks for by default; a client that decodes data packages
/// with its own type table (ur_rtde does) misreads every later value if one size here is wrong.
pub fn output_type(name: &str) -> Option<ValueType> {
    use ValueType::*;
    if let Some(rest) = name.strip_prefix("output_int_register_") {
        return rest.parse::<u8>().ok().filter(|n| *n < 48).map(|_| Int32);
    }
    if let Some(rest) = name.strip_prefix("output_double_register_") {
        return rest.parse::<u8>().ok().filter(|n| *n < 48).map(|_| Double);
    }
    if let Some(rest) = name.strip_prefix("output_bit_register_") {
        return rest
            .parse::<u8>()
            .ok()
            .filter(|n| (64..128).contains(n))
            .map(|_| Bool);
    }
    Some(match name {
        "timestamp"
        | "actual_execution_time"
        | "speed_scaling"
        | "target_speed_fraction"
        | "actual_momentum"
        | "actual_main_voltage"
        | "actual_robot_voltage"
        | "actual_robot_current"
        | "standard_analog_input0"
        | "standard_analog_input1"
        | "standard_analog_output0"
        | "standard_analog_output1"
        | "tool_analog_input0"
        | "tool_analog_input1"
        | "tool_output_current"
        | "tool_temperature"
        | "payload" => Double,
        "target_q"
        | "target_qd"
        | "target_qdd"
        | "target_current"
        | "target_moment"
        | "actual_q"
        | "actual_qd"
        | "actual_current"
        | "joint_control_output"
        | "actual_TCP_pose"
        | "actual_TCP_speed"
        | "actual_TCP_force"
        | "target_TCP_pose"
        | "target_TCP_speed"
        | "joint_temperatures"
        | "actual_joint_voltage"
        | "actual_current_window"
        | "ft_raw_wrench"
        | "payload_inertia" => Vector6d,
        "actual_tool_accelerometer" | "payload_cog" | "elbow_position" | "elbow_velocity" => {
            Vector3d
        }
        "joint_mode" => Vector6Int32,
        "robot_mode" | "safety_mode" | "safety_status" | "tool_output_voltage" => Int32,
        // 64 bits: standard, configurable and tool I/O side by side.
        "actual_digital_input_bits" | "actual_digital_output_bits" => Uint64,
        "runtime_state"
        | "tool_mode"
        | "robot_status_bits"
        | "safety_status_bits"
        | "analog_io_types"
        | "tool_analog_input_types"
        | "output_bit_registers0_to_31"
        | "output_bit_registers32_to_63"
        | "input_bit_registers0_to_31"
        | "input_bit_registers32_to_63" => Uint32,
        "tool_output_mode" | "tool_digital_output0_mode" | "tool_digital_output1_mode" => Uint8,
        _ => return None,
    })
}

/// One value of a data package, as plain numbers (booleans as 0/1).
pub type Value = Vec<f64>;

/// Appends `value` encoded as `kind`.
pub fn encode_value(kind: ValueType, value: &[f64], out: &mut Vec<u8>) {
    for index in 0..kind.count() {
        let v = value.get(index).copied().unwrap_or(0.0);
        match kind {
            ValueType::Bool | ValueType::Uint8 => out.push(v as u8),
            ValueType::Uint32 | ValueType::Vector6Uint32 => {
                out.extend_from_slice(&(v as u32).to_be_bytes())
            }
            ValueType::Int32 | ValueType::Vector6Int32 => {
                out.extend_from_slice(&(v as i32).to_be_bytes())
            }
            ValueType::Uint64 => out.extend_from_slice(&(v as u64).to_be_bytes()),
            ValueType::Double | ValueType::Vector3d | ValueType::Vector6d => {
                out.extend_from_slice(&v.to_be_bytes())
            }
        }
    }
}

/// Decodes the values of a data package laid out as `types`, starting at `offset`.
pub fn decode_values(
    bytes: &[u8],
    offset: usize,
    types: &[ValueType],
) -> Result<Vec<Value>, RtdeError> {
    let needed = offset + types.iter().map(|t| t.size()).sum::<usize>();
    if bytes.len() < needed {
        return Err(RtdeError::Short {
            kind: 'U',
            needed,
            got: bytes.len(),
        });
    }
    let mut at = offset;
    let mut values = Vec::with_capacity(types.len());
    for kind in types {
        let element = kind.size() / kind.count();
        let mut value = Vec::with_capacity(kind.count());
        for _ in 0..kind.count() {
            let raw = &bytes[at..at + element];
            at += element;
            value.push(match kind {
                ValueType::Bool | ValueType::Uint8 => raw[0] as f64,
                ValueType::Uint32 | ValueType::Vector6Uint32 => {
                    u32::from_be_bytes([raw[0], raw[1], raw[2], raw[3]]) as f64
                }
                ValueType::Int32 | ValueType::Vector6Int32 => {
                    i32::from_be_bytes([raw[0], raw[1], raw[2], raw[3]]) as f64
                }
                ValueType::Uint64 => u64::from_be_bytes(raw.try_into().unwrap_or([0; 8])) as f64,
                ValueType::Double | ValueType::Vector3d | ValueType::Vector6d => {
                    f64::from_be_bytes(raw.try_into().unwrap_or([0; 8]))
                }
            });
        }
        values.push(value);
    }
    Ok(values)
}

/// The variable names of a setup request's comma-separated list. ur_rtde ends its lists with a
/// comma and real controllers serve it, so a trailing comma is a terminator, not an empty name:
/// the one empty entry it leaves is dropped (an empty name anywhere else stays, to be refused).
pub fn recipe_names(list: &str) -> Vec<&str> {
    let list = list.strip_suffix(',').unwrap_or(list);
    list.split(',').collect()
}

/// Payload of a v2 output setup request: frequency and the comma-separated names.
pub fn setup_outputs_request(frequency_hz: Option<f64>, names: &[&str]) -> Package {
    let mut payload = Vec::new();
    if let Some(frequency) = frequency_hz {
        payload.extend_from_slice(&frequency.to_be_bytes());
    }
    payload.extend_from_slice(names.join(",").as_bytes());
    Package::new(package::CONTROL_PACKAGE_SETUP_OUTPUTS, payload)
}

/// The variable types of a setup reply: `NOT_FOUND` entries stay `None`.
pub fn parse_setup_reply(
    package: &Package,
    version: u16,
) -> Result<(u8, Vec<Option<ValueType>>), RtdeError> {
    let (recipe, text) = if version >= 2 {
        package.need(1)?;
        (package.payload[0], &package.payload[1..])
    } else {
        (0, &package.payload[..])
    };
    let text = std::str::from_utf8(text).map_err(|_| RtdeError::Text)?;
    let types = text
        .split(',')
        .map(|name| {
            if name == "NOT_FOUND" {
                Ok(None)
            } else {
                ValueType::parse(name).map(Some)
            }
        })
        .collect::<Result<_, _>>()?;
    Ok((recipe, types))
}

/// The v2 text message a controller sends to report a problem: message, source, warning level.
pub fn text_message(message: &str, source: &str, level: u8) -> Package {
    let mut payload = Vec::new();
    payload.push(message.len().min(255) as u8);
    payload.extend_from_slice(&message.as_bytes()[..message.len().min(255)]);
    payload.push(source.len().min(255) as u8);
    payload.extend_from_slice(&source.as_bytes()[..source.len().min(255)]);
    payload.push(level);
    Package::new(package::TEXT_MESSAGE, payload)
}
