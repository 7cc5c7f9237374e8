//! `ips kinematics`: a UR robot's factory calibration, read from its controller's primary
//! interface (or made from a calibration file), written as the kinematics file UR's ROS drivers
//! load (`kinematics: {shoulder: {x, y, z, roll, pitch, yaw}, ..., hash: calib_<n>}`).

use std::path::PathBuf;
use std::time::Duration;

use align_core::kinematics::{DhTable, UR_KINEMATICS_JOINTS};
use align_core::robots::ShippedRobot;
use clap::Args;
use serde::Serialize;

use crate::{BadInput, CliError, json_line};

#[derive(Debug, Args)]
pub struct KinematicsArgs {
    /// The robot model, for its nominal table (the file writes each joint where the nominal
    /// robot has it): ur10 or ur10e.
    #[arg(long, default_value = "ur10e")]
    pub robot: String,
    /// Read the calibration from the controller at HOST (its primary interface; no remote
    /// control needed).
    #[arg(long, value_name = "HOST", conflicts_with = "calibration")]
    pub robot_host: Option<String>,
    /// The controller's primary interface port.
    #[arg(long, default_value_t = 30001)]
    pub primary_port: u16,
    /// Or a calibration file: {"dh_delta": {"theta": [6], "a": [6], "d": [6], "alpha": [6]}}.
    #[arg(long, value_name = "FILE")]
    pub calibration: Option<PathBuf>,
    /// How long to wait for the controller, s.
    #[arg(long, value_name = "SECONDS", default_value_t = 5.0)]
    pub timeout: f64,
    /// Print one JSON document (the table, the joint origins and the hash) instead of the YAML.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Serialize)]
pub struct JointOrigin {
    pub name: String,
    pub xyz: [f64; 3],
    pub rpy: [f64; 3],
}

#[derive(Debug, Serialize)]
pub struct KinematicsOutput {
    pub robot: String,
    pub hash: String,
    pub dh_theta: Vec<f64>,
    pub dh_a: Vec<f64>,
    pub dh_d: Vec<f64>,
    pub dh_alpha: Vec<f64>,
    pub joints: Vec<JointOrigin>,
}

pub fn run(args: &KinematicsArgs) -> Result<String, CliError> {
    let robot = ShippedRobot::from_name(&args.robot)
        .filter(|robot| robot.nominal_dh().is_some())
        .ok_or_else(|| BadInput(format!("--robot '{}': expected ur10 or ur10e", args.robot)))?;
    let nominal = robot
        .nominal_dh()
        .ok_or_else(|| BadInput("no nominal table".to_owned()))?;
    let info = match (&args.robot_host, &args.calibration) {
        (Some(host), None) => {
            if !(args.timeout.is_finite() && args.timeout > 0.0) {
                return Err(BadInput(format!(
                    "--timeout must be a positive number of seconds, got {}",
                    args.timeout
                ))
                .into());
            }
            let address = format!("{host}:{}", args.primary_port);
            ur_primary::read_kinematics(&address, Duration::from_secs_f64(args.timeout.min(3600.0)))
                .map_err(CliError::Failure)?
        }
        (None, Some(path)) => {
            let text = std::fs::read_to_string(path).map_err(|error| {
                BadInput(format!(
                    "cannot read calibration {}: {error}",
                    path.display()
                ))
            })?;
            let delta = protocol::calibration::CalibrationFile::parse(&text)
                .map_err(|reason| BadInput(format!("calibration {}: {reason}", path.display())))?
                .dh_delta;
            let delta = DhTable::new(delta.theta, delta.a, delta.d, delta.alpha)
                .map_err(|error| BadInput(error.to_string()))?;
            let table = nominal
                .plus(&delta)
                .map_err(|error| BadInput(error.to_string()))?;
            let row = |values: &[f64]| std::array::from_fn(|j| values[j]);
            ur_primary::KinematicsInfo::from_table(
                row(&table.theta),
                row(&table.a),
                row(&table.d),
                row(&table.alpha),
            )
        }
        _ => {
            return Err(BadInput(
                "give the controller (--robot-host HOST) or a calibration file (--calibration FILE)"
                    .to_owned(),
            )
            .into());
        }
    };
    let table = DhTable::new(
        info.dh_theta.to_vec(),
        info.dh_a.to_vec(),
        info.dh_d.to_vec(),
        info.dh_alpha.to_vec(),
    )
    .map_err(|error| BadInput(error.to_string()))?;
    let origins = table
        .joint_origins(&nominal)
        .map_err(|error| BadInput(error.to_string()))?;
    let output = KinematicsOutput {
        robot: robot.name().to_owned(),
        hash: info.calibration_hash(),
        dh_theta: table.theta.clone(),
        dh_a: table.a.clone(),
        dh_d: table.d.clone(),
        dh_alpha: table.alpha.clone(),
        joints: UR_KINEMATICS_JOINTS
            .iter()
            .zip(&origins)
            .map(|(name, origin)| {
                let (roll, pitch, yaw) = origin.rotation.euler_angles();
                let t = origin.translation.vector;
                JointOrigin {
                    name: (*name).to_owned(),
                    xyz: [t.x, t.y, t.z],
                    rpy: [roll, pitch, yaw],
                }
            })
            .collect(),
    };
    if args.json {
        return json_line(&output);
    }
    Ok(yaml(&output))
}

/// The kinematics file of UR's ROS drivers; rpy as URDF reads it (fixed axes X, Y, Z).
fn yaml(output: &KinematicsOutput) -> String {
    let mut text = format!(
        "# {} factory calibration, written by `ips kinematics` (cobot-align)\nkinematics:\n",
        output.robot
    );
    for joint in &output.joints {
        text += &format!("  {}:\n", joint.name);
        let keys = ["x", "y", "z", "roll", "pitch", "yaw"];
        for (key, value) in keys.iter().zip(joint.xyz.iter().chain(&joint.rpy)) {
            // `+ 0.0` writes a negative zero as 0.0.
            text += &format!("    {key}: {:?}\n", value + 0.0);
        }
    }
    text += &format!("  hash: {}\n", output.hash);
    text
}
