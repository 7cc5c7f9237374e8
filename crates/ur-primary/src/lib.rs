//! The Universal Robots primary interface (TCP 30001, secondary 30002): the part of it that
//! carries the robot's factory calibration. Both ends use it: robot-bridge reads the calibrated
//! DH table on every (re)connection, sim-robot serves it.
//!
//! The controller sends a stream of messages, each `int32 size` (the whole message, header
//! included), `uint8 type`, payload; all numbers big-endian. A robot state message (type 16)
//! is a sequence of sub-packages framed the same way (`int32 size`, `uint8 type`, payload). The
//! KINEMATICS_INFO sub-package (type 5) holds, in order: a checksum per joint (uint32 x 6), the
//! calibrated DH table as `dh_theta`, `dh_a`, `dh_d`, `dh_alpha` (float64 x 6 each, rad and m),
//! and the calibration status (uint32): 220 bytes of payload, as Universal Robots' client
//! library parses it. Every other message and sub-package is skipped by its size.

use std::io::{Read, Write};

/// Message types of the primary interface.
pub mod message_type {
    /// The robot state: sub-packages with joint data, tool data, kinematics and more.
    pub const ROBOT_STATE: u8 = 16;
}

/// Sub-package types of a robot state message.
pub mod package_type {
    pub const KINEMATICS_INFO: u8 = 5;
}

/// Bytes of a message or sub-package header: `int32 size`, `uint8 type`.
pub const HEADER_BYTES: usize = 5;
/// Bytes of the KINEMATICS_INFO payload.
pub const KINEMATICS_INFO_BYTES: usize = 6 * 4 + 4 * 6 * 8 + 4;
/// The largest message accepted: real robot state messages are a few kilobytes; a size beyond
/// this is a stream out of step or not a UR controller, never a reason to allocate.
pub const MAX_MESSAGE_BYTES: usize = 1 << 20;

#[derive(Debug, thiserror::Error)]
pub enum PrimaryError {
    #[error("connection: {0}")]
    Io(#[from] std::io::Error),
    #[error("message size {0} is smaller than its 5-byte header")]
    TooSmall(i64),
    #[error("message size {0} exceeds the {MAX_MESSAGE_BYTES}-byte limit")]
    TooLarge(i64),
    #[error(
        "sub-package of type {kind} at byte {offset} claims {size} bytes, {left} left in the message"
    )]
    BadSubPackage {
        kind: u8,
        offset: usize,
        size: i64,
        left: usize,
    },
    #[error("KINEMATICS_INFO payload has {0} bytes, {KINEMATICS_INFO_BYTES} expected")]
    KinematicsLength(usize),
    #[error("KINEMATICS_INFO {field}[{joint}] is not a finite number ({value})")]
    NotFinite {
        field: &'static str,
        joint: usize,
        value: f64,
    },
}

/// One message or sub-package: its type and payload.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    pub kind: u8,
    pub payload: Vec<u8>,
}

impl Frame {
    pub fn new(kind: u8, payload: Vec<u8>) -> Self {
        Self { kind, payload }
    }

    /// The bytes on the wire: size (header included), type, payload.
    pub fn encode(&self) -> Vec<u8> {
        let size = (self.payload.len() + HEADER_BYTES) as u32;
        let mut bytes = Vec::with_capacity(size as usize);
        bytes.extend_from_slice(&size.to_be_bytes());
        bytes.push(self.kind);
        bytes.extend_from_slice(&self.payload);
        bytes
    }

    pub fn write_to(&self, writer: &mut impl Write) -> std::io::Result<()> {
        writer.write_all(&self.encode())
    }
}

/// The size field of a header, checked against the limits.
fn frame_size(header: [u8; 4]) -> Result<usize, PrimaryError> {
    let size = i32::from_be_bytes(header);
    if (size as i64) < HEADER_BYTES as i64 {
        return Err(PrimaryError::TooSmall(size.into()));
    }
    let size = size as usize;
    if size > MAX_MESSAGE_BYTES {
        return Err(PrimaryError::TooLarge(size as i64));
    }
    Ok(size)
}

/// Splits a byte stream into messages, however the reads cut it.
#[derive(Debug, Default)]
pub struct MessageReader {
    pending: Vec<u8>,
}

