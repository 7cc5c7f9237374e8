//! Point Set Alignment (thesis 2.1.5): move a part's mesh until its surface passes through touch
//! inspections.
//!
//! Each iteration finds, for every touch, the closest point of the part's surface (offset outward
//! by the probe's ball radius, since the touch reports the ball's centre), then moves the part:
//! - [`PsaMethod::PointToPoint`] is the thesis's step, the weighted SVD onto those points. It
//!   converges linearly: a touch on a plane may slide along it only a fraction per iteration.
//! - [`PsaMethod::PointToPlane`] (default) solves the linearised problem in which each touch
//!   constrains only its distance along the surface normal: Gauss-Newton on the signed
//!   distances, descending monotonically to their least-squares optimum.
//!
//! Iteration stops with the thesis's criterion (the pose still within `tolerance_m` of each of the
//! last `window` poses, section 2.1.4), when no step along the Gauss-Newton direction descends
//! (a minimum at the surface's resolution), or after `max_iterations`.
//!
//! After the alignment the touch geometry is checked: if the surface normals at the touches
//! cannot fix all six degrees of freedom (all touches on parallel faces, say), the error names the
//! free motion instead of returning an arbitrary pose.
//!
//! Beyond the local method: [`align_touches`] with [`Search::Global`] runs the local method from
//! many orientations spread over the rotation group (`global`), polishes the promising ones and
//! ranks them by likelihood; it reports the result as ambiguous only when distinct poses fit the
//! touches within the noise (a symmetric part probed on symmetric faces). Face hints restrict a
//! touch's correspondence to one named face of the part, as a CMM's 3-2-1 alignment does with
//! datum features. Coherence (thesis 2.1.6) is a prior, never a filter: a ball touches with any
//! point of its front hemisphere, up to 90 degrees from the probe axis (a vertical stylus on a
//! vertical wall touches with its equator), so a face turned away from the probe by more than
//! [`PsaOptions::coherence_cone_rad`] could not have been touched. The local search uses that
//! to steer touches to faces they could have touched (`local`), the ranking to break ties
//! between poses that fit equally well; the final fit always matches every touch to its plain
//! closest point.

mod constraint;
mod global;
mod local;
mod target;

use std::time::Instant;

use nalgebra::{Isometry3, Point3, Vector3};

use super::svd::RegistrationError;
use crate::registration::Alignment;
pub use global::spread_rotations;
use local::Workspace;
pub use target::{Face, PsaTarget};

/// One touch inspection in the robot base frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Touch {
    pub id: String,
    /// Centre of the probe's ball tip (the TCP), base frame, m.
    pub point: Point3<f64>,
    /// Direction the probe travelled when it touched, base frame (the tool's z axis for a probe
    /// mounted along the flange axis). Used by coherence; `None` when unknown.
    pub approach: Option<Vector3<f64>>,
    /// Name of the part face this touch was meant for (see [`Face`]); `None` when unlabelled.
    pub face: Option<String>,
}

