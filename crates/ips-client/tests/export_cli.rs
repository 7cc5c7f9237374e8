//! `ips align|diagnose SESSION --export FORMAT` (DESIGN.md 6.4): every format read back by a
//! parser that is not ours (the URDF by urdf-rs, every format by `scripts/check-export.py`, which
//! parses XML, the shell line, the KRL and URScript literals and the CSV with its own maths) and
//! compared with the same command's `--json` report, on the shipped example and on a part tilted
//! far from upright, and on poses where Euler angles and rotation vectors are at their edges.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

mod common;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use align_core::io::export::ExportFormat;
use align_core::kinematics::{PackageMap, RobotModel};
use align_core::pose::isometry_from_xyz_rpy;
use nalgebra::Isometry3;
use serde_json::{Value, json};

use common::Scratch;

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(path)
}

fn ips(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(args)
        .output()
        .unwrap()
}

fn stdout_of(args: &[&str]) -> String {
    let output = ips(args);
    assert!(
        output.status.success(),
        "ips {args:?}: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout).unwrap()
}

/// Runs the independent reader on `export`; panics with its reason when it disagrees.
fn independent_check(format: ExportFormat, export: &str, report: &Value) {
    let report_path = std::env::temp_dir().join(format!(
        "cobot-align-export-report-{}-{:x}.json",
        std::process::id(),
        fnv(&report.to_string())
    ));
    // Removed when the check ends, passed or not.
    let _report_file = Scratch::file(report_path.clone());
    std::fs::write(&report_path, report.to_string()).unwrap();
    let mut child = Command::new("python3")
        .arg(repo("scripts/check-export.py"))
        .arg(format.name())
        .arg(&report_path)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python3 runs");
    child
        .stdin
        .take()
        .unwrap()
        .write_all(export.as_bytes())
        .unwrap();
    let output = child.wait_with_output().unwrap();
    assert!(
        output.status.success(),
        "{} export not read back:\n{export}\n{}",
        format.name(),
        String::from_utf8_lossy(&output.stderr)
    );
}

fn fnv(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3)
    })
}

/// The URDF read by urdf-rs: the fixed joint's origin must be the report's pose.
fn urdf_rs_check(urdf: &str, pose: &Value, base_frame: &str) {
    let robot = urdf_rs::read_from_string(urdf).unwrap();
    assert_eq!(robot.name, "aligned_part");
    let joint = robot
        .joints
        .iter()
        .find(|j| j.name == "part_joint")
        .unwrap();
    assert!(matches!(joint.joint_type, urdf_rs::JointType::Fixed));
    assert_eq!(joint.parent.link, base_frame);
    assert_eq!(joint.child.link, "part");
    let read = isometry_from_xyz_rpy(*joint.origin.xyz, *joint.origin.rpy);
    let reported = pose_of(pose);
    assert!((read.translation.vector - reported.translation.vector).norm() < 1e-8);
    assert!(read.rotation.angle_to(&reported.rotation) < 1e-8);
}

fn pose_of(pose: &Value) -> Isometry3<f64> {
    let triple = |key: &str| -> [f64; 3] { serde_json::from_value(pose[key].clone()).unwrap() };
    isometry_from_xyz_rpy(triple("xyz"), triple("rpy"))
}

/// Every format of `command` (align or diagnose) on `session` agrees with its `--json`.
fn every_export_agrees(command: &str, session: &Path) {
    let path = session.to_str().unwrap();
    let report: Value = serde_json::from_str(&stdout_of(&[command, path, "--json"])).unwrap();
    let pose = if command == "diagnose" {
        &report["pose_after"]
    } else {
        &report["pose"]
    };
    for format in ExportFormat::ALL {
        let export = stdout_of(&[command, path, "--export", format.name()]);
        independent_check(format, &export, &report);
        if format == ExportFormat::Urdf {
            urdf_rs_check(&export, pose, report["base_frame"].as_str().unwrap());
        }
    }
}

#[test]
fn the_example_exports_in_every_format() {
    every_export_agrees("align", &repo("examples/step_block_ur10/session.json"));
    every_export_agrees(
        "diagnose",
        &repo("examples/step_block_ur10/session_probe_radius.json"),
    );
}

