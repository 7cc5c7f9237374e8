//! sim-robot's control socket (ZeroMQ REP, `--control`): how tests and `ips demo` script the
//! simulated robot and read its truth. Plain JSON objects `{"command": ..., ...}` (not the
//! thesis's envelope: nothing of the thesis talks to it); replies are `{"ok": true, ...}` or
//! `{"ok": false, "reason": "..."}`. sim-robot's crate documentation has the table of commands.

use std::path::PathBuf;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::envelope::kind_of;
use crate::pose::Pose;

/// A control request, tagged by its `command`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "command", rename_all = "snake_case")]
pub enum SimCommand {
    /// The clock, the clients, the FRI link and the probe run: [`SimStatus`].
    Status,
    /// Where the joints really are now, and what the encoders report: [`Truth`].
    Truth,
    /// As `truth`, at a controller time (s).
    TruthAt { time: f64 },
    /// Replace the scripted motion (and end any probe run).
    Motion { motion: Motion },
    /// Stop sending data (connections stay).
    Pause,
    /// Send data again.
    Resume,
    /// Close every controller connection (clients may reconnect).
    Drop,
    /// What the encoders get wrong, undeclared to everyone else.
    Effects(Effects),
    /// Plan touches on a part at a pose only the simulator knows and run them: [`ProbePlan`].
    Probe(Box<ProbeRequest>),
}

/// Scripted joint motion, a deterministic function of controller time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Motion {
    /// Stand still at `q` (rad).
    Hold { q: Vec<f64> },
    /// q_i(t) = centre_i + amplitude_i sin(2 pi t / period_s): smooth, within limits when the
    /// centre +- amplitude is.
    Sine {
        centre: Vec<f64>,
        amplitude: Vec<f64>,
        period_s: f64,
    },
    /// Joint-space moves through `waypoints` (controller times, increasing), each segment a
    /// smooth start-stop blend q_a + (q_b - q_a) (1 - cos(pi s)) / 2; held before the first and
    /// after the last. Two equal waypoints make a dwell.
    Path { waypoints: Vec<Waypoint> },
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Waypoint {
    pub time_s: f64,
    pub q: Vec<f64>,
    /// The segment that ends here runs at constant joint speed instead of the start-stop blend
    /// (a probe passing through contact on the fly).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub linear: bool,
}

/// What the simulated encoders report differs from the true joint angles. Every field is
/// optional and an absent one is no effect; sim-robot's `effects` module checks the values.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Effects {
    /// reported = true + offset (encoder zero off), rad per joint.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_offsets: Option<Vec<f64>>,
    /// Gravity sag: the joints really sit c tau_g further than reported, rad/(N m) per joint.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compliance_rad_per_nm: Option<Vec<f64>>,
    /// The load whose gravity the compliance acts against.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub payload: Option<Payload>,
    /// reported += a sin(n q) on one joint (an eccentric encoder disc).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cyclic_encoder: Option<CyclicEncoder>,
    /// Gaussian noise on every reported angle, rad.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_sigma_rad: Option<f64>,
    /// Each sample carries the joints of that much later than its time stamp, s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trigger_latency_s: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CyclicEncoder {
    /// 0-based joint index.
    pub joint: usize,
    pub amplitude_rad: f64,
    pub cycles_per_turn: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Payload {
    pub mass_kg: f64,
    /// Centre of mass in the flange frame, m.
    #[serde(default)]
    pub com_in_flange: [f64; 3],
}

fn one() -> f64 {
    1.0
}

fn nine() -> usize {
    9
}

fn default_tilt_rad() -> f64 {
    0.6
}

fn default_dwell_s() -> f64 {
    0.5
}

fn standard_input_0() -> crate::io::DigitalInput {
    crate::io::DigitalInput::DI0
}

/// The `probe` request.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProbeRequest {
    /// The part's mesh file, as sim-robot sees the path.
    pub mesh: PathBuf,
    /// Unit of the mesh file in metres.
    #[serde(default = "one")]
    pub mesh_scale: f64,
    /// Where the part really is (hidden from the alignment side).
    pub base_from_part: Pose,
    /// The probe's TCP in the flange frame, `flange_from_tcp`.
    pub tcp: Pose,
    /// The probe ball's radius, m.
    pub tip_radius: f64,
    /// The real part's size relative to its mesh.
    #[serde(default = "one")]
    pub part_scale: f64,
    #[serde(default = "nine")]
    pub touches: usize,
    /// Largest probe tilt from the surface normal, rad.
    #[serde(default = "default_tilt_rad")]
    pub max_tilt_rad: f64,
    /// How long each touch rests in contact, s.
    #[serde(default = "default_dwell_s")]
    pub dwell_s: f64,
    /// Vary the probe tilt from touch to touch.
    #[serde(default)]
    pub vary_tilt: bool,
    /// Touch on the fly instead of dwelling: pass through each contact at these speeds (m/s,
    /// used in turn, each at most 5 mm/s) along the probe axis. The contact's time is the
    /// trigger's time stamp a touch-trigger probe would give.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub on_the_fly_speeds_m_s: Option<Vec<f64>>,
    /// The digital input the simulated touch-trigger probe is wired to: high while the ball
    /// touches (or is pressed into) the part, in the RTDE output `actual_digital_input_bits`.
    #[serde(default = "standard_input_0")]
    pub trigger_input: crate::io::DigitalInput,
}

