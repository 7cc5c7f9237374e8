//! sim-robot: stands in for a real cobot controller, speaking its wire protocol so that the
//! bridge's real back-end code runs in every test.
//!
//! UR mode serves RTDE ([`rtde_server`]). The joints follow a scripted [`Motion`], a function of
//! the controller clock, so every sample's ground truth can be recomputed exactly. A ZeroMQ
//! control socket (REQ clients see a REP; module `control`) lets tests script the robot and read
//! the truth:
//!
//! | request (JSON) | reply |
//! | --- | --- |
//! | `{"command":"status"}` | `{"ok":true,"time":s,"clients":n,"paused":b,"robot":"ur10","at_rest":b,"fri":{...},"probe":{...}}` |
//! | `{"command":"truth"}` | `{"ok":true,"time":s,"q":[...],"reported_q":[...]}` (now) |
//! | `{"command":"truth_at","time":s}` | `{"ok":true,"time":s,"q":[...],"qd":[...],"reported_q":[...]}` |
//! | `{"command":"motion","motion":{"kind":"hold","q":[...]}}`, `{"kind":"sine",...}` or `{"kind":"path","waypoints":[{"time_s","q"}]}` | `{"ok":true}` |
//! | `{"command":"pause"}` / `{"command":"resume"}` | stop / restart sending data (connections stay) |
//! | `{"command":"drop"}` | close every RTDE connection (clients may reconnect) |
//! | `{"command":"effects","joint_offsets":[...],"compliance_rad_per_nm":[...],"payload":{...},"cyclic_encoder":{...},"noise_sigma_rad":s}` | what the encoders report differs from the true joint angles, undeclared to everyone else (module `effects`; absent fields are no effect) |
//! | `{"command":"probe","mesh":PATH,"base_from_part":{"xyz","rpy"},"tcp":{"xyz","rpy"},"tip_radius":m,...}` | plans 3-2-1 touches on the part at that (hidden) pose and runs them: `{"ok":true,"touches":n,"contacts":[{"from_s","until_s","at_s","released_s"}],"tilts_rad":[...],"end_s"}`; status then carries `"probe":{"touches","active_touch","at_rest","done"}` (module `probing`). The probe is a touch trigger wired to `"trigger_input"` (default `"DI0"`): that bit of the RTDE output `actual_digital_input_bits` is high from `at_s` to `released_s` |
//!
//! Errors reply `{"ok":false,"reason":"..."}`, among them requests of more than one frame, over
//! 64 KiB ([`MAX_REQUEST_BYTES`]), or with arrays where objects belong. `q` is where the joints really are; `reported_q`
//! what the controller streams (they differ by the encoder offsets of `effects`).
//!
//! iiwa mode emulates the Sunrise cabinet's FRI side ([`fri_server`]): a monitoring message to
//! the client at `--fri-target` every send period, the session state and connection quality
//! driven by how timely the client answers. There `status` also carries
//! `"fri": {"session_state","quality","sequence","timely_answers","local_address"}`, `pause`
//! stops sending and `drop` closes the FRI session (a new one starts from sequence 0 on a new
//! source port).

mod control;
mod effects;
mod fri_server;
pub mod motion;
mod primary_server;
mod probing;
mod rtde_server;

use std::net::{SocketAddr, TcpListener, ToSocketAddrs, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use align_core::kinematics::{Chain, DhTable};
use align_core::robots::ShippedRobot;
pub use control::MAX_REQUEST_BYTES;
pub use motion::Motion;
use motion::Trajectory;
use nalgebra::{DVector, Isometry3, Vector3};
use reply_socket::ReplySocket;

#[derive(Debug, Clone)]
pub struct Config {
    pub robot: ShippedRobot,
    /// RTDE listen address, e.g. "127.0.0.1:30004" ("127.0.0.1:0" picks a free port); UR only.
    pub rtde_listen: String,
    /// Primary interface listen address (the robot state with the calibrated kinematics), e.g.
    /// "127.0.0.1:30001"; UR only, `None` serves none.
    pub primary_listen: Option<String>,
    /// The robot's calibration: deltas to its nominal DH table (UR only). The simulated arm
    /// then moves with the calibrated kinematics, reports poses and probes with them, and its
    /// primary interface reports the calibrated table, as a real factory-calibrated arm does.
    pub calibration: Option<DhTable>,
    /// Control endpoint, e.g. "tcp://127.0.0.1:*".
    pub control: String,
    /// The FRI link; iiwa only.
    pub fri: FriSettings,
}

/// Where and how often the emulated iiwa controller sends FRI monitoring messages.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FriSettings {
    /// The client's UDP address, e.g. "127.0.0.1:30200".
    pub target: String,
    /// 1-100 ms, as the Sunrise controller allows.
    pub send_period_ms: u32,
    /// The client answers every n-th message.
    pub receive_multiplier: u32,
    /// The name of a boolean input the emulated Sunrise application registers for FRI
    /// (`registerIO`), which carries the probe's trigger, e.g. `Probe.Trigger`; `None`: the
    /// messages carry no IO, as when the application registers none.
    pub trigger_io: Option<String>,
}

