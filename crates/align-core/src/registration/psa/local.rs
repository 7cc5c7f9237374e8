//! One local alignment: closest-point correspondences and a rigid step, repeated until the pose
//! stops moving.
//!
//! With coherence on and approach directions known, a run has two phases. The guided phase
//! matches each touch to the nearest surface facing its probe, which widens the basin: a touch
//! pushed through a wall by a wrong start still finds the face it touched. The polish phase then
//! matches each touch to its plain closest point and descends monotonically to the least-squares
//! optimum of the signed distances, the pose the touches actually support. Coherence never
//! decides the final fit; it only steers the search and ranks its results.

use nalgebra::{Isometry3, Matrix6, Point3, Translation3, UnitQuaternion, Vector3, Vector6};

use super::target::{Contact, PsaTarget};
use super::{PsaMethod, PsaOptions, Touch, TouchResidual};
use crate::geometry::Mesh;
use crate::registration::convergence::{StopCriterion, pose_distance};
use crate::registration::{RegistrationError, weighted_svd};

/// How touches are matched to the surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Matching {
    /// The nearest surface facing the probe within the cone (rad), where the approach is known.
    Guided(f64),
    /// The plain closest point: what the least-squares optimum is defined by.
    Plain,
}

#[derive(Debug, Clone)]
pub(super) struct LocalSolution {
    pub pose: Isometry3<f64>,
    pub iterations: usize,
    pub converged: bool,
    /// RMS distance of the touches from the ball-offset surface at the last matching, m.
    pub rms_m: f64,
    /// Touches whose plain closest face turns away from the probe (polished solutions only).
    pub incoherent: usize,
}

/// The cone of the first guided stage: touches matched to faces they meet head-on.
const HEAD_ON_CONE_RAD: f64 = std::f64::consts::FRAC_PI_4;

/// The largest Levenberg-Marquardt damping tried before a pose counts as stationary.
const MAX_DAMPING: f64 = 1e4;

/// Halvings of a Gauss-Newton step that does not descend before it is damped instead. One: a
/// step that overshoots by more than twice mostly leans on a direction the touches barely
/// constrain, which damping handles and further halvings only approach (three halvings cost the
/// global search a quarter of its matchings; the trial tables held or improved with one).
const HALVINGS_BEFORE_DAMPING: i32 = 1;

/// A point-to-plane stage has settled when the pose moves by less than this fraction of the
/// RMS residual three iterations running: the touches cannot tell such poses apart.
const SETTLED_FRACTION_OF_RMS: f64 = 1e-4;

/// A point-to-plane step that lowers the RMS by less than this fraction ends the stage.
const RELATIVE_DESCENT: f64 = 1e-9;

/// Iterations of a guided stage that steers a later one at most.
const GUIDED_STAGE_ITERATIONS: usize = 40;
/// Pose tolerance of a steering stage, m.
const GUIDED_STAGE_TOLERANCE_M: f64 = 1e-7;

/// A copy of a workspace's correspondences.
#[derive(Debug, Default)]
struct SavedMatching {
    moved: Vec<Point3<f64>>,
    normals: Vec<Vector3<f64>>,
    weights: Vec<f64>,
    incoherent: usize,
}

/// How long one stage may run and when it has settled.
#[derive(Debug, Clone, Copy)]
struct StageBudget {
    max_iterations: usize,
    tolerance_m: f64,
}

/// Buffers reused across iterations and starts, so the hot loop does not allocate.
pub(super) struct Workspace<'t> {
    target: &'t PsaTarget<'t>,
    touches: &'t [Touch],
    surfaces: Vec<&'t Mesh>,
    pub(super) options: &'t PsaOptions,
    pub(super) radius_m: f64,
    moved: Vec<Point3<f64>>,
    normals: Vec<Vector3<f64>>,
    weights: Vec<f64>,
    fixed: Vec<Point3<f64>>,
    /// Touches whose contact at the last matching was incoherent.
    incoherent: usize,
    /// The correspondences at the pose a line search starts from, restored when a step fails
    /// instead of matched again.
    saved: SavedMatching,
    /// Each touch's last matched triangle: successive poses move a touch little, so it bounds
    /// the next closest-point search from the start.
    hints: Vec<Option<u32>>,
    /// Abandon a local run whose RMS is still above this after its first full steps.
    pub(super) abandon_above: Option<f64>,
    /// Whether runs go on past the head-on stage to the least-squares polish (off for the
    /// global search's exploration, which only finds where each start leads).
    pub(super) polish: bool,
    /// How much farther than the closest facing surface a guided contact may be (1: exact).
    /// The exploration allows more: it only finds where each start leads.
    pub(super) guided_slack: f64,
    /// A Gauss-Newton step that does not descend is halved this many times, then damped
    /// (Levenberg-Marquardt) if it still does not. Each try costs a matching of every touch.
    pub(super) halvings_before_damping: i32,
}

