//! sim-robot refuses numeric flags that are not whole numbers in range with exit code 2 and a
//! one-line reason, before it binds anything.

#![allow(clippy::unwrap_used, clippy::panic)] // Tests: a panic is the failure report.

use std::time::Duration;

/// How long a refused invocation may take; one still running then was not refused.
const EXIT_TIMEOUT: Duration = Duration::from_secs(10);

fn run(binary: &str, args: &[&str]) -> (Option<i32>, String) {
    cell::run_to_exit(std::path::Path::new(binary), args, EXIT_TIMEOUT)
        .unwrap_or_else(|error| panic!("{args:?}: {error}: flags accepted"))
}

/// Each invocation exits 2 with one line on stderr that contains its reason.
fn assert_refused(binary: &str, cases: &[(&[&str], &str)]) {
    for (args, reason) in cases {
        let (code, stderr) = run(binary, args);
        assert_eq!(code, Some(2), "{args:?}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "{args:?}: {stderr}");
        assert!(stderr.contains(reason), "{args:?}: {stderr}");
    }
}

#[test]
fn bad_numeric_flags_exit_2_with_a_reason() {
    // Were a case accepted, these keep it off fixed ports.
    let safe = [
        "--rtde-port",
        "0",
        "--primary-port",
        "0",
        "--control",
        "tcp://127.0.0.1:*",
    ];
    let with = |flag: &'static str, value: &'static str| -> Vec<&'static str> {
        let mut args = safe.to_vec();
        args.extend([flag, value]);
        args
    };
    let period = "--fri-send-period-ms";
    let multiplier = "--fri-receive-multiplier";
    let owned_cases = [
        (with(period, "0"), "outside the controller's 1-100 ms"),
        (with(period, "101"), "outside the controller's 1-100 ms"),
        (with(period, "nan"), "'nan' is not a whole number"),
        (with(period, "inf"), "'inf' is not a whole number"),
        (with(period, "-5"), "is not a whole number"),
        (with(period, "2.5"), "'2.5' is not a whole number"),
        (
            with(multiplier, "0"),
            "receive multiplier 0 is outside 1-100",
        ),
        (
            with(multiplier, "1000"),
            "receive multiplier 1000 is outside 1-100",
        ),
        (with(multiplier, "NaN"), "'NaN' is not a whole number"),
        (
            vec!["--rtde-port", "65536", "--control", "tcp://127.0.0.1:*"],
            "'65536' is not a port",
        ),
        (
            vec!["--rtde-port", "nan", "--control", "tcp://127.0.0.1:*"],
            "'nan' is not a port",
        ),
        (
            vec!["--rtde-port", "-1", "--control", "tcp://127.0.0.1:*"],
            "is not a port",
        ),
    ];
    let cases: Vec<(&[&str], &str)> = owned_cases
        .iter()
        .map(|(args, reason)| (args.as_slice(), *reason))
        .collect();
    assert_refused(env!("CARGO_BIN_EXE_sim-robot"), &cases);
}

#[test]
fn bad_calibration_files_exit_2_with_the_reason() {
    let folder = std::env::temp_dir().join(format!("sim-robot-calibration-{}", std::process::id()));
    std::fs::create_dir_all(&folder).unwrap();
    let write = |name: &str, text: &str| -> String {
        let path = folder.join(name);
        std::fs::write(&path, text).unwrap();
        path.display().to_string()
    };
    let row = "[0,0,0,0,0,0]";
    let five = write(
        "five.json",
        &format!(
            r#"{{"dh_delta": {{"theta": {row}, "a": [0,0,0,0,0], "d": {row}, "alpha": {row}}}}}"#
        ),
    );
    let missing = write(
        "missing.json",
        &format!(r#"{{"dh_delta": {{"theta": {row}, "a": {row}, "d": {row}}}}}"#),
    );
    let not_a_number = write(
        "nan.json",
        &format!(
            r#"{{"dh_delta": {{"theta": ["NaN",0,0,0,0,0], "a": {row}, "d": {row}, "alpha": {row}}}}}"#
        ),
    );
    let absent = folder.join("absent.json").display().to_string();
    let safe = [
        "--rtde-port",
        "0",
        "--primary-port",
        "0",
        "--control",
        "tcp://127.0.0.1:*",
    ];
    let with = |file: &str| -> Vec<String> {
        let mut args: Vec<String> = safe.iter().map(|s| (*s).to_owned()).collect();
        args.extend(["--calibration".to_owned(), file.to_owned()]);
        args
    };
    let owned = [
        (with(&five), "dh_delta.a has 5 values"),
        (with(&missing), "missing field `alpha`"),
        (with(&not_a_number), "not a calibration file"),
        (with(&absent), "cannot read calibration"),
    ];
    let borrowed: Vec<Vec<&str>> = owned
        .iter()
        .map(|(args, _)| args.iter().map(String::as_str).collect())
        .collect();
    let cases: Vec<(&[&str], &str)> = borrowed
        .iter()
        .zip(&owned)
        .map(|(args, (_, reason))| (args.as_slice(), *reason))
        .collect();
    assert_refused(env!("CARGO_BIN_EXE_sim-robot"), &cases);
    // An iiwa has no DH table to calibrate.
    let iiwa: Vec<String> = [
        "--robot",
        "iiwa14",
        "--control",
        "tcp://127.0.0.1:*",
        "--calibration",
    ]
    .iter()
    .map(|s| (*s).to_owned())
    .chain([write(
        "zero.json",
        &format!(r#"{{"dh_delta": {{"theta": {row}, "a": {row}, "d": {row}, "alpha": {row}}}}}"#),
    )])
    .collect();
    let iiwa: Vec<&str> = iiwa.iter().map(String::as_str).collect();
    assert_refused(
        env!("CARGO_BIN_EXE_sim-robot"),
        &[(iiwa.as_slice(), "has no DH table to calibrate")],
    );
    let _ = std::fs::remove_dir_all(&folder);
}
