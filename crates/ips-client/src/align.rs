//! `ips align SESSION`: Point Set Alignment of a session's part to its inspections.

use align_core::pose::{matrix_rows, xyz_rpy};
use align_core::registration::psa::{
    PsaMethod, PsaOptions, PsaResult, PsaTarget, Search, align_touches,
};
use nalgebra::Isometry3;
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

/// DESIGN.md 6.4 keys, plus `ambiguous`, `candidates`, `starts`, `notes`.
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
    Ok(output(&result, session.mesh.notes().to_vec()))
}

pub fn output(result: &PsaResult, notes: Vec<String>) -> AlignOutput {
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