impl<'t> Workspace<'t> {
    pub(super) fn new(
        target: &'t PsaTarget<'t>,
        touches: &'t [Touch],
        options: &'t PsaOptions,
    ) -> Result<Self, RegistrationError> {
        let surfaces = touches
            .iter()
            .map(|touch| target.surface_for(touch))
            .collect::<Result<Vec<_>, _>>()?;
        let count = touches.len();
        Ok(Self {
            target,
            touches,
            surfaces,
            options,
            radius_m: target.mesh().radius_m(),
            moved: Vec::with_capacity(count),
            normals: Vec::with_capacity(count),
            weights: Vec::with_capacity(count),
            fixed: touches.iter().map(|touch| touch.point).collect(),
            incoherent: 0,
            saved: SavedMatching::default(),
            hints: vec![None; count],
            abandon_above: None,
            polish: true,
            guided_slack: 1.0,
            halvings_before_damping: HALVINGS_BEFORE_DAMPING,
        })
    }

    fn guided_available(&self) -> bool {
        self.options.coherence
            && self
                .touches
                .iter()
                .any(|touch| touch.approach.is_some() && touch.face.is_none())
    }

    /// The contact of touch `index` at the pose whose inverse is `part_from_base`.
    fn contact(
        &mut self,
        index: usize,
        part_from_base: &Isometry3<f64>,
        matching: Matching,
    ) -> Contact {
        let touch = &self.touches[index];
        let in_part = part_from_base * touch.point;
        let facing = touch
            .approach
            .and_then(|approach| (part_from_base.rotation * -approach).try_normalize(1e-12));
        let cone = self.options.coherence_cone_rad;
        let hint = self.hints[index];
        // Where no surface faces the probe at this pose, the plain contact, marked incoherent.
        let contact = if let Matching::Guided(guide_cone) = matching
            && self.options.coherence
            && touch.face.is_none()
            && let Some(facing) = &facing
            && let Some(found) =
                self.target
                    .guided_contact(&in_part, facing, guide_cone, hint, self.guided_slack)
        {
            found
        } else {
            self.target
                .plain_contact(self.surfaces[index], &in_part, facing.as_ref(), cone, hint)
        };
        self.hints[index] = Some(contact.triangle);
        contact
    }

    /// The surface point each touch corresponds to at `pose`, offset by the ball radius along
    /// its normal, and that normal, both in the base frame.
    pub(super) fn correspond(&mut self, pose: &Isometry3<f64>, matching: Matching) {
        self.moved.clear();
        self.normals.clear();
        self.weights.clear();
        self.incoherent = 0;
        let part_from_base = pose.inverse();
        let radius = self.options.tip_radius_m;
        for index in 0..self.touches.len() {
            let contact = self.contact(index, &part_from_base, matching);
            self.incoherent += usize::from(!contact.coherent);
            let centre_in_part = match matching {
                Matching::Guided(_) => contact.point + contact.normal * radius,
                // Where the ball centre would sit at its radius along the distance gradient:
                // the point-to-plane residual is then exactly the signed distance minus the
                // radius, at edges and corners too.
                Matching::Plain => {
                    let in_part = part_from_base * self.touches[index].point;
                    in_part - contact.normal * (contact.signed_distance_m - radius)
                }
            };
            self.moved.push(pose * centre_in_part);
            self.normals.push(pose.rotation * contact.normal);
            self.weights.push(1.0);
        }
    }

    fn save_matching(&mut self) {
        self.saved.moved.clone_from(&self.moved);
        self.saved.normals.clone_from(&self.normals);
        self.saved.weights.clone_from(&self.weights);
        self.saved.incoherent = self.incoherent;
    }

