//! docs/your-cell.md, section 4, run verbatim: every ```sh cell block of the guide runs in
//! order, in bash with `set -euo pipefail`, against sim-robot as a calibrated UR10e, robot-bridge
//! and `ips serve` on free ports. Then the results the guide promises are checked: the
//! calibration's hash, the touches, a diagnosis that finds the undeclared encoder error, the
//! corrected session's pose at the nominal one, and exports that parse.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use align_core::robots::ShippedRobot;
use serde_json::{Value, json};
use system_tests::{Cell, binary, repo_root};

/// The guide's simulator blocks: fenced code whose info string is `sh cell`.
fn guide_blocks() -> Vec<String> {
    let guide = std::fs::read_to_string(repo_root().join("docs/your-cell.md")).unwrap();
    let mut blocks = Vec::new();
    let mut current: Option<String> = None;
    for line in guide.lines() {
        match (&mut current, line.trim_end()) {
            (None, "```sh cell") => current = Some(String::new()),
            (Some(block), "```") => {
                blocks.push(std::mem::take(block));
                current = None;
            }
            (Some(block), text) => {
                block.push_str(text);
                block.push('\n');
            }
            (None, _) => {}
        }
    }
    blocks
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn the_guides_simulator_track_runs_and_ends_at_the_nominal_pose() {
    system_tests::ensure_binaries();
    let python = system_tests::python();
    let blocks = guide_blocks();
    assert!(
        blocks.len() >= 5,
        "the guide has {} cell blocks",
        blocks.len()
    );

    let work = std::env::temp_dir().join(format!("cobot-align-your-cell-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&work);
    std::fs::create_dir_all(&work).unwrap();
    // The controller's factory calibration: UR's published test set C (a UR10e).
    let calibration = work.join("calibration.json");
    std::fs::write(
        &calibration,
        align_core::corpus::calibrations::ur_driver_calibration("C")
            .unwrap()
            .file_text(),
    )
    .unwrap();
    // The cell's session: the example's tool and part on a UR10e, no touches yet.
    let example = repo_root().join("examples/step_block_ur10");
    let mut session = read_json(&example.join("session.json"));
    session["robot"]["urdf"] = json!(repo_root().join("robots/ur10e.urdf"));
    session["part"]["mesh"] = json!(example.join("step_block.stl"));
    session["inspections"] = json!([]);
    std::fs::write(work.join("cell.json"), session.to_string()).unwrap();

    let cell = Cell::start_calibrated(ShippedRobot::Ur10e, Some(&calibration)).unwrap();
    let service = cell
        .serve(
            &binary("ips"),
            &work.join("cell.json"),
            &work.join("inspections.journal"),
        )
        .unwrap();
    let path = format!(
        "{}:{}",
        binary("ips").parent().unwrap().display(),
        std::env::var("PATH").unwrap_or_default()
    );
    for (index, block) in blocks.iter().enumerate() {
        let output = Command::new("bash")
            .args(["-euo", "pipefail", "-c", block])
            .current_dir(&work)
            .env("PATH", &path)
            .env("SERVICE", service.endpoint("rep").unwrap())
            .env("ROBOT_HOST", "127.0.0.1")
            .env("PRIMARY_PORT", cell.sim.port("primary").unwrap())
            .env("CONTROL", cell.sim.endpoint("control").unwrap())
            .env("PUB", cell.bridge.endpoint("pub").unwrap())
            .env("PYTHON", &python)
            .env("REPO", repo_root())
            .output()
            .unwrap();
        assert!(
            output.status.success(),
            "guide block {} failed:\n{block}\nstdout:\n{}\nstderr:\n{}",
            index + 1,
            String::from_utf8_lossy(&output.stdout),
            String::from_utf8_lossy(&output.stderr)
        );
    }

    // What the guide promises.
    let yaml = std::fs::read_to_string(work.join("my_robot_calibration.yaml")).unwrap();
    assert!(yaml.contains("hash: calib_"), "{yaml}");
    let started = read_json(&work.join("started.json"));
    assert!(
        started["robot"]["kinematics"].is_object(),
        "the saved session has the calibration"
    );
    let touched = read_json(&work.join("touched.json"));
    assert_eq!(touched["inspections"].as_array().unwrap().len(), 12);
    let diagnosis = &touched["results"]["diagnosis"]["report"];
    assert_eq!(diagnosis["verdict"], "effect", "{diagnosis}");
    assert_eq!(diagnosis["effect"]["name"], "joint_offsets", "{diagnosis}");
    // The corrected session cancels the encoder error and aligns to the nominal pose (the
    // touches were planned there).
    let corrected = read_json(&work.join("corrected.json"));
    let offset = corrected["robot"]["joint_offsets"][2].as_f64().unwrap();
    assert!((offset + 0.0015).abs() < 1e-4, "joint 3 offset {offset}");
    let output = Command::new(binary("ips"))
        .args([
            "align",
            work.join("corrected.json").to_str().unwrap(),
            "--json",
        ])
        .output()
        .unwrap();
    assert!(output.status.success());
    let aligned: Value = serde_json::from_slice(&output.stdout).unwrap();
    for axis in 0..3 {
        let got = aligned["pose"]["xyz"][axis].as_f64().unwrap();
        let nominal = session["part"]["nominal_pose"]["xyz"][axis]
            .as_f64()
            .unwrap();
        assert!(
            (got - nominal).abs() < 1e-4,
            "xyz[{axis}]: {got} vs {nominal}"
        );
    }
    let urdf = std::fs::read_to_string(work.join("aligned_part.urdf")).unwrap();
    assert!(urdf.contains("<joint name=\"part_joint\" type=\"fixed\">"));
    let csv = std::fs::read_to_string(work.join("touches.csv")).unwrap();
    assert_eq!(csv.lines().count(), 13);

    service.terminate(Duration::from_secs(5));
    let _ = std::fs::remove_dir_all(&work);
}
