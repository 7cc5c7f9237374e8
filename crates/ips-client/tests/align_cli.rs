//! `ips align SESSION` on the shipped example session (spawned binary), and bad sessions; and
//! sessions whose inspections give the controller's flange pose instead of joints (DESIGN.md
//! 6.3): they align like their joint twins, the diagnosis skips what needs joints and says why,
//! and malformed poses are refused with the reason.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use align_core::kinematics::{PackageMap, RobotModel};
use serde_json::{Value, json};

use common::Scratch;

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
    let result: Value = serde_json::from_slice(&output.stdout).unwrap();
    let truth: Value =
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

fn scratch_session(name: &str, edit: impl FnOnce(&mut Value)) -> Scratch {
    let mut session: Value =
        serde_json::from_str(&std::fs::read_to_string(example("session.json")).unwrap()).unwrap();
    edit(&mut session);
    let folder =
        std::env::temp_dir().join(format!("cobot-align-align-{}-{name}", std::process::id()));
    let scratch = Scratch::in_folder(folder, "session.json");
    // Paths in a session are relative to it: point them back at the example.
    session["robot"]["urdf"] = json!(example("../../robots/ur10.urdf").to_str().unwrap());
    if session["part"]["mesh"] == "step_block.stl" {
        session["part"]["mesh"] = json!(example("step_block.stl").to_str().unwrap());
    }
    std::fs::write(&scratch, session.to_string()).unwrap();
    scratch
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
    // Removed when the test ends, passed or not.
    let _garbage_file = Scratch::file(garbage.clone());
    std::fs::write(&garbage, "{ not json").unwrap();
    assert_refused(&garbage, "key must be a string");
    assert_refused(
        &scratch_session("format", |s| s["format"] = "other@2".into()),
        "format 'other@2' is not 'cobot-align/session@1'",
    );
    assert_refused(
        &scratch_session("joints", |s| s["inspections"][2]["q"] = json!([0.1, 0.2])),
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
            s["inspections"] = Value::Array(first);
        }),
        "cannot align: the measurements leave a degree of freedom free",
    );
}

/// The example session `name` with every inspection's joints replaced by the flange pose they
/// give (UR10 forward kinematics), the robot block removed, written to a scratch folder.
fn flange_only(name: &str, edit: impl FnOnce(&mut Value)) -> Scratch {
    let mut session: Value =
        serde_json::from_str(&std::fs::read_to_string(example(name)).unwrap()).unwrap();
    let chain = RobotModel::from_urdf_file(&example("../../robots/ur10.urdf"), &PackageMap::new())
        .unwrap()
        .chain("base_link", "tool0")
        .unwrap();
    for inspection in session["inspections"].as_array_mut().unwrap() {
        let q: Vec<f64> = serde_json::from_value(inspection["q"].clone()).unwrap();
        let pose = chain.forward(&q).unwrap();
        let rotation = pose.rotation.scaled_axis();
        let t = pose.translation.vector;
        let object = inspection.as_object_mut().unwrap();
        object.remove("q");
        object.remove("qd");
        object.insert(
            "flange_pose".to_owned(),
            json!([t.x, t.y, t.z, rotation.x, rotation.y, rotation.z]),
        );
    }
    session.as_object_mut().unwrap().remove("robot");
    session["part"]["mesh"] = json!(example("step_block.stl").to_str().unwrap());
    edit(&mut session);
    // A folder per variant, not per example: tests that share an example may run at once, and
    // each removes its own folder when it ends.
    let tag = session_tag(&session);
    let folder = std::env::temp_dir().join(format!(
        "cobot-align-flange-{}-{}-{tag}",
        std::process::id(),
        name.replace('.', "_")
    ));
    let scratch = Scratch::in_folder(folder, &format!("{tag}.json"));
    std::fs::write(&scratch, session.to_string()).unwrap();
    scratch
}

/// A name from the edit, so that edited variants of one example do not overwrite each other.
fn session_tag(session: &Value) -> String {
    let text = session.to_string();
    let hash = text.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3)
    });
    format!("{hash:016x}")
}

fn align_json(path: &Path) -> Value {
    let output = ips(&["align", path.to_str().unwrap(), "--json"]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).unwrap()
}

#[test]
fn flange_poses_align_exactly_as_the_joints_they_come_from() {
    let from_joints = align_json(&example("session.json"));
    let from_poses = align_json(&flange_only("session.json", |_| {}));
    for key in ["xyz", "rpy"] {
        for axis in 0..3 {
            let a = from_joints["pose"][key][axis].as_f64().unwrap();
            let b = from_poses["pose"][key][axis].as_f64().unwrap();
            assert!((a - b).abs() < 1e-9, "{key}[{axis}]: {a} vs {b}");
        }
    }
    assert_eq!(from_poses["ambiguous"], false);
}

