//! `ips align SESSION` on the shipped example session (spawned binary), and bad sessions.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn example(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/step_block_ur10")
        .join(file)
}

fn ips(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn example_session_aligns_to_the_hidden_truth() {
    let session = example("session.json");
    let output = ips(&["align", session.to_str().unwrap(), "--json"]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let result: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(example("truth.json")).unwrap()).unwrap();
    for key in ["xyz", "rpy"] {
        for axis in 0..3 {
            let got = result["pose"][key][axis].as_f64().unwrap();
            let want = truth["base_from_part"][key][axis].as_f64().unwrap();
            assert!((got - want).abs() < 1e-6, "{key}[{axis}]: {got} vs {want}");
        }
    }
    assert_eq!(result["converged"], true);
    assert_eq!(result["ambiguous"], false);
    assert!(result["rms"].as_f64().unwrap() < 1e-6);
    assert_eq!(result["residuals"].as_array().unwrap().len(), 9);
    assert_eq!(result["pose"]["matrix"].as_array().unwrap().len(), 4);
    assert!(result["time_s"].as_f64().unwrap() > 0.0);

    let text = ips(&["align", session.to_str().unwrap(), "--local"]);
    assert!(text.status.success());
    assert!(
        String::from_utf8_lossy(&text.stdout)
            .contains("base_from_part: xyz [m] 0.620000 -0.250000 0.020000")
    );
}

fn scratch_session(name: &str, edit: impl FnOnce(&mut serde_json::Value)) -> PathBuf {
    let mut session: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(example("session.json")).unwrap()).unwrap();
    edit(&mut session);
    let folder =
        std::env::temp_dir().join(format!("cobot-align-align-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&folder).unwrap();
    // Paths in a session are relative to it: point them back at the example.
    session["robot"]["urdf"] =
        serde_json::json!(example("../../robots/ur10.urdf").to_str().unwrap());
    if session["part"]["mesh"] == "step_block.stl" {
        session["part"]["mesh"] = serde_json::json!(example("step_block.stl").to_str().unwrap());
    }
    let path = folder.join("session.json");
    std::fs::write(&path, session.to_string()).unwrap();
    path
}

fn assert_refused(path: &Path, reason: &str) {
    let output = ips(&["align", path.to_str().unwrap()]);
    assert_eq!(output.status.code(), Some(2), "{}", path.display());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.contains(reason), "{stderr}");
}

#[test]
fn bad_sessions_exit_2_with_the_reason() {
    assert_refused(
        Path::new("/no/such/session.json"),
        "cannot read session '/no/such/session.json'",
    );
    let garbage =
        std::env::temp_dir().join(format!("cobot-align-garbage-{}.json", std::process::id()));
    std::fs::write(&garbage, "{ not json").unwrap();
    assert_refused(&garbage, "key must be a string");
    assert_refused(
        &scratch_session("format", |s| s["format"] = "other@2".into()),
        "format 'other@2' is not 'cobot-align/session@1'",
    );
    assert_refused(
        &scratch_session("joints", |s| {
            s["inspections"][2]["q"] = serde_json::json!([0.1, 0.2])
        }),
        "inspection '3': expected 6 joint values",
    );
    assert_refused(
        &scratch_session("mesh", |s| s["part"]["mesh"] = "missing.stl".into()),
        "missing.stl': No such file",
    );
    assert_refused(
        &scratch_session("tip", |s| s["robot"]["tip_link"] = "flange".into()),
        "no link named 'flange'",
    );
    // Three touches on the top alone leave x, y and the yaw free.
    assert_refused(
        &scratch_session("free", |s| {
            let first: Vec<_> = s["inspections"].as_array().unwrap()[..3].to_vec();
            s["inspections"] = serde_json::Value::Array(first);
        }),
        "cannot align: the measurements leave a degree of freedom free",
    );
}
