//! `ips align-cloud`: Point Cloud Alignment of a part's mesh to a scan, run here from the
//! command line or asked of a running service (`--service`, request `align-cloud`). Both go
//! through [`align`], so the service's reply data is the command's `--json` document.

use std::path::{Path, PathBuf};

use align_core::geometry::Mesh;
use align_core::io::{read_cloud, read_mesh};
use align_core::pose::isometry_from_xyz_rpy;
use align_core::registration::pca::{DeltaSchedule, PcaOptions, PcaStep, align_cloud};
use clap::Args;
use nalgebra::Isometry3;
use protocol::ServiceRequestBody;
use serde::{Deserialize, Serialize};

use crate::BadInput;
use crate::align::PoseJson;
use crate::session::PartSection;

/// The start pose's error bound a service request gets when it names none, m. A hand-placed
/// part in a modelled cell is within 100 mm of its nominal pose; at that delta our method found
/// 49 of 50 displaced parts in the cluttered trials (docs/pca-trials.md), and a larger bound
/// lets the cut-off box take in more clutter for nothing.
pub const SERVICE_DEFAULT_DELTA_M: f64 = 0.1;

#[derive(Debug, Args)]
pub struct AlignCloudArgs {
    /// Scanner cloud (.ply, .pcd, .xyz, .csv, .txt), in the robot base frame. With --service,
    /// the path as the service sees it.
    #[arg(long, value_name = "FILE")]
    pub cloud: PathBuf,
    /// Part mesh (.stl, .obj, .ply). Required without --service; with it, the default is the
    /// service session's part.
    #[arg(long, value_name = "FILE", required_unless_present = "service")]
    pub mesh: Option<PathBuf>,
    /// Unit of the mesh file in metres (0.001 for mm) [default: 1; with --service and no
    /// --mesh, the session part's own].
    #[arg(long)]
    pub mesh_scale: Option<f64>,
    /// Unit of the cloud file in metres.
    #[arg(long, default_value_t = 1.0)]
    pub cloud_scale: f64,
    /// Nominal part pose in the base frame: x,y,z (m), roll,pitch,yaw (rad). Required without
    /// --service; with it, the default is the session part's nominal pose.
    #[arg(
        long,
        value_name = "X,Y,Z,R,P,Y",
        allow_hyphen_values = true,
        required_unless_present = "service"
    )]
    pub pose: Option<String>,
    /// Upper bound of the nominal pose's error, m (the thesis's delta). Required without
    /// --service; with it, the default is 0.1.
    #[arg(long, required_unless_present = "service")]
    pub delta: Option<f64>,
    /// The thesis's SVD step instead of point-to-plane.
    #[arg(long)]
    pub point_to_point: bool,
    /// Delta shrinks as cos^2 (the thesis's code) instead of cos (its eq. 33).
    #[arg(long)]
    pub cos_squared: bool,
    /// No exploration of orientations around the nominal pose (the thesis's behaviour).
    #[arg(long)]
    pub local: bool,
    /// Ask the running alignment service at this REP endpoint (e.g. tcp://127.0.0.1:4000) to
    /// align instead of aligning here.
    #[arg(long, value_name = "ENDPOINT")]
    pub service: Option<String>,
    /// Print one JSON document instead of text.
    #[arg(long)]
    pub json: bool,
}

/// One Point Cloud Alignment to run, whoever asked for it.
#[derive(Debug, Clone)]
pub struct CloudAlignment {
    pub cloud: PathBuf,
    pub cloud_scale: f64,
    pub mesh: PathBuf,
    pub mesh_scale: f64,
    pub base_from_part_start: Isometry3<f64>,
    pub delta_m: f64,
    pub options: PcaOptions,
}

/// As `ips align` (DESIGN.md 6.4); for clouds `residuals` is empty (thousands of points) and the
/// point counts are given instead.
#[derive(Debug, Serialize, Deserialize)]
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

/// The command: aligned here, or by the service `--service` names.
pub fn run(args: &AlignCloudArgs) -> Result<AlignCloudOutput, BadInput> {
    match &args.service {
        Some(endpoint) => {
            let data = crate::client::request_data(endpoint, &service_request(args)?)?;
            serde_json::from_value(data).map_err(|error| {
                BadInput(format!(
                    "the service's align-cloud reply is not the document: {error}"
                ))
            })
        }
        None => run_here(args),
    }
}

