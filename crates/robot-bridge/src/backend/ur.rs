//! Universal Robots back end: an RTDE client on TCP 30004. Negotiates protocol 2 (falling back
//! to 1), reads the controller version, sets up the output recipe at the controller's maximum
//! frequency (125 Hz on CB3, 500 Hz on e-Series), starts, and turns data packages into samples.
//! Connection loss (EOF, an error, or 2 s of silence) is reported and retried with backoff.
//!
//! On every (re)connection it also reads the robot's factory calibration from the primary
//! interface (TCP 30001): the calibrated DH table of the robot state's KINEMATICS_INFO, which
//! puts the flange 2-4 mm nearer the truth than the nominal table. Reading needs no remote
//! control. A controller whose primary interface does not answer streams on without it, with a
//! warning.

use std::io::Read;
use std::net::{TcpStream, ToSocketAddrs};
use std::time::{Duration, Instant};

use ur_rtde::{
    Package, RtdeError, ValueType, decode_values, package, parse_setup_reply, setup_outputs_request,
};

use protocol::RobotSide;

use super::{Backend, BackendKind, BackendSettings, Event, OpenError, Sample};

/// The outputs every sample needs, in the order `next_event` decodes them.
const RECIPE: [&str; 7] = [
    "timestamp",
    "actual_q",
    "actual_qd",
    "actual_current",
    "actual_TCP_pose",
    "robot_mode",
    "safety_mode",
];
/// Asked for after [`RECIPE`] when the controller has it: the digital inputs (a touch-trigger
/// probe's among them). A controller that answers NOT_FOUND streams without them.
const DIGITAL_INPUTS: &str = "actual_digital_input_bits";

/// Silence after which the controller counts as lost.
pub const SILENCE_LIMIT: Duration = Duration::from_secs(2);
/// The controller's RTDE port.
pub const DEFAULT_RTDE_PORT: u16 = 30004;
/// The controller's primary interface port.
pub const DEFAULT_PRIMARY_PORT: u16 = 30001;
/// How long a connection waits for the robot state with the kinematics (the controller sends
/// it ten times a second).
const KINEMATICS_WITHIN: Duration = Duration::from_secs(1);

/// Where the UR controller is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UrConfig {
    pub robot_host: String,
    pub rtde_port: u16,
    /// The primary interface's port, for the calibration; `None` reads none.
    pub primary_port: Option<u16>,
}

impl BackendSettings for UrConfig {
    fn kind(&self) -> BackendKind {
        BackendKind::Ur
    }

    fn robot_side(&self) -> RobotSide {
        RobotSide::Ros
    }

    fn open(&self) -> Result<Box<dyn Backend>, OpenError> {
        let mut backend = UrBackend::new(&self.robot_host, self.rtde_port);
        backend.primary_address = self
            .primary_port
            .map(|port| format!("{}:{port}", self.robot_host));
        Ok(Box::new(backend))
    }
}

pub struct UrBackend {
    address: String,
    /// The primary interface, where the calibration is read on each connection.
    primary_address: Option<String>,
    /// Read on the latest connection, not yet reported.
    kinematics: Option<protocol::calibration::ControllerKinematics>,
    connection: Option<Connection>,
    backoff: Duration,
    retry_at: Instant,
    announced_connecting: bool,
}

struct Connection {
    stream: TcpStream,
    version: u16,
    types: Vec<ValueType>,
    last_data: Instant,
    /// Bytes received but not yet a whole package: a read timeout may fall mid-package.
    pending: Vec<u8>,
    /// Whether the recipe has [`DIGITAL_INPUTS`], after the required outputs.
    digital_inputs: bool,
}

impl Connection {
    /// The next whole package, reading for at most `timeout`; `Ok(None)` when none is complete.
    fn poll_package(&mut self, timeout: Duration) -> std::io::Result<Option<Package>> {
        loop {
            if self.pending.len() >= 3 {
                let size = u16::from_be_bytes([self.pending[0], self.pending[1]]) as usize;
                if size < 3 {
                    return Err(std::io::Error::other(format!(
                        "package size {size} is smaller than its header"
                    )));
                }
                if self.pending.len() >= size {
                    let rest = self.pending.split_off(size);
                    let whole = std::mem::replace(&mut self.pending, rest);
                    return Ok(Some(Package::new(whole[2], whole[3..].to_vec())));
                }
            }
            self.stream
                .set_read_timeout(Some(timeout.max(Duration::from_millis(1))))?;
            let mut buffer = [0u8; 4096];
            match self.stream.read(&mut buffer) {
                Ok(0) => {
                    return Err(std::io::Error::new(
                        std::io::ErrorKind::UnexpectedEof,
                        "the controller closed the connection",
                    ));
                }
                Ok(count) => self.pending.extend_from_slice(&buffer[..count]),
                Err(error)
                    if matches!(
                        error.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    return Ok(None);
                }
                Err(error) => return Err(error),
            }
        }
    }
}

