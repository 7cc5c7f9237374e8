//! sim-robot against the RTDE client UR users actually run: ur_rtde's RTDEReceiveInterface (PyPI
//! package ur-rtde, installed by `scripts/python-env.sh`). It reads joint positions and
//! timestamps from the simulator, which must match the simulator's ground truth.
//!
//! RTDEReceiveInterface always connects to port 30004, so each run binds sim-robot to port 30004
//! of a random loopback address 127.X.Y.Z (Linux routes all of 127/8 to loopback): parallel runs
//! and anything else on 127.0.0.1:30004 do not collide.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::collections::hash_map::RandomState;
use std::hash::BuildHasher;
use std::process::{Command, Output, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use serde_json::{Value, json};
use system_tests::{Service, binary, ensure_binaries, python, repo_root, try_spawn};

/// A UR10e pose away from sim-robot's home, so reading the home pose cannot pass.
const HOLD_Q: [f64; 6] = [0.31, -1.23, 1.42, -1.77, -1.49, 0.27];
const SAMPLES: usize = 5;
const JOINT_TOLERANCE_RAD: f64 = 1e-9;
const STANDARD_GRAVITY_M_PER_S2: f64 = 9.80665;

/// A random loopback address outside 127.0.0.0/16.
fn random_loopback_host() -> String {
    let bits = RandomState::new().hash_one(std::time::SystemTime::now());
    let [x, y, z, ..] = bits.to_le_bytes();
    // Clear of 127.0.0.0/16, where services with fixed ports (a real sim-robot on
    // 127.0.0.1:30004, say) usually listen.
    format!("127.{}.{}.{}", x.max(1), y, z.clamp(1, 254))
}

/// sim-robot (UR10e) serving RTDE on HOST:30004, retrying other hosts if one is taken.
fn spawn_sim_on_port_30004() -> (Service, String) {
    let mut failures = Vec::new();
    for _ in 0..5 {
        let host = random_loopback_host();
        let args = [
            "--robot",
            "ur10e",
            "--rtde-host",
            &host,
            "--rtde-port",
            "30004",
            "--control",
            "tcp://127.0.0.1:*",
        ];
        match try_spawn(binary("sim-robot"), &args, Duration::from_secs(20)) {
            Ok(sim) => return (sim, host),
            Err(reason) => failures.push(reason),
        }
    }
    panic!(
        "sim-robot could not serve RTDE on port 30004 of any loopback address tried: {failures:#?}"
    );
}

/// One request/reply on sim-robot's control socket, bounded in time.
fn control(socket: &zmq::Socket, request: Value) -> Value {
    socket.send(request.to_string().as_bytes(), 0).unwrap();
    let reply = socket
        .recv_bytes(0)
        .unwrap_or_else(|error| panic!("no reply from sim-robot to {request}: {error}"));
    let reply: Value = serde_json::from_slice(&reply).unwrap();
    assert_eq!(reply["ok"], true, "{request} -> {reply}");
    reply
}

/// Runs `command` to completion, killing it if it takes longer than `within` (a client that
/// never gets its first data package would wait forever).
fn output_within(mut command: Command, within: Duration) -> Output {
    let child = command
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id();
    let (sender, receiver) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = sender.send(child.wait_with_output());
    });
    match receiver.recv_timeout(within) {
        Ok(output) => output.unwrap(),
        Err(_) => {
            let _ = Command::new("kill")
                .args(["-KILL", &pid.to_string()])
                .status();
            panic!("the ur_rtde client did not finish within {within:?}");
        }
    }
}

fn floats(value: &Value) -> Vec<f64> {
    value
        .as_array()
        .unwrap_or_else(|| panic!("not an array: {value}"))
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect()
}

#[test]
fn ur_rtde_receive_interface_reads_the_simulated_joints_and_clock() {
    ensure_binaries();
    let python = python();
    let (sim, host) = spawn_sim_on_port_30004();

    let context = zmq::Context::new();
    let socket = context.socket(zmq::REQ).unwrap();
    socket.set_linger(0).unwrap();
    socket.set_rcvtimeo(10_000).unwrap();
    socket.set_sndtimeo(10_000).unwrap();
    socket.connect(sim.endpoint("control").unwrap()).unwrap();
    control(
        &socket,
        json!({"command": "motion", "motion": {"kind": "hold", "q": HOLD_Q}}),
    );
    let before = control(&socket, json!({"command": "truth"}));

    let mut client = Command::new(python);
    client
        .arg(repo_root().join("tests/python/ur_rtde_receive.py"))
        .arg(&host)
        .args(["--count", &SAMPLES.to_string(), "--timeout-s", "10"]);
    let output = output_within(client, Duration::from_secs(60));
    let after = control(&socket, json!({"command": "truth"}));
    assert!(
        output.status.success(),
        "the ur_rtde client failed ({}; a signal means it crashed):\n{}",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );

    let document: Value = serde_json::from_slice(&output.stdout).unwrap_or_else(|error| {
        panic!(
            "the client printed no JSON ({error}):\n{}",
            String::from_utf8_lossy(&output.stdout)
        )
    });
    let samples = document["samples"].as_array().unwrap();
    assert_eq!(samples.len(), SAMPLES);
    let truth_q = floats(&before["q"]);
    assert_eq!(truth_q, HOLD_Q);
    let (start_s, end_s) = (
        before["time"].as_f64().unwrap(),
        after["time"].as_f64().unwrap(),
    );
    let mut previous_s = start_s;
    for sample in samples {
        let actual_q = floats(&sample["actual_q"]);
        assert_eq!(actual_q.len(), truth_q.len(), "{sample}");
        for (read, truth) in actual_q.iter().zip(&truth_q) {
            assert!(
                (read - truth).abs() <= JOINT_TOLERANCE_RAD,
                "ur_rtde read {actual_q:?}, the simulator holds {truth_q:?}"
            );
        }
        // Controller time of a package streamed while the client ran: after the first truth
        // query, before the last, and advancing from package to package.
        let timestamp = sample["timestamp"].as_f64().unwrap();
        assert!(
            timestamp > previous_s && timestamp <= end_s,
            "timestamp {timestamp} s outside ({previous_s}, {end_s}] s"
        );
        previous_s = timestamp;

        // Variables behind ur_rtde's 64-bit digital I/O fields: garbage if any size before them
        // differed from ur_rtde's type table. A healthy arm at rest: RUNNING, NORMAL, PLAYING,
        // the normal-mode safety bit, and an accelerometer reading 1 g.
        assert_eq!(sample["robot_mode"], 7, "{sample}");
        assert_eq!(sample["safety_mode"], 1, "{sample}");
        assert_eq!(sample["runtime_state"], 2, "{sample}");
        assert_eq!(sample["safety_status_bits"], 1, "{sample}");
        let acceleration = floats(&sample["tool_accelerometer"]);
        let magnitude = acceleration.iter().map(|a| a * a).sum::<f64>().sqrt();
        assert!(
            (magnitude - STANDARD_GRAVITY_M_PER_S2).abs() < 1e-9,
            "{sample}"
        );
    }

    let status = sim
        .terminate(Duration::from_secs(10))
        .expect("sim-robot exits within 10 s of SIGTERM");
    assert!(status.success(), "{status:?}");
}