impl Default for FriSettings {
    fn default() -> Self {
        Self {
            target: "127.0.0.1:30200".to_owned(),
            send_period_ms: 5,
            receive_multiplier: 1,
            trigger_io: None,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error("FRI: {0}")]
    Fri(String),
    #[error("cannot listen for RTDE on {address}: {source}")]
    Listen {
        address: String,
        source: std::io::Error,
    },
    #[error("control socket {endpoint}: {source}")]
    Control {
        endpoint: String,
        source: zmq::Error,
    },
    #[error("robot model: {0}")]
    Model(String),
    #[error("calibration: {0}")]
    Calibration(String),
}

/// One controller sample.
pub(crate) struct Sample {
    time_s: f64,
    /// Where the joints are.
    true_q: Vec<f64>,
    /// What the encoders say.
    q: Vec<f64>,
    qd: Vec<f64>,
    qdd: Vec<f64>,
    /// Base frame, rotation as a rotation vector (UR's pose convention).
    tcp_pose: [f64; 6],
    /// Base frame: linear then angular velocity.
    tcp_speed: [f64; 6],
    /// Tool frame, m/s^2: what the tool flange's accelerometer reads at rest (gravity's
    /// reaction, pointing up); the arm's own accelerations are not modelled.
    tool_accelerometer: [f64; 3],
    /// The digital inputs as UR's `actual_digital_input_bits` lays them out: the probe's
    /// trigger input while its ball touches the part.
    digital_inputs: u64,
}

/// Controller states a healthy arm reports (UR's RTDE guide): robot mode RUNNING, safety mode
/// NORMAL, joint mode RUNNING, runtime state PLAYING, and the status bits that go with them
/// (robot: power on and program running; safety: normal mode).
const ROBOT_MODE_RUNNING: f64 = 7.0;
const SAFETY_MODE_NORMAL: f64 = 1.0;
const JOINT_MODE_RUNNING: f64 = 253.0;
const RUNTIME_STATE_PLAYING: f64 = 2.0;
const ROBOT_STATUS_POWER_ON_AND_PROGRAM_RUNNING: f64 = 0b11 as f64;
const SAFETY_STATUS_NORMAL_MODE: f64 = 0b1 as f64;
/// The arm's supply (V) and an idle joint's temperature (deg C): no electrical or thermal model,
/// so the values an idle arm in a room would show rather than zeros that read as a fault.
const SUPPLY_VOLTAGE_V: f64 = 48.0;
const IDLE_JOINT_TEMPERATURE_C: f64 = 25.0;
const STANDARD_GRAVITY_M_PER_S2: f64 = 9.80665;

impl Sample {
    /// The value of an RTDE output variable for this sample. Variables the simulation does not
    /// model (currents, torques, forces, I/O, registers, payload) read zero.
    pub(crate) fn value(&self, name: &str) -> Vec<f64> {
        match name {
            "timestamp" => vec![self.time_s],
            "actual_q" | "target_q" => self.q.clone(),
            "actual_qd" | "target_qd" => self.qd.clone(),
            "target_qdd" => self.qdd.clone(),
            "actual_TCP_pose" | "target_TCP_pose" => self.tcp_pose.to_vec(),
            "actual_TCP_speed" | "target_TCP_speed" => self.tcp_speed.to_vec(),
            "actual_tool_accelerometer" => self.tool_accelerometer.to_vec(),
            "robot_mode" => vec![ROBOT_MODE_RUNNING],
            "safety_mode" | "safety_status" => vec![SAFETY_MODE_NORMAL],
            "joint_mode" => vec![JOINT_MODE_RUNNING; self.q.len()],
            "runtime_state" => vec![RUNTIME_STATE_PLAYING],
            "robot_status_bits" => vec![ROBOT_STATUS_POWER_ON_AND_PROGRAM_RUNNING],
            "safety_status_bits" => vec![SAFETY_STATUS_NORMAL_MODE],
            "speed_scaling" | "target_speed_fraction" => vec![1.0],
            "actual_main_voltage" | "actual_robot_voltage" => vec![SUPPLY_VOLTAGE_V],
            "actual_joint_voltage" => vec![SUPPLY_VOLTAGE_V; self.q.len()],
            "joint_temperatures" => vec![IDLE_JOINT_TEMPERATURE_C; self.q.len()],
            // Exact as f64: only bits 0-17 are ever set.
            "actual_digital_input_bits" => vec![self.digital_inputs as f64],
            _ => Vec::new(),
        }
    }
}

/// State shared by the control socket and the protocol servers.
pub(crate) struct Shared {
    pub(crate) shutdown: AtomicBool,
    pub(crate) paused: AtomicBool,
    pub(crate) drop_generation: AtomicU64,
    pub(crate) clients: AtomicUsize,
    pub(crate) write_lock: Mutex<()>,
    pub(crate) max_frequency_hz: f64,
    pub(crate) controller_version: [u32; 4],
    started: Instant,
    motion: Mutex<Motion>,
    /// What the encoders get wrong (undeclared effects).
    effects: Mutex<effects::Effects>,
    chain: Chain,
    limits: Vec<(f64, f64)>,
    /// The FRI link as the emulated controller sees it (iiwa mode).
    fri: Mutex<Option<fri_server::LinkReport>>,
    /// The running probe's contact windows.
    probe: Mutex<Option<probing::Schedule>>,
}

impl Shared {
    fn now_s(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }

    fn sample_at(&self, time_s: f64) -> Sample {
        let motion = self
            .motion
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone();
        let effects = self
            .effects
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone();
        let true_q = motion.position(time_s);
        // The controller only knows its encoders: it reports, and computes its TCP from, the
        // angles they read, taken `latency` after the time stamp it puts on them.
        let latency_s = effects.latency_s();
        let q = effects.reported(&self.chain, &motion.position(time_s + latency_s), time_s);
        let qd = motion.velocity(time_s + latency_s);
        let (base_from_tool, jacobian): (Isometry3<f64>, _) = self.chain.jacobian_unchecked(&q);
        let t = base_from_tool.translation.vector;
        let r = base_from_tool.rotation.scaled_axis();
        let speed = jacobian * DVector::from_column_slice(&qd);
        // The inputs are sampled at the time stamp, with no encoder latency: a trigger
        // latency shows as encoder angles taken late relative to the edge.
        let digital_inputs = self
            .probe
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .as_ref()
            .map_or(0, |schedule| schedule.digital_inputs(time_s));
        let up_in_tool = base_from_tool
            .rotation
            .inverse_transform_vector(&Vector3::new(0.0, 0.0, STANDARD_GRAVITY_M_PER_S2));
        Sample {
            time_s,
            true_q,
            q,
            qd,
            qdd: motion.acceleration(time_s + latency_s),
            tcp_pose: [t.x, t.y, t.z, r.x, r.y, r.z],
            tcp_speed: [speed[0], speed[1], speed[2], speed[3], speed[4], speed[5]],
            tool_accelerometer: [up_in_tool.x, up_in_tool.y, up_in_tool.z],
            digital_inputs,
        }
    }

    /// Where the scripted motion puts the joints at `time_s` (true angles).
    fn motion_at(&self, time_s: f64) -> Vec<f64> {
        self.motion
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .position(time_s)
    }

    fn set_motion(&self, motion: Motion) {
        *self.motion.lock().unwrap_or_else(|p| p.into_inner()) = motion;
    }

