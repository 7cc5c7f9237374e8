//! `ips plan SESSION`: the 3-2-1 plan at the nominal pose. Checked by what it promises: each
//! contact's joints put the ball where the plan says, the ball sits one radius off the nominal
//! part, and touching at the planned joints lets `ips align` recover the nominal pose (the plan
//! fixes all six degrees of freedom).

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use align_core::geometry::Mesh;
use align_core::io::read_mesh;
use align_core::kinematics::{PackageMap, RobotModel};
use align_core::pose::isometry_from_xyz_rpy;
use nalgebra::{Point3, Vector3};
use serde_json::{Value, json};

mod common;

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

fn point(value: &Value) -> Point3<f64> {
    let v: [f64; 3] = serde_json::from_value(value.clone()).unwrap();
    Point3::from(v)
}

#[test]
fn planned_joints_touch_where_planned_and_let_the_alignment_recover_the_nominal_pose() {
    let session_path = example("session.json");
    let output = ips(&["plan", session_path.to_str().unwrap(), "--json"]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let plan: Value = serde_json::from_slice(&output.stdout).unwrap();
    let touches = plan["touches"].as_array().unwrap();
    assert_eq!(touches.len(), 9);
    let roles: Vec<&str> = touches
        .iter()
        .map(|t| t["role"].as_str().unwrap())
        .collect();
    assert_eq!(
        &roles[..6],
        [
            "primary",
            "primary",
            "primary",
            "secondary",
            "secondary",
            "tertiary"
        ]
    );

    let session: Value =
        serde_json::from_str(&std::fs::read_to_string(&session_path).unwrap()).unwrap();
    let chain = RobotModel::from_urdf_file(&example("../../robots/ur10.urdf"), &PackageMap::new())
        .unwrap()
        .chain("base_link", "tool0")
        .unwrap();
    let tcp = &session["tool"]["tcp"];
    let flange_from_tcp = isometry_from_xyz_rpy(
        serde_json::from_value(tcp["xyz"].clone()).unwrap(),
        serde_json::from_value(tcp["rpy"].clone()).unwrap(),
    );
    let nominal = &session["part"]["nominal_pose"];
    let base_from_part = isometry_from_xyz_rpy(
        serde_json::from_value(nominal["xyz"].clone()).unwrap(),
        serde_json::from_value(nominal["rpy"].clone()).unwrap(),
    );
    let soup = read_mesh(&example("step_block.stl"), 0.001).unwrap();
    let mesh = Mesh::new(&soup.vertices, &soup.triangles).unwrap();
    let radius = session["tool"]["tip_radius"].as_f64().unwrap();
    for touch in touches {
        let q: Vec<f64> = serde_json::from_value(touch["q_contact"].clone()).unwrap();
        let at_contact = chain.forward(&q).unwrap() * flange_from_tcp;
        let centre = point(&touch["ball_centre_m"]);
        assert!((Point3::from(at_contact.translation.vector) - centre).norm() < 1e-6);
        let approach: [f64; 3] = serde_json::from_value(touch["approach"].clone()).unwrap();
        assert!((at_contact.rotation * Vector3::z() - Vector3::from(approach)).norm() < 1e-9);
        let in_part = base_from_part.inverse() * centre;
        let distance = mesh.closest_point(&in_part).signed_distance;
        assert!((distance - radius).abs() < 1e-6, "{distance}");
    }

    // Touch at the planned joints: the alignment finds the nominal pose again.
    let mut touched = session.clone();
    touched["robot"]["urdf"] = json!(example("../../robots/ur10.urdf").to_str().unwrap());
    touched["part"]["mesh"] = json!(example("step_block.stl").to_str().unwrap());
    touched["inspections"] = touches
        .iter()
        .map(|t| json!({"id": t["id"], "q": t["q_contact"]}))
        .collect();
    let path = common::Scratch::file(
        std::env::temp_dir().join(format!("cobot-align-plan-{}.json", std::process::id())),
    );
    std::fs::write(&path, touched.to_string()).unwrap();
    let output = ips(&["align", path.to_str().unwrap(), "--json"]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let aligned: Value = serde_json::from_slice(&output.stdout).unwrap();
    for axis in 0..3 {
        let got = aligned["pose"]["xyz"][axis].as_f64().unwrap();
        let want = nominal["xyz"][axis].as_f64().unwrap();
        assert!((got - want).abs() < 1e-6, "xyz[{axis}] {got} vs {want}");
    }
    assert_eq!(aligned["ambiguous"], false);
}

#[test]
fn without_a_robot_the_plan_comes_in_along_the_normals_and_has_no_joints() {
    let output = ips(&[
        "plan",
        example("session.json").to_str().unwrap(),
        "--no-robot",
        "--json",
    ]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let plan: Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(plan["robot"], false);
    for touch in plan["touches"].as_array().unwrap() {
        assert!(touch.get("q_contact").is_none());
        let approach =
            Vector3::from(serde_json::from_value::<[f64; 3]>(touch["approach"].clone()).unwrap());
        let offset = point(&touch["ball_centre_m"]) - point(&touch["point_m"]);
        // The ball's centre lies against the approach, one radius out.
        assert!((offset.normalize() + approach).norm() < 1e-9, "{touch}");
    }
}

#[test]
fn bad_plan_requests_are_refused_with_the_reason() {
    let session = example("session.json");
    let session = session.to_str().unwrap();
    for (args, reason) in [
        (vec!["--touches", "5"], "at least 6 touches"),
        (
            vec!["--max-tilt-deg", "100"],
            "--max-tilt-deg must be between 0 and 80",
        ),
        (
            vec!["--seed-deg", "0,1,2"],
            "--seed-deg has 3 values, the robot 6 joints",
        ),
    ] {
        let mut all = vec!["plan", session];
        all.extend(args);
        let output = ips(&all);
        assert_eq!(output.status.code(), Some(2));
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains(reason), "{stderr}");
    }
}