impl MessageReader {
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        self.pending.extend_from_slice(bytes);
    }

    /// The next whole message, `Ok(None)` until one is complete. An error means the stream is
    /// out of step (a size no controller sends): the connection should be dropped.
    pub fn next_message(&mut self) -> Result<Option<Frame>, PrimaryError> {
        if self.pending.len() < HEADER_BYTES {
            return Ok(None);
        }
        let size = frame_size([
            self.pending[0],
            self.pending[1],
            self.pending[2],
            self.pending[3],
        ])?;
        if self.pending.len() < size {
            return Ok(None);
        }
        let rest = self.pending.split_off(size);
        let whole = std::mem::replace(&mut self.pending, rest);
        Ok(Some(Frame::new(whole[4], whole[HEADER_BYTES..].to_vec())))
    }

    /// Reads from `reader` until a whole message is buffered and returns it; `Ok(None)` when a
    /// read times out first (the reader's timeout decides how long that is).
    pub fn read_message(&mut self, reader: &mut impl Read) -> Result<Option<Frame>, PrimaryError> {
        loop {
            if let Some(message) = self.next_message()? {
                return Ok(Some(message));
            }
            let mut buffer = [0u8; 4096];
            match reader.read(&mut buffer) {
                Ok(0) => {
                    return Err(std::io::Error::new(
                        std::io::ErrorKind::UnexpectedEof,
                        "the controller closed the primary interface",
                    )
                    .into());
                }
                Ok(count) => self.push(&buffer[..count]),
                Err(error)
                    if matches!(
                        error.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    return Ok(None);
                }
                Err(error) => return Err(error.into()),
            }
        }
    }
}

/// Connects to a controller's primary interface at `address` (HOST:PORT) and reads robot state
/// messages until one carries KINEMATICS_INFO, for at most `within`.
pub fn read_kinematics(
    address: &str,
    within: std::time::Duration,
) -> Result<KinematicsInfo, String> {
    use std::net::{TcpStream, ToSocketAddrs};
    use std::time::{Duration, Instant};
    let deadline = Instant::now() + within;
    let socket = address
        .to_socket_addrs()
        .map_err(|error| format!("cannot resolve {address}: {error}"))?
        .next()
        .ok_or_else(|| format!("{address} names no address"))?;
    let mut stream = TcpStream::connect_timeout(&socket, within)
        .map_err(|error| format!("cannot connect to {address}: {error}"))?;
    let mut reader = MessageReader::new();
    while Instant::now() < deadline {
        let left = deadline.saturating_duration_since(Instant::now());
        stream
            .set_read_timeout(Some(left.max(Duration::from_millis(1))))
            .map_err(|error| error.to_string())?;
        let Some(message) = reader
            .read_message(&mut stream)
            .map_err(|error| format!("primary interface at {address}: {error}"))?
        else {
            continue;
        };
        if let Some(info) = KinematicsInfo::from_message(&message)
            .map_err(|error| format!("malformed robot state from {address}: {error}"))?
        {
            let _ = stream.shutdown(std::net::Shutdown::Both);
            return Ok(info);
        }
    }
    Err(format!(
        "no robot state with KINEMATICS_INFO from {address} within {} s",
        within.as_secs_f64()
    ))
}

/// The sub-packages of a robot state message's payload, in order.
pub fn sub_packages(payload: &[u8]) -> Result<Vec<Frame>, PrimaryError> {
    let mut frames = Vec::new();
    let mut offset = 0;
    while offset < payload.len() {
        let left = payload.len() - offset;
        if left < HEADER_BYTES {
            return Err(PrimaryError::BadSubPackage {
                kind: 0,
                offset,
                size: left as i64,
                left,
            });
        }
        let head = &payload[offset..offset + HEADER_BYTES];
        let size = i32::from_be_bytes([head[0], head[1], head[2], head[3]]);
        let kind = head[4];
        if (size as i64) < HEADER_BYTES as i64 || size as i64 > left as i64 {
            return Err(PrimaryError::BadSubPackage {
                kind,
                offset,
                size: size.into(),
                left,
            });
        }
        let size = size as usize;
        frames.push(Frame::new(
            kind,
            payload[offset + HEADER_BYTES..offset + size].to_vec(),
        ));
        offset += size;
    }
    Ok(frames)
}

