//! The shipped binaries as a user runs them: sim-robot and robot-bridge spawned on free ports,
//! READY lines read back, a third-party client (pyzmq, in the venv `scripts/python-env.sh`
//! makes) mirroring joint states with the thesis's messages, clean exit on SIGTERM, and flags
//! refused with exit code 2.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::process::Command;
use std::time::Duration;

use align_core::robots::ShippedRobot;
use system_tests::{Cell, binary, ensure_binaries, python, repo_root, spawn, start_cell};

#[test]
fn binaries_serve_a_pyzmq_client_and_exit_cleanly_on_sigterm() {
    ensure_binaries();
    // The UR cell exactly as `ips demo` starts it.
    let Cell { sim, bridge } = start_cell(ShippedRobot::Ur10);
    let output = Command::new(python())
        .arg(repo_root().join("examples/python/mirror_joint_states.py"))
        .args([
            "--rep",
            bridge.endpoint("rep").unwrap(),
            "--pub",
            bridge.endpoint("pub").unwrap(),
            "--count",
            "25",
            "--json",
            "--timeout-ms",
            "10000",
        ])
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let lines: Vec<serde_json::Value> = String::from_utf8(output.stdout)
        .unwrap()
        .lines()
        .map(|line| serde_json::from_str(line).unwrap())
        .collect();
    assert_eq!(lines.len(), 25);
    assert!(
        lines
            .windows(2)
            .all(|w| w[1]["seq"].as_u64() == w[0]["seq"].as_u64().map(|s| s + 1))
    );
    assert_eq!(lines[0]["position"].as_array().unwrap().len(), 6);

    for service in [bridge, sim] {
        let status = service
            .terminate(Duration::from_secs(10))
            .expect("exits within 10 s of SIGTERM");
        assert!(status.success(), "{status:?}");
    }
}

#[test]
fn iiwa_binaries_mirror_over_fri_to_a_pyzmq_client() {
    ensure_binaries();
    // The bridge listens first; the controller is pointed at it, as on a real cell.
    let bridge = spawn(
        binary("robot-bridge"),
        &[
            "--backend",
            "iiwa",
            "--robot-host",
            "127.0.0.1",
            "--fri-port",
            "0",
            "--rep",
            "tcp://127.0.0.1:*",
            "--pub",
            "tcp://127.0.0.1:*",
        ],
        Duration::from_secs(20),
    );
    let fri_port = bridge.port("fri").unwrap();
    let sim = spawn(
        binary("sim-robot"),
        &[
            "--robot",
            "iiwa14",
            "--fri-target",
            &format!("127.0.0.1:{fri_port}"),
            "--fri-send-period-ms",
            "2",
            "--control",
            "tcp://127.0.0.1:*",
        ],
        Duration::from_secs(20),
    );
    assert!(sim.endpoint("fri_target").unwrap().ends_with(&fri_port));
    let output = Command::new(python())
        .arg(repo_root().join("examples/python/mirror_joint_states.py"))
        .args([
            "--rep",
            bridge.endpoint("rep").unwrap(),
            "--pub",
            bridge.endpoint("pub").unwrap(),
            "--robot-side",
            "IiwaDrive",
            "--count",
            "50",
            "--json",
            "--timeout-ms",
            "10000",
        ])
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let lines: Vec<serde_json::Value> = String::from_utf8(output.stdout)
        .unwrap()
        .lines()
        .map(|line| serde_json::from_str(line).unwrap())
        .collect();
    assert_eq!(lines.len(), 50);
    assert_eq!(lines[0]["from"], "IiwaDrive");
    assert_eq!(lines[0]["position"].as_array().unwrap().len(), 7);
    let span_s = lines[49]["controller_time"].as_f64().unwrap()
        - lines[0]["controller_time"].as_f64().unwrap();
    // 2 ms send period; a loaded machine only ever stretches the simulator's clock.
    assert!((0.0019..0.004).contains(&(span_s / 49.0)), "{span_s}");
    for service in [sim, bridge] {
        let status = service
            .terminate(Duration::from_secs(10))
            .expect("exits within 10 s of SIGTERM");
        assert!(status.success(), "{status:?}");
    }
}

#[test]
fn bad_flags_exit_2_with_a_reason() {
    ensure_binaries();
    let taken = std::net::UdpSocket::bind("0.0.0.0:0").unwrap();
    let taken_port = taken.local_addr().unwrap().port().to_string();
    let cases: [(&str, &[&str], &str); 5] = [
        (
            "robot-bridge",
            &["--backend", "abb", "--robot-host", "x"],
            "unknown back end 'abb'",
        ),
        (
            "robot-bridge",
            &[
                "--backend",
                "iiwa",
                "--robot-host",
                "127.0.0.1",
                "--fri-port",
                &taken_port,
                "--rep",
                "tcp://127.0.0.1:*",
                "--pub",
                "tcp://127.0.0.1:*",
            ],
            "cannot listen for FRI on UDP port",
        ),
        ("sim-robot", &["--robot", "kr16"], "unknown robot 'kr16'"),
        (
            "sim-robot",
            &[
                "--robot",
                "iiwa14",
                "--fri-send-period-ms",
                "0",
                "--control",
                "tcp://127.0.0.1:*",
            ],
            "outside the controller's 1-100 ms",
        ),
        (
            "sim-robot",
            &[
                "--robot",
                "iiwa14",
                "--fri-target",
                "nowhere",
                "--control",
                "tcp://127.0.0.1:*",
            ],
            "is not a HOST:PORT address",
        ),
    ];
    for (program, args, reason) in cases {
        let output = Command::new(binary(program)).args(args).output().unwrap();
        assert_eq!(output.status.code(), Some(2), "{program} {args:?}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(stderr.contains(reason), "{program}: {stderr}");
    }
}
