//! Point Cloud Alignment of a part's mesh to a scanner cloud file, whoever asked for it: `ips
//! align-cloud` builds a [`CloudAlignment`] from its flags, the service's `align-cloud` from the
//! request ([`from_request`]); both run [`align`], so the service's reply is the command's
//! `--json` document.

use std::path::{Path, PathBuf};

use align_core::geometry::Mesh;
use align_core::io::{read_cloud, read_mesh};
use align_core::pose::isometry_from_xyz_rpy;
use align_core::registration::pca::{DeltaSchedule, PcaOptions, PcaStep, align_cloud};
use nalgebra::Isometry3;
use protocol::AlignCloudRequest;
use protocol::reports::{CloudReport, CloudUniqueness};
use protocol::session::PartSection;

use crate::BadInput;
use crate::jobs::align::{report_pose, summary, uncertainty_json};
use crate::jobs::units::{extent_m, refuse_unit_mismatch, unit_hints, with_hints};

/// The start pose's error bound a service request gets when it names none, m. A hand-placed
/// part in a modelled cell is within 100 mm of its nominal pose; at that delta our method found
/// 49 of 50 displaced parts in the cluttered trials (docs/pca-trials.md), and a larger bound
/// lets the cut-off box take in more clutter for nothing.
pub const SERVICE_DEFAULT_DELTA_M: f64 = 0.1;

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

/// The service's side: a request to a [`CloudAlignment`], the session's part standing in for
/// what the request leaves out. Relative paths in the request are the service's (its working
/// directory); the session part's mesh is relative to the session's `folder`.
pub fn from_request(
    body: &AlignCloudRequest,
    part: &PartSection,
    folder: &Path,
) -> Result<CloudAlignment, BadInput> {
    let cloud = &body.cloud;
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
    let start = body.start_pose.unwrap_or(part.nominal_pose);
    let delta_m = body.delta_m.unwrap_or(SERVICE_DEFAULT_DELTA_M);
    check_delta(delta_m, "delta_m")?;
    Ok(CloudAlignment {
        cloud: PathBuf::from(cloud),
        cloud_scale: body.cloud_scale.unwrap_or(1.0),
        mesh,
        mesh_scale,
        base_from_part_start: isometry_from_xyz_rpy(start.xyz, start.rpy),
        delta_m,
        options: cloud_options(
            body.point_to_point.unwrap_or(false),
            chosen_schedule(
                body.cos_squared.unwrap_or(false),
                body.cosine.unwrap_or(false),
                ("cos_squared", "cosine"),
            )?,
            body.local.unwrap_or(false),
        ),
    })
}

/// `what` names the value as the user wrote it (a flag or a request field).
pub fn check_delta(delta_m: f64, what: &str) -> Result<(), BadInput> {
    if delta_m.is_finite() && delta_m > 0.0 {
        Ok(())
    } else {
        Err(BadInput(format!(
            "{what} must be a positive distance in m, got {delta_m}"
        )))
    }
}

/// The schedule two choices ask for (`None`: the default), named in an error as `names` are.
pub fn chosen_schedule(
    cos_squared: bool,
    cosine: bool,
    names: (&str, &str),
) -> Result<Option<DeltaSchedule>, BadInput> {
    match (cos_squared, cosine) {
        (true, true) => Err(BadInput(format!(
            "{} and {} are two schedules: pick one",
            names.0, names.1
        ))),
        (true, false) => Ok(Some(DeltaSchedule::CosineSquared)),
        (false, true) => Ok(Some(DeltaSchedule::Cosine)),
        (false, false) => Ok(None),
    }
}

pub fn cloud_options(
    point_to_point: bool,
    schedule: Option<DeltaSchedule>,
    local: bool,
) -> PcaOptions {
    let defaults = PcaOptions::default();
    PcaOptions {
        step: if point_to_point {
            PcaStep::PointToPoint
        } else {
            PcaStep::PointToPlane
        },
        schedule: schedule.unwrap_or(defaults.schedule),
        starts: if local { 0 } else { defaults.starts },
        // The thesis's SVD step asks for its loop: every band matched exactly, from delta0.
        wide_band_slack: !point_to_point,
        local_band_within_radius: !point_to_point,
        ..defaults
    }
}

pub fn align(job: &CloudAlignment) -> Result<CloudReport, BadInput> {
    let soup = read_mesh(&job.mesh, job.mesh_scale).map_err(BadInput::new)?;
    let mesh = Mesh::new(&soup.vertices, &soup.triangles)
        .map_err(|error| BadInput(format!("'{}': {error}", job.mesh.display())))?;
    let cloud = read_cloud(&job.cloud, job.cloud_scale).map_err(BadInput::new)?;
    refuse_unit_mismatch(&mesh, job.mesh_scale, extent_m(&cloud), "the cloud spans")?;
    let hints = unit_hints(&mesh, job.mesh_scale, None);
    let result = align_cloud(
        &mesh,
        &cloud,
        &job.base_from_part_start,
        job.delta_m,
        &job.options,
    )
    .map_err(|error| BadInput(with_hints(format!("cannot align: {error}"), &hints)))?;
    Ok(CloudReport {
        // Thousands of points: no residual per point.
        alignment: summary(&result.alignment, Vec::new()),
        cloud_points: cloud.len(),
        keypoints: result.keypoints,
        kept_points: result.kept,
        final_delta: result.final_delta_m,
        starts: result.alignment.starts,
        notes: mesh.notes_with_unit_scale(job.mesh_scale),
        ambiguous: result.uniqueness.as_ref().is_some_and(|u| u.ambiguous),
        uniqueness: result.uniqueness.as_ref().map(|u| CloudUniqueness {
            score: u.score,
            runner_up_score: u.runner_up_score,
            margin: u.margin,
            runner_up: report_pose(&u.runner_up),
        }),
        uncertainty: result
            .uncertainty
            .as_ref()
            .ok()
            .map(|found| uncertainty_json(found, "scan")),
        uncertainty_error: result.uncertainty.as_ref().err().map(ToString::to_string),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_schedule_choice_reaches_the_options_and_two_at_once_are_refused() {
        let schedule = |cos_squared, cosine| {
            chosen_schedule(cos_squared, cosine, ("cos_squared", "cosine"))
                .map(|choice| cloud_options(false, choice, false).schedule)
        };
        assert_eq!(schedule(false, false), Ok(PcaOptions::default().schedule));
        assert_eq!(schedule(true, false), Ok(DeltaSchedule::CosineSquared));
        assert_eq!(schedule(false, true), Ok(DeltaSchedule::Cosine));
        let refused = schedule(true, true).unwrap_err();
        assert!(
            refused.0.contains("cos_squared and cosine"),
            "{}",
            refused.0
        );
    }
}