/// A robot state message made of `packages`.
pub fn robot_state(packages: &[Frame]) -> Frame {
    let payload = packages.iter().flat_map(Frame::encode).collect();
    Frame::new(message_type::ROBOT_STATE, payload)
}

/// The calibrated DH table a UR controller reports, and its checksums and status.
#[derive(Debug, Clone, PartialEq)]
pub struct KinematicsInfo {
    pub checksum: [u32; 6],
    pub dh_theta: [f64; 6],
    pub dh_a: [f64; 6],
    pub dh_d: [f64; 6],
    pub dh_alpha: [f64; 6],
    pub calibration_status: u32,
}

impl KinematicsInfo {
    /// The KINEMATICS_INFO a controller with this DH table sends; checksums and status as URSim
    /// sends them (all bits set, 0), which nothing here reads.
    pub fn from_table(
        dh_theta: [f64; 6],
        dh_a: [f64; 6],
        dh_d: [f64; 6],
        dh_alpha: [f64; 6],
    ) -> Self {
        Self {
            checksum: [u32::MAX; 6],
            dh_theta,
            dh_a,
            dh_d,
            dh_alpha,
            calibration_status: 0,
        }
    }

    /// The sub-package's payload.
    pub fn encode_payload(&self) -> Vec<u8> {
        let mut bytes = Vec::with_capacity(KINEMATICS_INFO_BYTES);
        for value in self.checksum {
            bytes.extend_from_slice(&value.to_be_bytes());
        }
        for row in [self.dh_theta, self.dh_a, self.dh_d, self.dh_alpha] {
            for value in row {
                bytes.extend_from_slice(&value.to_be_bytes());
            }
        }
        bytes.extend_from_slice(&self.calibration_status.to_be_bytes());
        bytes
    }

    /// The sub-package, header included.
    pub fn to_frame(&self) -> Frame {
        Frame::new(package_type::KINEMATICS_INFO, self.encode_payload())
    }

    /// Parses the sub-package's payload: exactly [`KINEMATICS_INFO_BYTES`], every DH value
    /// finite. (The d values may be hundreds of metres: a calibration moves the parallel axes'
    /// common normals far along them and the offsets cancel; they are not checked against any
    /// link length.)
    pub fn decode_payload(payload: &[u8]) -> Result<Self, PrimaryError> {
        if payload.len() != KINEMATICS_INFO_BYTES {
            return Err(PrimaryError::KinematicsLength(payload.len()));
        }
        let word = |at: usize| {
            u32::from_be_bytes([
                payload[at],
                payload[at + 1],
                payload[at + 2],
                payload[at + 3],
            ])
        };
        let double = |at: usize| {
            let mut bytes = [0u8; 8];
            bytes.copy_from_slice(&payload[at..at + 8]);
            f64::from_be_bytes(bytes)
        };
        let checksum = std::array::from_fn(|j| word(4 * j));
        let mut rows = [[0.0; 6]; 4];
        const NAMES: [&str; 4] = ["dh_theta", "dh_a", "dh_d", "dh_alpha"];
        for (r, row) in rows.iter_mut().enumerate() {
            for (j, value) in row.iter_mut().enumerate() {
                *value = double(24 + 48 * r + 8 * j);
                if !value.is_finite() {
                    return Err(PrimaryError::NotFinite {
                        field: NAMES[r],
                        joint: j,
                        value: *value,
                    });
                }
            }
        }
        let [dh_theta, dh_a, dh_d, dh_alpha] = rows;
        Ok(Self {
            checksum,
            dh_theta,
            dh_a,
            dh_d,
            dh_alpha,
            calibration_status: word(KINEMATICS_INFO_BYTES - 4),
        })
    }

    /// The KINEMATICS_INFO of a message, if it is a robot state that carries one.
    pub fn from_message(message: &Frame) -> Result<Option<Self>, PrimaryError> {
        if message.kind != message_type::ROBOT_STATE {
            return Ok(None);
        }
        sub_packages(&message.payload)?
            .iter()
            .find(|package| package.kind == package_type::KINEMATICS_INFO)
            .map(|package| Self::decode_payload(&package.payload))
            .transpose()
    }
}