    fn restore_matching(&mut self) {
        self.moved.clone_from(&self.saved.moved);
        self.normals.clone_from(&self.saved.normals);
        self.weights.clone_from(&self.saved.weights);
        self.incoherent = self.saved.incoherent;
    }

    /// RMS distance of the touches from the (ball-offset) surface at the current correspondences.
    fn rms(&self) -> f64 {
        let sum: f64 = self
            .moved
            .iter()
            .zip(&self.fixed)
            .map(|(moved, fixed)| (fixed - moved).norm_squared())
            .sum();
        (sum / self.moved.len() as f64).sqrt()
    }

    /// One local alignment from `start`. Where coherence applies, the touches are first matched
    /// to surface facing them head-on (within [`HEAD_ON_CONE_RAD`]), which is where a start far
    /// off is most likely to find each touch's face, then to any surface their ball could have
    /// touched (the coherence cone), and finally polished on their plain closest points
    /// (point-to-plane only; the thesis's point-to-point step runs as it did).
    pub(super) fn run_local(&mut self, start: &Isometry3<f64>) -> LocalSolution {
        let point_to_plane = self.options.method == PsaMethod::PointToPlane;
        let guided = self.guided_available();
        let mut stages = Vec::with_capacity(3);
        if guided {
            stages.push(Matching::Guided(
                HEAD_ON_CONE_RAD.min(self.options.coherence_cone_rad),
            ));
            if self.polish && point_to_plane && self.options.coherence_cone_rad > HEAD_ON_CONE_RAD {
                stages.push(Matching::Guided(self.options.coherence_cone_rad));
            }
        }
        if self.polish && (point_to_plane || !guided) {
            stages.push(Matching::Plain);
        }
        let mut solution: Option<LocalSolution> = None;
        let abandon = self.abandon_above;
        let stage_count = stages.len();
        let last_matching = stages.last().copied();
        for (index, matching) in stages.into_iter().enumerate() {
            let from = solution.as_ref().map_or(*start, |s| s.pose);
            let slide = if index == 0 {
                self.options.slide_first
            } else {
                0
            };
            // Only the first stage may abandon: the later ones start where it settled.
            self.abandon_above = if index == 0 { abandon } else { None };
            // A guided stage followed by others only steers: it need not settle to the last
            // nanometre, and on curved, finely tessellated parts its matching may creep.
            let budget = if index + 1 < stage_count && matches!(matching, Matching::Guided(_)) {
                StageBudget {
                    max_iterations: self.options.max_iterations.min(GUIDED_STAGE_ITERATIONS),
                    tolerance_m: self.options.tolerance_m.max(GUIDED_STAGE_TOLERANCE_M),
                }
            } else {
                StageBudget {
                    max_iterations: self.options.max_iterations,
                    tolerance_m: self.options.tolerance_m,
                }
            };
            let mut next = self.iterate(&from, matching, slide, budget);
            next.iterations += solution.map_or(0, |s| s.iterations);
            solution = Some(next);
        }
        self.abandon_above = abandon;
        let mut solution = solution.unwrap_or_else(|| {
            let budget = StageBudget {
                max_iterations: self.options.max_iterations,
                tolerance_m: self.options.tolerance_m,
            };
            self.iterate(start, Matching::Plain, 0, budget)
        });
        solution.incoherent = match (self.polish, last_matching) {
            (false, _) => 0,
            // The last stage left the plain matching at the final pose.
            (true, Some(Matching::Plain)) => self.incoherent,
            (true, _) => {
                self.correspond(&solution.pose, Matching::Plain);
                self.incoherent
            }
        };
        if !(self.polish && guided && point_to_plane) {
            return solution;
        }
        // The guided stages widen the basin but, from a start already near the optimum, can
        // drag it elsewhere: a side contact matched head-on to the wrong face. The plain polish
        // straight from the start competes, and the better fit stands.
        let budget = StageBudget {
            max_iterations: self.options.max_iterations,
            tolerance_m: self.options.tolerance_m,
        };
        let mut direct = self.iterate(start, Matching::Plain, 0, budget);
        direct.incoherent = self.incoherent;
        let sigma = solution
            .rms_m
            .min(direct.rms_m)
            .max(self.options.ambiguity_tolerance_m);
        let score = |s: &LocalSolution| {
            (s.rms_m / sigma).powi(2) * self.touches.len() as f64
                + self.options.incoherence_penalty_chi2 * s.incoherent as f64
        };
        direct.iterations += solution.iterations;
        if score(&direct) < score(&solution) {
            direct
        } else {
            solution.iterations = direct.iterations;
            solution
        }
    }

