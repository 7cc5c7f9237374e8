//! `ips kinematics`: the calibration read from a (simulated) controller's primary interface is
//! the one a calibration file describes, written as UR's ROS drivers' kinematics file.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::process::{Command, Output};

use align_core::robots::ShippedRobot;

fn ips(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn the_controllers_calibration_and_its_file_give_the_same_kinematics_file() {
    let folder = std::env::temp_dir().join(format!("ips-kinematics-{}", std::process::id()));
    std::fs::create_dir_all(&folder).unwrap();
    let file = folder.join("calibration.json");
    // Set C of UR's ROS driver tests: d offsets of 439 and -446 m on the parallel joints cancel.
    let published = align_core::corpus::calibrations::ur_driver_calibration("C").unwrap();
    std::fs::write(&file, published.file_text()).unwrap();
    let delta = published.delta.clone();
    let sim = sim_robot::start(&sim_robot::Config {
        robot: ShippedRobot::Ur10e,
        rtde_listen: "127.0.0.1:0".to_owned(),
        primary_listen: Some("127.0.0.1:0".to_owned()),
        calibration: Some(delta),
        control: "tcp://127.0.0.1:*".to_owned(),
        fri: sim_robot::FriSettings::default(),
    })
    .unwrap();
    let port = sim
        .primary_address
        .as_deref()
        .unwrap()
        .rsplit(':')
        .next()
        .unwrap()
        .to_owned();
    let from_controller = ips(&[
        "kinematics",
        "--robot",
        "ur10e",
        "--robot-host",
        "127.0.0.1",
        "--primary-port",
        &port,
    ]);
    assert!(
        from_controller.status.success(),
        "{}",
        String::from_utf8_lossy(&from_controller.stderr)
    );
    let from_file = ips(&[
        "kinematics",
        "--robot",
        "ur10e",
        "--calibration",
        file.to_str().unwrap(),
    ]);
    assert!(from_file.status.success());
    assert_eq!(from_controller.stdout, from_file.stdout);
    let yaml = String::from_utf8(from_file.stdout).unwrap();
    // Every joint of UR's file, six values each, and the hash last.
    for joint in [
        "shoulder",
        "upper_arm",
        "forearm",
        "wrist_1",
        "wrist_2",
        "wrist_3",
    ] {
        assert!(yaml.contains(&format!("\n  {joint}:\n")), "{yaml}");
    }
    assert_eq!(yaml.matches("    roll: ").count(), 6);
    assert!(yaml.lines().last().unwrap().starts_with("  hash: calib_"));
    // The joints are written where they physically are (millimetres from the nominal UR10e),
    // not 439 m along the parallel axes as the DH table has them.
    let json: serde_json::Value = serde_json::from_slice(
        &ips(&[
            "kinematics",
            "--robot",
            "ur10e",
            "--calibration",
            file.to_str().unwrap(),
            "--json",
        ])
        .stdout,
    )
    .unwrap();
    for joint in json["joints"].as_array().unwrap() {
        let xyz: Vec<f64> = serde_json::from_value(joint["xyz"].clone()).unwrap();
        assert!(xyz.iter().all(|v| v.abs() < 0.7), "{joint}");
    }
    assert!(json["dh_d"][1].as_f64().unwrap() > 400.0);
    sim.stop();
    // Bad input: no source, an iiwa, a controller that is not there.
    let none = ips(&["kinematics", "--robot", "ur10e"]);
    assert_eq!(none.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&none.stderr).contains("--robot-host HOST"));
    let iiwa = ips(&[
        "kinematics",
        "--robot",
        "iiwa14",
        "--calibration",
        file.to_str().unwrap(),
    ]);
    assert_eq!(iiwa.status.code(), Some(2));
    let closed = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let closed_port = closed.local_addr().unwrap().port().to_string();
    drop(closed);
    let absent = ips(&[
        "kinematics",
        "--robot-host",
        "127.0.0.1",
        "--primary-port",
        &closed_port,
        "--timeout",
        "1",
    ]);
    assert_eq!(absent.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&absent.stderr).contains("cannot connect"));
    let _ = std::fs::remove_dir_all(&folder);
}
