//! The thesis's AlignmentTests (section 2.3.4), reproduced: the part starts at its true pose,
//! is displaced at random (t = beta mu, beta ~ U[0, delta]; R = exp(alpha mu'), alpha ~
//! U[0, delta / r]; mu, mu' random unit vectors), and the alignment must bring it back. A trial
//! succeeds when the final pose lies within 1 mm of the truth by the thesis's pose distance
//! (eq. 22, with the part's radius r). The displacement turns the part about its centroid, so
//! delta bounds how far its points move wherever it sits in the cell.
//!
//! The generator is seeded; the same seed gives the same trials for every method compared.

pub mod clouds;
pub mod parts;
pub mod planning;
pub mod probing;
pub mod robot_scan;
pub mod robot_trials;

use std::time::Instant;

use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use crate::geometry::Mesh;
use crate::registration::convergence::pose_distance;
use crate::registration::pca::{PcaOptions, align_cloud};
use crate::registration::psa::{PsaOptions, PsaTarget, Touch, align_touches};
use clouds::{ScanOptions, scan_part};
use parts::TestPart;

/// A trial passes when the final pose is this close to the truth (thesis eq. 22), m.
pub const SUCCESS_THRESHOLD_M: f64 = 1e-3;

/// One row of the thesis's result tables.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialRow {
    pub delta_m: f64,
    pub succeeded: usize,
    pub failed: usize,
    /// Trials the method reported as ambiguous (counted in succeeded or failed by their pose).
    pub ambiguous: usize,
    pub mean_iterations: f64,
    /// Mean final pose distance over all trials, as the thesis reports it.
    pub mean_error_m: f64,
    pub mean_time_s: f64,
}

/// The trials' generator: seeded, so trials are identical on every machine.
pub type TrialRng = crate::rng::SplitMix64;

/// The thesis's random displacement (eq. 27-31).
pub fn random_displacement(rng: &mut TrialRng, delta_m: f64, radius_m: f64) -> Isometry3<f64> {
    let direction = rng.unit_vector();
    let axis = rng.unit_vector();
    let beta = rng.uniform() * delta_m;
    let alpha = rng.uniform() * delta_m / radius_m;
    Isometry3::from_parts(
        Translation3::from(direction * beta),
        UnitQuaternion::from_scaled_axis(axis * alpha),
    )
}

/// `base_from_part` displaced about the part's centroid.
pub fn displace_about_centroid(
    base_from_part: &Isometry3<f64>,
    mesh: &Mesh,
    displacement: &Isometry3<f64>,
) -> Isometry3<f64> {
    let centre = Isometry3::translation(mesh.centroid().x, mesh.centroid().y, mesh.centroid().z);
    base_from_part * centre * displacement * centre.inverse()
}

/// Which touches the trial uses and what they carry.
#[derive(Debug, Clone, PartialEq)]
pub struct TouchSetup {
    pub count: usize,
    pub tip_radius_m: f64,
    /// Label each touch with its planned face (CMM-style face hints).
    pub face_hints: bool,
    /// Give each touch its approach direction (the probe's axis, along the inward normal).
    pub approach: bool,
}

/// Ball-centre touches of `part` at `base_from_part`, from its touch plan.
pub fn plan_touches(
    part: &TestPart,
    base_from_part: &Isometry3<f64>,
    setup: &TouchSetup,
) -> Vec<Touch> {
    part.touches
        .iter()
        .take(setup.count)
        .enumerate()
        .map(|(index, planned)| Touch {
            id: (index + 1).to_string(),
            point: base_from_part * (planned.point + planned.normal * setup.tip_radius_m),
            approach: setup
                .approach
                .then(|| base_from_part.rotation * -planned.normal),
            face: setup.face_hints.then(|| planned.face.clone()),
        })
        .collect()
}