#[test]
fn diagnosis_of_flange_poses_skips_joint_effects_with_the_reason() {
    let path = flange_only("session_probe_radius.json", |_| {});
    let output = ips(&["diagnose", path.to_str().unwrap(), "--json"]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let report: Value = serde_json::from_slice(&output.stdout).unwrap();
    let alternatives = report["alternatives"].as_array().unwrap();
    for name in ["joint_offsets", "joint_compliance", "trigger_latency"] {
        let skipped = alternatives
            .iter()
            .find(|a| a["name"] == name)
            .unwrap_or_else(|| panic!("{name} not listed: {report}"));
        let reason = skipped["reason"].as_str().unwrap();
        assert!(reason.contains("needs joint"), "{name}: {reason}");
    }
    // The ball-radius change the example hides still shows (tied with the TCP on its head-on
    // touches, or named).
    let verdict = report["verdict"].as_str().unwrap();
    assert!(verdict == "effect" || verdict == "ambiguous", "{report}");
}

#[test]
fn malformed_flange_poses_are_refused_with_the_reason() {
    assert_refused(
        &flange_only("session.json", |s| {
            s["inspections"][1]["flange_pose"][3] = json!(0.0);
            s["inspections"][1]["flange_pose"][4] = json!(0.0);
            s["inspections"][1]["flange_pose"][5] = json!(-180.0);
        }),
        "inspection '2': flange_pose has a rotation vector of 180.0000 rad, over pi: is it in degrees?",
    );
    assert_refused(
        &flange_only("session.json", |s| {
            s["inspections"][0]["q"] = json!([0.0, -1.5, 1.5, -1.5, -1.5, 0.0]);
        }),
        "inspection '1' gives both q and flange_pose",
    );
    assert_refused(
        &flange_only("session.json", |s| {
            s["inspections"][2]
                .as_object_mut()
                .unwrap()
                .remove("flange_pose");
        }),
        "inspection '3' gives neither q (joints) nor flange_pose",
    );
    assert_refused(
        &flange_only("session.json", |s| {
            s["inspections"][3]["flange_pose"] = json!([0.1, 0.2, 0.3]);
        }),
        "invalid length 3, expected an array of length 6",
    );
    assert_refused(
        &flange_only("session.json", |s| {
            s["inspections"][3]["flange_pose"] = json!({"x": 0.1});
        }),
        "expected an array of length 6",
    );
    assert_refused(
        &flange_only("session.json", |s| {
            s["inspections"][4] = json!({"id": "5", "q": [0.1, -1.2, 1.4, -1.8, -1.57, 0.0]});
        }),
        "inspection '5' gives joints (q) but the session has no robot",
    );
}

/// The UR10's nominal DH table plus set A of the calibration tests in UR's ROS drivers, as a
/// controller reports it.
fn calibrated_ur10_kinematics() -> Value {
    let table = align_core::corpus::calibrations::ur_driver_calibration("A")
        .unwrap()
        .calibrated()
        .unwrap();
    json!({"dh_theta": table.theta, "dh_a": table.a, "dh_d": table.d,
           "dh_alpha": table.alpha, "hash": "calib_1"})
}

#[test]
fn a_session_with_the_controllers_kinematics_aligns_with_them_and_bad_ones_are_refused() {
    let nominal = align_json(&example("session.json"));
    let calibrated = align_json(&scratch_session("kinematics", |session| {
        session["robot"]["kinematics"] = calibrated_ur10_kinematics();
    }));
    // The same joints through another robot geometry: the part lands millimetres away.
    let apart: f64 = (0..3)
        .map(|i| {
            let a = nominal["pose"]["xyz"][i].as_f64().unwrap();
            let b = calibrated["pose"]["xyz"][i].as_f64().unwrap();
            (a - b).powi(2)
        })
        .sum::<f64>()
        .sqrt();
    assert!(apart > 5e-4 && apart < 0.02, "{apart} m");
    assert_refused(
        &scratch_session("kinematics-short", |session| {
            let mut kinematics = calibrated_ur10_kinematics();
            kinematics["dh_a"] = json!([0, 0, 0, 0, 0]);
            session["robot"]["kinematics"] = kinematics;
        }),
        "robot.kinematics: dh_a has 5 values",
    );
    assert_refused(
        &scratch_session("kinematics-other-robot", |session| {
            let mut kinematics = calibrated_ur10_kinematics();
            kinematics["dh_d"][0] = json!(0.5);
            session["robot"]["kinematics"] = kinematics;
        }),
        "another robot model than the session's",
    );
}