impl KinematicsInfo {
    /// The hash Universal Robots' ROS drivers write as `hash: calib_<n>` in a kinematics file
    /// and compare with the controller's at start: per joint theta, d, a and alpha, each printed
    /// as a C++ stream prints a double by default (6 significant digits, `%g`), concatenated,
    /// then hashed as libstdc++'s `std::hash<std::string>` does on 64-bit machines (the drivers
    /// are built with it). Checked against the hashes in the published default kinematics files.
    pub fn calibration_hash(&self) -> String {
        let mut text = String::new();
        for j in 0..6 {
            for value in [
                self.dh_theta[j],
                self.dh_d[j],
                self.dh_a[j],
                self.dh_alpha[j],
            ] {
                text += &format_like_cpp_stream(value);
            }
        }
        format!("calib_{}", libstdcxx_string_hash(text.as_bytes()))
    }
}

/// A double as `std::ostream << double` prints it with the default flags: `%g` with 6
/// significant digits (trailing zeros dropped, exponent of at least two digits).
fn format_like_cpp_stream(value: f64) -> String {
    const DIGITS: i32 = 6;
    if value == 0.0 {
        return if value.is_sign_negative() { "-0" } else { "0" }.to_owned();
    }
    if !value.is_finite() {
        return if value.is_nan() {
            "nan".to_owned()
        } else if value > 0.0 {
            "inf".to_owned()
        } else {
            "-inf".to_owned()
        };
    }
    // The exponent after rounding to the significant digits decides the style, as in C.
    let scientific = format!("{:.*e}", (DIGITS - 1) as usize, value);
    let (mantissa, exponent) = scientific.split_once('e').unwrap_or((&scientific, "0"));
    let exponent: i32 = exponent.parse().unwrap_or(0);
    let trim = |text: &str| -> String {
        if text.contains('.') {
            text.trim_end_matches('0').trim_end_matches('.').to_owned()
        } else {
            text.to_owned()
        }
    };
    if !(-4..DIGITS).contains(&exponent) {
        let sign = if exponent < 0 { '-' } else { '+' };
        format!("{}e{sign}{:02}", trim(mantissa), exponent.abs())
    } else {
        let decimals = (DIGITS - 1 - exponent).max(0) as usize;
        trim(&format!("{value:.decimals$}"))
    }
}

/// libstdc++'s `std::_Hash_bytes` for 64-bit `size_t` with the seed `std::hash<std::string>`
/// uses (0xc70f6907): a MurmurHash2 variant over little-endian 8-byte words.
fn libstdcxx_string_hash(bytes: &[u8]) -> u64 {
    const MUL: u64 = (0xc6a4_a793u64 << 32) + 0x5bd1_e995;
    const SEED: u64 = 0xc70f_6907;
    let shift_mix = |v: u64| v ^ (v >> 47);
    let mut hash = SEED ^ (bytes.len() as u64).wrapping_mul(MUL);
    let mut words = bytes.chunks_exact(8);
    for word in &mut words {
        let mut buffer = [0u8; 8];
        buffer.copy_from_slice(word);
        let data = shift_mix(u64::from_le_bytes(buffer).wrapping_mul(MUL)).wrapping_mul(MUL);
        hash ^= data;
        hash = hash.wrapping_mul(MUL);
    }
    let tail = words.remainder();
    if !tail.is_empty() {
        let data = tail
            .iter()
            .rev()
            .fold(0u64, |sum, &b| (sum << 8) + u64::from(b));
        hash ^= data;
        hash = hash.wrapping_mul(MUL);
    }
    hash = shift_mix(hash).wrapping_mul(MUL);
    shift_mix(hash)
}

#[cfg(test)]
#[allow(clippy::approx_constant)] // The controller's pi/2 is 1.570796327, as it reports it.
mod tests {
    use super::*;