/// Runs `trials` seeded PSA trials at each delta and summarises them as the thesis's table.
/// `on_trial` is called after every trial (for progress output).
pub fn run_psa_trials(
    part: &TestPart,
    setup: &TouchSetup,
    options: &PsaOptions,
    deltas_m: &[f64],
    trials: usize,
    seed: u64,
    on_trial: impl FnMut(f64, usize),
) -> Vec<TrialRow> {
    let base_from_part = trial_pose();
    let touches = plan_touches(part, &base_from_part, setup);
    let target = match PsaTarget::new(&part.mesh).with_faces(&part.faces) {
        Ok(target) => target,
        Err(_) => PsaTarget::new(&part.mesh),
    };
    let options = PsaOptions {
        tip_radius_m: setup.tip_radius_m,
        ..options.clone()
    };
    run_trials(part, deltas_m, trials, seed, on_trial, |start, _| {
        align_touches(&target, &touches, start, &options)
            .ok()
            .map(|r| {
                (
                    r.alignment.base_from_part,
                    r.alignment.iterations,
                    r.is_ambiguous(),
                )
            })
    })
}

/// The seeded trial loop shared by PSA and PCA: `align(start, delta)` returns the final pose,
/// the iterations and whether the result was ambiguous, or `None` when it refused (the part
/// then stays where it started).
fn run_trials(
    part: &TestPart,
    deltas_m: &[f64],
    trials: usize,
    seed: u64,
    mut on_trial: impl FnMut(f64, usize),
    mut align: impl FnMut(&Isometry3<f64>, f64) -> Option<(Isometry3<f64>, usize, bool)>,
) -> Vec<TrialRow> {
    let base_from_part = trial_pose();
    let radius_m = part.mesh.radius_m();
    deltas_m
        .iter()
        .map(|&delta_m| {
            // Every method sees the same displacements for a given seed and delta.
            let mut rng = TrialRng::new(seed ^ delta_m.to_bits());
            let mut row = TrialRow {
                delta_m,
                succeeded: 0,
                failed: 0,
                ambiguous: 0,
                mean_iterations: 0.0,
                mean_error_m: 0.0,
                mean_time_s: 0.0,
            };
            for trial in 0..trials {
                let displacement = random_displacement(&mut rng, delta_m, radius_m);
                let start = displace_about_centroid(&base_from_part, &part.mesh, &displacement);
                let started = Instant::now();
                let result = align(&start, delta_m);
                let elapsed = started.elapsed().as_secs_f64();
                let (pose, iterations, ambiguous) = result.unwrap_or((start, 0, false));
                let error = pose_distance(&pose, &base_from_part, radius_m);
                if error < SUCCESS_THRESHOLD_M {
                    row.succeeded += 1;
                } else {
                    row.failed += 1;
                }
                row.ambiguous += usize::from(ambiguous);
                row.mean_iterations += iterations as f64;
                row.mean_error_m += error;
                row.mean_time_s += elapsed;
                on_trial(delta_m, trial);
            }
            let count = trials.max(1) as f64;
            row.mean_iterations /= count;
            row.mean_error_m /= count;
            row.mean_time_s /= count;
            row
        })
        .collect()
}

/// The cell pose the trials place the part at.
pub fn trial_pose() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.6, 0.1, 0.05),
        UnitQuaternion::from_euler_angles(0.0, 0.0, 0.3),
    )
}

/// Runs `trials` seeded PCA trials at each delta (delta is also the user's bound passed to the
/// alignment, as in the thesis) on one scan of the part at its true pose.
pub fn run_pca_trials(
    part: &TestPart,
    scan: &ScanOptions,
    options: &PcaOptions,
    deltas_m: &[f64],
    trials: usize,
    seed: u64,
    on_trial: impl FnMut(f64, usize),
) -> Vec<TrialRow> {
    let cloud = scan_part(&part.mesh, &trial_pose(), scan);
    run_trials(part, deltas_m, trials, seed, on_trial, |start, delta_m| {
        align_cloud(&part.mesh, &cloud, start, delta_m, options)
            .ok()
            .map(|r| {
                let ambiguous = r.uniqueness.as_ref().is_some_and(|u| u.ambiguous);
                (
                    r.alignment.base_from_part,
                    r.alignment.iterations,
                    ambiguous,
                )
            })
    })
}
