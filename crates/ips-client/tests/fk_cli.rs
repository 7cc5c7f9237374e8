//! `ips fk` from the command line: the spawned binary, its text and JSON output, and one-line
//! reasons with exit code 2 for bad input.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::process::{Command, Output};

use align_core::robots::ShippedRobot;

fn robot_path(file: &str) -> String {
    format!("{}/../../robots/{file}", env!("CARGO_MANIFEST_DIR"))
}

fn ips(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(args)
        .output()
        .expect("spawn ips")
}

fn stderr_line(output: &Output) -> String {
    let text = String::from_utf8_lossy(&output.stderr).into_owned();
    assert_eq!(
        text.lines().count(),
        1,
        "expected one line on stderr, got {text:?}"
    );
    text.trim_end().to_owned()
}

fn ur10_args<'a>(urdf: &'a str, q: &'a str) -> Vec<&'a str> {
    vec![
        "fk",
        "--urdf",
        urdf,
        "--base",
        "base_link",
        "--tip",
        "tool0",
        "--q",
        q,
    ]
}

#[test]
fn text_output_shows_the_matrix_and_the_stretched_arm_position() {
    let urdf = robot_path("ur10.urdf");
    let output = ips(&ur10_args(&urdf, "0,0,0,0,0,0"));
    assert!(output.status.success());
    let text = String::from_utf8(output.stdout).unwrap();
    assert!(
        text.starts_with("base_from_tip (base_link <- tool0):"),
        "{text}"
    );
    assert_eq!(
        text.lines()
            .filter(|line| line.trim_start().starts_with('['))
            .count(),
        4
    );
    // UR10 DH at q = 0: x = a2 + a3, y = -(d4 + d6), z = d1 - d5.
    assert!(
        text.contains("xyz [m]:   -1.184300000 -0.256141000 0.011600000"),
        "{text}"
    );
}

#[test]
fn json_output_is_one_document_matching_the_library() {
    let urdf = robot_path("ur10.urdf");
    let q = [0.3, -1.2, 1.4, -0.5, 1.1, 2.0];
    let q_text = q.map(|v| v.to_string()).join(",");
    let mut args = ur10_args(&urdf, &q_text);
    args.push("--json");
    let output = ips(&args);
    assert!(output.status.success());
    let stdout = String::from_utf8(output.stdout).unwrap();
    assert_eq!(stdout.lines().count(), 1);
    let document: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let rows = document["base_from_tip"].as_array().expect("4 rows");
    assert_eq!(rows.len(), 4);
    let expected = ShippedRobot::Ur10
        .chain()
        .unwrap()
        .forward(&q)
        .unwrap()
        .to_homogeneous();
    for (r, row) in rows.iter().enumerate() {
        let row = row.as_array().expect("a row of 4");
        assert_eq!(row.len(), 4);
        for (c, value) in row.iter().enumerate() {
            assert_eq!(value.as_f64().unwrap(), expected[(r, c)], "({r}, {c})");
        }
    }
    assert_eq!(document["joints"].as_array().unwrap().len(), 6);
}

#[test]
fn negative_first_value_and_repeated_package_dirs_are_accepted() {
    let urdf = robot_path("ur10.urdf");
    let output = ips(&[
        "fk",
        "--urdf",
        &urdf,
        "--base",
        "base_link",
        "--tip",
        "tool0",
        "--q=-1,0,0,0,0,0",
        "--package-dir",
        "ur_description=/opt/ur",
        "--package-dir",
        "other=/tmp",
    ]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
}

#[test]
fn iiwa_stands_1306_mm_tall_at_zero() {
    let urdf = robot_path("iiwa14.urdf");
    let output = ips(&[
        "fk",
        "--urdf",
        &urdf,
        "--base",
        "iiwa_link_0",
        "--tip",
        "iiwa_link_ee",
        "--q",
        "0,0,0,0,0,0,0",
        "--json",
    ]);
    let document: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let xyz: Vec<f64> = document["xyz"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(
        (xyz[0]).abs() < 1e-12 && xyz[1].abs() < 1e-12 && (xyz[2] - 1.306).abs() < 1e-12,
        "{xyz:?}"
    );
}

#[test]
fn bad_input_exits_2_with_a_one_line_reason() {
    let urdf = robot_path("ur10.urdf");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "fk",
                "--urdf",
                &urdf,
                "--base",
                "base_link",
                "--tip",
                "tool",
                "--q",
                "0",
            ],
            "no link named 'tool'",
        ),
        (ur10_args(&urdf, "0,0"), "expected 6 joint values"),
        (
            ur10_args(&urdf, "0,x,0,0,0,0"),
            "--q: item 2 ('x') is not a finite number",
        ),
        (
            ur10_args(&urdf, "0,nan,0,0,0,0"),
            "--q: item 2 ('nan') is not a finite number",
        ),
        (
            ur10_args("/no/such/robot.urdf", "0"),
            "cannot read URDF '/no/such/robot.urdf'",
        ),
        (
            vec!["fk", "--urdf", &urdf],
            "the following required arguments were not provided",
        ),
        (
            vec![
                "fk",
                "--urdf",
                &urdf,
                "--base",
                "base_link",
                "--tip",
                "tool0",
                "--q",
                "0,0,0,0,0,0",
                "--package-dir",
                "ur_description",
            ],
            "is not of the form NAME=DIR",
        ),
        (vec!["frobnicate"], "unrecognized subcommand"),
    ];
    for (args, reason) in cases {
        let output = ips(&args);
        assert_eq!(output.status.code(), Some(2), "{args:?}");
        let line = stderr_line(&output);
        assert!(
            line.starts_with("ips: ") && line.contains(reason),
            "{args:?}: {line}"
        );
        assert!(output.stdout.is_empty());
    }
}

#[test]
fn help_succeeds() {
    let output = ips(&["fk", "--help"]);
    assert!(output.status.success());
    assert!(String::from_utf8_lossy(&output.stdout).contains("--package-dir <NAME=DIR>"));
}