    fn sample() -> KinematicsInfo {
        KinematicsInfo {
            checksum: [1, 2, 3, 4, 5, 0xdead_beef],
            dh_theta: [1e-4, -2e-4, 3e-4, 0.0, 1e-5, -1e-5],
            dh_a: [2e-5, -0.6127, -0.57155, 1e-5, 0.0, 0.0],
            dh_d: [0.1807, -440.3, 440.4, 0.17415, 0.11985, 0.11655],
            dh_alpha: [
                std::f64::consts::FRAC_PI_2,
                1e-4,
                -2e-4,
                std::f64::consts::FRAC_PI_2,
                -std::f64::consts::FRAC_PI_2,
                0.0,
            ],
            calibration_status: 2,
        }
    }

    /// A nominal table as the controller reports pi/2 (1.570796327).
    fn nominal(a: [f64; 6], d: [f64; 6]) -> KinematicsInfo {
        KinematicsInfo {
            checksum: [u32::MAX; 6],
            dh_theta: [0.0; 6],
            dh_a: a,
            dh_d: d,
            dh_alpha: [1.570796327, 0.0, 0.0, 1.570796327, -1.570796327, 0.0],
            calibration_status: 0,
        }
    }

    #[test]
    fn calibration_hashes_match_the_published_default_kinematics_files() {
        // ros-industrial universal_robot, ur_description/config/ur10/default_kinematics.yaml
        let ur10 = nominal(
            [0.0, -0.612, -0.5723, 0.0, 0.0, 0.0],
            [0.1273, 0.0, 0.0, 0.163941, 0.1157, 0.0922],
        );
        let text: String = (0..6)
            .flat_map(|j| {
                [
                    ur10.dh_theta[j],
                    ur10.dh_d[j],
                    ur10.dh_a[j],
                    ur10.dh_alpha[j],
                ]
            })
            .map(format_like_cpp_stream)
            .collect();
        assert_eq!(
            text,
            "00.127301.570800-0.612000-0.5723000.16394101.570800.11570-1.570800.092200"
        );
        assert_eq!(ur10.calibration_hash(), "calib_17227329492635474227");
        // ur_description/config/ur5e/default_kinematics.yaml
        let ur5e = nominal(
            [0.0, -0.425, -0.3922, 0.0, 0.0, 0.0],
            [0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996],
        );
        assert_eq!(ur5e.calibration_hash(), "calib_12788084448423163542");
    }

    #[test]
    fn doubles_print_as_a_cpp_stream_prints_them() {
        for (value, text) in [
            (1e-5, "1e-05"),
            (-1.573498686836816e-05, "-1.5735e-05"),
            (303.469_135_666_158_2, "303.469"),
            (-446.027_059_806_332_1, "-446.027"),
            (1234567.0, "1.23457e+06"),
            (0.0001, "0.0001"),
            (999999.5, "1e+06"),
            (0.5, "0.5"),
            (-0.0, "-0"),
        ] {
            assert_eq!(format_like_cpp_stream(value), text, "{value}");
        }
    }

    #[test]
    fn the_payload_has_the_published_layout() {
        let bytes = sample().encode_payload();
        assert_eq!(bytes.len(), 220);
        // checksum[0], big-endian
        assert_eq!(&bytes[0..4], &[0, 0, 0, 1]);
        assert_eq!(&bytes[20..24], &[0xde, 0xad, 0xbe, 0xef]);
        // dh_theta[0] = 1e-4 as a big-endian IEEE double (0x3F1A36E2EB1C432D)
        assert_eq!(
            &bytes[24..32],
            &[0x3f, 0x1a, 0x36, 0xe2, 0xeb, 0x1c, 0x43, 0x2d]
        );
        // dh_d[1] starts after 6 checksums, 6 thetas, 6 a's and one d
        let at = 24 + 48 * 2 + 8;
        assert_eq!(
            f64::from_be_bytes(bytes[at..at + 8].try_into().unwrap()),
            -440.3
        );
        // the status is the last word
        assert_eq!(&bytes[216..220], &[0, 0, 0, 2]);
        // Bytes of the sub-package in the first robot state of a UR5e (URSim 5.8) that
        // Universal Robots' client library tests its parser with: the header says 225 bytes of
        // type 5, a = -0.425 and alpha = 1.570796327 as these eight bytes.
        let ur5e = nominal(
            [0.0, -0.425, -0.3922, 0.0, 0.0, 0.0],
            [0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996],
        )
        .to_frame()
        .encode();
        assert_eq!(&ur5e[..5], &[0, 0, 0, 0xe1, 5]);
        assert_eq!(&ur5e[5..9], &[0xff; 4]);
        assert_eq!(
            &ur5e[5 + 80..5 + 88],
            &[0xbf, 0xdb, 0x33, 0x33, 0x33, 0x33, 0x33, 0x33]
        );
        assert_eq!(
            &ur5e[5 + 168..5 + 176],
            &[0x3f, 0xf9, 0x21, 0xfb, 0x54, 0x52, 0x45, 0x50]
        );
    }