impl Touch {
    pub fn new(id: impl Into<String>, point: Point3<f64>) -> Self {
        Self {
            id: id.into(),
            point,
            approach: None,
            face: None,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PsaMethod {
    PointToPoint,
    PointToPlane,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Search {
    /// One local alignment from the start pose (the thesis's behaviour).
    Local,
    /// Local alignments from the start pose and from `starts` orientations spread over SO(3).
    Global { starts: usize },
}

#[derive(Debug, Clone, PartialEq)]
pub struct PsaOptions {
    pub method: PsaMethod,
    pub search: Search,
    /// Radius of the probe's ball tip, m.
    pub tip_radius_m: f64,
    pub max_iterations: usize,
    /// Stopping criterion: the pose must stay within `tolerance_m` (thesis eq. 22) of each of the
    /// last `window` poses. Thesis: N = 19.
    pub window: usize,
    pub tolerance_m: f64,
    /// Coherence of correspondences (thesis 2.1.6), a prior: touches with a known approach
    /// direction are steered to surface facing the probe while the search runs, and poses at
    /// which a touch's closest face turns away from its probe rank lower. The final fit matches
    /// every touch to its plain closest point whatever this says.
    pub coherence: bool,
    /// Largest angle between a touched face's outward normal and the reversed approach
    /// direction: the ball's front hemisphere (90 degrees) plus a margin for the stylus's and the
    /// mesh's normal errors.
    pub coherence_cone_rad: f64,
    /// The declared touch noise (1 sigma), m. Poses are ranked by RSS / sigma^2; without it
    /// sigma is estimated from the best fit's residual.
    pub noise_sigma_m: Option<f64>,
    /// Poses scoring within this of the best (-2 log-likelihood units; 6 is a likelihood ratio
    /// of 20) are equally supported by the touches: the result is then ambiguous.
    pub ambiguity_chi2: f64,
    /// Prior cost of one touch whose closest face turns away from its probe, in the same units
    /// (9: as unlikely as a 3-sigma residual).
    pub incoherence_penalty_chi2: f64,
    /// The smallest sigma the ranking uses, m: on noiseless data, fits this close are ties.
    pub ambiguity_tolerance_m: f64,
    /// Poses closer than this (thesis eq. 22) are the same solution, m.
    pub distinct_pose_m: f64,
    /// Iterations that only translate the part before full steps begin (point-to-plane only).
    /// The global search's starts use them: their orientation is a guess, their translation a
    /// rough centroid match.
    pub slide_first: usize,
}

impl Default for PsaOptions {
    fn default() -> Self {
        Self {
            method: PsaMethod::PointToPlane,
            search: Search::Global { starts: 384 },
            tip_radius_m: 0.0,
            max_iterations: 300,
            window: 19,
            tolerance_m: 1e-9,
            coherence: true,
            coherence_cone_rad: 100f64.to_radians(),
            noise_sigma_m: None,
            ambiguity_chi2: 6.0,
            incoherence_penalty_chi2: 9.0,
            ambiguity_tolerance_m: 1e-5,
            distinct_pose_m: 1e-3,
            slide_first: 0,
        }
    }
}

/// Signed distance of one touch from the aligned surface (ball radius removed), m.
#[derive(Debug, Clone, PartialEq)]
pub struct TouchResidual {
    pub id: String,
    pub distance_m: f64,
}

/// A converged candidate pose of a global search.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    pub base_from_part: Isometry3<f64>,
    pub rms_m: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct PsaResult {
    pub alignment: Alignment,
    pub residuals: Vec<TouchResidual>,
    /// Other distinct poses that fit as well as the chosen one (empty unless ambiguous).
    pub ambiguous_with: Vec<Candidate>,
    /// Touches whose closest face at the chosen pose turns away from their probe (beyond the
    /// coherence cone): a contact the ball could not have made there, worth a look.
    pub incoherent: Vec<String>,
}

impl PsaResult {
    pub fn is_ambiguous(&self) -> bool {
        !self.ambiguous_with.is_empty()
    }
}

/// Aligns the part to the touches, starting from `base_from_part_start` (the nominal pose).
pub fn align_touches(
    target: &PsaTarget<'_>,
    touches: &[Touch],
    base_from_part_start: &Isometry3<f64>,
    options: &PsaOptions,
) -> Result<PsaResult, RegistrationError> {
    let started = Instant::now();
    validate(touches, options)?;
    let mut workspace = Workspace::new(target, touches, options)?;
    let radius_m = target.mesh().radius_m();
    let (mut solutions, starts) = match options.search {
        Search::Local => (vec![workspace.run_local(base_from_part_start)], 1),
        Search::Global { starts } => {
            // The screening does not depend on the local run: the two go side by side.
            let (local, screened) = rayon::join(
                || workspace.run_local(base_from_part_start),
                || global::screen(target, touches, options, starts),
            );
            let explored = global::explore(target, screened?, local.rms_m)?;
            let contenders = global::contenders(explored, radius_m, options);
            let mut solutions = global::polish(target, touches, options, contenders)?;
            solutions.push(local);
            (solutions, starts + 1)
        }
    };
    solutions.retain(|s| s.rms_m.is_finite());
    if solutions.is_empty() {
        return Err(RegistrationError::Underconstrained {
            dof: "no start reached the part's surface".to_owned(),
        });
    }
    let (mut best, ambiguous_with) = global::choose(
        solutions,
        base_from_part_start,
        radius_m,
        touches.len(),
        options,
    );
    // Checked where the alignment ended: far from the part every touch may find the same face,
    // which says nothing about the touches themselves.
    constraint::check_constrained(&mut workspace, &best.pose)?;
    best.iterations = best.iterations.max(1);
    let (residuals, incoherent): (Vec<TouchResidual>, Vec<String>) =
        workspace.residuals(&best.pose).into_iter().fold(
            (Vec::new(), Vec::new()),
            |(mut all, mut odd), (residual, coherent)| {
                if options.coherence && !coherent {
                    odd.push(residual.id.clone());
                }
                all.push(residual);
                (all, odd)
            },
        );
    let max_m = residuals
        .iter()
        .map(|r| r.distance_m.abs())
        .fold(0.0, f64::max);
    Ok(PsaResult {
        alignment: Alignment {
            base_from_part: best.pose,
            iterations: best.iterations,
            converged: best.converged,
            rms_m: best.rms_m,
            max_m,
            starts,
            time_s: started.elapsed().as_secs_f64(),
        },
        residuals,
        ambiguous_with,
        incoherent,
    })
}

fn validate(touches: &[Touch], options: &PsaOptions) -> Result<(), RegistrationError> {
    if touches.len() < 3 {
        return Err(RegistrationError::TooFewPoints(touches.len()));
    }
    for (index, touch) in touches.iter().enumerate() {
        let approach_finite = touch
            .approach
            .is_none_or(|a| a.iter().all(|c| c.is_finite()));
        if !touch.point.coords.iter().all(|c| c.is_finite()) || !approach_finite {
            return Err(RegistrationError::NonFinite { index });
        }
    }
    if !(options.tip_radius_m.is_finite() && options.tip_radius_m >= 0.0) {
        return Err(RegistrationError::NonFinite { index: usize::MAX });
    }
    Ok(())
}
