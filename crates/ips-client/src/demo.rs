//! `ips demo`: the whole loop on the simulator in one command. Starts sim-robot, robot-bridge
//! and `ips serve` as child processes on free ports, places the step block at a pose only the
//! simulator knows, drives the robot to nine touches, captures each through the service, aligns,
//! and prints the result beside the truth. Children are stopped with SIGTERM at the end; if one
//! dies early the demo says which and fails.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use align_core::io::{TriangleSoup, write_stl_binary};
use align_core::pose::{isometry_from_xyz_rpy, xyz_rpy};
use align_core::robots::ShippedRobot;
use align_core::trials::parts::step_block;
use serde::Serialize;
use serde_json::{Value, json};

use crate::BadInput;
use crate::session::{FORMAT, PartSection, PoseSection, RobotSection, SessionFile, ToolSection};

#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Simulated robot: ur10 (RTDE, 125 Hz), ur10e (RTDE, 500 Hz) or iiwa14 (FRI, 5 ms).
    #[arg(long, default_value = "ur10")]
    pub robot: String,
    /// An effect the simulated cell has and the model does not declare: none, probe_radius
    /// (3.4 mm ball, 3 mm declared), tcp_offset (TCP 2.3 mm off), part_scale (part 0.4% larger
    /// than its model), joint_offsets (encoder offsets of 1-2 mrad), joint_compliance (two
    /// joints sag under gravity, 3-4e-5 rad/(N m)), cyclic_encoder (an eccentric encoder on the
    /// shoulder, 1 mrad twice per turn: outside the diagnosis library), trigger_latency (touches
    /// taken on the fly at 1-4 mm/s, each sample 50 ms later than its trigger time stamp). With an
    /// effect the demo takes 16 tilted touches and runs the diagnosis.
    #[arg(long, default_value = "none")]
    pub effect: String,
    /// Encoder noise of 20 urad on every joint of every sample (the session declares 50 um).
    #[arg(long)]
    pub noise: bool,
    /// Print one JSON document instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Serialize)]
pub struct DemoOutput {
    pub robot: String,
    /// The effect the simulated cell had.
    pub effect: String,
    /// The diagnosis of the residual: verdict, effect found and its parameters.
    pub diagnosis: Value,
    /// Pose error after modelling the diagnosed effect (equal to the aligned error when none
    /// was applied), m and rad.
    pub pose_error_after_diagnosis_m: f64,
    pub pose_error_after_diagnosis_rad: f64,
    pub inspections: usize,
    /// Distance between the aligned and the true part position, m.
    pub pose_error_m: f64,
    /// Angle between the aligned and the true part orientation, rad.
    pub pose_error_rad: f64,
    /// The nominal (virtual) pose's error before alignment.
    pub nominal_error_m: f64,
    pub nominal_error_rad: f64,
    pub rms_m: f64,
    pub align_time_s: f64,
    pub pose: Value,
    pub truth: Value,
}

struct ChildService {
    name: &'static str,
    child: Child,
    endpoints: Vec<(String, String)>,
}

impl ChildService {
    fn endpoint(&self, key: &str) -> Result<String, BadInput> {
        self.endpoints
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.clone())
            .ok_or_else(|| BadInput(format!("{} printed no '{key}' endpoint", self.name)))
    }

    fn check_alive(&mut self) -> Result<(), BadInput> {
        match self.child.try_wait() {
            Ok(Some(status)) => Err(BadInput(format!("{} exited early ({status})", self.name))),
            _ => Ok(()),
        }
    }

    fn terminate(mut self) {
        let _ = Command::new("kill")
            .arg("-TERM")
            .arg(self.child.id().to_string())
            .status();
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for ChildService {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

fn sibling_binary(name: &str) -> Result<PathBuf, BadInput> {
    let here = std::env::current_exe().map_err(BadInput::new)?;
    let path = here.with_file_name(name);
    if path.exists() {
        Ok(path)
    } else {
        Err(BadInput(format!(
            "'{}' not found next to ips; build the services first: cargo build --release --locked -p sim-robot -p robot-bridge",
            path.display()
        )))
    }
}

fn spawn(name: &'static str, program: &Path, args: &[String]) -> Result<ChildService, BadInput> {
    let mut child = Command::new(program)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .map_err(|error| BadInput(format!("cannot start {name}: {error}")))?;
    let stdout = child
        .stdout
        .take()
        .ok_or_else(|| BadInput(format!("{name}: no stdout")))?;
    let (sender, receiver) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if line.starts_with("READY") {
                let _ = sender.send(line);
            }
        }
    });
    let mut service = ChildService {
        name,
        child,
        endpoints: Vec::new(),
    };
    let line = receiver
        .recv_timeout(Duration::from_secs(30))
        .map_err(|_| {
            let state = service
                .check_alive()
                .err()
                .map_or("still running".to_owned(), |e| e.0);
            BadInput(format!("{name} did not report READY within 30 s ({state})"))
        })?;
    service.endpoints = line
        .split_whitespace()
        .skip(1)
        .filter_map(|pair| {
            pair.split_once('=')
                .map(|(k, v)| (k.to_owned(), v.to_owned()))
        })
        .collect();
    Ok(service)
}