    #[test]
    fn a_robot_state_round_trips_through_a_stream_cut_anywhere() {
        let other = Frame::new(1, vec![7; 251]);
        let message = robot_state(&[other.clone(), sample().to_frame(), Frame::new(9, vec![])]);
        let mut wire = Frame::new(20, vec![0; 17]).encode();
        wire.extend(message.encode());
        // The message header: size = 5 + (5 + 251) + (5 + 220) + 5, type 16.
        let start = 5 + 17;
        assert_eq!(&wire[start..start + 5], &[0, 0, 1, 235, 16]);
        for cut in [1, 4, 5, 6, 22, 23, 100, 300, wire.len() - 1] {
            let mut reader = MessageReader::new();
            reader.push(&wire[..cut]);
            let mut messages = Vec::new();
            while let Some(m) = reader.next_message().unwrap() {
                messages.push(m);
            }
            reader.push(&wire[cut..]);
            while let Some(m) = reader.next_message().unwrap() {
                messages.push(m);
            }
            assert_eq!(messages.len(), 2, "cut at {cut}");
            assert_eq!(KinematicsInfo::from_message(&messages[0]).unwrap(), None);
            assert_eq!(
                KinematicsInfo::from_message(&messages[1]).unwrap(),
                Some(sample())
            );
        }
    }

    #[test]
    fn malformed_input_is_an_error_never_a_panic() {
        let mut reader = MessageReader::new();
        reader.push(&[0, 0, 0, 3, 16]);
        assert!(matches!(
            reader.next_message(),
            Err(PrimaryError::TooSmall(3))
        ));
        let mut reader = MessageReader::new();
        reader.push(&[0x7f, 0, 0, 0, 16]);
        assert!(matches!(
            reader.next_message(),
            Err(PrimaryError::TooLarge(_))
        ));
        let mut reader = MessageReader::new();
        reader.push(&[0xff, 0xff, 0xff, 0xff, 16]);
        assert!(matches!(
            reader.next_message(),
            Err(PrimaryError::TooSmall(-1))
        ));
        // A sub-package longer than its message.
        let bad = Frame::new(message_type::ROBOT_STATE, vec![0, 0, 1, 0, 5, 1, 2]);
        assert!(matches!(
            KinematicsInfo::from_message(&bad),
            Err(PrimaryError::BadSubPackage { kind: 5, .. })
        ));
        // A KINEMATICS_INFO of the wrong length, and one with a NaN.
        let short = robot_state(&[Frame::new(package_type::KINEMATICS_INFO, vec![0; 219])]);
        assert!(matches!(
            KinematicsInfo::from_message(&short),
            Err(PrimaryError::KinematicsLength(219))
        ));
        let mut nan = sample();
        nan.dh_a[3] = f64::NAN;
        let message = robot_state(&[nan.to_frame()]);
        assert!(matches!(
            KinematicsInfo::from_message(&message),
            Err(PrimaryError::NotFinite {
                field: "dh_a",
                joint: 3,
                ..
            })
        ));
        // Random bytes: errors or nothing, never a panic.
        let mut state = 0x1234_5678_9abc_def0u64;
        for _ in 0..2000 {
            let len = (state % 300) as usize;
            let bytes: Vec<u8> = (0..len)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    state as u8
                })
                .collect();
            let _ = KinematicsInfo::from_message(&Frame::new(16, bytes.clone()));
            let mut reader = MessageReader::new();
            reader.push(&bytes);
            while let Ok(Some(_)) = reader.next_message() {}
        }
    }
}
