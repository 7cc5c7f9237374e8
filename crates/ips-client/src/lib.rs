//! The IPS side of cobot-align: the `ips` command-line tool. Each subcommand is a module with a
//! `run` function returning its output; `bin/ips.rs` only parses arguments and maps errors to exit
//! codes (0 success, 2 bad input with a one-line reason on stderr).

pub mod align;
pub mod align_cloud;
pub mod align_robot;
pub mod cli;
pub mod client;
pub mod demo;
pub mod diagnose;
pub mod fk;
pub mod robot_trials;
pub mod serve;
pub mod session;
pub mod trials;

/// An error the user caused (bad arguments, a missing or malformed file): exit code 2.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct BadInput(pub String);

impl BadInput {
    pub fn new(message: impl std::fmt::Display) -> Self {
        Self(message.to_string())
    }
}

/// Loads a URDF, its package:// meshes resolved from `--package-dir NAME=DIR` entries (and the
/// URDF's parent folders for packages not given).
pub fn load_urdf(
    urdf: &std::path::Path,
    package_dirs: &[String],
) -> Result<align_core::kinematics::RobotModel, BadInput> {
    let mut packages = align_core::kinematics::PackageMap::new();
    for entry in package_dirs {
        let (name, dir) =
            align_core::kinematics::PackageMap::parse_entry(entry).map_err(BadInput)?;
        packages.insert(name, dir);
    }
    align_core::kinematics::RobotModel::from_urdf_file(urdf, &packages).map_err(BadInput::new)
}

/// Parses a comma-separated list of numbers such as `0.1,-1.2,1.4`; `what` names the list in
/// errors.
pub fn parse_number_list(text: &str, what: &str) -> Result<Vec<f64>, BadInput> {
    text.split(',')
        .enumerate()
        .map(|(index, item)| {
            let item = item.trim();
            match item.parse::<f64>() {
                Ok(value) if value.is_finite() => Ok(value),
                _ => Err(BadInput(format!(
                    "{what}: item {} ('{item}') is not a finite number",
                    index + 1
                ))),
            }
        })
        .collect()
}

/// Rounds for display so that -0.0000001 prints as 0.000000, not -0.000000.
pub fn display_round(value: f64, decimals: i32) -> f64 {
    let scale = 10f64.powi(decimals);
    (value * scale).round() / scale + 0.0
}