fn request(socket: &zmq::Socket, body: Value, what: &str) -> Result<Value, BadInput> {
    let message =
        json!({"header": {"from": "ips", "to": "align", "type": "request"}, "body": body});
    socket
        .send(message.to_string().as_bytes(), 0)
        .map_err(BadInput::new)?;
    let reply = socket
        .recv_bytes(0)
        .map_err(|_| BadInput(format!("{what}: no reply within the timeout")))?;
    serde_json::from_slice(&reply).map_err(|error| BadInput(format!("{what}: bad reply: {error}")))
}

/// How long a touch rests in contact before it is captured: a few controller sample periods
/// (8 ms at 125 Hz), so that the stream has caught up with the arm at rest.
const SETTLE_S: f64 = 0.05;

/// One request to sim-robot's control socket.
fn control_request(socket: &zmq::Socket, body: &Value) -> Result<Value, BadInput> {
    socket
        .send(body.to_string().as_bytes(), 0)
        .map_err(BadInput::new)?;
    let reply = socket
        .recv_bytes(0)
        .map_err(|_| BadInput("sim-robot control: no reply within the timeout".to_owned()))?;
    serde_json::from_slice(&reply).map_err(BadInput::new)
}

fn zmq_socket(
    context: &zmq::Context,
    kind: zmq::SocketType,
    endpoint: &str,
) -> Result<zmq::Socket, BadInput> {
    let socket = context.socket(kind).map_err(BadInput::new)?;
    socket.set_linger(0).map_err(BadInput::new)?;
    socket.set_rcvtimeo(10_000).map_err(BadInput::new)?;
    socket.connect(endpoint).map_err(BadInput::new)?;
    Ok(socket)
}

