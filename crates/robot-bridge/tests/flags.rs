//! robot-bridge refuses port flags that are not whole numbers in range with exit code 2 and a
//! one-line reason, before it binds anything.

#![allow(clippy::unwrap_used, clippy::panic)] // Tests: a panic is the failure report.

use std::io::Read;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::thread;
use std::time::Duration;

/// How long a refused invocation may take; one still running then was not refused.
const EXIT_TIMEOUT: Duration = Duration::from_secs(10);

/// Runs the binary with `args` and returns its exit code and stderr, killing it if it is still
/// running after [`EXIT_TIMEOUT`] (it then accepted the flags and went on to serve).
fn run(binary: &str, args: &[&str]) -> (Option<i32>, String) {
    let mut child = Command::new(binary)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr_pipe = child.stderr.take().unwrap();
    let (sender, receiver) = mpsc::channel();
    // The pipe reaches its end when the process exits.
    thread::spawn(move || {
        let mut stderr = String::new();
        let _ = stderr_pipe.read_to_string(&mut stderr);
        let _ = sender.send(stderr);
    });
    match receiver.recv_timeout(EXIT_TIMEOUT) {
        Ok(stderr) => (child.wait().unwrap().code(), stderr),
        Err(_) => {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{binary} {args:?} still running after {EXIT_TIMEOUT:?}: flags accepted");
        }
    }
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
