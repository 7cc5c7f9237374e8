//! `ips align SESSION` reports the pose uncertainty: new JSON keys next to the unchanged DESIGN.md
//! 6.4 keys, a text line after the rms, and the reason when it cannot be computed.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

use common::Scratch;

fn example(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/step_block_ur10")
        .join(file)
}

fn ips(args: &[&str]) -> Output {
    let output = Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

fn align_json(session: &Path) -> Value {
    let output = ips(&["align", session.to_str().unwrap(), "--json"]);
    serde_json::from_slice(&output.stdout).unwrap()
}

fn align_text(session: &Path) -> String {
    let output = ips(&["align", session.to_str().unwrap()]);
    String::from_utf8(output.stdout).unwrap()
}

/// A copy of the example session, edited, in its own folder with absolute paths.
fn scratch_session(name: &str, edit: impl FnOnce(&mut Value)) -> Scratch {
    let mut session: Value =
        serde_json::from_str(&std::fs::read_to_string(example("session.json")).unwrap()).unwrap();
    let robot = example("../../robots/ur10.urdf").canonicalize().unwrap();
    let mesh = example("step_block.stl").canonicalize().unwrap();
    session["robot"]["urdf"] = Value::from(robot.to_str().unwrap());
    session["part"]["mesh"] = Value::from(mesh.to_str().unwrap());
    edit(&mut session);
    let folder = std::env::temp_dir().join(format!(
        "cobot-align-uncertainty-{}-{name}",
        std::process::id()
    ));
    let scratch = Scratch::in_folder(folder, "session.json");
    std::fs::write(&scratch, serde_json::to_string_pretty(&session).unwrap()).unwrap();
    scratch
}

fn number(value: &Value) -> f64 {
    let number = value
        .as_f64()
        .unwrap_or_else(|| panic!("not a number: {value}"));
    assert!(number.is_finite(), "{value}");
    number
}

fn positive(value: &Value) -> f64 {
    let number = number(value);
    assert!(number > 0.0, "{value}");
    number
}

fn unit_vector(value: &Value) {
    let norm: f64 = (0..3)
        .map(|i| number(&value[i]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!((norm - 1.0).abs() < 1e-9, "{value}");
}

fn check_ellipsoid(region: &Value, names: [&str; 3]) {
    let semi: Vec<f64> = (0..3).map(|i| positive(&region["semi_axes"][i])).collect();
    assert!(semi[0] >= semi[1] && semi[1] >= semi[2], "{region}");
    for i in 0..3 {
        unit_vector(&region["axes"][i]);
    }
    for name in names {
        // A 1-dof half-width never exceeds the largest 3-dof semi-axis.
        assert!(positive(&region[name]) <= semi[0], "{region}");
    }
}

#[test]
fn example_session_reports_the_pose_uncertainty() {
    let session = example("session.json");
    let result = align_json(&session);

    // The DESIGN.md 6.4 keys and the earlier additions are all there, unchanged in kind.
    let keys: Vec<&str> = result
        .as_object()
        .unwrap()
        .keys()
        .map(String::as_str)
        .collect();
    for key in [
        "pose",
        "iterations",
        "converged",
        "rms",
        "max",
        "time_s",
        "residuals",
        "ambiguous",
        "candidates",
        "starts",
        "notes",
        "uncertainty",
        "base_frame",
    ] {
        assert!(keys.contains(&key), "{key} missing from {keys:?}");
    }
    assert_eq!(keys.len(), 13, "{keys:?}");
    assert_eq!(result["base_frame"], "base_link");
    assert!(result["residuals"][0]["ball_centre"].is_array());
    assert!(result.get("uncertainty_error").is_none());
    assert_eq!(result["converged"], true);
    assert_eq!(result["residuals"].as_array().unwrap().len(), 9);
    assert_eq!(result["residuals"][0]["id"], "1");
    assert!(result["residuals"][0]["distance"].is_f64());
    assert_eq!(result["pose"]["matrix"].as_array().unwrap().len(), 4);
    assert!((number(&result["pose"]["xyz"][0]) - 0.62).abs() < 1e-6);

    let uncertainty = &result["uncertainty"];
    assert_eq!(number(&uncertainty["sigma_m"]), 5e-5);
    assert_eq!(uncertainty["sigma_source"], "declared");
    assert_eq!(
        uncertainty["covariance_order"],
        serde_json::json!(["rx", "ry", "rz", "x", "y", "z"])
    );
    let covariance = uncertainty["covariance"].as_array().unwrap();
    assert_eq!(covariance.len(), 6);
    for (i, row) in covariance.iter().enumerate() {
        assert_eq!(row.as_array().unwrap().len(), 6);
        positive(&row[i]);
        for (j, other) in covariance.iter().enumerate() {
            let (a, b) = (number(&row[j]), number(&other[i]));
            assert!((a - b).abs() <= 1e-12 * a.abs().max(b.abs()), "{i} {j}");
            // A correlation is within [-1, 1].
            let bound = (number(&row[i]) * number(&other[j])).sqrt();
            assert!(a.abs() <= bound * (1.0 + 1e-9));
        }
    }
    check_ellipsoid(&uncertainty["position_95_mm"], ["x", "y", "z"]);
    check_ellipsoid(&uncertainty["rotation_95_mrad"], ["rx", "ry", "rz"]);
    // The half-widths are 1.96 sd of the covariance's diagonal.
    let x_mm = number(&uncertainty["position_95_mm"]["x"]);
    let sd_x_mm = number(&covariance[3][3]).sqrt() * 1e3;
    assert!((x_mm - 1.959_964 * sd_x_mm).abs() < 1e-6 * x_mm);
    let rz_mrad = number(&uncertainty["rotation_95_mrad"]["rz"]);
    let sd_rz_mrad = number(&covariance[2][2]).sqrt() * 1e3;
    assert!((rz_mrad - 1.959_964 * sd_rz_mrad).abs() < 1e-6 * rz_mrad);
    // 9 touches with 0.05 mm noise on a 200 mm part: tenths of a millimetre, about a milliradian.
    assert!(x_mm > 0.01 && x_mm < 1.0, "{x_mm}");
    assert!(rz_mrad > 0.05 && rz_mrad < 10.0, "{rz_mrad}");

    let weak = &uncertainty["weak_direction"];
    let kind = weak["kind"].as_str().unwrap();
    assert!(
        ["translation", "rotation", "screw"].contains(&kind),
        "{weak}"
    );
    unit_vector(&weak["axis"]);
    positive(&weak["size_95"]);
    assert_eq!(
        weak["unit"],
        if kind == "translation" { "mm" } else { "mrad" }
    );
    if kind == "translation" {
        assert!(weak["point"].is_null());
    } else {
        (0..3).for_each(|i| {
            number(&weak["point"][i]);
        });
    }
    let sentence = weak["text"].as_str().unwrap();
    assert!(
        sentence.starts_with(&format!("weakest: {kind} ")),
        "{sentence}"
    );

    let text = align_text(&session);
    let lines: Vec<&str> = text.lines().collect();
    assert!(
        lines[1].starts_with("  = xyz [mm] 620.000 -250.000 20.000, rpy [deg]"),
        "{text}"
    );
    assert!(lines[2].contains("residual rms"), "{text}");
    assert!(
        lines[3].starts_with("95% confidence (noise sigma 0.0500 mm, declared): position +-"),
        "{text}"
    );
    assert!(lines[3].contains("mm (x/y/z), rotation +-"), "{text}");
    assert!(lines[4].trim_start().starts_with("weakest: "), "{text}");
}

#[test]
fn without_a_declared_noise_the_sigma_is_estimated_or_the_reason_given() {
    let estimated = scratch_session("estimated", |session| {
        session.as_object_mut().unwrap().remove("noise_sigma");
    });
    let result = align_json(&estimated);
    let uncertainty = &result["uncertainty"];
    assert_eq!(uncertainty["sigma_source"], "estimated");
    // Noiseless touches: an estimate of (almost) nothing, equal to the residuals' own.
    let sigma = number(&uncertainty["sigma_m"]);
    assert!((0.0..1e-6).contains(&sigma), "{sigma}");
    assert_eq!(number(&uncertainty["residual_sigma_m"]), sigma);
    assert!(align_text(&estimated).contains(", estimated): position +-"));

    // Six touches leave no degree of freedom for an estimate: the alignment still succeeds and
    // says why there is no uncertainty.
    let six = scratch_session("six", |session| {
        session.as_object_mut().unwrap().remove("noise_sigma");
        session["inspections"].as_array_mut().unwrap().truncate(6);
    });
    let result = align_json(&six);
    assert!(result.get("uncertainty").is_none(), "{result}");
    let why = result["uncertainty_error"].as_str().unwrap();
    assert!(why.contains("cannot be estimated"), "{why}");
    assert!(result["pose"]["xyz"].is_array());
    let text = align_text(&six);
    assert!(
        text.contains("pose uncertainty not available: no noise_sigma declared"),
        "{text}"
    );
}
