//! `ips fk`: forward kinematics of any chain of a URDF robot.

use std::path::PathBuf;

use align_core::pose::{matrix_rows, xyz_rpy};
use serde::Serialize;

use clap::Args;

use crate::{BadInput, CliError, json_line, parse_number_list};

#[derive(Debug, Args)]
pub struct FkArgs {
    /// Robot description (URDF; expand xacro files first).
    #[arg(long, value_name = "FILE")]
    pub urdf: PathBuf,
    /// Where a ROS package named in package:// mesh URIs lives; repeatable. Packages not given
    /// are looked for among the URDF file's parent folders.
    #[arg(long = "package-dir", value_name = "NAME=DIR")]
    pub package_dirs: Vec<String>,
    /// Link the pose is expressed in.
    #[arg(long, value_name = "LINK")]
    pub base: String,
    /// Link whose pose is computed.
    #[arg(long, value_name = "LINK")]
    pub tip: String,
    /// Joint values of the chain's movable joints from base to tip, comma-separated
    /// (rad for revolute, m for prismatic). Use --q=-1,... when the first value is negative.
    #[arg(long, value_name = "A,B,C,...", allow_hyphen_values = true)]
    pub q: String,
    /// Print one JSON document instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Serialize)]
pub struct FkOutput {
    /// Homogeneous transform, 4 rows of 4 (row-major).
    pub base_from_tip: [[f64; 4]; 4],
    pub xyz: [f64; 3],
    pub rpy: [f64; 3],
    pub base: String,
    pub tip: String,
    pub joints: Vec<String>,
    /// Mesh URIs that could not be resolved (kinematics does not need them).
    pub warnings: Vec<String>,
}

/// The command: prints the pose (warnings about the model on stderr).
pub fn command(args: &FkArgs) -> Result<String, CliError> {
    let output = run(args)?;
    for warning in &output.warnings {
        eprintln!("warning: {warning}");
    }
    if args.json {
        json_line(&output)
    } else {
        Ok(output.to_text())
    }
}

pub fn run(args: &FkArgs) -> Result<FkOutput, BadInput> {
    let model = crate::load_urdf(&args.urdf, &args.package_dirs)?;
    let chain = model.chain(&args.base, &args.tip).map_err(BadInput::new)?;
    let q = parse_number_list(&args.q, "--q")?;
    let base_from_tip = chain.forward(&q).map_err(BadInput::new)?;
    let (xyz, rpy) = xyz_rpy(&base_from_tip);
    Ok(FkOutput {
        base_from_tip: matrix_rows(&base_from_tip),
        xyz,
        rpy,
        base: args.base.clone(),
        tip: args.tip.clone(),
        joints: chain.joint_names().into_iter().map(str::to_owned).collect(),
        warnings: model.mesh_problems(),
    })
}

impl FkOutput {
    pub fn to_text(&self) -> String {
        let mut text = format!("base_from_tip ({} <- {}):\n", self.base, self.tip);
        for row in &self.base_from_tip {
            text += &format!(
                "  [{:>12.9} {:>12.9} {:>12.9} {:>12.9}]\n",
                row[0], row[1], row[2], row[3]
            );
        }
        let [x, y, z] = self.xyz.map(|v| crate::display_round(v, 9));
        let [roll, pitch, yaw] = self.rpy.map(|v| crate::display_round(v, 9));
        text += &format!("xyz [m]:   {x:.9} {y:.9} {z:.9}\n");
        text += &format!("rpy [rad]: {roll:.9} {pitch:.9} {yaw:.9}\n");
        text += &format!("joints:    {}\n", self.joints.join(", "));
        text
    }
}