/// Flags to a [`CloudAlignment`], run in this process.
fn run_here(args: &AlignCloudArgs) -> Result<AlignCloudOutput, BadInput> {
    let (Some(mesh), Some(pose), Some(delta_m)) = (&args.mesh, &args.pose, args.delta) else {
        return Err(BadInput(
            "--mesh, --pose and --delta are required without --service".to_owned(),
        ));
    };
    let start = parse_pose(pose)?;
    check_delta(delta_m, "--delta")?;
    align(&CloudAlignment {
        cloud: args.cloud.clone(),
        cloud_scale: args.cloud_scale,
        mesh: mesh.clone(),
        mesh_scale: args.mesh_scale.unwrap_or(1.0),
        base_from_part_start: isometry_from_xyz_rpy(start.xyz, start.rpy),
        delta_m,
        options: options(args.point_to_point, args.cos_squared, args.local),
    })
}

/// The flags' request to a service: only what the user gave, so the service's defaults apply
/// to the rest.
pub fn service_request(args: &AlignCloudArgs) -> Result<protocol::ServiceRequest, BadInput> {
    let mut request = protocol::service_request("align-cloud");
    let body = &mut request.body;
    body.cloud = Some(args.cloud.display().to_string());
    body.cloud_scale = Some(args.cloud_scale);
    body.mesh = args.mesh.as_ref().map(|mesh| mesh.display().to_string());
    body.mesh_scale = args.mesh_scale;
    body.start_pose = args.pose.as_deref().map(parse_pose).transpose()?;
    if let Some(delta_m) = args.delta {
        check_delta(delta_m, "--delta")?;
        body.delta_m = Some(delta_m);
    }
    // Flags left off are left out: the request then reads as the user typed it.
    body.point_to_point = args.point_to_point.then_some(true);
    body.cos_squared = args.cos_squared.then_some(true);
    body.local = args.local.then_some(true);
    Ok(request)
}

/// The service's side: a request to a [`CloudAlignment`], the session's part standing in for
/// what the request leaves out. Relative paths in the request are the service's (its working
/// directory); the session part's mesh is relative to the session's `folder`.
pub fn from_request(
    body: &ServiceRequestBody,
    part: &PartSection,
    folder: &Path,
) -> Result<CloudAlignment, BadInput> {
    let cloud = body.cloud.as_ref().ok_or_else(|| {
        BadInput(
            "align-cloud needs a 'cloud' (a scanner cloud file as the service sees the path)"
                .to_owned(),
        )
    })?;
    let (mesh, mesh_scale) = match (&body.mesh, body.mesh_scale) {
        (Some(mesh), scale) => (PathBuf::from(mesh), scale.unwrap_or(1.0)),
        (None, None) => (folder.join(&part.mesh), part.mesh_scale),
        (None, Some(_)) => {
            return Err(BadInput(
                "align-cloud: 'mesh_scale' needs a 'mesh' (the session's part has its own scale)"
                    .to_owned(),
            ));
        }
    };
    let start = body.start_pose.unwrap_or(protocol::PoseXyzRpy {
        xyz: part.nominal_pose.xyz,
        rpy: part.nominal_pose.rpy,
    });
    let delta_m = body.delta_m.unwrap_or(SERVICE_DEFAULT_DELTA_M);
    check_delta(delta_m, "delta_m")?;
    Ok(CloudAlignment {
        cloud: PathBuf::from(cloud),
        cloud_scale: body.cloud_scale.unwrap_or(1.0),
        mesh,
        mesh_scale,
        base_from_part_start: isometry_from_xyz_rpy(start.xyz, start.rpy),
        delta_m,
        options: options(
            body.point_to_point.unwrap_or(false),
            body.cos_squared.unwrap_or(false),
            body.local.unwrap_or(false),
        ),
    })
}