pub fn run(args: &DemoArgs, mut progress: impl FnMut(&str)) -> Result<DemoOutput, BadInput> {
    let Some(robot) = ShippedRobot::from_name(&args.robot) else {
        return Err(BadInput(format!(
            "--robot '{}': expected ur10, ur10e or iiwa14",
            args.robot
        )));
    };
    let sim_program = sibling_binary("sim-robot")?;
    let bridge_program = sibling_binary("robot-bridge")?;
    let ips_program = std::env::current_exe().map_err(BadInput::new)?;

    // The cell: the step block at a pose the service is not told, a nominal pose 42 mm / 6
    // degrees off, a probe with a 3 mm ball 150 mm from the flange. The iiwa's reach is shorter
    // than the UR10's: its table stands closer.
    let folder = std::env::temp_dir().join(format!("cobot-align-demo-{}", std::process::id()));
    std::fs::create_dir_all(&folder).map_err(BadInput::new)?;
    let part = step_block().map_err(BadInput::new)?;
    let soup = TriangleSoup {
        vertices: part.mesh.vertices().collect(),
        triangles: part.mesh.triangles().to_vec(),
    };
    write_stl_binary(&folder.join("part.stl"), &soup).map_err(BadInput::new)?;
    std::fs::write(folder.join("robot.urdf"), robot.urdf()).map_err(BadInput::new)?;
    let (truth, nominal) = match robot {
        ShippedRobot::Iiwa14 => (
            isometry_from_xyz_rpy([0.5, -0.2, 0.02], [0.0, 0.0, 0.35]),
            isometry_from_xyz_rpy([0.53, -0.17, 0.02], [0.0, 0.0, 0.25]),
        ),
        _ => (
            isometry_from_xyz_rpy([0.62, -0.25, 0.02], [0.0, 0.0, 0.35]),
            isometry_from_xyz_rpy([0.65, -0.22, 0.02], [0.0, 0.0, 0.25]),
        ),
    };
    let tcp = isometry_from_xyz_rpy([0.0, 0.0, 0.15], [0.0; 3]);
    let tip_radius = 0.003;
    let pose = |p: &nalgebra::Isometry3<f64>| {
        let (xyz, rpy) = xyz_rpy(p);
        PoseSection { xyz, rpy }
    };
    let template = SessionFile {
        format: FORMAT.to_owned(),
        robot: Some(RobotSection {
            urdf: "robot.urdf".to_owned(),
            base_link: robot.base_link().to_owned(),
            tip_link: robot.flange_link().to_owned(),
            package_dirs: Default::default(),
        }),
        tool: ToolSection {
            tcp: pose(&tcp),
            tip_radius,
            mass: 0.4,
        },
        part: PartSection {
            mesh: "part.stl".to_owned(),
            mesh_scale: 1.0,
            nominal_pose: pose(&nominal),
            faces: Vec::new(),
        },
        noise_sigma: Some(0.00005),
        inspections: Vec::new(),
    };
    let session_path = folder.join("session.json");
    std::fs::write(
        &session_path,
        serde_json::to_string_pretty(&template).map_err(BadInput::new)?,
    )
    .map_err(BadInput::new)?;
    let journal = folder.join("inspections.journal");
    let _ = std::fs::remove_file(&journal);
    let dof = robot.home().len();
    // The cell as it physically is; the session above declares the nominal tool and part.
    let mut true_tcp = tcp;
    let (mut true_radius, mut true_scale) = (tip_radius, 1.0);
    // What sim-robot's encoders get wrong (its `effects` request).
    let mut encoders = serde_json::Map::new();
    if args.noise {
        encoders.insert("noise_sigma_rad".to_owned(), json!(2e-5));
    }
    let shoulder_and_elbow = |values: [f64; 2]| -> Vec<f64> {
        let mut per_joint = vec![0.0; dof];
        // UR: shoulder lift and elbow (joints 2 and 3); iiwa: joints 2 and 4.
        let elbow = if robot == ShippedRobot::Iiwa14 { 3 } else { 2 };
        per_joint[1] = values[0];
        per_joint[elbow] = values[1];
        per_joint
    };
    match args.effect.as_str() {
        "none" => {}
        "probe_radius" => true_radius = 0.0034,
        "tcp_offset" => {
            true_tcp.translation.vector += nalgebra::Vector3::new(0.0015, -0.001, 0.0015)
        }
        "part_scale" => true_scale = 1.004,
        "joint_offsets" => {
            let offsets = match robot {
                ShippedRobot::Iiwa14 => vec![0.0, 0.0015, 0.0, -0.002, 0.0, 0.001, 0.0],
                _ => vec![0.0, 0.0015, -0.002, 0.001, 0.0, 0.0],
            };
            encoders.insert("joint_offsets".to_owned(), json!(offsets));
        }
        "joint_compliance" => {
            encoders.insert(
                "compliance_rad_per_nm".to_owned(),
                json!(shoulder_and_elbow([3e-5, 4e-5])),
            );
            // The tool the session declares: its mass at the TCP.
            encoders.insert(
                "payload".to_owned(),
                json!({"mass_kg": 0.4, "com_in_flange": tcp.translation.vector.as_slice()}),
            );
        }
        "trigger_latency" => {
            encoders.insert("trigger_latency_s".to_owned(), json!(0.05));
        }
        "cyclic_encoder" => {
            encoders.insert(
                "cyclic_encoder".to_owned(),
                json!({"joint": 1, "amplitude_rad": 0.001, "cycles_per_turn": 2.0}),
            );
        }
        other => {
            return Err(BadInput(format!(
                "--effect '{other}': expected none, probe_radius, tcp_offset, part_scale, joint_offsets, joint_compliance, trigger_latency or cyclic_encoder"
            )));
        }
    }
    // Nine touches align; a diagnosis needs more, at varied tilts (a ball-radius change and a
    // TCP shift look alike on head-on touches).
    let touch_count: usize = if args.effect == "none" { 9 } else { 16 };
    let probe_request = json!({
        "command": "probe",
        "mesh": folder.join("part.stl"),
        "base_from_part": pose(&truth),
        "tcp": pose(&true_tcp),
        "tip_radius": true_radius,
        "part_scale": true_scale,
        "touches": touch_count,
        "max_tilt_rad": 0.6,
        "vary_tilt": args.effect != "none",
        "dwell_s": 0.3,
    });
    // A latency shows only on touches taken while moving, at different speeds (at rest a late
    // sample is the same sample; at one speed it looks like a larger ball).
    let on_the_fly = args.effect == "trigger_latency";
    let mut probe_request = probe_request;
    if on_the_fly {
        probe_request["on_the_fly_speeds_m_s"] = json!([0.001, 0.0025, 0.004]);
    }

    progress("starting sim-robot, robot-bridge and the alignment service");
    let (mut sim, mut bridge) = start_cell(robot, &sim_program, &bridge_program)?;
    let (bridge_rep, bridge_pub) = (bridge.endpoint("rep")?, bridge.endpoint("pub")?);
    let mut service = spawn(
        "ips serve",
        &ips_program,
        &[
            "serve".to_owned(),
            "--session".to_owned(),
            session_path.display().to_string(),
            "--journal".to_owned(),
            journal.display().to_string(),
            "--rep".to_owned(),
            "tcp://127.0.0.1:*".to_owned(),
            "--bridge-rep".to_owned(),
            bridge_rep,
            "--bridge-pub".to_owned(),
            bridge_pub.clone(),
        ],
    )?;
    let context = zmq::Context::new();
    let client = zmq_socket(&context, zmq::REQ, &service.endpoint("rep")?)?;
    let control = zmq_socket(&context, zmq::REQ, &sim.endpoint("control")?)?;
    if !encoders.is_empty() {
        encoders.insert("command".to_owned(), json!("effects"));
        let reply = control_request(&control, &Value::Object(encoders))?;
        if reply["ok"] != true {
            return Err(BadInput(format!(
                "sim-robot refused the effect: {}",
                reply["reason"]
            )));
        }
    }

    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let reply = request(&client, json!({"command": "start"}), "start")?;
        if reply["body"]["ok"] == true {
            break;
        }
        for child in [&mut sim, &mut bridge, &mut service] {
            child.check_alive()?;
        }
        if Instant::now() > deadline {
            return Err(BadInput(format!(
                "the service could not start mirroring: {}",
                reply["body"]["reason"]
            )));
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    progress(&format!(
        "sim-robot plans {touch_count} touches on the part at its hidden pose"
    ));
    // Planning runs dozens of IK solves per touch: give it longer than a plain request.
    control.set_rcvtimeo(120_000).map_err(BadInput::new)?;
    let planned = control_request(&control, &probe_request)?;
    control.set_rcvtimeo(10_000).map_err(BadInput::new)?;
    if planned["ok"] != true {
        return Err(BadInput(format!(
            "sim-robot could not probe the part: {}",
            planned["reason"]
        )));
    }
    let tilts_deg: Vec<String> = planned["tilts_rad"]
        .as_array()
        .map(|tilts| {
            tilts
                .iter()
                .map(|t| format!("{:.0}", t.as_f64().unwrap_or(f64::NAN).to_degrees()))
                .collect()
        })
        .unwrap_or_default();
    progress(&format!(
        "probe tilts from the normal (deg): {}",
        tilts_deg.join(" ")
    ));
    for index in 0..touch_count {
        // The simulator says when the ball rests on touch `index`; capture it then.
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            let status = control_request(&control, &json!({"command": "status"}))?;
            let probe = &status["probe"];
            // At rest by the simulator's clock; the bridge's newest sample may be one period
            // older, so let the contact settle for a few sample periods first.
            let contact = &planned["contacts"][index];
            let now_s = status["time"].as_f64().unwrap_or(0.0);
            if on_the_fly {
                // Past the contact far enough for the stream to hold the trigger's sample.
                if now_s >= contact["at_s"].as_f64().unwrap_or(f64::MAX) + SETTLE_S {
                    break;
                }
            } else {
                let settled = now_s >= contact["from_s"].as_f64().unwrap_or(f64::MAX) + SETTLE_S;
                if probe["active_touch"].as_u64() == Some(index as u64)
                    && status["at_rest"] == true
                    && settled
                {
                    break;
                }
            }
            if probe["done"] == true {
                return Err(BadInput(format!(
                    "sim-robot finished probing before touch {} was captured",
                    index + 1
                )));
            }
            for child in [&mut sim, &mut bridge, &mut service] {
                child.check_alive()?;
            }
            if Instant::now() > deadline {
                return Err(BadInput(format!(
                    "touch {} did not come to rest within 60 s",
                    index + 1
                )));
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        // On the fly, the touch is the sample at the trigger's time stamp, as a touch-trigger
        // probe wired to the controller would give it.
        let get = if on_the_fly {
            json!({"command": "get", "time_s": planned["contacts"][index]["at_s"]})
        } else {
            json!({"command": "get"})
        };
        let reply = request(&client, get, "get")?;
        if reply["body"]["ok"] != true {
            return Err(BadInput(format!(
                "get refused at touch {}: {}",
                index + 1,
                reply["body"]["reason"]
            )));
        }
        progress(&format!("touch {} of {touch_count} captured", index + 1));
    }
    let aligned = request(&client, json!({"command": "align"}), "align")?;
    let saved = folder.join("captured.json");
    let _ = request(
        &client,
        json!({"command": "save", "path": saved.display().to_string()}),
        "save",
    )?;
    let _ = request(&client, json!({"command": "stop"}), "stop");
    for child in [&mut sim, &mut bridge, &mut service] {
        child.check_alive()?;
    }
    for child in [service, bridge, sim] {
        child.terminate();
    }
    let diagnosis = crate::diagnose::run_file(&saved)?;
    let _ = std::fs::remove_dir_all(&folder);
    if aligned["body"]["ok"] != true {
        return Err(BadInput(format!(
            "align failed: {}",
            aligned["body"]["reason"]
        )));
    }
    let data = &aligned["body"]["data"];
    let xyz: Vec<f64> = (0..3)
        .map(|i| data["pose"]["xyz"][i].as_f64().unwrap_or(f64::NAN))
        .collect();
    let rpy: Vec<f64> = (0..3)
        .map(|i| data["pose"]["rpy"][i].as_f64().unwrap_or(f64::NAN))
        .collect();
    let found = isometry_from_xyz_rpy([xyz[0], xyz[1], xyz[2]], [rpy[0], rpy[1], rpy[2]]);
    let error = |p: &nalgebra::Isometry3<f64>| {
        (
            (p.translation.vector - truth.translation.vector).norm(),
            p.rotation.angle_to(&truth.rotation),
        )
    };
    let (pose_error_m, pose_error_rad) = error(&found);
    let (nominal_error_m, nominal_error_rad) = error(&nominal);
    let after = &diagnosis.pose_after;
    let after_pose = isometry_from_xyz_rpy(
        std::array::from_fn(|i| after["xyz"][i].as_f64().unwrap_or(f64::NAN)),
        std::array::from_fn(|i| after["rpy"][i].as_f64().unwrap_or(f64::NAN)),
    );
    let (pose_error_after_diagnosis_m, pose_error_after_diagnosis_rad) = error(&after_pose);
    Ok(DemoOutput {
        robot: robot.name().to_owned(),
        effect: args.effect.clone(),
        diagnosis: json!({
            "verdict": diagnosis.verdict,
            "effect": diagnosis.effect,
            "explanation": diagnosis.explanation,
            "alternatives": diagnosis.alternatives,
            "before": diagnosis.before,
            "after": diagnosis.after,
        }),
        pose_error_after_diagnosis_m,
        pose_error_after_diagnosis_rad,
        inspections: touch_count,
        pose_error_m,
        pose_error_rad,
        nominal_error_m,
        nominal_error_rad,
        rms_m: data["rms"].as_f64().unwrap_or(f64::NAN),
        align_time_s: data["time_s"].as_f64().unwrap_or(f64::NAN),
        pose: data["pose"].clone(),
        truth: serde_json::to_value(pose(&truth)).unwrap_or(Value::Null),
    })
}

/// Starts the simulated controller and the bridge on free ports. A UR controller serves RTDE
/// and the bridge connects to it; an iiwa controller sends FRI to the bridge, so the bridge
/// listens first.
fn start_cell(
    robot: ShippedRobot,
    sim_program: &Path,
    bridge_program: &Path,
) -> Result<(ChildService, ChildService), BadInput> {
    let zmq_endpoints = ["--rep", "tcp://127.0.0.1:*", "--pub", "tcp://127.0.0.1:*"];
    let owned = |args: &[&str]| args.iter().map(|a| (*a).to_owned()).collect::<Vec<_>>();
    if robot == ShippedRobot::Iiwa14 {
        let mut bridge_args = owned(&[
            "--backend",
            "iiwa",
            "--robot-host",
            "127.0.0.1",
            "--fri-port",
            "0",
        ]);
        bridge_args.extend(owned(&zmq_endpoints));
        let bridge = spawn("robot-bridge", bridge_program, &bridge_args)?;
        let fri_port = bridge
            .endpoint("fri")?
            .rsplit(':')
            .next()
            .unwrap_or("30200")
            .to_owned();
        let sim = spawn(
            "sim-robot",
            sim_program,
            &owned(&[
                "--robot",
                robot.name(),
                "--fri-target",
                &format!("127.0.0.1:{fri_port}"),
                "--control",
                "tcp://127.0.0.1:*",
            ]),
        )?;
        return Ok((sim, bridge));
    }
    let sim = spawn(
        "sim-robot",
        sim_program,
        &owned(&[
            "--robot",
            robot.name(),
            "--rtde-host",
            "127.0.0.1",
            "--rtde-port",
            "0",
            "--control",
            "tcp://127.0.0.1:*",
        ]),
    )?;
    let rtde_port = sim
        .endpoint("rtde")?
        .rsplit(':')
        .next()
        .unwrap_or("30004")
        .to_owned();
    let mut bridge_args = owned(&[
        "--backend",
        "ur",
        "--robot-host",
        "127.0.0.1",
        "--rtde-port",
        &rtde_port,
    ]);
    bridge_args.extend(owned(&zmq_endpoints));
    let bridge = spawn("robot-bridge", bridge_program, &bridge_args)?;
    Ok((sim, bridge))
}

impl DemoOutput {
    pub fn to_text(&self) -> String {
        let mut text = format!(
            "{} touches on the {} aligned the part:\n  nominal pose error: {:8.3} mm  {:8.3} mrad\n  aligned pose error: {:8.5} mm  {:8.5} mrad\n  residual rms {:.4} mm, alignment {:.1} ms\n",
            self.inspections,
            self.robot,
            self.nominal_error_m * 1e3,
            self.nominal_error_rad * 1e3,
            self.pose_error_m * 1e3,
            self.pose_error_rad * 1e3,
            self.rms_m * 1e3,
            self.align_time_s * 1e3
        );
        text += &format!(
            "simulated effect: {}; diagnosis: {} ({})\n",
            self.effect,
            self.diagnosis["verdict"].as_str().unwrap_or("?"),
            self.diagnosis["explanation"].as_str().unwrap_or("")
        );
        if let Some(params) = self.diagnosis["effect"]["params"].as_object() {
            for (key, value) in params {
                text += &format!(
                    "  {key} = {:.4e} +- {:.1e}\n",
                    value.as_f64().unwrap_or(f64::NAN),
                    self.diagnosis["effect"]["stderr"][key]
                        .as_f64()
                        .unwrap_or(f64::NAN)
                );
            }
        }
        text += &format!(
            "  pose error after modelling it: {:8.5} mm  {:8.5} mrad\n",
            self.pose_error_after_diagnosis_m * 1e3,
            self.pose_error_after_diagnosis_rad * 1e3
        );
        text
    }
}
