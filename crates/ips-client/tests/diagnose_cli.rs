//! `ips diagnose` on the shipped sessions: the noiseless one has nothing to explain; the one
//! touched with a 3.4 mm ball while declaring 3 mm is traced to the probe radius.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

mod common;

use std::path::Path;
use std::process::Command;

use common::Scratch;

/// A copy of an example session in a scratch folder (the plot is written next to it).
fn scratch_session(name: &str) -> Scratch {
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/step_block_ur10");
    let mut session: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(example.join(name)).unwrap()).unwrap();
    session["robot"]["urdf"] =
        serde_json::json!(example.join("../../robots/ur10.urdf").to_str().unwrap());
    session["part"]["mesh"] = serde_json::json!(example.join("step_block.stl").to_str().unwrap());
    // One folder per call: tests run in parallel and each removes its own when it ends.
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let folder = std::env::temp_dir().join(format!(
        "cobot-align-diagnose-{}-{call}-{name}",
        std::process::id()
    ));
    let scratch = Scratch::in_folder(folder, name);
    std::fs::write(&scratch, session.to_string()).unwrap();
    scratch
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
}

fn ips(args: &[&std::ffi::OsStr]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(args)
        .output()
        .unwrap()
}

/// `ips diagnose SESSION --apply OUT --json`, which must succeed.
fn apply(session: &Path, out: &Path) -> serde_json::Value {
    let output = ips(&[
        "diagnose".as_ref(),
        session.as_os_str(),
        "--apply".as_ref(),
        out.as_os_str(),
        "--json".as_ref(),
    ]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).unwrap()
}

fn scratch_folder(name: &str) -> Scratch {
    let folder =
        std::env::temp_dir().join(format!("cobot-align-apply-{}-{name}", std::process::id()));
    Scratch::folder(folder)
}

/// The shipped session touched with a 3.4 mm ball declared as 3 mm, applied from where it lies
/// (paths relative to examples/) to a file elsewhere: the radius is corrected, the paths still
/// resolve, and the corrected session aligns to the diagnosis's pose after modelling with nothing
/// left to explain.
#[test]
fn apply_writes_the_fitted_radius_into_a_session_that_aligns_to_the_pose_after() {
    let session = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/step_block_ur10/session_probe_radius.json");
    let folder = scratch_folder("radius");
    let out = folder.join("corrected.json");
    let applied = apply(&session, &out);
    assert_eq!(applied["effect"], "probe_radius");
    let change = &applied["changes"][0];
    assert_eq!(change["key"], "tool.tip_radius");
    assert_eq!(change["before"], 0.003);
    assert!((change["after"].as_f64().unwrap() - 0.0034).abs() < 5e-5);
    assert!(change["text"].as_str().unwrap().contains(" mm (+0.4"));
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert!(Path::new(written["part"]["mesh"].as_str().unwrap()).is_absolute());
    let before = diagnose(&session);
    let after = diagnose(&out);
    assert_eq!(after["verdict"], "no_effect", "{after}");
    for axis in 0..3 {
        let moved = after["pose_before"]["xyz"][axis].as_f64().unwrap()
            - before["pose_after"]["xyz"][axis].as_f64().unwrap();
        assert!(moved.abs() < 1e-5, "axis {axis}: {moved} m");
    }
}

/// A session that declares a wrong joint zero (joint 3 off by 1.5 mrad): the diagnosis finds the
/// offset that cancels it and --apply writes it into robot.joint_offsets, after which nothing is
/// left. The same for a wrong compliance of joint 2.
#[test]
fn apply_corrects_declared_joint_offsets_and_compliance() {
    let cases = [
        ("joint_offsets", "robot.joint_offsets[2]", 0.0015, 1e-5),
        ("joint_compliance", "robot.joint_compliance[1]", -2e-5, 1e-6),
    ];
    for (key, changed, wrong, tolerance) in cases {
        let folder = scratch_folder(key);
        let mut session: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(scratch_session("session_probe_radius.json")).unwrap(),
        )
        .unwrap();
        session["tool"]["tip_radius"] = serde_json::json!(0.0034);
        let mut values = vec![0.0; 6];
        values[if key == "joint_offsets" { 2 } else { 1 }] = wrong;
        session["robot"][key] = serde_json::json!(values);
        let path = folder.join("wrong.json");
        std::fs::write(&path, session.to_string()).unwrap();
        let applied = apply(&path, &folder.join("fixed.json"));
        assert_eq!(applied["effect"], key, "{applied}");
        let change = applied["changes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["key"] == changed)
            .unwrap_or_else(|| panic!("{applied}"));
        assert!(
            change["after"].as_f64().unwrap().abs() < tolerance,
            "{change}"
        );
        assert_eq!(diagnose(&folder.join("fixed.json"))["verdict"], "no_effect");
    }
}

