//! `ips align-cloud`: Point Cloud Alignment of a part's mesh to a scan, run here from the
//! command line or asked of a running service (`--service`, request `align-cloud`). Both run
//! `align_service::jobs::cloud::align`, so the service's reply is the command's `--json`
//! document.

use std::path::PathBuf;

use align_core::pose::isometry_from_xyz_rpy;
use align_service::jobs::cloud::{
    CloudAlignment, align, check_delta, chosen_schedule, cloud_options,
};
use clap::Args;
use protocol::reports::CloudReport;
use protocol::{AlignCloudRequest, Pose, ServiceCommand};

use crate::commands::align::confidence_text;
use crate::{BadInput, CliError, client, json_line};

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
    /// Delta shrinks as cos^2 over 100 steps (the thesis's code) instead of halving each time
    /// the pose settles, coarse to fine (the default).
    #[arg(long)]
    pub cos_squared: bool,
    /// Delta shrinks as cos over 100 steps (the thesis's eq. 33) instead of halving.
    #[arg(long, conflicts_with = "cos_squared")]
    pub cosine: bool,
    /// No exploration of orientations around the nominal pose and no uniqueness test: the local
    /// stage alone, as the thesis aligns (with --cos-squared --point-to-point, its loop).
    #[arg(long)]
    pub local: bool,
    /// Ask the running alignment service at this REP endpoint (e.g. tcp://127.0.0.1:4000) to
    /// align instead of aligning here.
    #[arg(long, value_name = "ENDPOINT")]
    pub service: Option<String>,
    /// The text calls the pose LOOSE when it may be this far or more from the truth (95 %, the
    /// thesis's pose distance: the origin's shift and the turn times the part's radius), mm.
    #[arg(long, value_name = "MM", default_value_t = 1.0, value_parser = tolerance_mm)]
    pub tolerance_mm: f64,
    /// Print one JSON document instead of text.
    #[arg(long)]
    pub json: bool,
}

/// A tolerance in mm: finite and above zero.
fn tolerance_mm(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(mm) if mm.is_finite() && mm > 0.0 => Ok(mm),
        _ => Err(format!(
            "expected a distance in mm (finite, above 0), got '{text}'"
        )),
    }
}

/// The command: aligned here, or by the service `--service` names.
pub fn run(args: &AlignCloudArgs) -> Result<String, CliError> {
    let report: CloudReport = match &args.service {
        Some(endpoint) => client::request(
            endpoint,
            ServiceCommand::AlignCloud(Box::new(service_request(args)?)),
        )?,
        None => run_here(args)?,
    };
    if args.json {
        json_line(&report)
    } else {
        Ok(to_text(&report, args.tolerance_mm))
    }
}

/// Flags to a [`CloudAlignment`], run in this process.
fn run_here(args: &AlignCloudArgs) -> Result<CloudReport, BadInput> {
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
        options: cloud_options(
            args.point_to_point,
            chosen_schedule(args.cos_squared, args.cosine, ("--cos-squared", "--cosine"))?,
            args.local,
        ),
    })
}

/// The flags' request to a service: only what the user gave, so the service's defaults apply
/// to the rest.
pub fn service_request(args: &AlignCloudArgs) -> Result<AlignCloudRequest, BadInput> {
    let delta_m = args.delta;
    if let Some(delta_m) = delta_m {
        check_delta(delta_m, "--delta")?;
    }
    Ok(AlignCloudRequest {
        cloud: args.cloud.display().to_string(),
        cloud_scale: Some(args.cloud_scale),
        mesh: args.mesh.as_ref().map(|mesh| mesh.display().to_string()),
        mesh_scale: args.mesh_scale,
        start_pose: args.pose.as_deref().map(parse_pose).transpose()?,
        delta_m,
        // Flags left off are left out: the request then reads as the user typed it.
        point_to_point: args.point_to_point.then_some(true),
        cos_squared: args.cos_squared.then_some(true),
        cosine: args.cosine.then_some(true),
        local: args.local.then_some(true),
    })
}

fn parse_pose(text: &str) -> Result<Pose, BadInput> {
    let values = crate::parse_number_list(text, "--pose")?;
    let [x, y, z, roll, pitch, yaw] = values[..] else {
        return Err(BadInput(format!(
            "--pose needs 6 values x,y,z,roll,pitch,yaw, got {}",
            values.len()
        )));
    };
    Ok(Pose::new([x, y, z], [roll, pitch, yaw]))
}

