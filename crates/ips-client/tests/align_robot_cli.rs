//! `ips align-robot` (spawned binary): a shipped robot and a robot built here (mesh links via
//! package://, a prismatic joint) found in generated scans, and bad input.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use align_core::geometry::shapes::extrude;
use align_core::io::{TriangleSoup, write_stl_binary, write_xyz};
use align_core::kinematics::{PackageMap, RobotModel};
use align_core::pose::isometry_from_xyz_rpy;
use align_core::registration::articulated::ArticulatedBody;
use align_core::trials::TrialRng;
use align_core::trials::robot_scan::{RobotScanOptions, scan_robot};
use align_core::trials::robot_trials::{perturb_robot, surface_deviation_m};
use nalgebra::Isometry3;

fn ips(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(args)
        .output()
        .unwrap()
}

fn scratch_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("ips-align-robot-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn list(values: &[f64]) -> String {
    values
        .iter()
        .map(|v| format!("{v}"))
        .collect::<Vec<_>>()
        .join(",")
}

fn pose_text(pose: &Isometry3<f64>) -> String {
    let (xyz, rpy) = align_core::pose::xyz_rpy(pose);
    list(&[xyz[0], xyz[1], xyz[2], rpy[0], rpy[1], rpy[2]])
}

/// Scans the robot at the truth, runs the command from a perturbed start, and returns the
/// largest surface deviation of a visible link and the JSON document.
fn align_scanned(
    urdf: &Path,
    packages: &PackageMap,
    package_flags: &[String],
    truth: &Isometry3<f64>,
    q_true: &[f64],
    delta_m: f64,
) -> (f64, serde_json::Value) {
    let model = RobotModel::from_urdf_file(urdf, packages).unwrap();
    let body = ArticulatedBody::from_model(&model).unwrap();
    let dir = scratch_dir(&model.name);
    let cloud_path = dir.join("scan.xyz");
    write_xyz(
        &cloud_path,
        &scan_robot(&body, truth, q_true, &RobotScanOptions::default()),
    )
    .unwrap();
    let mut rng = TrialRng::new(7);
    let (start, q0) = perturb_robot(&body, truth, q_true, delta_m, &mut rng);
    let (base_pose, q0, delta) = (pose_text(&start), list(&q0), delta_m.to_string());
    let mut args = vec![
        "align-robot",
        "--urdf",
        urdf.to_str().unwrap(),
        "--cloud",
        cloud_path.to_str().unwrap(),
        "--base-pose",
        &base_pose,
        "--q0",
        &q0,
        "--delta",
        &delta,
        "--json",
    ];
    for flag in package_flags {
        args.extend(["--package-dir", flag.as_str()]);
    }
    let output = ips(&args);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let result: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let numbers = |v: &serde_json::Value| -> Vec<f64> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let (xyz, rpy) = (
        numbers(&result["base_pose"]["xyz"]),
        numbers(&result["base_pose"]["rpy"]),
    );
    let fitted_base = isometry_from_xyz_rpy([xyz[0], xyz[1], xyz[2]], [rpy[0], rpy[1], rpy[2]]);
    let fitted = body.link_poses(&fitted_base, &numbers(&result["q"]));
    let true_poses = body.link_poses(truth, q_true);
    let mut worst: f64 = 0.0;
    for (index, link) in body.links().iter().enumerate() {
        let Some(mesh) = &link.surface else { continue };
        let reported = result["links"]
            .as_array()
            .unwrap()
            .iter()
            .find(|l| l["name"] == link.name.as_str())
            .unwrap();
        if reported["visible"].as_bool().unwrap() {
            worst = worst.max(surface_deviation_m(
                mesh,
                &fitted[index],
                &true_poses[index],
            ));
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
    (worst, result)
}

#[test]
fn the_shipped_ur10_is_found_in_a_cluttered_scan() {
    let urdf = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../robots/ur10.urdf");
    let truth = isometry_from_xyz_rpy([0.3, -0.2, 0.0], [0.0, 0.0, 0.5]);
    let q_true = [0.3, -1.2, 1.4, -1.9, -1.4, 0.2];
    let (worst, result) = align_scanned(&urdf, &PackageMap::new(), &[], &truth, &q_true, 0.1);
    assert!(worst < 1e-3, "{worst} m: {result}");
    assert_eq!(result["q"].as_array().unwrap().len(), 6);
    assert_eq!(result["links"].as_array().unwrap().len(), 7);
    assert!(result["time_s"].as_f64().unwrap() > 0.0);
    // The UR10's round base: the shoulder pan is observed only together with the base's yaw.
    let flags: Vec<bool> = result["joints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j["turns_with_base"].as_bool().unwrap())
        .collect();
    assert_eq!(flags, [true, false, false, false, false, false], "{result}");
    // Each joint's 95 % interval: none for the pan (its split with the base is the start's),
    // a fraction of a degree for the others the scan shows, none for those it does not.
    for (index, joint) in result["joints"].as_array().unwrap().iter().enumerate() {
        let within = &joint["within_95"];
        if index == 0 || !joint["observed"].as_bool().unwrap() {
            assert!(within.is_null(), "{joint}");
        } else {
            let rad = within.as_f64().unwrap();
            assert!(rad > 0.0 && rad < 0.01, "{joint}");
        }
    }
}

/// Writes a robot of its own into `dir`: a box base, an L-shaped mesh arm (package://my_robot)
/// on a revolute joint and a box carriage on a prismatic one. Returns the URDF and the
/// `--package-dir` value.
fn slider_robot(dir: &Path) -> (PathBuf, String) {
    let meshes = dir.join("my_robot/meshes");
    std::fs::create_dir_all(&meshes).unwrap();
    // An L-shaped arm: no symmetry for the scan to hide a rotation in.
    let arm = extrude(
        &[
            [0.0, -0.04],
            [0.5, -0.04],
            [0.5, 0.04],
            [0.12, 0.04],
            [0.12, 0.15],
            [0.0, 0.15],
        ],
        0.08,
    )
    .unwrap();
    let soup = TriangleSoup {
        vertices: arm.vertices().collect(),
        triangles: arm.triangles().to_vec(),
    };
    write_stl_binary(&meshes.join("arm.stl"), &soup).unwrap();
    let urdf = dir.join("my_robot.urdf");
    std::fs::write(
        &urdf,
        r#"<robot name="slider">
  <link name="base"><visual><origin xyz="0 0 0.1"/><geometry><box size="0.5 0.3 0.2"/></geometry></visual></link>
  <link name="arm"><visual><geometry><mesh filename="package://my_robot/meshes/arm.stl"/></geometry></visual></link>
  <link name="carriage"><visual><geometry><box size="0.12 0.1 0.06"/></geometry></visual></link>
  <joint name="turn" type="revolute"><parent link="base"/><child link="arm"/>
    <origin xyz="0.1 0 0.2"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="slide" type="prismatic"><parent link="arm"/><child link="carriage"/>
    <origin xyz="0 0 0.11"/><axis xyz="1 0 0"/><limit lower="0" upper="0.45" effort="1" velocity="1"/></joint>
</robot>"#,
    )
    .unwrap();
    let package = format!("my_robot={}", dir.join("my_robot").display());
    (urdf, package)
}

#[test]
fn a_robot_with_mesh_links_and_a_prismatic_joint_is_found() {
    let dir = scratch_dir("package");
    let (urdf, package) = slider_robot(&dir);
    let mut packages = PackageMap::new();
    let (name, path) = PackageMap::parse_entry(&package).unwrap();
    packages.insert(name, path);
    let truth = isometry_from_xyz_rpy([0.1, 0.2, 0.0], [0.0, 0.0, -0.3]);
    let (worst, result) = align_scanned(&urdf, &packages, &[package], &truth, &[0.7, 0.25], 0.05);
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(worst < 1e-3, "{worst} m: {result}");
    let joints = result["joints"].as_array().unwrap();
    assert!(
        joints.iter().all(|j| j["observed"].as_bool().unwrap()),
        "{result}"
    );
    // A box base shows its yaw: no joint shares it.
    assert!(
        joints
            .iter()
            .all(|j| !j["turns_with_base"].as_bool().unwrap()),
        "{result}"
    );
}

#[test]
fn bad_input_exits_2_with_the_reason() {
    let urdf = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../robots/ur10.urdf");
    let urdf = urdf.to_str().unwrap();
    let dir = scratch_dir("bad");
    let cloud = dir.join("scan.xyz");
    std::fs::write(&cloud, "0 0 0\n0.1 0 0\n0 0.1 0\n").unwrap();
    let cloud = cloud.to_str().unwrap();
    let six = "0,-1.57,1.57,-1.57,-1.57,0";
    let cases: [(&[&str], &str); 6] = [
        (
            &[
                "--urdf",
                "/nonexistent/robot.urdf",
                "--cloud",
                cloud,
                "--base-pose",
                "0,0,0,0,0,0",
                "--q0",
                six,
                "--delta",
                "0.1",
            ],
            "/nonexistent/robot.urdf",
        ),
        (
            &[
                "--urdf",
                urdf,
                "--cloud",
                "/nonexistent/scan.xyz",
                "--base-pose",
                "0,0,0,0,0,0",
                "--q0",
                six,
                "--delta",
                "0.1",
            ],
            "/nonexistent/scan.xyz",
        ),
        (
            &[
                "--urdf",
                urdf,
                "--cloud",
                cloud,
                "--base-pose",
                "0,0,0,0,0,0",
                "--q0",
                "0,0,0",
                "--delta",
                "0.1",
            ],
            "6 joints",
        ),
        (
            &[
                "--urdf",
                urdf,
                "--cloud",
                cloud,
                "--base-pose",
                "0,0,0,0,0,0",
                "--q0",
                "0,NaN,0,0,0,0",
                "--delta",
                "0.1",
            ],
            "--q0: item 2",
        ),
        (
            &[
                "--urdf",
                urdf,
                "--cloud",
                cloud,
                "--base-pose",
                "0,0,0,0,0",
                "--q0",
                six,
                "--delta",
                "0.1",
            ],
            "--base-pose needs 6 values",
        ),
        (
            &[
                "--urdf",
                urdf,
                "--cloud",
                cloud,
                "--base-pose",
                "0,0,0,0,0,0",
                "--q0",
                six,
                "--delta",
                "-1",
            ],
            "--delta must be a positive distance",
        ),
    ];
    for (args, reason) in cases {
        let mut full = vec!["align-robot"];
        full.extend_from_slice(args);
        let output = ips(&full);
        assert_eq!(output.status.code(), Some(2), "{args:?}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(stderr.contains(reason), "{args:?}: {stderr}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `ips trials --robot` can start part-way through its seeded sequence and says where it
/// started; `--first-trial` without `--robot` is refused.
#[test]
fn robot_trials_start_at_a_given_trial_and_say_so() {
    let output = ips(&[
        "trials",
        "--robot",
        "ur10",
        "--deltas",
        "50",
        "--trials",
        "1",
        "--first-trial",
        "3",
        "--hierarchical-only",
        "--json",
    ]);
    assert!(output.status.success(), "{output:?}");
    let json: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(json["first_trial"], 3, "{json}");
    assert_eq!(json["trials_per_delta"], 1, "{json}");
    let whole = &json["rows"][0]["hierarchical"];
    let failed = whole["failed_trials"].as_array().unwrap();
    assert_eq!(
        whole["failed"].as_u64().unwrap() as usize,
        failed.len(),
        "{json}"
    );
    assert!(failed.iter().all(|t| t == 3), "{json}");

    let output = ips(&["trials", "--first-trial", "3"]);
    assert_eq!(output.status.code(), Some(2), "{output:?}");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("--robot"), "{stderr}");
}

/// `ips trials --urdf`: the robot trials on a robot that is not shipped, scanned at `--home`;
/// a `--home` that does not fit the robot is refused with its joints named.
#[test]
fn robot_trials_run_on_a_urdf_of_ones_own() {
    let dir = scratch_dir("trials-urdf");
    let (urdf, package) = slider_robot(&dir);
    let urdf = urdf.to_str().unwrap();
    let trials = |home: &str| {
        ips(&[
            "trials",
            "--urdf",
            urdf,
            "--package-dir",
            &package,
            "--home",
            home,
            "--deltas",
            "50",
            "--trials",
            "2",
            "--hierarchical-only",
            "--json",
        ])
    };
    let output = trials("0.7,0.25");
    let refused = trials("0.7");
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(output.status.success(), "{output:?}");
    let json: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(json["robot"], "slider", "{json}");
    assert_eq!(json["home"], serde_json::json!([0.7, 0.25]), "{json}");
    let objects: Vec<&str> = json["rows"]
        .as_array()
        .unwrap()
        .iter()
        .map(|row| row["object"].as_str().unwrap())
        .collect();
    assert_eq!(objects, ["slider", "base", "arm", "carriage"], "{json}");
    for row in json["rows"].as_array().unwrap() {
        assert_eq!(row["hierarchical"]["succeeded"], 2, "{json}");
        assert!(row["independent"].is_null(), "{json}");
    }

    assert_eq!(refused.status.code(), Some(2), "{refused:?}");
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        stderr.contains("--home: 1 values for the 2 moving joints")
            && stderr.contains("turn, slide"),
        "{stderr}"
    );
}