/// The reply to `status`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimStatus {
    /// True while the arm does not move.
    pub at_rest: bool,
    /// Connected RTDE clients.
    pub clients: usize,
    /// The FRI link, in iiwa mode.
    pub fri: Option<FriLink>,
    pub paused: bool,
    /// The probe run, once one was asked for.
    pub probe: Option<ProbeStatus>,
    pub robot: String,
    /// Controller time, s.
    pub time: f64,
}

/// The simulated Sunrise cabinet's view of its FRI link.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FriLink {
    pub local_address: String,
    pub quality: String,
    pub sequence: u64,
    pub session_state: String,
    pub timely_answers: u64,
}

/// Where a probe run is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProbeStatus {
    /// The touch in contact now, 0-based.
    pub active_touch: Option<usize>,
    pub at_rest: bool,
    /// True once the last touch is over.
    pub done: bool,
    pub touches: usize,
}

/// The reply to `truth` and `truth_at`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    /// Where the joints really are, rad.
    pub q: Vec<f64>,
    pub qd: Vec<f64>,
    /// What the encoders report.
    pub reported_q: Vec<f64>,
    pub time: f64,
}

/// The reply to `probe`: the planned touches' times in contact and tilts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProbePlan {
    pub contacts: Vec<Contact>,
    /// When the last touch is over, controller time, s.
    pub end_s: f64,
    /// Each touch's probe tilt from the surface normal, rad.
    pub tilts_rad: Vec<f64>,
    pub touches: usize,
}

/// One touch's time in contact, controller time, s: resting from `from_s` to `until_s`, or on
/// the fly crossing the contact at `at_s`. The trigger input is high from `at_s` (the ball
/// reaches the surface) until `released_s` (it leaves it again).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Contact {
    pub at_s: f64,
    pub from_s: f64,
    pub until_s: f64,
    #[serde(default)]
    pub released_s: f64,
}

/// The reply to the commands that only succeed or fail.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Done {}

/// The text of a success reply carrying `data`'s fields beside `"ok": true`.
pub fn reply_ok<T: Serialize>(data: &T) -> String {
    let mut value = serde_json::to_value(data).unwrap_or(serde_json::Value::Null);
    match value.as_object_mut() {
        Some(object) => {
            object.insert("ok".to_owned(), serde_json::Value::Bool(true));
            value.to_string()
        }
        None => reply_error("the reply could not be encoded"),
    }
}

/// The text of a failure reply.
pub fn reply_error(reason: &str) -> String {
    serde_json::json!({"ok": false, "reason": reason}).to_string()
}

/// Why a control reply gave no data.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimReplyError {
    #[error("sim-robot refused: {0}")]
    Refused(String),
    #[error("bad reply from sim-robot: {0}")]
    Shape(String),
}

/// Reads a control reply as `T`.
pub fn parse_reply<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, SimReplyError> {
    let value: serde_json::Value =
        serde_json::from_slice(bytes).map_err(|error| SimReplyError::Shape(error.to_string()))?;
    if value["ok"] != true {
        let reason = value["reason"].as_str().unwrap_or("no reason given");
        return Err(SimReplyError::Refused(reason.to_owned()));
    }
    serde_json::from_value(value).map_err(|error| SimReplyError::Shape(error.to_string()))
}

/// Fields that hold objects wherever they appear at the top of a request.
const OBJECT_FIELDS: [&str; 5] = [
    "motion",
    "payload",
    "cyclic_encoder",
    "base_from_part",
    "tcp",
];

/// Checks that objects are objects: serde's derived structs also read arrays
/// (`["hold",[0,0,0,0,0,0]]` would read as a hold motion), which no client writes.
fn check_objects(value: &serde_json::Value) -> Result<(), String> {
    let Some(object) = value.as_object() else {
        return Err(format!(
            "the request must be a JSON object, got {}",
            kind_of(value)
        ));
    };
    for field in OBJECT_FIELDS {
        match object.get(field) {
            Some(inner) if !inner.is_object() => {
                return Err(format!(
                    "'{field}' must be an object, got {}",
                    kind_of(inner)
                ));
            }
            _ => {}
        }
    }
    let waypoints = object
        .get("motion")
        .and_then(|motion| motion.get("waypoints"))
        .and_then(serde_json::Value::as_array);
    for (index, waypoint) in waypoints.into_iter().flatten().enumerate() {
        if !waypoint.is_object() {
            return Err(format!(
                "'motion.waypoints[{index}]' must be an object, got {}",
                kind_of(waypoint)
            ));
        }
    }
    Ok(())
}

/// Reads a control request, naming what is wrong with it.
pub fn parse_command(bytes: &[u8]) -> Result<SimCommand, String> {
    let value: serde_json::Value =
        serde_json::from_slice(bytes).map_err(|_| "the request is not JSON".to_owned())?;
    check_objects(&value)?;
    let Some(name) = value.get("command") else {
        return Err("the request has no 'command'".to_owned());
    };
    let Some(name) = name.as_str().map(str::to_owned) else {
        return Err("'command' must be a string".to_owned());
    };
    const KNOWN: [&str; 9] = [
        "status", "truth", "truth_at", "motion", "pause", "resume", "drop", "effects", "probe",
    ];
    if !KNOWN.contains(&name.as_str()) {
        return Err(format!("unknown command '{name}'"));
    }
    serde_json::from_value(value).map_err(|error| match name.as_str() {
        "motion" => format!("bad motion: {error}"),
        "effects" => format!("bad effects: {error}"),
        "probe" => format!("bad probe request: {error}"),
        "truth_at" => "truth_at needs a finite 'time' in s".to_owned(),
        _ => format!("bad {name} request: {error}"),
    })
}
