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
    let safe = ["--rtde-port", "0", "--control", "tcp://127.0.0.1:*"];
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
