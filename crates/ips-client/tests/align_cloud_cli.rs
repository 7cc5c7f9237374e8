//! `ips align-cloud` on the shipped example scan (spawned binary), and bad input.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn example(file: &str) -> String {
    let path: PathBuf = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/step_block_ur10")
        .join(file);
    path.to_str().unwrap().to_owned()
}

fn ips(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn cluttered_example_scan_aligns_within_a_millimetre_of_the_truth() {
    let (cloud, mesh) = (example("scan.xyz"), example("step_block.stl"));
    let output = ips(&[
        "align-cloud",
        "--cloud",
        &cloud,
        "--cloud-scale",
        "0.001",
        "--mesh",
        &mesh,
        "--mesh-scale",
        "0.001",
        "--pose",
        "0.65,-0.22,0.02,0,0,0.25",
        "--delta",
        "0.1",
        "--json",
    ]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let result: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(example("truth.json")).unwrap()).unwrap();
    let xyz =
        |v: &serde_json::Value| -> Vec<f64> { (0..3).map(|i| v[i].as_f64().unwrap()).collect() };
    let (got, want) = (
        xyz(&result["pose"]["xyz"]),
        xyz(&truth["base_from_part"]["xyz"]),
    );
    let translation = got
        .iter()
        .zip(&want)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        .sqrt();
    let yaw_error = (result["pose"]["rpy"][2].as_f64().unwrap()
        - truth["base_from_part"]["rpy"][2].as_f64().unwrap())
    .abs();
    // Scan noise 0.3 mm, floor, a neighbour and 10% outliers: well under the 1 mm success bar.
    assert!(translation < 2e-4, "{translation}");
    assert!(yaw_error * 0.2 < 2e-4, "{yaw_error}");
    assert!(result["kept_points"].as_u64().unwrap() > 1000);
    for key in [
        "pose",
        "iterations",
        "converged",
        "rms",
        "max",
        "time_s",
        "residuals",
    ] {
        assert!(result.get(key).is_some(), "missing {key}");
    }
}

#[test]
fn bad_input_exits_2_with_the_reason() {
    let (cloud, mesh) = (example("scan.xyz"), example("step_block.stl"));
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "align-cloud",
                "--cloud",
                &cloud,
                "--mesh",
                &mesh,
                "--pose",
                "0,0,0",
                "--delta",
                "0.1",
            ],
            "--pose needs 6 values",
        ),
        (
            vec![
                "align-cloud",
                "--cloud",
                &cloud,
                "--mesh",
                &mesh,
                "--pose",
                "0,0,0,0,0,0",
                "--delta=-1",
            ],
            "--delta must be a positive distance",
        ),
        (
            vec![
                "align-cloud",
                "--cloud",
                "/no/scan.ply",
                "--mesh",
                &mesh,
                "--pose",
                "0,0,0,0,0,0",
                "--delta",
                "0.1",
            ],
            "'/no/scan.ply': No such file",
        ),
        (
            vec![
                "align-cloud",
                "--cloud",
                &cloud,
                "--cloud-scale",
                "0.001",
                "--mesh",
                &mesh,
                "--mesh-scale",
                "0.001",
                "--pose",
                "5,5,5,0,0,0",
                "--delta",
                "0.1",
            ],
            "cannot align: only 0 cloud points lie within delta",
        ),
    ];
    for (args, reason) in cases {
        let output = ips(&args);
        assert_eq!(output.status.code(), Some(2), "{args:?}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(stderr.contains(reason), "{args:?}: {stderr}");
    }
}
