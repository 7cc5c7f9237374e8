//! `ips demo` runs in CI: the whole loop on the simulator, as a user types it.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::process::Command;

mod common;

/// The demo starts the sibling binaries; `cargo test -p ips-client` alone does not build them.
fn ensure_services_built() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    cell::build_workspace_binaries(&root).unwrap();
}

/// Runs `ips demo ARGS` (which must include --json), which must succeed, and returns its document.
fn run_demo(args: &[&str]) -> serde_json::Value {
    run_demo_with_temp(args, &std::env::temp_dir())
}

/// [`run_demo`] with `temp` as the demo's temp folder (TMPDIR).
fn run_demo_with_temp(args: &[&str], temp: &std::path::Path) -> serde_json::Value {
    ensure_services_built();
    let output = Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(args)
        .env("TMPDIR", temp)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).unwrap()
}

#[test]
fn demo_recovers_the_hidden_pose_to_a_tenth_of_a_millimetre() {
    // Its own temp folder: the demo's scratch folder (session, journal, capture) must be gone
    // when it ends.
    let temp = common::Scratch::folder(
        std::env::temp_dir().join(format!("cobot-align-demo-test-{}", std::process::id())),
    );
    let result = run_demo_with_temp(&["demo", "--json"], &temp);
    let left: Vec<_> = std::fs::read_dir(&*temp)
        .unwrap()
        .map(|entry| entry.unwrap().file_name())
        .collect();
    assert!(left.is_empty(), "the demo left {left:?}");
    let error_m = result["pose_error_m"].as_f64().unwrap();
    let error_rad = result["pose_error_rad"].as_f64().unwrap();
    assert!(error_m < 1e-4, "{error_m} m");
    assert!(error_rad < 1e-4, "{error_rad} rad");
    assert!(result["nominal_error_m"].as_f64().unwrap() > 0.01);
    assert_eq!(result["inspections"], 9);
}

#[test]
fn demo_on_the_iiwa_over_fri_recovers_the_hidden_pose() {
    let result = run_demo(&["demo", "--robot", "iiwa14", "--json"]);
    assert_eq!(result["robot"], "iiwa14");
    let error_m = result["pose_error_m"].as_f64().unwrap();
    let error_rad = result["pose_error_rad"].as_f64().unwrap();
    assert!(error_m < 1e-4, "{error_m} m");
    assert!(error_rad < 1e-4, "{error_rad} rad");
    assert!(result["nominal_error_m"].as_f64().unwrap() > 0.01);
}

#[test]
fn demo_refuses_robots_it_cannot_simulate() {
    let output = Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(["demo", "--robot", "kr16"])
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&output.stderr).contains("expected ur10, ur10e or iiwa14"));
}

/// The simulated cell carries an undeclared effect; the demo's diagnosis must name it as its best
/// candidate, estimate it within 3 standard errors and leave the part pose better than plain
/// alignment.
fn demo_with(effect: &str, parameter: &str, truth: f64) {
    let result = run_demo(&["demo", "--effect", effect, "--json"]);
    let diagnosis = &result["diagnosis"];
    // With 16 touches and the declared 50 um noise, some pairs (a larger ball and a longer TCP)
    // stay within the ambiguity margin: the diagnosis may say so, but its best candidate must
    // be the simulated effect and modelling it must help.
    let verdict = diagnosis["verdict"].as_str().unwrap();
    assert!(verdict == "effect" || verdict == "ambiguous", "{diagnosis}");
    assert_eq!(diagnosis["effect"]["name"], effect, "{diagnosis}");
    let estimate = diagnosis["effect"]["params"][parameter].as_f64().unwrap();
    let stderr = diagnosis["effect"]["stderr"][parameter].as_f64().unwrap();
    assert!(
        (estimate - truth).abs() < 3.0 * stderr,
        "{estimate} +- {stderr}, truth {truth}"
    );
    let before = result["pose_error_m"].as_f64().unwrap();
    let after = result["pose_error_after_diagnosis_m"].as_f64().unwrap();
    if verdict == "effect" {
        assert!(
            after < before,
            "pose error {after} after modelling, {before} before"
        );
    } else {
        // Ambiguous: nothing is applied, so the pose is left as aligned, never made worse.
        assert!(after <= before + 1e-9, "{after} vs {before}");
    }
}