/// The example session with the whole scene turned by `base_from_old_base` (flange poses
/// instead of joints, so that any tilt is reachable): the part then stands far from upright.
/// In a folder of its own, which also takes the plot and page `diagnose` writes next to it.
fn tilted_session(base_from_old_base: &Isometry3<f64>) -> Scratch {
    let example = repo("examples/step_block_ur10/session_probe_radius.json");
    let mut session: Value =
        serde_json::from_str(&std::fs::read_to_string(&example).unwrap()).unwrap();
    let chain = RobotModel::from_urdf_file(&repo("robots/ur10.urdf"), &PackageMap::new())
        .unwrap()
        .chain("base_link", "tool0")
        .unwrap();
    for inspection in session["inspections"].as_array_mut().unwrap() {
        let q: Vec<f64> = serde_json::from_value(inspection["q"].clone()).unwrap();
        let pose = base_from_old_base * chain.forward(&q).unwrap();
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
    let nominal = &session["part"]["nominal_pose"];
    let nominal = base_from_old_base * pose_of(nominal);
    let (xyz, rpy) = align_core::pose::xyz_rpy(&nominal);
    session["part"]["nominal_pose"] = json!({"xyz": xyz, "rpy": rpy});
    session.as_object_mut().unwrap().remove("robot");
    session["part"]["mesh"] = json!(
        repo("examples/step_block_ur10/step_block.stl")
            .to_str()
            .unwrap()
    );
    let folder = std::env::temp_dir().join(format!(
        "cobot-align-export-tilted-{}-{:x}",
        std::process::id(),
        fnv(&session.to_string())
    ));
    let scratch = Scratch::in_folder(folder, "session.json");
    std::fs::write(&scratch, session.to_string()).unwrap();
    scratch
}

#[test]
fn a_part_tilted_far_from_upright_exports_in_every_format() {
    let tilt = isometry_from_xyz_rpy([0.1, -0.3, 0.4], [2.4, -1.1, 0.9]);
    let session = tilted_session(&tilt);
    let report: Value =
        serde_json::from_str(&stdout_of(&["align", session.to_str().unwrap(), "--json"])).unwrap();
    // The turn reached the pose: the part is far from upright (roll and pitch well off zero).
    let rpy: [f64; 3] = serde_json::from_value(report["pose"]["rpy"].clone()).unwrap();
    assert!(rpy[0].abs() > 0.5 && rpy[1].abs() > 0.5, "{rpy:?}");
    assert_eq!(report["base_frame"], "base");
    every_export_agrees("align", &session);
    every_export_agrees("diagnose", &session);
}

/// Poses at the formats' edges: pitch at +-90 degrees (roll and yaw trade off), a half turn
/// (the rotation vector's length is pi, its sign arbitrary) and none at all, through the same
/// writer the command uses and the same independent reader.
#[test]
fn rotations_at_the_edges_of_euler_angles_and_rotation_vectors_read_back() {
    let edges = [
        [0.3, std::f64::consts::FRAC_PI_2, -0.7],
        [0.0, -std::f64::consts::FRAC_PI_2, 2.0],
        [std::f64::consts::PI, 0.0, 0.0],
        [0.0, 0.0, -std::f64::consts::PI + 1e-9],
        [3.0, 0.1, -3.1],
        [0.0, 0.0, 0.0],
    ];
    for rpy in edges {
        let pose = isometry_from_xyz_rpy([1.25, -0.002, -0.5], rpy);
        let (xyz, rpy) = align_core::pose::xyz_rpy(&pose);
        let report: Value = json!({
            "pose": {"xyz": xyz, "rpy": rpy}, "iterations": 1, "converged": true,
            "rms": 0.0, "max": 0.0, "time_s": 0.0, "ambiguous": false, "candidates": [],
            "starts": 1, "notes": [], "base_frame": "world",
            "residuals": [{"id": "a,1", "distance": -1e-4, "ball_centre": [0.1, 0.2, -0.3]}],
        });
        let parsed: protocol::reports::AlignReport =
            serde_json::from_value(report.clone()).unwrap();
        for format in ExportFormat::ALL {
            let export = ips_client::export::alignment(format, &parsed, None).unwrap();
            independent_check(format, &export, &report);
        }
    }
}

#[test]
fn export_refuses_what_it_cannot_write() {
    let session = repo("examples/step_block_ur10/session.json");
    let path = session.to_str().unwrap();
    let unknown = ips(&["align", path, "--export", "step"]);
    assert_eq!(unknown.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&unknown.stderr).contains("expected one of urdf, sdf"));
    let both = ips(&["align", path, "--export", "urdf", "--json"]);
    assert_eq!(both.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&both.stderr).contains("cannot be used with"));
}
