//! `ips align SESSION`: Point Set Alignment of a session's part to its inspections.

use align_core::pose::{matrix_rows, xyz_rpy};
use align_core::registration::psa::{
    PsaMethod, PsaOptions, PsaResult, PsaTarget, Search, align_touches,
};
use align_core::registration::uncertainty::{
    COVARIANCE_ORDER, PoseUncertainty, WeakDirection, pose_uncertainty, sigma_from_residuals,
};
use nalgebra::{Isometry3, Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::BadInput;
use crate::cli::AlignArgs;
use crate::session::LoadedSession;

#[derive(Debug, Serialize, Deserialize)]
pub struct PoseJson {
    pub xyz: [f64; 3],
    pub rpy: [f64; 3],
    /// Homogeneous 4x4 `base_from_part`, rows.
    pub matrix: [[f64; 4]; 4],
}

impl From<&Isometry3<f64>> for PoseJson {
    fn from(pose: &Isometry3<f64>) -> Self {
        let (xyz, rpy) = xyz_rpy(pose);
        Self {
            xyz,
            rpy,
            matrix: matrix_rows(pose),
        }
    }
}

#[derive(Debug, Serialize, Deserialize)]
pub struct ResidualJson {
    pub id: String,
    /// Signed distance of the touch from the aligned surface (ball radius removed), m.
    pub distance: f64,
}

#[derive(Debug, Serialize)]
pub struct CandidateJson {
    pub pose: PoseJson,
    pub rms: f64,
}

/// The 95 % confidence region of the part origin's position, mm.
#[derive(Debug, Serialize)]
pub struct Position95Json {
    /// Semi-axes of the 3-dof 95 % ellipsoid, largest first.
    pub semi_axes: [f64; 3],
    /// Their unit directions, base frame.
    pub axes: [[f64; 3]; 3],
    /// 95 % half-widths (1.96 sd) of x, y, z alone.
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// The 95 % confidence region of the orientation (rotation vector, base frame), mrad.
#[derive(Debug, Serialize)]
pub struct Rotation95Json {
    pub semi_axes: [f64; 3],
    pub axes: [[f64; 3]; 3],
    pub rx: f64,
    pub ry: f64,
    pub rz: f64,
}

/// The least constrained motion of the part.
#[derive(Debug, Serialize)]
pub struct WeakDirectionJson {
    /// "translation", "rotation" or "screw".
    pub kind: &'static str,
    /// Translation direction or rotation axis (unit, base frame).
    pub axis: [f64; 3],
    /// A point on the rotation axis (base frame, m); null for a translation.
    pub point: Option<[f64; 3]>,
    /// 95 % size (1.96 sd along this one motion) in `unit`.
    pub size_95: f64,
    /// "mm" for a translation, "mrad" for a rotation or screw.
    pub unit: &'static str,
    /// Screws only: translation along the axis per rotation, m/rad (= mm/mrad).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pitch_m_per_rad: Option<f64>,
    pub text: String,
}

/// Pose covariance from the noise and the touch geometry (align_core::registration::uncertainty).
#[derive(Debug, Serialize)]
pub struct UncertaintyJson {
    /// Touch noise the covariance assumes, m.
    pub sigma_m: f64,
    /// "declared" (the session's `noise_sigma`) or "estimated" (from the residuals, N - 6 dof).
    pub sigma_source: &'static str,
    /// The noise the residuals suggest, sqrt(RSS / (N - 6)), m; null with 6 touches or fewer. Far
    /// above a declared sigma, the model lacks an effect (`ips diagnose`) and the covariance,
    /// which assumes the declared noise, is optimistic.
    pub residual_sigma_m: Option<f64>,
    /// 6x6 rows in `covariance_order`: rotation vector of the part in the base frame (rad), then
    /// the part origin's position in the base frame (m).
    pub covariance: [[f64; 6]; 6],
    pub covariance_order: [&'static str; 6],
    pub position_95_mm: Position95Json,
    pub rotation_95_mrad: Rotation95Json,
    pub weak_direction: WeakDirectionJson,
    /// The part point (base frame, m) whose position is known best, if computable.
    pub least_uncertain_point: Option<[f64; 3]>,
}

/// DESIGN.md 6.4 keys, plus `ambiguous`, `candidates`, `starts`, `notes`, and from `ips align
/// SESSION` either `uncertainty` or `uncertainty_error` (why it could not be computed).
#[derive(Debug, Serialize)]
pub struct AlignOutput {
    pub pose: PoseJson,
    pub iterations: usize,
    pub converged: bool,
    pub rms: f64,
    pub max: f64,
    pub time_s: f64,
    pub residuals: Vec<ResidualJson>,
    pub ambiguous: bool,
    pub candidates: Vec<CandidateJson>,
    pub starts: usize,
    pub notes: Vec<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<UncertaintyJson>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty_error: Option<String>,
}

pub fn options_for(args: &AlignArgs, tip_radius_m: f64) -> PsaOptions {
    let defaults = PsaOptions::default();
    PsaOptions {
        method: if args.point_to_point {
            PsaMethod::PointToPoint
        } else {
            PsaMethod::PointToPlane
        },
        search: if args.local {
            Search::Local
        } else {
            defaults.search
        },
        coherence: !args.no_coherence,
        tip_radius_m,
        ..defaults
    }
}

pub fn run(args: &AlignArgs) -> Result<AlignOutput, BadInput> {
    let path = args
        .session
        .as_ref()
        .ok_or_else(|| BadInput("align needs a SESSION file or --service ENDPOINT".to_owned()))?;
    let session = LoadedSession::load(path)?;
    let target = PsaTarget::new(&session.mesh)
        .with_faces(&session.faces)
        .map_err(BadInput::new)?;
    let options = options_for(args, session.tool.tip_radius_m);
    let result = align_touches(
        &target,
        &session.touches,
        &session.base_from_part_nominal,
        &options,
    )
    .map_err(|error| BadInput(format!("cannot align: {error}")))?;
    Ok(report(&session, &result))
}

/// The alignment's report with the pose uncertainty (or why there is none): what `ips align
/// SESSION` prints and the service's `align` replies.
pub fn report(session: &LoadedSession, result: &PsaResult) -> AlignOutput {
    let mut aligned = output(result, session.mesh.notes().to_vec());
    match uncertainty(session, result) {
        Ok(json) => aligned.uncertainty = Some(json),
        Err(why) => aligned.uncertainty_error = Some(why),
    }
    aligned
}

/// The pose's uncertainty at the aligned pose, with the session's declared noise or, when it
/// declares none, the noise estimated from the residuals; `Err` says why it is not available.
pub fn uncertainty(session: &LoadedSession, result: &PsaResult) -> Result<UncertaintyJson, String> {
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
        &result.base_from_part,
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

pub fn uncertainty_json(found: &PoseUncertainty, sigma_source: &'static str) -> UncertaintyJson {
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
    UncertaintyJson {
        sigma_m: found.sigma_m,
        sigma_source,
        residual_sigma_m: None,
        covariance,
        covariance_order: COVARIANCE_ORDER,
        position_95_mm: Position95Json {
            semi_axes: position.semi_axes,
            axes: position.axes.map(|a| array(&a)),
            x: position.half_widths[0],
            y: position.half_widths[1],
            z: position.half_widths[2],
        },
        rotation_95_mrad: Rotation95Json {
            semi_axes: rotation.semi_axes,
            axes: rotation.axes.map(|a| array(&a)),
            rx: rotation.half_widths[0],
            ry: rotation.half_widths[1],
            rz: rotation.half_widths[2],
        },
        weak_direction: WeakDirectionJson {
            kind: weak.kind(),
            axis: array(&weak.axis()),
            point: weak.point().map(|p| point_array(&p)),
            size_95,
            unit,
            pitch_m_per_rad: match weak {
                WeakDirection::Screw {
                    pitch_m_per_rad, ..
                } => Some(*pitch_m_per_rad),
                _ => None,
            },
            text: weak.describe(),
        },
        least_uncertain_point: found.least_uncertain_point.map(|p| point_array(&p)),
    }
}

fn output(result: &PsaResult, notes: Vec<String>) -> AlignOutput {
    AlignOutput {
        pose: PoseJson::from(&result.base_from_part),
        iterations: result.iterations,
        converged: result.converged,
        rms: result.rms_m,
        max: result.max_m,
        time_s: result.time_s,
        residuals: result
            .residuals
            .iter()
            .map(|r| ResidualJson {
                id: r.id.clone(),
                distance: r.distance_m,
            })
            .collect(),
        ambiguous: result.is_ambiguous(),
        candidates: result
            .ambiguous_with
            .iter()
            .map(|c| CandidateJson {
                pose: PoseJson::from(&c.base_from_part),
                rms: c.rms_m,
            })
            .collect(),
        starts: result.starts,
        notes,
        uncertainty: None,
        uncertainty_error: None,
    }
}

impl AlignOutput {
    pub fn to_text(&self) -> String {
        let [x, y, z] = self.pose.xyz.map(|v| crate::display_round(v, 6));
        let [roll, pitch, yaw] = self.pose.rpy.map(|v| crate::display_round(v, 6));
        let mut text = format!(
            "base_from_part: xyz [m] {x:.6} {y:.6} {z:.6}, rpy [rad] {roll:.6} {pitch:.6} {yaw:.6}\n"
        );
        text += &format!(
            "{} after {} iterations ({} starts) in {:.1} ms; residual rms {:.4} mm, max {:.4} mm\n",
            if self.converged {
                "converged"
            } else {
                "NOT converged"
            },
            self.iterations,
            self.starts,
            self.time_s * 1e3,
            self.rms * 1e3,
            self.max * 1e3
        );
        if let Some(found) = &self.uncertainty {
            let position = &found.position_95_mm;
            let rotation = &found.rotation_95_mrad;
            text += &format!(
                "95% confidence (noise sigma {:.4} mm, {}): position +-{:.3} / {:.3} / {:.3} mm (x/y/z), \
                 rotation +-{:.3} / {:.3} / {:.3} mrad (rx/ry/rz)\n  {}\n",
                found.sigma_m * 1e3,
                found.sigma_source,
                position.x,
                position.y,
                position.z,
                rotation.rx,
                rotation.ry,
                rotation.rz,
                found.weak_direction.text
            );
            if let Some(residual) = found.residual_sigma_m
                && found.sigma_source == "declared"
                && residual > 2.0 * found.sigma_m
            {
                text += &format!(
                    "  the residuals suggest a noise of {:.4} mm against the declared {:.4} mm: \
                     the model lacks an effect (ips diagnose) and these limits are optimistic\n",
                    residual * 1e3,
                    found.sigma_m * 1e3
                );
            }
        } else if let Some(why) = &self.uncertainty_error {
            text += &format!("pose uncertainty not available: {why}\n");
        }
        if self.ambiguous {
            text += &format!(
                "AMBIGUOUS: {} other poses fit the inspections as well (symmetric part or too few touches); \
                 the pose shown is the one nearest the nominal pose. Add touches on distinguishing features \
                 or label touches with faces.\n",
                self.candidates.len()
            );
            for candidate in &self.candidates {
                let [x, y, z] = candidate.pose.xyz;
                let [roll, pitch, yaw] = candidate.pose.rpy;
                text += &format!(
                    "  candidate: xyz {x:.6} {y:.6} {z:.6}, rpy {roll:.4} {pitch:.4} {yaw:.4}, rms {:.4} mm\n",
                    candidate.rms * 1e3
                );
            }
        }
        text += "residuals (mm):\n";
        for residual in &self.residuals {
            text += &format!("  {:>6}  {:+.4}\n", residual.id, residual.distance * 1e3);
        }
        for note in &self.notes {
            text += &format!("note: {note}\n");
        }
        text
    }
}
