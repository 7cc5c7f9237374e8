//! Point Set Alignment of a session: the options, the call, and the report with the pose's
//! uncertainty that `ips align SESSION` prints and the service's `align` replies.

use align_core::pose::{matrix_rows, xyz_rpy};
use align_core::registration::Alignment;
use align_core::registration::psa::{
    PsaMethod, PsaOptions, PsaResult, PsaTarget, Search, align_touches,
};
use align_core::registration::uncertainty::{
    COVARIANCE_ORDER, PoseUncertainty, WeakDirection as FoundWeakDirection, pose_uncertainty,
    sigma_from_residuals,
};
use nalgebra::{Isometry3, Point3, Vector3};
use protocol::Pose;
use protocol::reports::{
    AlignReport, AlignmentSummary, Candidate, Position95, Residual, Rotation95, Uncertainty,
    WeakDirection,
};

use crate::BadInput;
use crate::jobs::units::{
    extent_m, refuse_impossible_tool, refuse_unit_mismatch, tool_warning, unit_hints, with_hints,
};
use crate::session::LoadedSession;

/// The keys every alignment report starts with, from what every alignment returns.
pub fn summary(alignment: &Alignment, residuals: Vec<Residual>) -> AlignmentSummary {
    AlignmentSummary {
        pose: report_pose(&alignment.base_from_part),
        iterations: alignment.iterations,
        converged: alignment.converged,
        rms: alignment.rms_m,
        max: alignment.max_m,
        time_s: alignment.time_s,
        residuals,
    }
}

/// A pose as reports give it: xyz, rpy and the 4x4 matrix.
pub fn report_pose(pose: &Isometry3<f64>) -> Pose {
    let (xyz, rpy) = xyz_rpy(pose);
    Pose {
        xyz,
        rpy,
        matrix: Some(matrix_rows(pose)),
    }
}

/// The thesis's switches a user may flip; the defaults are the service's.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AlignChoices {
    /// One local alignment from the nominal pose, no global search.
    pub local: bool,
    /// The thesis's SVD (point-to-point) step instead of point-to-plane.
    pub point_to_point: bool,
    /// Ignore the probe's approach direction.
    pub no_coherence: bool,
}

/// The PSA options for a session's tool with the user's `choices`.
pub fn options_for(choices: AlignChoices, tip_radius_m: f64) -> PsaOptions {
    let defaults = PsaOptions::default();
    PsaOptions {
        method: if choices.point_to_point {
            PsaMethod::PointToPoint
        } else {
            PsaMethod::PointToPlane
        },
        search: if choices.local {
            Search::Local
        } else {
            defaults.search
        },
        coherence: !choices.no_coherence,
        tip_radius_m,
        ..defaults
    }
}

/// Point Set Alignment of the session's part to its touches from the part's nominal pose: the
/// one call sequence `ips align`, the service's `align` and the diagnosis share.
pub fn align_session(
    session: &LoadedSession,
    choices: AlignChoices,
) -> Result<PsaResult, BadInput> {
    let target = PsaTarget::new(&session.mesh)
        .with_faces(&session.faces)
        .map_err(BadInput::new)?;
    let mesh_scale = session.file.part.mesh_scale;
    refuse_impossible_tool(&session.tool)?;
    let touch_points: Vec<Point3<f64>> = session.touches.iter().map(|t| t.point).collect();
    refuse_unit_mismatch(
        &session.mesh,
        mesh_scale,
        extent_m(&touch_points),
        "the touches span",
    )?;
    let options = options_for(choices, session.tool.tip_radius_m);
    align_touches(
        &target,
        &session.touches,
        &session.base_from_part_nominal,
        &options,
    )
    .map_err(|error| {
        let hints = unit_hints(&session.mesh, mesh_scale, Some(&session.tool));
        BadInput(with_hints(format!("cannot align: {error}"), &hints))
    })
}

/// The alignment's report with the pose uncertainty (or why there is none): what `ips align
/// SESSION` prints and the service's `align` replies.
pub fn report(session: &LoadedSession, result: &PsaResult) -> AlignReport {
    let mut notes = session
        .mesh
        .notes_with_unit_scale(session.file.part.mesh_scale);
    notes.extend(tool_warning(&session.tool));
    let mut aligned = output(result, notes);
    for residual in &mut aligned.alignment.residuals {
        residual.ball_centre = session
            .touches
            .iter()
            .find(|touch| touch.id == residual.id)
            .map(|touch| point_array(&touch.point));
    }
    aligned.base_frame = Some(session.base_frame().to_owned());
    match uncertainty(session, result) {
        Ok(json) => aligned.uncertainty = Some(json),
        Err(why) => aligned.uncertainty_error = Some(why),
    }
    aligned
}

