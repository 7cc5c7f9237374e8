//! `--export FORMAT` on `ips align` and `ips diagnose`: the report's part pose (after modelling,
//! for a diagnosis) written by [`align_core::io::export`] instead of the report.

use std::path::Path;

use align_core::io::export::{ExportFormat, ExportMesh, ExportRow, PoseExport, render};
use align_core::pose::isometry_from_xyz_rpy;
use protocol::Pose;
use protocol::reports::{AlignReport, DiagnoseReport};
use protocol::session::SessionFile;

use crate::{BadInput, CliError};

/// The help text of `--export`.
pub const HELP: &str = "Print the part pose in FORMAT instead of the report: urdf, sdf, ros-tf, \
                        kuka-base (KRL FRAME, mm and degrees), ur-pose (URScript p[...]) or csv \
                        (each touch's ball centre and residual). The pose is base_from_part in \
                        the robot base frame; the URDF and SDF name the part's mesh when a \
                        SESSION file gives it";

/// Parses a `--export` value.
pub fn parse_format(text: &str) -> Result<ExportFormat, String> {
    text.parse()
}

/// The part's mesh of a session file, as an absolute path, for the model formats.
pub fn session_mesh(session_path: &Path) -> Option<ExportMesh> {
    let text = std::fs::read_to_string(session_path).ok()?;
    let file: SessionFile = serde_json::from_str(&text).ok()?;
    let folder = session_path.parent().unwrap_or(Path::new("."));
    let path = std::path::absolute(folder.join(&file.part.mesh)).ok()?;
    Some(ExportMesh {
        path,
        scale: file.part.mesh_scale,
    })
}

fn write(
    format: ExportFormat,
    base_frame: Option<&str>,
    pose: &Pose,
    mesh: Option<ExportMesh>,
    rows: &[ExportRow],
) -> Result<String, CliError> {
    let export = PoseExport {
        base_frame: base_frame.unwrap_or("base"),
        base_from_part: isometry_from_xyz_rpy(pose.xyz, pose.rpy),
        mesh,
        rows,
    };
    render(format, &export)
        .map_err(|why| BadInput(format!("--export {}: {why}", format.name())).into())
}

/// An alignment's pose in `format`.
pub fn alignment(
    format: ExportFormat,
    report: &AlignReport,
    mesh: Option<ExportMesh>,
) -> Result<String, CliError> {
    let rows = report
        .alignment
        .residuals
        .iter()
        .filter_map(|r| {
            r.ball_centre.map(|centre| ExportRow {
                id: r.id.clone(),
                ball_centre_m: centre,
                residual_m: r.distance,
            })
        })
        .collect::<Vec<_>>();
    write(
        format,
        report.base_frame.as_deref(),
        &report.alignment.pose,
        mesh,
        &rows,
    )
}

/// A diagnosis's pose after modelling in `format`; the CSV lists the ball centres and
/// residuals after the effect.
pub fn diagnosis(
    format: ExportFormat,
    report: &DiagnoseReport,
    mesh: Option<ExportMesh>,
) -> Result<String, CliError> {
    let rows = report
        .inspections
        .iter()
        .filter_map(|i| {
            i.ball_centre_after.map(|centre| ExportRow {
                id: i.id.clone(),
                ball_centre_m: centre,
                residual_m: i.residual_after,
            })
        })
        .collect::<Vec<_>>();
    write(
        format,
        report.base_frame.as_deref(),
        &report.pose_after,
        mesh,
        &rows,
    )
}