fn parse_pose(text: &str) -> Result<protocol::PoseXyzRpy, BadInput> {
    let values = crate::parse_number_list(text, "--pose")?;
    let [x, y, z, roll, pitch, yaw] = values[..] else {
        return Err(BadInput(format!(
            "--pose needs 6 values x,y,z,roll,pitch,yaw, got {}",
            values.len()
        )));
    };
    Ok(protocol::PoseXyzRpy {
        xyz: [x, y, z],
        rpy: [roll, pitch, yaw],
    })
}

/// `what` names the value as the user wrote it (a flag or a request field).
fn check_delta(delta_m: f64, what: &str) -> Result<(), BadInput> {
    if delta_m.is_finite() && delta_m > 0.0 {
        Ok(())
    } else {
        Err(BadInput(format!(
            "{what} must be a positive distance in m, got {delta_m}"
        )))
    }
}

fn options(point_to_point: bool, cos_squared: bool, local: bool) -> PcaOptions {
    let defaults = PcaOptions::default();
    PcaOptions {
        step: if point_to_point {
            PcaStep::PointToPoint
        } else {
            PcaStep::PointToPlane
        },
        schedule: if cos_squared {
            DeltaSchedule::CosineSquared
        } else {
            DeltaSchedule::Cosine
        },
        starts: if local { 0 } else { defaults.starts },
        ..defaults
    }
}

pub fn align(job: &CloudAlignment) -> Result<AlignCloudOutput, BadInput> {
    let soup = read_mesh(&job.mesh, job.mesh_scale).map_err(BadInput::new)?;
    let mesh = Mesh::new(&soup.vertices, &soup.triangles)
        .map_err(|error| BadInput(format!("'{}': {error}", job.mesh.display())))?;
    let cloud = read_cloud(&job.cloud, job.cloud_scale).map_err(BadInput::new)?;
    let result = align_cloud(
        &mesh,
        &cloud,
        &job.base_from_part_start,
        job.delta_m,
        &job.options,
    )
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

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

    use clap::Parser;

    use crate::cli::{Cli, Command};

    fn request_for(args: &[&str]) -> protocol::ServiceRequestBody {
        let cli = Cli::try_parse_from(args).unwrap();
        let Command::AlignCloud(args) = cli.command else {
            panic!("not align-cloud");
        };
        super::service_request(&args).unwrap().body
    }

    #[test]
    fn flags_left_off_are_left_out_of_the_request_so_the_service_defaults_apply() {
        let body = request_for(&[
            "ips",
            "align-cloud",
            "--service",
            "tcp://127.0.0.1:4000",
            "--cloud",
            "scan.ply",
        ]);
        assert_eq!(body.command, "align-cloud");
        assert_eq!(body.cloud.as_deref(), Some("scan.ply"));
        assert_eq!(
            (body.mesh, body.mesh_scale, body.start_pose, body.delta_m),
            (None, None, None, None)
        );
        assert_eq!(
            (body.point_to_point, body.cos_squared, body.local),
            (None, None, None)
        );
    }

    #[test]
    fn flags_given_reach_the_request() {
        let body = request_for(&[
            "ips",
            "align-cloud",
            "--service",
            "tcp://127.0.0.1:4000",
            "--cloud",
            "scan.ply",
            "--mesh",
            "part.stl",
            "--mesh-scale",
            "0.001",
            "--pose",
            "0.6,-0.1,0.05,0,0,0.3",
            "--delta",
            "0.05",
            "--point-to-point",
            "--cos-squared",
            "--local",
        ]);
        assert_eq!(body.mesh.as_deref(), Some("part.stl"));
        assert_eq!(body.mesh_scale, Some(0.001));
        let pose = body.start_pose.unwrap();
        assert_eq!((pose.xyz, pose.rpy), ([0.6, -0.1, 0.05], [0.0, 0.0, 0.3]));
        assert_eq!(body.delta_m, Some(0.05));
        assert_eq!(
            (body.point_to_point, body.cos_squared, body.local),
            (Some(true), Some(true), Some(true))
        );
    }

    #[test]
    fn the_offline_command_still_needs_mesh_pose_and_delta() {
        let error = Cli::try_parse_from(["ips", "align-cloud", "--cloud", "scan.ply"]).unwrap_err();
        let message = error.to_string();
        for flag in ["--mesh", "--pose", "--delta"] {
            assert!(message.contains(flag), "{message}");
        }
    }
}