impl std::fmt::Debug for UrBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("UrBackend")
            .field("address", &self.address)
            .finish()
    }
}

impl UrBackend {
    pub fn new(host: &str, port: u16) -> Self {
        Self {
            address: format!("{host}:{port}"),
            primary_address: None,
            kinematics: None,
            connection: None,
            backoff: Duration::from_millis(100),
            retry_at: Instant::now(),
            announced_connecting: false,
        }
    }

    fn connect(&self) -> Result<(Connection, String), RtdeError> {
        let address = self
            .address
            .to_socket_addrs()?
            .next()
            .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::NotFound, "no address"))?;
        let mut stream = TcpStream::connect_timeout(&address, Duration::from_secs(2))?;
        stream.set_nodelay(true)?;
        stream.set_read_timeout(Some(SILENCE_LIMIT))?;
        let mut version = 2;
        Package::new(
            package::REQUEST_PROTOCOL_VERSION,
            2u16.to_be_bytes().to_vec(),
        )
        .write_to(&mut stream)?;
        if read_reply(&mut stream, package::REQUEST_PROTOCOL_VERSION)?.first_byte()? != 1 {
            version = 1;
            Package::new(
                package::REQUEST_PROTOCOL_VERSION,
                1u16.to_be_bytes().to_vec(),
            )
            .write_to(&mut stream)?;
            if read_reply(&mut stream, package::REQUEST_PROTOCOL_VERSION)?.first_byte()? != 1 {
                return Err(std::io::Error::other(
                    "the controller accepts neither RTDE protocol 2 nor 1",
                )
                .into());
            }
        }
        Package::new(package::GET_URCONTROL_VERSION, Vec::new()).write_to(&mut stream)?;
        let reply = read_reply(&mut stream, package::GET_URCONTROL_VERSION)?;
        let parts: Vec<u32> = reply
            .payload
            .chunks_exact(4)
            .map(|c| u32::from_be_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        let major = parts.first().copied().unwrap_or(0);
        // CB3 controllers (3.x) stream at most 125 Hz, e-Series (5.x) 500 Hz.
        let frequency = if major >= 5 { 500.0 } else { 125.0 };
        let rate = (version >= 2).then_some(frequency);
        let mut names = RECIPE.to_vec();
        names.push(DIGITAL_INPUTS);
        let mut types = setup_recipe(&mut stream, version, rate, &names)?;
        let digital_inputs = types.last().is_some_and(Option::is_some);
        if !digital_inputs {
            // One NOT_FOUND spoils the whole recipe: ask again for the required outputs alone.
            names.pop();
            types = setup_recipe(&mut stream, version, rate, &names)?;
        }
        let types = match types.into_iter().collect::<Option<Vec<ValueType>>>() {
            Some(types) => types,
            None => {
                return Err(
                    std::io::Error::other("the controller refused the output recipe").into(),
                );
            }
        };
        Package::new(package::CONTROL_PACKAGE_START, Vec::new()).write_to(&mut stream)?;
        if read_reply(&mut stream, package::CONTROL_PACKAGE_START)?.first_byte()? != 1 {
            return Err(std::io::Error::other("the controller refused to start streaming").into());
        }
        let description = format!(
            "RTDE v{version} to {} (controller {}), {frequency} Hz, {}",
            self.address,
            parts
                .iter()
                .map(u32::to_string)
                .collect::<Vec<_>>()
                .join("."),
            if digital_inputs {
                "with digital inputs"
            } else {
                "without digital inputs (the controller has no actual_digital_input_bits)"
            }
        );
        Ok((
            Connection {
                stream,
                version,
                types,
                last_data: Instant::now(),
                pending: Vec::new(),
                digital_inputs,
            },
            description,
        ))
    }

    fn lose(&mut self, reason: String) -> Event {
        if let Some(connection) = self.connection.take() {
            let _ = connection.stream.shutdown(std::net::Shutdown::Both);
        }
        self.retry_at = Instant::now() + self.backoff;
        self.backoff = (self.backoff * 2).min(Duration::from_secs(2));
        self.announced_connecting = false;
        Event::Lost { reason }
    }
}

/// The calibrated kinematics of the controller whose primary interface is at `address`, with
/// their hash, read within `within`.
pub fn read_kinematics(
    address: &str,
    within: Duration,
) -> Result<protocol::calibration::ControllerKinematics, String> {
    let info = ur_primary::read_kinematics(address, within)?;
    Ok(protocol::calibration::ControllerKinematics {
        dh_theta: info.dh_theta.to_vec(),
        dh_a: info.dh_a.to_vec(),
        dh_d: info.dh_d.to_vec(),
        dh_alpha: info.dh_alpha.to_vec(),
        hash: Some(info.calibration_hash()),
    })
}