    /// Iterates correspondences and steps. A step that increases the RMS distance (a
    /// linearisation that overshot, typically when a correspondence jumps to another face) is
    /// halved until it does not; when no fraction descends, the pose is a minimum at the
    /// resolution of the surface and the run has converged. The thesis's point-to-point step
    /// keeps its original rule (accept after six halvings), so its trial tables are unchanged.
    fn iterate(
        &mut self,
        start: &Isometry3<f64>,
        matching: Matching,
        translation_only: usize,
        budget: StageBudget,
    ) -> LocalSolution {
        let mut pose = *start;
        let mut stop = StopCriterion::new(self.options.window, budget.tolerance_m, self.radius_m);
        let mut converged = false;
        let mut iterations = 0;
        stop.update(&pose);
        self.correspond(&pose, matching);
        let mut rms = self.rms();
        let point_to_point = self.options.method == PsaMethod::PointToPoint;
        let mut still = 0;
        // Levenberg-Marquardt damping, relative to the normal matrix's mean diagonal.
        let mut damping = 0.0;
        'outer: while iterations < budget.max_iterations {
            iterations += 1;
            let sliding = iterations <= translation_only;
            let step = match self.options.method {
                PsaMethod::PointToPoint => weighted_svd(&self.moved, &self.fixed, &self.weights)
                    .ok()
                    .map(Twist::from_isometry),
                PsaMethod::PointToPlane => self.point_to_plane_step(sliding, damping),
            };
            let Some(mut step) = step else {
                break;
            };
            let mut fraction = 1.0;
            let rms_before = rms;
            self.save_matching();
            let candidate = loop {
                let candidate = step.scaled(fraction) * pose;
                self.correspond(&candidate, matching);
                let candidate_rms = self.rms();
                // While sliding, the orientation may still be wrong and the RMS need not fall.
                if sliding
                    || candidate_rms <= rms * (1.0 + 1e-12)
                    || (point_to_point && fraction < 1.0 / 64.0)
                {
                    if fraction == 1.0 {
                        damping = if damping > 1e-6 { damping * 0.1 } else { 0.0 };
                    }
                    rms = candidate_rms;
                    break candidate;
                }
                if !point_to_point && fraction <= 0.5f64.powi(self.halvings_before_damping) {
                    // The Gauss-Newton step overshoots even shortened: it leans on a direction
                    // the touches barely constrain (the spin of a turned part). Damp it towards
                    // gradient descent instead (Levenberg-Marquardt).
                    damping = if damping > 0.0 { damping * 10.0 } else { 1e-3 };
                    self.restore_matching();
                    match self.point_to_plane_step(sliding, damping) {
                        Some(damped) if damping <= MAX_DAMPING => {
                            step = damped;
                            fraction = 1.0;
                            continue;
                        }
                        _ => {
                            // No descent along any damped step: the pose is stationary.
                            converged = true;
                            break 'outer;
                        }
                    }
                }
                if fraction < 1.0 / 1024.0 {
                    // No descent along the step: the pose is stationary.
                    self.restore_matching();
                    converged = true;
                    break 'outer;
                }
                fraction *= 0.5;
            };
            let moved_m = pose_distance(&pose, &candidate, self.radius_m);
            pose = candidate;
            if !sliding && stop.update(&pose) {
                converged = true;
                break;
            }
            if !sliding && moved_m < budget.tolerance_m * 1e-3 {
                // Settled to far below the tolerance: every remaining iteration of the window
                // would find the same correspondences and stay within it.
                converged = true;
                break;
            }
            // Moves far below what the residual can resolve, three times running: settled.
            still = if moved_m < SETTLED_FRACTION_OF_RMS * rms {
                still + 1
            } else {
                0
            };
            if !sliding
                && !point_to_point
                && (rms_before - rms <= RELATIVE_DESCENT * rms_before || still >= 3)
            {
                // The RMS no longer falls: what moves now is a creep along a direction the
                // touches barely constrain (the spin of a turned part), a ripple of the
                // tessellation, far below what the touches can tell.
                converged = true;
                break;
            }
            if let Some(limit) = self.abandon_above
                && iterations >= translation_only + 6
                && rms > limit
            {
                break;
            }
        }
        LocalSolution {
            pose,
            iterations,
            converged,
            rms_m: rms,
            incoherent: self.incoherent,
        }
    }

    /// Normal equations of the linearised point-to-plane problem about the weighted centroid `c`:
    /// unknowns x = (omega, t), moved point y' = y + omega x (y - c) + t, residual
    /// n . (y' - i) = 0. Rotation columns are scaled by the part radius so the system is
    /// well-conditioned whatever the units.
    pub(super) fn normal_equations(&self) -> (Matrix6<f64>, Vector6<f64>, Point3<f64>) {
        let total: f64 = self.weights.iter().sum();
        let centre = Point3::from(
            self.moved
                .iter()
                .zip(&self.weights)
                .fold(Vector3::zeros(), |sum, (p, w)| sum + p.coords * *w)
                / total,
        );
        let scale = self.radius_m.max(1e-9);
        let mut normal_matrix = Matrix6::zeros();
        let mut rhs = Vector6::zeros();
        for (((moved, fixed), normal), weight) in self
            .moved
            .iter()
            .zip(&self.fixed)
            .zip(&self.normals)
            .zip(&self.weights)
        {
            let lever = (moved - centre).cross(normal) / scale;
            let row = Vector6::new(lever.x, lever.y, lever.z, normal.x, normal.y, normal.z);
            let residual = normal.dot(&(fixed - moved));
            normal_matrix += row * row.transpose() * *weight;
            rhs += row * (residual * weight);
        }
        (normal_matrix, rhs, centre)
    }

    fn point_to_plane_step(&self, translation_only: bool, damping: f64) -> Option<Twist> {
        let (mut normal_matrix, rhs, centre) = self.normal_equations();
        if damping > 0.0 {
            let mean_diagonal = normal_matrix.trace() / 6.0;
            for i in 0..6 {
                normal_matrix[(i, i)] += damping * mean_diagonal;
            }
        }
        if translation_only {
            let block = normal_matrix.fixed_view::<3, 3>(3, 3).into_owned();
            let translation = block
                .cholesky()?
                .solve(&rhs.fixed_rows::<3>(3).into_owned());
            return Some(Twist {
                omega: Vector3::zeros(),
                translation,
                centre,
            });
        }
        let solution = normal_matrix.cholesky()?.solve(&rhs);
        let scale = self.radius_m.max(1e-9);
        Some(Twist {
            omega: Vector3::new(solution[0], solution[1], solution[2]) / scale,
            translation: Vector3::new(solution[3], solution[4], solution[5]),
            centre,
        })
    }

    /// Each touch's signed distance from the aligned surface (ball radius removed) at its plain
    /// contact, and whether that contact is coherent.
    pub(super) fn residuals(&mut self, pose: &Isometry3<f64>) -> Vec<(TouchResidual, bool)> {
        let part_from_base = pose.inverse();
        (0..self.touches.len())
            .map(|index| {
                let contact = self.contact(index, &part_from_base, Matching::Plain);
                (
                    TouchResidual {
                        id: self.touches[index].id.clone(),
                        distance_m: contact.signed_distance_m - self.options.tip_radius_m,
                    },
                    contact.coherent,
                )
            })
            .collect()
    }
}

/// A rigid step: rotation `omega` (rotation vector) about `centre`, then `translation`.
#[derive(Debug, Clone, Copy)]
struct Twist {
    omega: Vector3<f64>,
    translation: Vector3<f64>,
    centre: Point3<f64>,
}

impl Twist {
    fn from_isometry(step: Isometry3<f64>) -> Self {
        Self {
            omega: step.rotation.scaled_axis(),
            translation: step.translation.vector,
            centre: Point3::origin(),
        }
    }

    /// The step shortened to `fraction` of its rotation and translation: y' = R (y - c) + c + t.
    fn scaled(&self, fraction: f64) -> Isometry3<f64> {
        let rotation = UnitQuaternion::from_scaled_axis(self.omega * fraction);
        let shift =
            self.centre.coords + self.translation * fraction - rotation * self.centre.coords;
        Isometry3::from_parts(Translation3::from(shift), rotation)
    }
}