    pub(crate) fn sample(&self) -> Sample {
        self.sample_at(self.now_s())
    }
}

/// A running simulator.
#[derive(Debug)]
pub struct SimHandle {
    /// The RTDE server's address (UR mode).
    pub rtde_address: Option<String>,
    /// The primary interface's address (UR mode, when asked for).
    pub primary_address: Option<String>,
    /// The FRI controller's UDP address and its target (iiwa mode).
    pub fri_address: Option<String>,
    pub fri_target: Option<String>,
    pub control_endpoint: String,
    /// Wall-clock time of controller time zero, s since the Unix epoch (for latency figures).
    pub clock_origin_unix_s: f64,
    shared: Arc<SharedDebug>,
    threads: Vec<JoinHandle<()>>,
}

/// Wrapper so the handle can derive Debug without exposing internals.
struct SharedDebug(Arc<Shared>);

impl std::fmt::Debug for SharedDebug {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Shared")
    }
}

impl SimHandle {
    /// The RTDE server's port (UR mode).
    pub fn rtde_port(&self) -> Option<u16> {
        self.rtde_address
            .as_deref()?
            .rsplit(':')
            .next()?
            .parse()
            .ok()
    }

    /// Asks every thread to stop and waits for them.
    pub fn stop(mut self) {
        self.shared.0.shutdown.store(true, Ordering::Relaxed);
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
    }
}

impl Drop for SimHandle {
    fn drop(&mut self) {
        self.shared.0.shutdown.store(true, Ordering::Relaxed);
    }
}

/// Where the simulated arm starts: [`ShippedRobot::home`].
pub fn home(robot: ShippedRobot) -> Vec<f64> {
    robot.home()
}

/// Starts the simulator's servers and returns their bound endpoints.
pub fn start(config: &Config) -> Result<SimHandle, SimError> {
    let (max_frequency_hz, controller_version) = match config.robot {
        ShippedRobot::Ur10 => (125.0, [3, 15, 7, 106]),
        ShippedRobot::Ur10e => (500.0, [5, 11, 6, 108]),
        // Not an RTDE controller: these only set the RTDE server's figures, which is not run.
        ShippedRobot::Iiwa14 => (1000.0 / f64::from(config.fri.send_period_ms.max(1)), [0; 4]),
    };
    let nominal_chain = config
        .robot
        .chain()
        .map_err(|e| SimError::Model(e.to_string()))?;
    // The DH table the arm really moves with (nominal, or nominal plus the calibration) and the
    // chain that moves with it.
    let (chain, table) = match (config.robot.nominal_dh(), &config.calibration) {
        (Some(nominal), Some(delta)) => {
            let table = nominal
                .plus(delta)
                .map_err(|e| SimError::Calibration(e.to_string()))?;
            let chain = nominal_chain
                .with_dh(&nominal, &table)
                .map_err(|e| SimError::Calibration(e.to_string()))?;
            (chain, Some(table))
        }
        (Some(nominal), None) => (nominal_chain, Some(nominal)),
        (None, Some(_)) => {
            return Err(SimError::Calibration(format!(
                "{} has no DH table to calibrate (UR robots only)",
                config.robot.name()
            )));
        }
        (None, None) => (nominal_chain, None),
    };
    let primary_listener = match (&config.primary_listen, &table) {
        (Some(address), Some(_)) => {
            Some(
                TcpListener::bind(address).map_err(|source| SimError::Listen {
                    address: address.clone(),
                    source,
                })?,
            )
        }
        _ => None,
    };
    let limits = chain
        .joints()
        .iter()
        .map(|j| (j.limits.lower, j.limits.upper))
        .collect();
    let shared = Arc::new(Shared {
        shutdown: AtomicBool::new(false),
        paused: AtomicBool::new(false),
        drop_generation: AtomicU64::new(0),
        clients: AtomicUsize::new(0),
        write_lock: Mutex::new(()),
        max_frequency_hz,
        controller_version,
        started: Instant::now(),
        motion: Mutex::new(Motion::Hold {
            q: home(config.robot),
        }),
        effects: Mutex::new(effects::Effects::default()),
        chain,
        limits,
        fri: Mutex::new(None),
        probe: Mutex::new(None),
    });
    let server = match config.robot {
        ShippedRobot::Iiwa14 => Server::Fri(fri_link(&config.fri)?),
        _ => {
            let listener =
                TcpListener::bind(&config.rtde_listen).map_err(|source| SimError::Listen {
                    address: config.rtde_listen.clone(),
                    source,
                })?;
            Server::Rtde(listener)
        }
    };
    let context = zmq::Context::new();
    // A ROUTER doing REP's part (the reply-socket crate says why); REQ clients see a REP.
    let (control, control_endpoint) =
        ReplySocket::bind(&context, &config.control, 100).map_err(|source| SimError::Control {
            endpoint: config.control.clone(),
            source,
        })?;
    let mut threads = Vec::new();
    let (mut rtde_address, mut fri_address, mut fri_target) = (None, None, None);
    let mut primary_address = None;
    if let (Some(listener), Some(table)) = (primary_listener, &table) {
        primary_address = listener.local_addr().ok().map(|a| a.to_string());
        let kinematics = kinematics_info(table);
        let shared = Arc::clone(&shared);
        threads.push(thread::spawn(move || {
            primary_server::serve(listener, shared, kinematics)
        }));
    }
    match server {
        Server::Rtde(listener) => {
            rtde_address = Some(
                listener
                    .local_addr()
                    .map(|a| a.to_string())
                    .unwrap_or_else(|_| config.rtde_listen.clone()),
            );
            let shared = Arc::clone(&shared);
            threads.push(thread::spawn(move || rtde_server::serve(listener, shared)));
        }
        Server::Fri((socket, link)) => {
            fri_address = socket.local_addr().ok().map(|a| a.to_string());
            fri_target = Some(link.target.to_string());
            let shared = Arc::clone(&shared);
            threads.push(thread::spawn(move || {
                fri_server::serve(socket, link, shared)
            }));
        }
    }
    {
        let shared = Arc::clone(&shared);
        let robot = config.robot;
        threads.push(thread::spawn(move || {
            control::control_loop(control, shared, robot)
        }));
    }
    let clock_origin_unix_s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
        - shared.started.elapsed().as_secs_f64();
    Ok(SimHandle {
        rtde_address,
        primary_address,
        fri_address,
        fri_target,
        control_endpoint,
        clock_origin_unix_s,
        shared: Arc::new(SharedDebug(shared)),
        threads,
    })
}

