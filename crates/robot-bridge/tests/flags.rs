//! robot-bridge refuses bad flags (ports and the FRI silence limit that are not whole numbers
//! in range, malformed FRI inputs) with exit code 2 and a one-line reason, before it binds
//! anything.

#![allow(clippy::unwrap_used, clippy::panic)] // Tests: a panic is the failure report.

use std::time::Duration;

/// How long a refused invocation may take; one still running then was not refused.
const EXIT_TIMEOUT: Duration = Duration::from_secs(10);

fn run(binary: &str, args: &[&str]) -> (Option<i32>, String) {
    cell::run_to_exit(std::path::Path::new(binary), args, EXIT_TIMEOUT)
        .unwrap_or_else(|error| panic!("{args:?}: {error}: flags accepted"))
}

/// A bridge with `backend` on free ZeroMQ ports and `extra` flags added.
fn bridge_with(backend: &'static str, extra: &[&'static str]) -> Vec<&'static str> {
    let mut args = vec![
        "--backend",
        backend,
        "--robot-host",
        "127.0.0.1",
        "--rep",
        "tcp://127.0.0.1:*",
        "--pub",
        "tcp://127.0.0.1:*",
    ];
    args.extend_from_slice(extra);
    args
}

/// [`assert_refused`] on argument lists built per case.
fn assert_all_refused(owned_cases: &[(Vec<&str>, &str)]) {
    let cases: Vec<(&[&str], &str)> = owned_cases
        .iter()
        .map(|(args, reason)| (args.as_slice(), *reason))
        .collect();
    assert_refused(env!("CARGO_BIN_EXE_robot-bridge"), &cases);
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
    let ur = |value| bridge_with("ur", &["--rtde-port", value]);
    let iiwa = |value| bridge_with("iiwa", &["--fri-port", value]);
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
    assert_all_refused(&owned_cases);
}

#[test]
fn bad_fri_inputs_exit_2_with_a_reason() {
    // The FRI port free, so that only the input is wrong.
    let iiwa = |value| bridge_with("iiwa", &["--fri-port", "0", "--fri-input", value]);
    let owned_cases = [
        (iiwa("Probe.Trigger"), "is not NAME=INPUT"),
        (iiwa("Probe.Trigger=DI8"), "'DI8' is not a digital input"),
        (iiwa("=DI0"), "must be 1-63 ASCII characters"),
        (iiwa("Probe.Trigger=X"), "'X' is not a digital input"),
    ];
    assert_all_refused(&owned_cases);
}

#[test]
fn a_controller_silence_limit_out_of_range_exits_2_with_a_reason() {
    let iiwa = |value| bridge_with("iiwa", &["--fri-port", "0", "--fri-silence-ms", value]);
    let owned_cases = [
        (iiwa("0"), "'--fri-silence-ms <MS>': 0 is not in 1..=60000"),
        (iiwa("60001"), "60001 is not in 1..=60000"),
        (
            iiwa("nan"),
            "invalid value 'nan' for '--fri-silence-ms <MS>'",
        ),
        (iiwa("-5"), "invalid value '-5' for '--fri-silence-ms <MS>'"),
    ];
    assert_all_refused(&owned_cases);
}
