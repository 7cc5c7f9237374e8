//! Controller back ends: each turns a controller's own protocol into [`Event`]s. A back end is a
//! module owning its settings (a type implementing [`BackendSettings`]) and its connection (a
//! type implementing [`Backend`]); [`BackendConfig`] lists them, and is the only place that does.
//!
//! Adding a robot brand: a module here (settings, connection), a [`BackendKind`] and a
//! [`BackendConfig`] variant, its flags in `src/bin/robot-bridge.rs`, and a test file with a
//! `Cell` for it and the line `conformance!(BrandCell);` (see `tests/conformance/mod.rs`).

pub mod dummy;
pub mod iiwa;
pub mod ur;

use std::time::Duration;

use protocol::RobotSide;

/// One joint-state sample from the controller.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    pub effort: Option<Vec<f64>>,
    pub controller_time: f64,
    pub controller_seq: Option<u64>,
    pub robot_mode: Option<i32>,
    pub safety_mode: Option<i32>,
    /// The link as the controller grades it, where the protocol says (FRI).
    pub link: Option<LinkState>,
    /// The controller's digital inputs, one bit each (see `protocol::io`), where it offers
    /// them (UR: RTDE `actual_digital_input_bits`).
    pub digital_inputs: Option<u64>,
}

/// A controller's own view of the link (FRI session state and connection quality).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LinkState {
    pub session_state: Option<&'static str>,
    pub quality: Option<&'static str>,
}

/// What a back end reports.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    Connecting,
    Connected {
        description: String,
    },
    /// The controller's calibrated kinematics, read on a (re)connection (UR primary interface).
    Kinematics(protocol::calibration::ControllerKinematics),
    Sample(Sample),
    Lost {
        reason: String,
    },
}

/// A controller connection. `next_event` blocks at most `timeout`; `None` means nothing new.
pub trait Backend: Send {
    fn joint_names(&self) -> Vec<String>;
    /// Unit of [`Sample::effort`].
    fn effort_unit(&self) -> Option<&'static str>;
    fn next_event(&mut self, timeout: Duration) -> Option<Event>;
    /// Datagrams dropped as not from the controller or not its messages, and the latest reason
    /// (datagram protocols only).
    fn rejected_datagrams(&self) -> Option<(u64, Option<String>)> {
        None
    }
    /// Where the controller's messages are received, for protocols where the controller
    /// connects to the bridge (FRI): e.g. "udp://0.0.0.0:30200".
    fn controller_endpoint(&self) -> Option<String> {
        None
    }
}

/// Which controller protocol the bridge speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BackendKind {
    Ur,
    Iiwa,
    Dummy,
}

impl BackendKind {
    /// The name in the status reply's `backend` field and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            BackendKind::Ur => "ur",
            BackendKind::Iiwa => "iiwa",
            BackendKind::Dummy => "dummy",
        }
    }
}

/// A back end's settings: which protocol it is, the side name its robot has in the thesis's
/// messages, and how to open the connection.
pub trait BackendSettings {
    fn kind(&self) -> BackendKind;
    /// `"ros"` for UR (the thesis's ROS link), `"IiwaDrive"` for iiwa.
    fn robot_side(&self) -> RobotSide;
    /// Opens the connection; from then on the back end connects and reconnects by itself, so
    /// only a local failure (a port that cannot be bound) is an error.
    fn open(&self) -> Result<Box<dyn Backend>, OpenError>;
}

/// A failure to open a back end.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    #[error("cannot listen for FRI on UDP port {port}: {source}")]
    FriListen { port: u16, source: std::io::Error },
}

/// The back end to run, with its own settings.
#[derive(Debug, Clone)]
pub enum BackendConfig {
    Ur(ur::UrConfig),
    Iiwa(iiwa::IiwaConfig),
    Dummy(dummy::DummyConfig),
}

impl BackendConfig {
    /// The one dispatch over back ends: everything else goes through [`BackendSettings`].
    pub fn settings(&self) -> &dyn BackendSettings {
        match self {
            BackendConfig::Ur(config) => config,
            BackendConfig::Iiwa(config) => config,
            BackendConfig::Dummy(config) => config,
        }
    }

    pub fn kind(&self) -> BackendKind {
        self.settings().kind()
    }

    pub fn robot_side(&self) -> RobotSide {
        self.settings().robot_side()
    }
}
