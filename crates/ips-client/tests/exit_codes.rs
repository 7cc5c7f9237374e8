//! Exit codes as the README documents them: 2 for input the user can fix (refused by `ips` or by
//! the service), 1 for a failure at run time (no reply in time).

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::process::{Command, Output};

fn ips(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(args)
        .output()
        .unwrap()
}

fn one_line_stderr(output: &Output) -> String {
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    stderr
}

#[test]
fn a_service_that_never_answers_is_a_run_time_failure_exit_1() {
    // A REP socket that receives and never replies: the request is delivered, no answer comes.
    let context = zmq::Context::new();
    let silent = context.socket(zmq::REP).unwrap();
    silent.set_linger(0).unwrap();
    silent.set_rcvtimeo(5_000).unwrap();
    silent.bind("tcp://127.0.0.1:*").unwrap();
    let endpoint = silent.get_last_endpoint().unwrap().unwrap();
    let output = ips(&["status", "--service", &endpoint, "--timeout", "0.3"]);
    assert_eq!(output.status.code(), Some(1), "{output:?}");
    let stderr = one_line_stderr(&output);
    assert!(stderr.contains("no reply from the service"), "{stderr}");
    // The request did arrive: the silence was the service's, not a lost message.
    assert!(silent.recv_bytes(0).unwrap().starts_with(b"{\"header\""));
}

#[test]
fn input_the_user_can_fix_is_exit_2() {
    let cases: [(&[&str], &str); 4] = [
        (
            &["status", "--service", "not-an-endpoint"],
            "not-an-endpoint",
        ),
        (
            &["status", "--timeout", "0"],
            "--timeout must be a positive number of seconds",
        ),
        (&["align", "/no/such/session.json"], "cannot read session"),
        (&["demo", "--effect", "gravity"], "invalid value 'gravity'"),
    ];
    for (args, reason) in cases {
        let output = ips(args);
        assert_eq!(output.status.code(), Some(2), "{args:?}: {output:?}");
        let stderr = one_line_stderr(&output);
        assert!(stderr.contains(reason), "{args:?}: {stderr}");
    }
}
