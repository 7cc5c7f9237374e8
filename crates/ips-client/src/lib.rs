//! The IPS side of cobot-align: the `ips` command-line tool. Each subcommand is a file under
//! [`commands`] owning its arguments, its run and its output; `bin/ips.rs` only parses
//! arguments, prints and maps errors to exit codes. The service itself, the sessions and the
//! alignment jobs are the `align-service` library.

pub mod cli;
pub mod client;
pub mod commands;
pub mod export;

pub use align_service::BadInput;

/// Why a command failed, and so its exit code.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    /// The user's to fix (arguments, files, a request the service refused): exit code 2.
    #[error(transparent)]
    BadInput(#[from] BadInput),
    /// The run failed (no reply in time, a child that died, a file that cannot be written):
    /// exit code 1.
    #[error("{0}")]
    Failure(String),
}

impl CliError {
    pub fn exit_code(&self) -> u8 {
        match self {
            CliError::BadInput(_) => 2,
            CliError::Failure(_) => 1,
        }
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

/// `NAME: xyz [m] X Y Z, rpy [rad] R P Y` with a newline, six decimals, no negative zeros, and
/// under it the same in mm and degrees: how every alignment's text starts.
pub fn pose_line(name: &str, pose: &protocol::Pose) -> String {
    let [x, y, z] = pose.xyz.map(|v| display_round(v, 6));
    let [roll, pitch, yaw] = pose.rpy.map(|v| display_round(v, 6));
    let [x_mm, y_mm, z_mm] = pose.xyz.map(|v| display_round(v * 1e3, 3));
    let [roll_deg, pitch_deg, yaw_deg] = pose.rpy.map(|v| display_round(v.to_degrees(), 4));
    format!(
        "{name}: xyz [m] {x:.6} {y:.6} {z:.6}, rpy [rad] {roll:.6} {pitch:.6} {yaw:.6}\n  \
         = xyz [mm] {x_mm:.3} {y_mm:.3} {z_mm:.3}, rpy [deg] {roll_deg:.4} {pitch_deg:.4} {yaw_deg:.4}\n"
    )
}

/// One JSON document on one line, as every `--json` prints.
pub fn json_line(value: &impl serde::Serialize) -> Result<String, CliError> {
    serde_json::to_string(value)
        .map(|text| text + "\n")
        .map_err(|error| CliError::Failure(format!("cannot encode the result as JSON: {error}")))
}
