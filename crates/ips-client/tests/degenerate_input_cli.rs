//! Degenerate parts, clouds that cannot fix a pose and unit mistakes, through the spawned `ips`:
//! exit code 2 with a one-line reason, never a panic or a confident wrong answer.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::{Value, json};

use common::Scratch;

fn example(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/step_block_ur10")
        .join(file)
}

fn scratch(name: &str) -> Scratch {
    Scratch::folder(std::env::temp_dir().join(format!(
        "cobot-align-degenerate-{}-{name}",
        std::process::id()
    )))
}

fn ips(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(args)
        .output()
        .unwrap()
}

/// Exit code 2 and the reason on one line of stderr, which must contain `reason`.
fn assert_refused(output: &Output, reason: &str) {
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.contains(reason), "{stderr}");
}

/// A binary STL of `triangles` (corners in the file's unit).
fn write_binary_stl(path: &Path, triangles: &[[[f32; 3]; 3]]) {
    let mut bytes = vec![0u8; 80];
    bytes.extend((triangles.len() as u32).to_le_bytes());
    for triangle in triangles {
        bytes.extend([0u8; 12]); // normal: readers recompute it
        for corner in triangle {
            for coordinate in corner {
                bytes.extend(coordinate.to_le_bytes());
            }
        }
        bytes.extend([0u8; 2]);
    }
    std::fs::write(path, bytes).unwrap();
}

/// The example session with its part's mesh and scale replaced.
fn session_with_mesh(folder: &Path, mesh: &Path, mesh_scale: f64) -> PathBuf {
    let mut session: Value =
        serde_json::from_str(&std::fs::read_to_string(example("session.json")).unwrap()).unwrap();
    session["robot"]["urdf"] = json!(example("../../robots/ur10.urdf").to_str().unwrap());
    session["part"]["mesh"] = json!(mesh.to_str().unwrap());
    session["part"]["mesh_scale"] = json!(mesh_scale);
    let path = folder.join("session.json");
    std::fs::write(&path, session.to_string()).unwrap();
    path
}

#[test]
fn a_part_of_collinear_triangles_is_refused_by_align_and_diagnose() {
    let folder = scratch("collinear-part");
    let stl = folder.join("collinear.stl");
    write_binary_stl(
        &stl,
        &[[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]]; 12],
    );
    let session = session_with_mesh(&folder, &stl, 0.001);
    for command in ["align", "diagnose"] {
        let output = ips(&[command, session.to_str().unwrap()]);
        assert_refused(&output, "the mesh has no surface");
    }
}

#[test]
fn a_collinear_cloud_is_refused_by_align_cloud() {
    let folder = scratch("collinear-cloud");
    let cloud = folder.join("line.xyz");
    let line: String = (0..2000)
        .map(|i| format!("{} -220 20\n", 550.0 + 0.1 * i as f64))
        .collect();
    std::fs::write(&cloud, line).unwrap();
    let output = ips(&[
        "align-cloud",
        "--cloud",
        cloud.to_str().unwrap(),
        "--cloud-scale",
        "0.001",
        "--mesh",
        example("step_block.stl").to_str().unwrap(),
        "--mesh-scale",
        "0.001",
        "--pose",
        "0.65,-0.22,0.02,0,0,0.25",
        "--delta",
        "0.1",
    ]);
    assert_refused(&output, "lie on a line");
    assert!(String::from_utf8_lossy(&output.stderr).contains("unconstrained"));
}

#[test]
fn a_mesh_scale_of_1000_instead_of_0_001_is_refused_with_the_unit_hint() {
    let output = ips(&[
        "align-cloud",
        "--cloud",
        example("scan.xyz").to_str().unwrap(),
        "--cloud-scale",
        "0.001",
        "--mesh",
        example("step_block.stl").to_str().unwrap(),
        "--mesh-scale",
        "1000",
        "--pose",
        "0.65,-0.22,0.02,0,0,0.25",
        "--delta",
        "0.1",
    ]);
    assert_refused(&output, "km across");
    assert!(String::from_utf8_lossy(&output.stderr).contains("its scale is 0.001, not 1000"));

    let folder = scratch("km-session");
    let session = session_with_mesh(&folder, &example("step_block.stl"), 1000.0);
    let output = ips(&["align", session.to_str().unwrap()]);
    assert_refused(&output, "its scale is 0.001, not 1000");
}

#[test]
fn a_tcp_offset_in_mm_given_as_m_is_refused_with_the_unit_hint() {
    let folder = scratch("tcp-in-mm");
    let session = session_with_mesh(&folder, &example("step_block.stl"), 0.001);
    let mut file: Value =
        serde_json::from_str(&std::fs::read_to_string(&session).unwrap()).unwrap();
    file["tool"]["tcp"]["xyz"] = json!([0.0, 0.0, 150.0]);
    std::fs::write(&session, file.to_string()).unwrap();
    let output = ips(&["align", session.to_str().unwrap()]);
    assert_refused(&output, "150.00 m from the flange");
}
