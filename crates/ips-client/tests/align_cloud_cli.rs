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

/// `ips align-cloud` on the example scan (mm) from 50 mm off, with `extra` flags.
fn align_the_example(extra: &[&str]) -> Output {
    let (cloud, mesh) = (example("scan.xyz"), example("step_block.stl"));
    let mut args = vec![
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
    ];
    args.extend_from_slice(extra);
    ips(&args)
}

#[test]
fn cluttered_example_scan_aligns_within_a_millimetre_of_the_truth() {
    let output = align_the_example(&["--json"]);
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
    // The uncertainty: the scan's noise (0.3 mm) measured on the matches and widened by the
    // calibration (1.4), and a 95 % bound on the pose distance that holds the error found.
    let uncertainty = &result["uncertainty"];
    assert_eq!(uncertainty["sigma_source"], "scan", "{uncertainty}");
    let sigma_mm = uncertainty["sigma_m"].as_f64().unwrap() * 1e3;
    assert!((0.35..0.55).contains(&sigma_mm), "{sigma_mm}");
    let within_mm = uncertainty["pose_distance_95_mm"].as_f64().unwrap();
    assert!(
        translation * 1e3 < within_mm && within_mm < 1.0,
        "{within_mm}"
    );
    assert!(result.get("uncertainty_error").is_none());
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
fn the_text_report_gives_the_noise_the_95_percent_limits_and_the_weakest_direction() {
    let output = align_the_example(&[]);
    assert!(output.status.success());
    let text = String::from_utf8_lossy(&output.stdout);
    for expected in [
        "95% confidence (noise sigma ",
        " mm, scan): position +-",
        "weakest: ",
        "of the truth at 95% confidence (the thesis's pose distance)",
    ] {
        assert!(text.contains(expected), "no '{expected}' in\n{text}");
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
