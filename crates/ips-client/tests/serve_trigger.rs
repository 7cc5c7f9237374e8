//! `ips serve --trigger DI0` with sim-robot probing the example part on the fly with its
//! touch-trigger probe and robot-bridge between them: every touch becomes an inspection without
//! a `get`, at the rising edge's time (the midpoint of the samples around it, joints
//! interpolated there), and its ball lies on the part's true surface within the approach speed
//! times half the sample gap. A bad `--trigger` is refused before anything starts.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

mod common;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use align_core::geometry::Mesh;
use align_core::pose::isometry_from_xyz_rpy;
use align_core::robots::ShippedRobot;
use nalgebra::{Isometry3, Point3, Translation3};
use serde_json::{Value, json};

use common::Scratch;

/// Approach speeds along the probe axis, used in turn (sim-robot allows up to 5 mm/s).
const SPEEDS_M_S: [f64; 3] = [0.005, 0.002, 0.0035];
const TOUCHES: usize = 9;
const TIP_RADIUS_M: f64 = 0.003;
const TCP_Z_M: f64 = 0.15;
/// What the interpolation adds to the time error: the joints move linearly in time through a
/// contact, but in joint space, so the ball's path bends by well under a micrometre over one
/// sample; and the mesh's signed distance is exact. A margin, not a fudge for the bound.
const CHORD_SLACK_M: f64 = 1e-6;

fn example(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/step_block_ur10")
        .join(file)
}

fn req(context: &zmq::Context, endpoint: &str) -> zmq::Socket {
    let socket = context.socket(zmq::REQ).unwrap();
    socket.set_linger(0).unwrap();
    socket.set_rcvtimeo(10_000).unwrap();
    socket.set_sndtimeo(10_000).unwrap();
    socket.connect(endpoint).unwrap();
    socket
}

fn call(socket: &zmq::Socket, body: Value) -> Value {
    let request =
        json!({"header": {"from": "ips", "to": "align", "type": "request"}, "body": body});
    socket.send(request.to_string().as_bytes(), 0).unwrap();
    let reply: Value = serde_json::from_slice(&socket.recv_bytes(0).unwrap()).unwrap();
    reply["body"].clone()
}

fn control(socket: &zmq::Socket, request: Value) -> Value {
    socket.send(request.to_string().as_bytes(), 0).unwrap();
    serde_json::from_slice(&socket.recv_bytes(0).unwrap()).unwrap()
}

fn numbers(value: &Value) -> Vec<f64> {
    value
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect()
}

/// One hwState sample as the test's own subscriber saw it.
struct Seen {
    time_s: f64,
    q: Vec<f64>,
    di0: bool,
}