/// The KINEMATICS_INFO a controller with this DH table sends.
fn kinematics_info(table: &DhTable) -> ur_primary::KinematicsInfo {
    let row = |values: &[f64]| std::array::from_fn(|j| values.get(j).copied().unwrap_or(0.0));
    ur_primary::KinematicsInfo::from_table(
        row(&table.theta),
        row(&table.a),
        row(&table.d),
        row(&table.alpha),
    )
}

enum Server {
    Rtde(TcpListener),
    Fri((UdpSocket, fri_server::FriLink)),
}

/// Checks the FRI settings and opens the controller's socket on the interface that reaches the
/// target.
fn fri_link(settings: &FriSettings) -> Result<(UdpSocket, fri_server::FriLink), SimError> {
    if !(1..=100).contains(&settings.send_period_ms) {
        return Err(SimError::Fri(format!(
            "send period {} ms is outside the controller's 1-100 ms",
            settings.send_period_ms
        )));
    }
    if settings.receive_multiplier == 0 {
        return Err(SimError::Fri(
            "receive multiplier must be at least 1".to_owned(),
        ));
    }
    if let Some(name) = &settings.trigger_io {
        // The SDK holds IO names in 64-byte C strings.
        if name.is_empty() || name.len() > kuka_fri::MAX_IO_NAME_BYTES || !name.is_ascii() {
            return Err(SimError::Fri(format!(
                "IO name '{name}' must be 1-{} ASCII characters, e.g. Probe.Trigger",
                kuka_fri::MAX_IO_NAME_BYTES
            )));
        }
    }
    let target: SocketAddr = settings
        .target
        .to_socket_addrs()
        .ok()
        .and_then(|mut addresses| addresses.next())
        .ok_or_else(|| {
            SimError::Fri(format!(
                "target '{}' is not a HOST:PORT address",
                settings.target
            ))
        })?;
    let local = if target.ip().is_loopback() {
        SocketAddr::new(target.ip(), 0)
    } else {
        SocketAddr::from(([0, 0, 0, 0], 0))
    };
    let socket = UdpSocket::bind(local)
        .map_err(|error| SimError::Fri(format!("cannot open a UDP socket on {local}: {error}")))?;
    Ok((
        socket,
        fri_server::FriLink {
            target,
            send_period: Duration::from_millis(u64::from(settings.send_period_ms)),
            receive_multiplier: settings.receive_multiplier,
            trigger_io: settings.trigger_io.clone(),
        },
    ))
}
