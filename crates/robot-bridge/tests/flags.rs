//! robot-bridge refuses port flags that are not whole numbers in range with exit code 2 and a
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
    let ur = |value: &'static str| -> Vec<&'static str> {
        vec![
            "--backend",
            "ur",
            "--robot-host",
            "127.0.0.1",
            "--rep",
            "tcp://127.0.0.1:*",
            "--pub",
            "tcp://127.0.0.1:*",
            "--rtde-port",
            value,
        ]
    };
    let iiwa = |value: &'static str| -> Vec<&'static str> {
        vec![
            "--backend",
            "iiwa",
            "--robot-host",
            "127.0.0.1",
            "--rep",
            "tcp://127.0.0.1:*",
            "--pub",
            "tcp://127.0.0.1:*",
            "--fri-port",
            value,
        ]
    };
    let owned_cases = [
        (ur("0"), "port 0 names no controller"),
        (ur("65536"), "'65536' is not a port"),
        (ur("nan"), "'nan' is not a port"),
        (ur("-1"), "is not a port"),
        (ur("30004.5"), "'30004.5' is not a port"),
        (iiwa("70000"), "'70000' is not a port"),
        (iiwa("inf"), "'inf' is not a port"),
        (iiwa("-30200"), "is not a port"),
    ];
    let cases: Vec<(&[&str], &str)> = owned_cases
        .iter()
        .map(|(args, reason)| (args.as_slice(), *reason))
        .collect();
    assert_refused(env!("CARGO_BIN_EXE_robot-bridge"), &cases);
}

#[test]
fn bad_fri_inputs_exit_2_with_a_reason() {
    let iiwa = |value: &'static str| -> Vec<&'static str> {
        vec![
            "--backend",
            "iiwa",
            "--robot-host",
            "127.0.0.1",
            "--rep",
            "tcp://127.0.0.1:*",
            "--pub",
            "tcp://127.0.0.1:*",
            "--fri-port",
            "0",
            "--fri-input",
            value,
        ]
    };
    let owned_cases = [
        (iiwa("Probe.Trigger"), "is not NAME=INPUT"),
        (iiwa("Probe.Trigger=DI8"), "'DI8' is not a digital input"),
        (iiwa("=DI0"), "must be 1-63 ASCII characters"),
        (iiwa("Probe.Trigger=X"), "'X' is not a digital input"),
    ];
    let cases: Vec<(&[&str], &str)> = owned_cases
        .iter()
        .map(|(args, reason)| (args.as_slice(), *reason))
        .collect();
    assert_refused(env!("CARGO_BIN_EXE_robot-bridge"), &cases);
}

#[test]
fn a_controller_silence_limit_out_of_range_exits_2_with_a_reason() {
    let iiwa = |value: &'static str| -> Vec<&'static str> {
        vec![
            "--backend",
            "iiwa",
            "--robot-host",
            "127.0.0.1",
            "--fri-port",
            "0",
            "--rep",
            "tcp://127.0.0.1:*",
            "--pub",
            "tcp://127.0.0.1:*",
            "--fri-silence-ms",
            value,
        ]
    };
    let owned_cases = [
        (iiwa("0"), "--fri-silence-ms"),
        (iiwa("60001"), "60001"),
        (iiwa("nan"), "nan"),
        (iiwa("-5"), "--fri-silence-ms"),
    ];
    let cases: Vec<(&[&str], &str)> = owned_cases
        .iter()
        .map(|(args, reason)| (args.as_slice(), *reason))
        .collect();
    assert_refused(env!("CARGO_BIN_EXE_robot-bridge"), &cases);
}
