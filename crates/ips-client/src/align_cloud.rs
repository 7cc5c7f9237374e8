//! `ips align-cloud`: Point Cloud Alignment of a part's mesh to a scan.

use std::path::PathBuf;

use align_core::geometry::Mesh;
use align_core::io::{read_cloud, read_mesh};
use align_core::pose::isometry_from_xyz_rpy;
use align_core::registration::pca::{DeltaSchedule, PcaOptions, PcaStep, align_cloud};
use clap::Args;
use serde::Serialize;

use crate::BadInput;
use crate::align::PoseJson;

#[derive(Debug, Args)]
pub struct AlignCloudArgs {
    /// Scanner cloud (.ply, .pcd, .xyz, .csv, .txt), in the robot base frame.
    #[arg(long, value_name = "FILE")]
    pub cloud: PathBuf,
    /// Part mesh (.stl, .obj, .ply).
    #[arg(long, value_name = "FILE")]
    pub mesh: PathBuf,
    /// Unit of the mesh file in metres (0.001 for mm).
    #[arg(long, default_value_t = 1.0)]
    pub mesh_scale: f64,
    /// Unit of the cloud file in metres.
    #[arg(long, default_value_t = 1.0)]
    pub cloud_scale: f64,
    /// Nominal part pose in the base frame: x,y,z (m), roll,pitch,yaw (rad).
    #[arg(long, value_name = "X,Y,Z,R,P,Y", allow_hyphen_values = true)]
    pub pose: String,
    /// Upper bound of the nominal pose's error, m (the thesis's delta).
    #[arg(long)]
    pub delta: f64,
    /// The thesis's SVD step instead of point-to-plane.
    #[arg(long)]
    pub point_to_point: bool,
    /// Delta shrinks as cos^2 (the thesis's code) instead of cos (its eq. 33).
    #[arg(long)]
    pub cos_squared: bool,
    /// No exploration of orientations around the nominal pose (the thesis's behaviour).
    #[arg(long)]
    pub local: bool,
    /// Print one JSON document instead of text.
    #[arg(long)]
    pub json: bool,
}

/// As `ips align` (DESIGN.md 6.4); for clouds `residuals` is empty (thousands of points) and the
/// point counts are given instead.
#[derive(Debug, Serialize)]
pub struct AlignCloudOutput {
    pub pose: PoseJson,
    pub iterations: usize,
    pub converged: bool,
    pub rms: f64,
    pub max: f64,
    pub time_s: f64,
    pub residuals: Vec<crate::align::ResidualJson>,
    pub cloud_points: usize,
    pub keypoints: usize,
    pub kept_points: usize,
    pub final_delta: f64,
    pub starts: usize,
    pub notes: Vec<String>,
}

pub fn run(args: &AlignCloudArgs) -> Result<AlignCloudOutput, BadInput> {
    let values = crate::parse_number_list(&args.pose, "--pose")?;
    let [x, y, z, roll, pitch, yaw] = values[..] else {
        return Err(BadInput(format!(
            "--pose needs 6 values x,y,z,roll,pitch,yaw, got {}",
            values.len()
        )));
    };
    if !(args.delta.is_finite() && args.delta > 0.0) {
        return Err(BadInput(format!(
            "--delta must be a positive distance in m, got {}",
            args.delta
        )));
    }
    let soup = read_mesh(&args.mesh, args.mesh_scale).map_err(BadInput::new)?;
    let mesh = Mesh::new(&soup.vertices, &soup.triangles)
        .map_err(|error| BadInput(format!("'{}': {error}", args.mesh.display())))?;
    let cloud = read_cloud(&args.cloud, args.cloud_scale).map_err(BadInput::new)?;
    let options = PcaOptions {
        step: if args.point_to_point {
            PcaStep::PointToPoint
        } else {
            PcaStep::PointToPlane
        },
        schedule: if args.cos_squared {
            DeltaSchedule::CosineSquared
        } else {
            DeltaSchedule::Cosine
        },
        starts: if args.local {
            0
        } else {
            PcaOptions::default().starts
        },
        ..PcaOptions::default()
    };
    let start = isometry_from_xyz_rpy([x, y, z], [roll, pitch, yaw]);
    let result = align_cloud(&mesh, &cloud, &start, args.delta, &options)
        .map_err(|error| BadInput(format!("cannot align: {error}")))?;
    Ok(AlignCloudOutput {
        pose: PoseJson::from(&result.base_from_part),
        iterations: result.iterations,
        converged: result.converged,
        rms: result.rms_m,
        max: result.max_m,
        time_s: result.time_s,
        residuals: Vec::new(),
        cloud_points: cloud.len(),
        keypoints: result.keypoints,
        kept_points: result.kept,
        final_delta: result.final_delta_m,
        starts: result.starts,
        notes: mesh.notes().to_vec(),
    })
}

impl AlignCloudOutput {
    pub fn to_text(&self) -> String {
        let [x, y, z] = self.pose.xyz.map(|v| crate::display_round(v, 6));
        let [roll, pitch, yaw] = self.pose.rpy.map(|v| crate::display_round(v, 6));
        let mut text = format!(
            "base_from_part: xyz [m] {x:.6} {y:.6} {z:.6}, rpy [rad] {roll:.6} {pitch:.6} {yaw:.6}\n"
        );
        text += &format!(
            "{} after {} iterations ({} runs) in {:.1} ms\n",
            if self.converged {
                "converged"
            } else {
                "NOT converged (iteration limit)"
            },
            self.iterations,
            self.starts,
            self.time_s * 1e3
        );
        text += &format!(
            "{} cloud points -> {} keypoints, {} kept within {:.1} mm of the part: rms {:.3} mm, max {:.3} mm\n",
            self.cloud_points,
            self.keypoints,
            self.kept_points,
            self.final_delta * 1e3,
            self.rms * 1e3,
            self.max * 1e3
        );
        for note in &self.notes {
            text += &format!("note: {note}\n");
        }
        text
    }
}