/// The example session without inspections, paths absolute, in a fresh folder.
fn template_folder(name: &str) -> Scratch {
    let mut template: Value =
        serde_json::from_str(&std::fs::read_to_string(example("session.json")).unwrap()).unwrap();
    template["inspections"] = json!([]);
    template["robot"]["urdf"] = json!(example("../../robots/ur10.urdf").to_str().unwrap());
    template["part"]["mesh"] = json!(example("step_block.stl").to_str().unwrap());
    let folder = std::env::temp_dir().join(format!("cobot-align-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&folder);
    let folder = Scratch::folder(folder);
    std::fs::write(folder.join("template.json"), template.to_string()).unwrap();
    folder
}

/// The true part and the ball's distance from its surface (m, positive outside).
struct TruePart {
    mesh: Mesh,
    part_from_base: Isometry3<f64>,
    chain: align_core::kinematics::Chain,
    flange_from_tcp: Isometry3<f64>,
}

impl TruePart {
    fn load(truth: &Value) -> Self {
        let soup = align_core::io::read_mesh(&example("step_block.stl"), 0.001).unwrap();
        let pose = &truth["base_from_part"];
        let xyz = numbers(&pose["xyz"]);
        let rpy = numbers(&pose["rpy"]);
        Self {
            mesh: Mesh::new(&soup.vertices, &soup.triangles).unwrap(),
            part_from_base: isometry_from_xyz_rpy(
                [xyz[0], xyz[1], xyz[2]],
                [rpy[0], rpy[1], rpy[2]],
            )
            .inverse(),
            chain: ShippedRobot::Ur10.chain().unwrap(),
            flange_from_tcp: Translation3::new(0.0, 0.0, TCP_Z_M).into(),
        }
    }

    fn ball_to_surface_m(&self, q: &[f64]) -> f64 {
        let tcp = self.chain.forward_unchecked(q) * self.flange_from_tcp;
        let in_part = self.part_from_base * Point3::from(tcp.translation.vector);
        self.mesh.signed_closest(&in_part).signed_distance_m - TIP_RADIUS_M
    }
}

#[test]
fn a_trigger_probe_captures_every_touch_at_its_edge_without_a_get() {
    let sim = sim_robot::start(&sim_robot::Config {
        robot: ShippedRobot::Ur10,
        rtde_listen: "127.0.0.1:0".to_owned(),
        primary_listen: None,
        calibration: None,
        control: "tcp://127.0.0.1:*".to_owned(),
        fri: sim_robot::FriSettings::default(),
    })
    .unwrap();
    let bridge = robot_bridge::start(&robot_bridge::Config {
        backend: robot_bridge::BackendConfig::Ur(robot_bridge::backend::ur::UrConfig {
            robot_host: "127.0.0.1".to_owned(),
            rtde_port: sim.rtde_port().unwrap(),
            primary_port: None,
        }),
        rep: "tcp://127.0.0.1:*".to_owned(),
        publish: "tcp://127.0.0.1:*".to_owned(),
    })
    .unwrap();
    let folder = template_folder("serve-trigger");
    let journal = folder.join("inspections.journal");
    let args: Vec<String> = [
        "serve",
        "--session",
        folder.join("template.json").to_str().unwrap(),
        "--journal",
        journal.to_str().unwrap(),
        "--rep",
        "tcp://127.0.0.1:*",
        "--bridge-rep",
        &bridge.rep_endpoint,
        "--bridge-pub",
        &bridge.pub_endpoint,
        "--trigger",
        "DI0",
    ]
    .map(str::to_owned)
    .to_vec();
    let service = cell::spawn(
        "ips serve",
        Path::new(env!("CARGO_BIN_EXE_ips")),
        &args,
        cell::READY_WITHIN,
    )
    .unwrap();
    let context = zmq::Context::new();
    let client = req(&context, service.endpoint("rep").unwrap());
    let sim_control = req(&context, &sim.control_endpoint);
    let sub = context.socket(zmq::SUB).unwrap();
    sub.set_linger(0).unwrap();
    sub.set_rcvtimeo(5000).unwrap();
    sub.set_subscribe(b"").unwrap();
    sub.connect(&bridge.pub_endpoint).unwrap();

    // The bridge may still be connecting to the controller: start succeeds once it is.
    let deadline = Instant::now() + Duration::from_secs(10);
    while call(&client, json!({"command": "start"}))["ok"] != true {
        assert!(
            Instant::now() < deadline,
            "the service never started mirroring"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // Our own subscriber sees the stream before the probe moves (its first frame proves it).
    sub.recv_bytes(0).unwrap();
    let truth: Value =
        serde_json::from_str(&std::fs::read_to_string(example("truth.json")).unwrap()).unwrap();
    let plan = control(
        &sim_control,
        json!({"command": "probe", "mesh": example("step_block.stl"), "mesh_scale": 0.001,
            "base_from_part": truth["base_from_part"],
            "tcp": {"xyz": [0.0, 0.0, TCP_Z_M], "rpy": [0.0, 0.0, 0.0]},
            "tip_radius": TIP_RADIUS_M, "touches": TOUCHES, "on_the_fly_speeds_m_s": SPEEDS_M_S}),
    );
    assert_eq!(plan["ok"], true, "{plan}");
    let contacts_at_s: Vec<f64> = plan["contacts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["at_s"].as_f64().unwrap())
        .collect();
    assert_eq!(contacts_at_s.len(), TOUCHES);

    // Record the stream until the probe run is over.
    let end_s = plan["end_s"].as_f64().unwrap();
    let mut seen = Vec::new();
    loop {
        let state: Value = serde_json::from_slice(&sub.recv_bytes(0).unwrap()).unwrap();
        let body = &state["body"];
        let time_s = body["controller_time"].as_f64().unwrap();
        seen.push(Seen {
            time_s,
            q: numbers(&body["position"]),
            di0: body["digital_inputs"].as_u64().unwrap() & 1 == 1,
        });
        if time_s > end_s {
            break;
        }
    }
    // The service drains its trigger queue at least every 100 ms.
    let deadline = Instant::now() + Duration::from_secs(10);
    let inspections = loop {
        let listed = call(&client, json!({"command": "list"}));
        let inspections = listed["data"]["inspections"].as_array().unwrap().clone();
        if inspections.len() >= TOUCHES || Instant::now() > deadline {
            break inspections;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(inspections.len(), TOUCHES, "one inspection per touch");

    let part = TruePart::load(&truth);
    let mut worst_ratio: f64 = 0.0;
    for (index, (inspection, at_s)) in inspections.iter().zip(&contacts_at_s).enumerate() {
        assert_eq!(inspection["trigger"], "DI0", "{inspection}");
        assert_eq!(inspection["id"], (index + 1).to_string());
        let stamp_s = inspection["stamp"].as_f64().unwrap();
        let q = numbers(&inspection["q"]);
        // The samples around the edge, as the stream carried them.
        let high = seen
            .iter()
            .position(|s| s.time_s >= *at_s)
            .expect("a sample after the contact");
        let (before, after) = (&seen[high - 1], &seen[high]);
        assert!(
            !before.di0 && after.di0,
            "touch {index}: the edge is between them"
        );
        let midpoint_s = 0.5 * (before.time_s + after.time_s);
        assert!(
            (stamp_s - midpoint_s).abs() < 1e-9,
            "touch {index}: {stamp_s} vs {midpoint_s}"
        );
        for (j, value) in q.iter().enumerate() {
            let mean = 0.5 * (before.q[j] + after.q[j]);
            assert!((value - mean).abs() < 1e-12, "touch {index} joint {j}");
        }
        let half_gap_s = 0.5 * (after.time_s - before.time_s);
        let time_error_s = stamp_s - at_s;
        assert!(time_error_s.abs() <= half_gap_s + 1e-9, "touch {index}");
        let speed_m_s = SPEEDS_M_S[index % SPEEDS_M_S.len()];
        let bound_m = speed_m_s * half_gap_s + CHORD_SLACK_M;
        let off_surface_m = part.ball_to_surface_m(&q);
        println!(
            "touch {index}: {:.1} mm/s, edge {:+.2} ms from the contact (half gap {:.2} ms), ball {:+.2} um from the surface (bound {:.2} um)",
            speed_m_s * 1e3,
            time_error_s * 1e3,
            half_gap_s * 1e3,
            off_surface_m * 1e6,
            bound_m * 1e6
        );
        assert!(
            off_surface_m.abs() <= bound_m,
            "touch {index}: {off_surface_m} m"
        );
        worst_ratio = worst_ratio.max(off_surface_m.abs() / bound_m);
    }
    println!("worst error / bound: {worst_ratio:.2}");

    // Journaled like a get's, with the input that fired.
    let journaled = std::fs::read_to_string(&journal).unwrap();
    assert_eq!(journaled.matches("\"trigger\":\"DI0\"").count(), TOUCHES);
    // And they align: the part is found where it really is.
    let aligned = call(&client, json!({"command": "align"}));
    assert_eq!(aligned["ok"], true, "{aligned}");
    let xyz = numbers(&aligned["data"]["pose"]["xyz"]);
    let want = numbers(&truth["base_from_part"]["xyz"]);
    for axis in 0..3 {
        assert!(
            (xyz[axis] - want[axis]).abs() < 5e-5,
            "xyz {xyz:?} vs {want:?}"
        );
    }

    assert_eq!(
        service.terminate(Duration::from_secs(10)).map(|s| s.code()),
        Some(Some(0))
    );
    bridge.stop();
    sim.stop();
}

#[test]
fn an_unknown_trigger_input_is_refused_with_one_line_and_exit_code_2() {
    let (code, stderr) = cell::run_to_exit(
        Path::new(env!("CARGO_BIN_EXE_ips")),
        &[
            "serve",
            "--session",
            "no-such-session.json",
            "--trigger",
            "XYZ",
        ],
        Duration::from_secs(30),
    )
    .unwrap();
    assert_eq!(code, Some(2), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    assert!(
        stderr.contains("'XYZ' is not a digital input: expected DI0-DI7, CI0-CI7 or TI0-TI1"),
        "{stderr}"
    );
}