/// The report for people; a pose whose 95 % bound on the pose distance reaches `tolerance_mm` is
/// called loose.
pub fn to_text(report: &CloudReport, tolerance_mm: f64) -> String {
    let mut text = crate::pose_line("base_from_part", &report.alignment.pose);
    text += &format!(
        "{} after {} iterations ({} runs) in {:.1} ms\n",
        if report.alignment.converged {
            "converged"
        } else {
            "NOT converged (iteration limit)"
        },
        report.alignment.iterations,
        report.starts,
        report.alignment.time_s * 1e3
    );
    text += &format!(
        "{} cloud points -> {} keypoints, {} kept within {:.1} mm of the part: rms {:.3} mm, max {:.3} mm\n",
        report.cloud_points,
        report.keypoints,
        report.kept_points,
        report.final_delta * 1e3,
        report.alignment.rms * 1e3,
        report.alignment.max * 1e3
    );
    if let Some(found) = &report.uniqueness {
        let [x, y, z] = found.runner_up.xyz;
        let [roll, pitch, yaw] = found.runner_up.rpy;
        text += &format!(
            "{}: score {:.0} against {:.0} for the best other pose (margin {:.1} %): xyz {x:.6} {y:.6} {z:.6}, rpy {roll:.4} {pitch:.4} {yaw:.4}\n",
            if report.ambiguous {
                "AMBIGUOUS: another pose fits the scan as well (a symmetric part, or too little of it seen)"
            } else {
                "unique"
            },
            found.score,
            found.runner_up_score,
            found.margin * 100.0
        );
    } else if report.starts > 1 {
        // Silence here read as "unique"; it means no run ended anywhere else.
        text += &format!(
            "uniqueness: no other pose to compare, all {} runs from the start ended at this one\n",
            report.starts
        );
    } else {
        text += "uniqueness: not tested, a single run (a local alignment, or a delta too small to turn this part and below the global search's)\n";
    }
    if let Some(found) = &report.uncertainty {
        text += &confidence_text(found);
        if let Some(mm) = found.pose_distance_95_mm.filter(|&mm| mm >= tolerance_mm) {
            text += &format!(
                "LOOSE: the pose may be {mm:.2} mm from the truth (95%, pose distance), over the {tolerance_mm} mm \
                 tolerance: scan more of the part where it would stop the weakest motion above\n"
            );
        }
    } else if let Some(why) = &report.uncertainty_error {
        text += &format!("pose uncertainty not available: {why}\n");
    }
    for note in &report.notes {
        text += &format!("note: {note}\n");
    }
    text
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

    use clap::Parser;

    use crate::cli::{Cli, Command};

    fn request_for(args: &[&str]) -> protocol::AlignCloudRequest {
        let cli = Cli::try_parse_from(args).unwrap();
        let Command::AlignCloud(args) = cli.command else {
            panic!("not align-cloud");
        };
        super::service_request(&args).unwrap()
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
        assert_eq!(body.cloud, "scan.ply");
        assert_eq!(
            (body.mesh, body.mesh_scale, body.start_pose, body.delta_m),
            (None, None, None, None)
        );
        assert_eq!(
            (
                body.point_to_point,
                body.cos_squared,
                body.cosine,
                body.local
            ),
            (None, None, None, None)
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

    /// A report of `starts` runs with the uncertainty of a box's faces seen with noise
    /// `sigma_m` (none: not available).
    fn report(starts: usize, sigma_m: Option<f64>) -> protocol::reports::CloudReport {
        use align_core::registration::uncertainty::{
            SurfaceObservation, uncertainty_of_observations,
        };
        use nalgebra::{Isometry3, Point3, Vector3};
        let mut observations = Vec::new();
        for axis in 0..3 {
            for sign in [-1.0, 1.0] {
                for (u, v) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
                    let mut surface = Point3::origin();
                    surface[axis] = 0.05 * sign;
                    surface[(axis + 1) % 3] = 0.04 * u;
                    surface[(axis + 2) % 3] = 0.04 * v;
                    observations.push(SurfaceObservation {
                        surface,
                        direction: Vector3::ith(axis, sign),
                    });
                }
            }
        }
        let found = sigma_m.map(|sigma_m| {
            let pose = Isometry3::identity();
            let found =
                uncertainty_of_observations(&observations, &pose, 0.09, &Point3::origin(), sigma_m)
                    .unwrap();
            align_service::jobs::align::uncertainty_json(&found, "scan")
        });
        protocol::reports::CloudReport {
            uncertainty_error: found
                .is_none()
                .then(|| "6 residuals cannot estimate a sigma".to_owned()),
            uncertainty: found,
            alignment: protocol::reports::AlignmentSummary {
                pose: protocol::Pose::new([0.1, 0.2, 0.3], [0.0, 0.0, 0.5]),
                iterations: 12,
                converged: true,
                rms: 4e-4,
                max: 2e-3,
                time_s: 0.2,
                residuals: Vec::new(),
            },
            cloud_points: 50_000,
            keypoints: 9_000,
            kept_points: 800,
            final_delta: 0.0015,
            starts,
            notes: Vec::new(),
            ambiguous: false,
            uniqueness: None,
        }
    }

    #[test]
    fn a_report_without_a_runner_up_says_why_instead_of_nothing() {
        let single = super::to_text(&report(1, None), 1.0);
        assert!(
            single.contains("uniqueness: not tested, a single run"),
            "{single}"
        );
        let many = super::to_text(&report(49, None), 1.0);
        assert!(
            many.contains("no other pose to compare, all 49 runs"),
            "{many}"
        );
    }

    #[test]
    fn a_pose_uncertain_beyond_a_millimetre_is_called_loose_and_a_missing_one_says_why() {
        let tight = super::to_text(&report(1, Some(1e-4)), 1.0);
        assert!(
            tight.contains("95% confidence (noise sigma 0.1000 mm, scan)"),
            "{tight}"
        );
        assert!(!tight.contains("LOOSE"), "{tight}");
        let loose = super::to_text(&report(1, Some(5e-3)), 1.0);
        assert!(loose.contains("LOOSE: the pose may be "), "{loose}");
        // A wider tolerance takes the same pose as it is.
        let within_mm = report(1, Some(5e-3))
            .uncertainty
            .and_then(|u| u.pose_distance_95_mm)
            .unwrap();
        let tolerant = super::to_text(&report(1, Some(5e-3)), within_mm + 0.1);
        assert!(!tolerant.contains("LOOSE"), "{tolerant}");
        assert!(super::tolerance_mm("0").is_err() && super::tolerance_mm("NaN").is_err());
        let missing = super::to_text(&report(1, None), 1.0);
        assert!(
            missing.contains("pose uncertainty not available: 6 residuals"),
            "{missing}"
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
