//! A whole inspection session through the shipped binaries and the Python example: touches
//! captured, the service killed with SIGKILL mid-session and restarted, nothing acknowledged
//! lost, the rest of the touches taken, the part aligned to the hidden truth.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::path::PathBuf;
use std::process::Command;
use std::time::Duration;

use align_core::robots::ShippedRobot;
use serde_json::{Value, json};
use system_tests::{Cell, Service, binary, spawn, start_cell};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn python_session(
    python: &PathBuf,
    service: &Service,
    sim: &Service,
    bridge: &Service,
    extra: &[&str],
) -> Vec<Value> {
    let output = Command::new(python)
        .arg(root().join("examples/python/full_session.py"))
        .args([
            "--service",
            service.endpoint("rep").unwrap(),
            "--sim-control",
            sim.endpoint("control").unwrap(),
            "--bridge-pub",
            bridge.endpoint("pub").unwrap(),
        ])
        .arg("--plan")
        .arg(root().join("examples/step_block_ur10/session.json"))
        .args(extra)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn session_survives_sigkill_and_aligns_to_the_truth() {
    system_tests::ensure_binaries();
    let python = system_tests::python();

    // The example session's robot, tool and part, without inspections.
    let example = root().join("examples/step_block_ur10");
    let mut template: Value =
        serde_json::from_str(&std::fs::read_to_string(example.join("session.json")).unwrap())
            .unwrap();
    template["inspections"] = json!([]);
    template["robot"]["urdf"] = json!(root().join("robots/ur10.urdf").to_str().unwrap());
    template["part"]["mesh"] = json!(example.join("step_block.stl").to_str().unwrap());
    let folder = std::env::temp_dir().join(format!("cobot-align-session-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&folder);
    std::fs::create_dir_all(&folder).unwrap();
    let session = folder.join("session.json");
    std::fs::write(&session, template.to_string()).unwrap();
    let journal = folder.join("cell.journal");

    // The UR cell exactly as `ips demo` starts it.
    let Cell { sim, bridge } = start_cell(ShippedRobot::Ur10);
    let serve_args = |journal: &PathBuf| -> Vec<String> {
        [
            "serve",
            "--session",
            session.to_str().unwrap(),
            "--journal",
            journal.to_str().unwrap(),
            "--rep",
            "tcp://127.0.0.1:*",
            "--bridge-rep",
            bridge.endpoint("rep").unwrap(),
            "--bridge-pub",
            bridge.endpoint("pub").unwrap(),
        ]
        .map(str::to_owned)
        .to_vec()
    };
    let args = serve_args(&journal);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let mut service = spawn(binary("ips"), &args, Duration::from_secs(20));
    let first = python_session(
        &python,
        &service,
        &sim,
        &bridge,
        &["--first", "0", "--count", "5"],
    );
    assert_eq!(first.len(), 5);

    // SIGKILL: no chance to flush anything that was not already on disk.
    service.child.kill().unwrap();
    let _ = service.child.wait();
    drop(service);
    let service = spawn(binary("ips"), &args, Duration::from_secs(20));
    let rest = python_session(
        &python,
        &service,
        &sim,
        &bridge,
        &["--first", "5", "--align"],
    );
    // Four more inspections, numbered after the five restored ones, then the alignment.
    assert_eq!(rest.len(), 5);
    assert_eq!(rest[0]["inspection"], "6");
    let truth: Value =
        serde_json::from_str(&std::fs::read_to_string(example.join("truth.json")).unwrap())
            .unwrap();
    for axis in 0..3 {
        let got = rest[4]["pose"]["xyz"][axis].as_f64().unwrap();
        let want = truth["base_from_part"]["xyz"][axis].as_f64().unwrap();
        assert!((got - want).abs() < 1e-4, "xyz[{axis}]: {got} vs {want}");
    }
    for service in [service, bridge, sim] {
        assert!(
            service
                .terminate(Duration::from_secs(10))
                .unwrap()
                .success()
        );
    }
    let _ = std::fs::remove_dir_all(&folder);
}
