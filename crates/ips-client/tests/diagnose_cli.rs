//! `ips diagnose` on the shipped sessions: the noiseless one has nothing to explain; the one
//! touched with a 3.4 mm ball while declaring 3 mm is traced to the probe radius.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::path::{Path, PathBuf};
use std::process::Command;

/// A copy of an example session in a scratch folder (the plot is written next to it).
fn scratch_session(name: &str) -> PathBuf {
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/step_block_ur10");
    let mut session: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(example.join(name)).unwrap()).unwrap();
    session["robot"]["urdf"] =
        serde_json::json!(example.join("../../robots/ur10.urdf").to_str().unwrap());
    session["part"]["mesh"] = serde_json::json!(example.join("step_block.stl").to_str().unwrap());
    let folder = std::env::temp_dir().join(format!(
        "cobot-align-diagnose-{}-{name}",
        std::process::id()
    ));
    std::fs::create_dir_all(&folder).unwrap();
    let path = folder.join(name);
    std::fs::write(&path, session.to_string()).unwrap();
    path
}

fn diagnose(path: &Path) -> serde_json::Value {
    let output = Command::new(env!("CARGO_BIN_EXE_ips"))
        .arg("diagnose")
        .arg(path)
        .arg("--json")
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
fn noiseless_session_has_no_effect() {
    let path = scratch_session("session.json");
    let result = diagnose(&path);
    assert_eq!(result["verdict"], "no_effect");
    assert!(result["effect"].is_null());
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}

#[test]
fn undeclared_ball_radius_is_found_with_the_design_keys() {
    let path = scratch_session("session_probe_radius.json");
    let result = diagnose(&path);
    assert_eq!(result["verdict"], "effect");
    assert_eq!(result["effect"]["name"], "probe_radius");
    let estimate = result["effect"]["params"]["delta_radius_m"]
        .as_f64()
        .unwrap();
    let stderr = result["effect"]["stderr"]["delta_radius_m"]
        .as_f64()
        .unwrap();
    assert!(
        (estimate - 0.0004).abs() < 3.0 * stderr,
        "{estimate} +- {stderr}"
    );
    assert!(result["after"]["rms"].as_f64().unwrap() < result["before"]["rms"].as_f64().unwrap());
    for key in [
        "alternatives",
        "before",
        "after",
        "pose_before",
        "pose_after",
        "inspections",
    ] {
        assert!(result.get(key).is_some(), "missing {key}");
    }
    assert_eq!(result["inspections"].as_array().unwrap().len(), 27);
    let plot = std::fs::read_to_string(result["plot"].as_str().unwrap()).unwrap();
    assert!(plot.starts_with("<svg") && plot.contains("modelling probe_radius"));
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}