/// Sets up an output recipe of `names` and returns their types, NOT_FOUND as `None`; an error
/// when a required output ([`RECIPE`]) is missing or the controller refuses a complete recipe.
fn setup_recipe(
    stream: &mut TcpStream,
    version: u16,
    frequency_hz: Option<f64>,
    names: &[&str],
) -> Result<Vec<Option<ValueType>>, RtdeError> {
    setup_outputs_request(frequency_hz, names).write_to(stream)?;
    let (recipe, types) = parse_setup_reply(
        &read_reply(stream, package::CONTROL_PACKAGE_SETUP_OUTPUTS)?,
        version,
    )?;
    if types.len() != names.len() {
        return Err(std::io::Error::other(format!(
            "the controller answered {} types for {} outputs",
            types.len(),
            names.len()
        ))
        .into());
    }
    if let Some(missing) = types[..RECIPE.len()].iter().position(Option::is_none) {
        return Err(std::io::Error::other(format!(
            "the controller does not know output '{}' (NOT_FOUND)",
            RECIPE[missing]
        ))
        .into());
    }
    let complete = types.iter().all(Option::is_some);
    if complete && version >= 2 && recipe == 0 {
        return Err(std::io::Error::other("the controller refused the output recipe").into());
    }
    Ok(types)
}

/// Reads packages until one of `kind` arrives (text messages and stray data are skipped).
fn read_reply(stream: &mut TcpStream, kind: u8) -> Result<Package, RtdeError> {
    loop {
        let package = Package::read_from(stream)?;
        if package.kind == kind {
            return Ok(package);
        }
    }
}

impl Backend for UrBackend {
    fn joint_names(&self) -> Vec<String> {
        [
            "shoulder_pan_joint",
            "shoulder_lift_joint",
            "elbow_joint",
            "wrist_1_joint",
            "wrist_2_joint",
            "wrist_3_joint",
        ]
        .map(str::to_owned)
        .to_vec()
    }

    fn effort_unit(&self) -> Option<&'static str> {
        Some("A")
    }

    fn next_event(&mut self, timeout: Duration) -> Option<Event> {
        if let Some(kinematics) = self.kinematics.take() {
            return Some(Event::Kinematics(kinematics));
        }
        let Some(connection) = self.connection.as_mut() else {
            let now = Instant::now();
            if now < self.retry_at {
                std::thread::sleep((self.retry_at - now).min(timeout));
                return None;
            }
            if !self.announced_connecting {
                self.announced_connecting = true;
                return Some(Event::Connecting);
            }
            return match self.connect() {
                Ok((connection, description)) => {
                    self.connection = Some(connection);
                    self.backoff = Duration::from_millis(100);
                    if let Some(primary) = &self.primary_address {
                        match read_kinematics(primary, KINEMATICS_WITHIN) {
                            Ok(kinematics) => self.kinematics = Some(kinematics),
                            Err(reason) => tracing::warn!(
                                %reason,
                                "no calibration from the controller's primary interface at {primary}: poses use the nominal kinematics"
                            ),
                        }
                    }
                    Some(Event::Connected { description })
                }
                Err(error) => Some(self.lose(format!(
                    "cannot connect to the controller at {}: {error}",
                    self.address
                ))),
            };
        };
        match connection.poll_package(timeout) {
            Ok(Some(package)) if package.kind == package::DATA_PACKAGE => {
                connection.last_data = Instant::now();
                let offset = usize::from(connection.version >= 2);
                match decode_values(&package.payload, offset, &connection.types) {
                    Ok(values) => Some(Event::Sample(Sample {
                        controller_time: values[0][0],
                        position: values[1].clone(),
                        velocity: values[2].clone(),
                        effort: Some(values[3].clone()),
                        controller_seq: None,
                        robot_mode: Some(values[5][0] as i32),
                        safety_mode: Some(values[6][0] as i32),
                        link: None,
                        // UINT64 decoded as f64: exact for the 18 bits a controller sets.
                        digital_inputs: connection
                            .digital_inputs
                            .then(|| values[RECIPE.len()][0] as u64),
                    })),
                    Err(error) => Some(self.lose(format!("malformed data package: {error}"))),
                }
            }
            Ok(Some(_)) => None,
            Ok(None) => {
                if connection.last_data.elapsed() >= SILENCE_LIMIT {
                    Some(self.lose(format!(
                        "no data from the controller for {} s",
                        SILENCE_LIMIT.as_secs()
                    )))
                } else {
                    None
                }
            }
            Err(error) => Some(self.lose(format!("controller connection lost: {error}"))),
        }
    }
}