/// The pose's uncertainty at the aligned pose, with the session's declared noise or, when it
/// declares none, the noise estimated from the residuals; `Err` says why it is not available.
pub fn uncertainty(session: &LoadedSession, result: &PsaResult) -> Result<Uncertainty, String> {
    let residuals: Vec<f64> = result.residuals.iter().map(|r| r.distance_m).collect();
    let residual_sigma = sigma_from_residuals(&residuals, 6);
    let (sigma_m, sigma_source) = match (session.file.noise_sigma, &residual_sigma) {
        (Some(sigma), _) => (sigma, "declared"),
        (None, Ok(sigma)) => (*sigma, "estimated"),
        (None, Err(error)) => {
            return Err(format!(
                "no noise_sigma declared and it cannot be estimated: {error}"
            ));
        }
    };
    let found = pose_uncertainty(
        &session.mesh,
        &session.touches,
        &result.alignment.base_from_part,
        session.tool.tip_radius_m,
        sigma_m,
    )
    .map_err(|error| error.to_string())?;
    let mut json = uncertainty_json(&found, sigma_source);
    json.residual_sigma_m = residual_sigma.ok();
    Ok(json)
}

fn array(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

fn point_array(p: &Point3<f64>) -> [f64; 3] {
    [p.x, p.y, p.z]
}

pub fn uncertainty_json(found: &PoseUncertainty, sigma_source: &str) -> Uncertainty {
    let mut covariance = [[0.0; 6]; 6];
    for (row, values) in covariance.iter_mut().enumerate() {
        for (col, value) in values.iter_mut().enumerate() {
            *value = found.covariance[(row, col)];
        }
    }
    let position = &found.position_95_mm;
    let rotation = &found.rotation_95_mrad;
    let weak = &found.weak_direction;
    let (size_95, unit) = weak.size_95();
    Uncertainty {
        sigma_m: found.sigma_m,
        sigma_source: sigma_source.to_owned(),
        residual_sigma_m: None,
        covariance,
        covariance_order: COVARIANCE_ORDER.map(str::to_owned),
        position_95_mm: Position95 {
            semi_axes: position.semi_axes,
            axes: position.axes.map(|a| array(&a)),
            x: position.half_widths[0],
            y: position.half_widths[1],
            z: position.half_widths[2],
        },
        rotation_95_mrad: Rotation95 {
            semi_axes: rotation.semi_axes,
            axes: rotation.axes.map(|a| array(&a)),
            rx: rotation.half_widths[0],
            ry: rotation.half_widths[1],
            rz: rotation.half_widths[2],
        },
        weak_direction: WeakDirection {
            kind: weak.kind().to_owned(),
            axis: array(&weak.axis()),
            point: weak.point().map(|p| point_array(&p)),
            size_95,
            unit: unit.to_owned(),
            pitch_m_per_rad: match weak {
                FoundWeakDirection::Screw {
                    pitch_m_per_rad, ..
                } => Some(*pitch_m_per_rad),
                _ => None,
            },
            text: weak.describe(),
        },
        least_uncertain_point: found.least_uncertain_point.map(|p| point_array(&p)),
        pose_distance_95_mm: Some(found.pose_distance_95_m * 1e3),
    }
}

fn output(result: &PsaResult, notes: Vec<String>) -> AlignReport {
    let residuals = result
        .residuals
        .iter()
        .map(|r| Residual {
            id: r.id.clone(),
            distance: r.distance_m,
            ball_centre: None,
        })
        .collect();
    AlignReport {
        alignment: summary(&result.alignment, residuals),
        ambiguous: result.is_ambiguous(),
        candidates: result
            .ambiguous_with
            .iter()
            .map(|c| Candidate {
                pose: report_pose(&c.base_from_part),
                rms: c.rms_m,
            })
            .collect(),
        starts: result.alignment.starts,
        notes,
        uncertainty: None,
        uncertainty_error: None,
        base_frame: None,
    }
}