#[test]
fn apply_refuses_a_session_with_nothing_to_apply_and_bad_corrections() {
    let folder = scratch_folder("refused");
    let refused = |edit: &dyn Fn(&mut serde_json::Value), reason: &str| {
        let mut session: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(scratch_session("session.json")).unwrap(),
        )
        .unwrap();
        edit(&mut session);
        let path = folder.join("session.json");
        std::fs::write(&path, session.to_string()).unwrap();
        let out = folder.join("out.json");
        let output = ips(&[
            "diagnose".as_ref(),
            path.as_os_str(),
            "--apply".as_ref(),
            out.as_os_str(),
        ]);
        assert_eq!(output.status.code(), Some(2));
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains(reason), "{stderr}");
        assert!(!out.exists());
    };
    refused(&|_| {}, "nothing applied: the verdict is no_effect");
    refused(
        &|s| s["robot"]["joint_offsets"] = serde_json::json!([0.0, 0.1, 0.0, 0.0, 0.0]),
        "robot.joint_offsets has 5 values, the robot 6 joints",
    );
    refused(
        &|s| s["robot"]["trigger_latency_s"] = serde_json::json!(20.0),
        "robot.trigger_latency_s = 20 must be finite and within +-1 s (is it in ms?)",
    );
    refused(
        &|s| s["robot"]["joint_compliance"] = serde_json::json!("stiff"),
        "invalid type: string \"stiff\"",
    );
}

/// The residual plot: titles that fit its width, bars of at least 2 px even for a zero
/// residual, and a caption that says nothing was applied when the verdict applies nothing (the
/// example's head-on touches alone cannot tell the ball radius from the TCP length).
#[test]
fn the_residual_plot_fits_its_titles_shows_every_bar_and_says_what_was_applied() {
    let heights = |svg: &str| -> Vec<f64> {
        svg.lines()
            .filter(|l| l.starts_with("<rect x=") && l.contains("<title>"))
            .map(|l| {
                let at = l.find("height=\"").unwrap() + 8;
                l[at..].split('"').next().unwrap().parse().unwrap()
            })
            .collect()
    };
    let path = scratch_session("session_probe_radius.json");
    let result = diagnose(&path);
    let plot = std::fs::read_to_string(result["plot"].as_str().unwrap()).unwrap();
    let width: f64 = plot
        .split("width=\"")
        .nth(1)
        .unwrap()
        .split('"')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    for title in plot
        .lines()
        .filter(|l| l.starts_with("<text x=\"10\" y=\""))
    {
        let text = title.split('>').nth(1).unwrap().split('<').next().unwrap();
        assert!(
            10.0 + 7.0 * text.chars().count() as f64 <= width,
            "'{text}' in {width} px"
        );
    }
    assert!(plot.contains("Verdict: effect; after = modelling probe_radius"));
    // The after bars of a fully explained residual are zero: still drawn.
    assert!(
        heights(&plot).iter().all(|h| *h >= 2.0),
        "{:?}",
        heights(&plot)
    );

    let mut session: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let head_on: Vec<serde_json::Value> = session["inspections"]
        .as_array()
        .unwrap()
        .iter()
        .step_by(3)
        .cloned()
        .collect();
    session["inspections"] = serde_json::Value::Array(head_on);
    let ambiguous_path = path.with_file_name("head_on.json");
    std::fs::write(&ambiguous_path, session.to_string()).unwrap();
    let result = diagnose(&ambiguous_path);
    assert_eq!(result["verdict"], "ambiguous", "{result}");
    let plot = std::fs::read_to_string(result["plot"].as_str().unwrap()).unwrap();
    assert!(plot.contains("nothing applied"), "{plot}");
    assert!(!plot.contains("modelling"), "{plot}");
    assert!(plot.contains("No effect applied (verdict ambiguous)"));
}

/// `ips diagnose SESSION` also writes the diagnosis as a page: the verdict, the parameters in mm,
/// the plot inline and one row per candidate that lost and per touch.
#[test]
fn the_diagnosis_page_holds_the_verdict_the_plot_the_candidates_and_the_touches() {
    let path = scratch_session("session_probe_radius.json");
    let result = diagnose(&path);
    let page = std::fs::read_to_string(result["page"].as_str().unwrap()).unwrap();
    assert!(page.starts_with("<!doctype html>"));
    assert!(page.contains("<strong id=\"verdict\">effect</strong>"));
    assert!(
        page.contains("<td>delta_radius_m</td><td class=\"n\">+0.4"),
        "{page}"
    );
    assert!(page.contains("<figure><svg"));
    let rows = |table: &str| {
        let start = page.find(&format!("<table id=\"{table}\">")).unwrap();
        let end = start + page[start..].find("</table>").unwrap();
        page[start..end].matches("<tr><td>").count()
    };
    assert_eq!(
        rows("alternatives"),
        result["alternatives"].as_array().unwrap().len()
    );
    assert_eq!(rows("touches"), 27);
    // No script, and nothing fetched: the only address is the SVG namespace.
    assert!(!page.contains("<script"));
    assert_eq!(page.matches("http").count(), 1, "{page}");
}