#[test]
fn demo_finds_an_undeclared_ball_radius() {
    demo_with("probe_radius", "delta_radius_m", 0.0004);
}

#[test]
fn demo_finds_an_undeclared_part_scale() {
    demo_with("part_scale", "scale_minus_one", 0.004);
}

#[test]
fn demo_finds_an_undeclared_tcp_offset() {
    demo_with("tcp_offset", "dz_m", 0.0015);
}

#[test]
fn demo_finds_undeclared_encoder_offsets() {
    // The diagnosis reports the correction to the encoders: minus what the simulator added.
    demo_with("joint_offsets", "joint_3_rad", 0.002);
}

#[test]
fn demo_finds_undeclared_gravity_sag() {
    demo_with("joint_compliance", "joint_2_rad_per_nm", 3e-5);
}

/// An eccentric encoder is outside the diagnosis library: the residual must be noticed, and no
/// effect may be applied that leaves the part further from the truth.
#[test]
fn demo_with_an_effect_outside_the_library_is_never_made_worse() {
    let result = run_demo(&["demo", "--effect", "cyclic_encoder", "--json"]);
    let diagnosis = &result["diagnosis"];
    assert_ne!(diagnosis["verdict"], "no_effect", "{diagnosis}");
    let before = result["pose_error_m"].as_f64().unwrap();
    let after = result["pose_error_after_diagnosis_m"].as_f64().unwrap();
    assert!(after <= before + 1e-9, "{after} after vs {before} before");
}

#[test]
fn demo_finds_an_undeclared_trigger_latency_on_the_fly() {
    demo_with("trigger_latency", "latency_s", 0.05);
}

#[test]
fn demo_on_a_calibrated_ur10e_uses_the_controllers_calibration() {
    let folder = std::env::temp_dir().join(format!("ips-demo-calibration-{}", std::process::id()));
    std::fs::create_dir_all(&folder).unwrap();
    let file = folder.join("calibration.json");
    // Set C of UR's ROS driver tests: d offsets of 439 and -446 m on the parallel joints cancel.
    let calibration = align_core::corpus::calibrations::ur_driver_calibration("C")
        .unwrap()
        .file_text();
    std::fs::write(&file, &calibration).unwrap();
    let path = file.display().to_string();
    let result = run_demo(&["demo", "--robot", "ur10e", "--calibration", &path, "--json"]);
    // Read from the controller through the bridge: the pose to well under 0.1 mm ...
    let error_m = result["pose_error_m"].as_f64().unwrap();
    assert!(error_m < 1e-4, "{error_m} m: {result}");
    assert!(
        result["calibration_hash"]
            .as_str()
            .unwrap()
            .starts_with("calib_")
    );
    // ... where the nominal kinematics, given the same touches, are millimetres off.
    let nominal_m = result["nominal_kinematics_pose_error_m"].as_f64().unwrap();
    assert!(nominal_m > 5e-4, "{nominal_m} m: {result}");
    // Bad files and robots are refused before anything starts.
    std::fs::write(&file, calibration.replacen("\"a\": [", "\"a\": [0, ", 1)).unwrap();
    let output = Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(["demo", "--robot", "ur10e", "--calibration", &path])
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&output.stderr).contains("dh_delta.a has 7 values"));
    let output = Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(["demo", "--robot", "iiwa14", "--calibration", &path])
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&output.stderr).contains("UR robots only"));
    let _ = std::fs::remove_dir_all(&folder);
}
