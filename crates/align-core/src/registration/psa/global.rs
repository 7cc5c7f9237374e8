//! The global search: local alignments from orientations spread over the rotation group, the
//! promising ones polished, and the results ranked by likelihood with coherence as a prior.
//!
//! Ranking: with the touch noise sigma (declared, or estimated from the best fit), a pose scores
//! RSS / sigma^2 (its -2 log-likelihood) plus a penalty for every touch whose closest face turns
//! away from the probe. Poses within [`PsaOptions::ambiguity_chi2`] of the best score are
//! equally supported by the touches: the result is ambiguous only then, never because a start
//! failed to converge.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::local::{LocalSolution, Workspace};
use super::target::PsaTarget;
use super::{Candidate, PsaOptions, Touch};
use crate::registration::RegistrationError;
use crate::registration::convergence::pose_distance;

/// Explored starts polished in full at least (when that many distinct ones exist).
const MIN_CONTENDERS: usize = 8;
/// Explored starts polished in full at most: enough for every face pairing of a cube.
const MAX_CONTENDERS: usize = 32;

/// Touches the exploration matches at most: its runs only find where each start leads. On the
/// corpus parts (docs/touch-corpus.md) a spread two dozen found the basins that all 65 found; a
/// dozen lost one fixture session in four.
const EXPLORATION_TOUCHES: usize = 24;
/// Starts explored side by side between updates of the abandon threshold: the threshold, and so
/// the result, does not depend on how many threads run them.
const EXPLORATION_CHUNK: usize = 32;

/// The exploration's guided contacts may lie this factor farther than the closest facing
/// surface: its queries are mostly tens of millimetres off the part, where an exact answer
/// must open every node the sphere through the best triangle meets.
const EXPLORATION_SLACK: f64 = 1.5;

/// Poses scoring within this of the best fit alike (-2 log-likelihood units): a tie between
/// symmetric twins, not evidence.
const EXACT_TIE_CHI2: f64 = 0.1;

/// Full steps every start takes before the screening ranks them.
const SCREENING_STEPS: usize = 2;
/// The screening keeps one start in this many.
const SCREENING_KEEP_ONE_IN: usize = 4;

/// Local runs from each start in `starts`, side by side in chunks; `best_rms` (the abandon
/// threshold's reference) is updated between chunks.
fn run_chunks(
    target: &PsaTarget<'_>,
    touches: &[Touch],
    options: &PsaOptions,
    starts: &[Isometry3<f64>],
    best_rms: &mut f64,
    radius_m: f64,
) -> Result<Vec<LocalSolution>, RegistrationError> {
    let mut solutions = Vec::with_capacity(starts.len());
    for chunk in starts.chunks(EXPLORATION_CHUNK) {
        // A start still far worse than the best after its first full steps is heading for
        // another minimum: abandon it (ties that matter are found by the starts that get there
        // directly).
        let abandon_above = Some((20.0 * *best_rms).max(0.02 * radius_m));
        let explored: Vec<LocalSolution> = chunk
            .par_iter()
            .map(|start| {
                Workspace::new(target, touches, options).map(|mut explorer| {
                    explorer.polish = false;
                    explorer.guided_slack = EXPLORATION_SLACK;
                    // Only where each start leads matters here. Damping at once (no halving)
                    // was 10% faster but returned the twin nearest the start less often on the
                    // thesis's ambiguous 6-touch trials (49/40/24/11 of 50 at 100-1000 mm,
                    // against 50/47/30/12 with one halving).
                    explorer.halvings_before_damping = 1;
                    explorer.abandon_above = abandon_above;
                    explorer.run_local(start)
                })
            })
            .collect::<Result<_, _>>()?;
        *best_rms = explored.iter().map(|s| s.rms_m).fold(*best_rms, f64::min);
        solutions.extend(explored);
    }
    Ok(solutions)
}

/// Up to `count` touches spread over the set: farthest-point sampling from the touch farthest
/// from the centroid, so every region of the part the touches cover keeps a say.
fn spread_subset(touches: &[Touch], count: usize) -> Vec<Touch> {
    if touches.len() <= count {
        return touches.to_vec();
    }
    let centroid = touches
        .iter()
        .fold(Vector3::zeros(), |sum, touch| sum + touch.point.coords)
        / touches.len() as f64;
    let farthest = |distances: &[f64]| {
        distances
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map_or(0, |(i, _)| i)
    };
    let mut nearest: Vec<f64> = touches
        .iter()
        .map(|t| (t.point.coords - centroid).norm())
        .collect();
    let mut chosen = Vec::with_capacity(count);
    while chosen.len() < count {
        let next = farthest(&nearest);
        chosen.push(next);
        for (distance, touch) in nearest.iter_mut().zip(touches) {
            *distance = distance.min((touch.point - touches[next].point).norm());
        }
    }
    chosen.sort_unstable();
    chosen.into_iter().map(|i| touches[i].clone()).collect()
}

/// The screened starts of the exploration: where a few steps from each led.
pub(super) struct Screened {
    /// The spread subset of the touches the exploration matches.
    subset: Vec<Touch>,
    /// The exploration's options (short window, coarse tolerance).
    explore: PsaOptions,
    /// Each start's screening run, in the order of the starts.
    runs: Vec<LocalSolution>,
}

/// Short local runs from `count` orientations spread over SO(3), each translated so that the
/// mesh's centroid sits on the touches' centroid: the slide and a few full steps from every
/// start, on a spread subset of the touches matched head-on only, in parallel. Their results do
/// not depend on any other run (no start is abandoned this early), so the local run from the
/// user's start may run beside them.
pub(super) fn screen(
    target: &PsaTarget<'_>,
    touches: &[Touch],
    options: &PsaOptions,
    count: usize,
) -> Result<Screened, RegistrationError> {
    let centroid = touches
        .iter()
        .fold(Vector3::zeros(), |sum, touch| sum + touch.point.coords)
        / touches.len() as f64;
    let part_centroid = target.mesh().centroid().coords;
    let subset = spread_subset(touches, EXPLORATION_TOUCHES);
    // A short stopping window and a coarse tolerance find where each start leads; only the
    // poses that compete for best are then refined to full precision.
    let explore = PsaOptions {
        window: 3,
        tolerance_m: 1e-6,
        max_iterations: 30,
        slide_first: 4,
        ..options.clone()
    };
    // Fails here, once, rather than in every thread (a face hint naming no face).
    Workspace::new(target, &subset, &explore)?;
    let radius_m = target.mesh().radius_m();
    let starts: Vec<Isometry3<f64>> = spread_rotations(count)
        .into_iter()
        .map(|rotation| {
            let translation = centroid - rotation * part_centroid;
            Isometry3::from_parts(Translation3::from(translation), rotation)
        })
        .collect();
    let screen = PsaOptions {
        max_iterations: explore.slide_first + SCREENING_STEPS,
        ..explore.clone()
    };
    // No screening run is abandoned (they stop before the abandon check), so the threshold they
    // keep is not needed afterwards.
    let mut unused_best_rms_m = f64::INFINITY;
    let runs = run_chunks(
        target,
        &subset,
        &screen,
        &starts,
        &mut unused_best_rms_m,
        radius_m,
    )?;
    Ok(Screened {
        subset,
        explore,
        runs,
    })
}

/// The screened starts heading for the best fits (the best quarter) run on to where they lead.
/// `best_rms_m` is the best fit known besides (the local run from the user's start): starts
/// still far worse than it after their first steps are abandoned.
pub(super) fn explore(
    target: &PsaTarget<'_>,
    screened: Screened,
    best_rms_m: f64,
) -> Result<Vec<LocalSolution>, RegistrationError> {
    let Screened {
        subset,
        explore,
        runs,
    } = screened;
    let mut order: Vec<usize> = (0..runs.len()).collect();
    order.sort_by(|a, b| runs[*a].rms_m.total_cmp(&runs[*b].rms_m));
    let kept = (runs.len() / SCREENING_KEEP_ONE_IN).max(MIN_CONTENDERS * 4);
    let promising: Vec<Isometry3<f64>> = order.iter().take(kept).map(|&i| runs[i].pose).collect();
    let continued = PsaOptions {
        slide_first: 0,
        ..explore
    };
    let mut best_rms = runs.iter().map(|s| s.rms_m).fold(best_rms_m, f64::min);
    let radius_m = target.mesh().radius_m();
    let mut solutions = run_chunks(
        target,
        &subset,
        &continued,
        &promising,
        &mut best_rms,
        radius_m,
    )?;
    for (solution, &i) in solutions.iter_mut().zip(&order) {
        solution.iterations += runs[i].iterations;
    }
    Ok(solutions)
}

/// The explored solutions worth polishing: the distinct ones near the best RMS (every pose of a
/// symmetric set), and at least the [`MIN_CONTENDERS`] best distinct ones, since an explored RMS
/// is only a guide to the polished one.
pub(super) fn contenders(
    mut explored: Vec<LocalSolution>,
    radius_m: f64,
    options: &PsaOptions,
) -> Vec<LocalSolution> {
    explored.sort_by(|a, b| a.rms_m.total_cmp(&b.rms_m));
    let Some(best) = explored.first().map(|s| s.rms_m) else {
        return explored;
    };
    let band = 1.5 * best + 2.0 * options.ambiguity_tolerance_m;
    let mut distinct: Vec<LocalSolution> = Vec::new();
    for solution in explored {
        if distinct.len() >= MAX_CONTENDERS
            || (distinct.len() >= MIN_CONTENDERS && solution.rms_m > band)
        {
            break;
        }
        let seen = distinct.iter().any(|other| {
            pose_distance(&other.pose, &solution.pose, radius_m) < options.distinct_pose_m
        });
        if !seen {
            distinct.push(solution);
        }
    }
    distinct
}

/// Polishes the contenders in full, side by side.
pub(super) fn polish(
    target: &PsaTarget<'_>,
    touches: &[Touch],
    options: &PsaOptions,
    contenders: Vec<LocalSolution>,
) -> Result<Vec<LocalSolution>, RegistrationError> {
    contenders
        .into_par_iter()
        .map(|solution| {
            let mut workspace = Workspace::new(target, touches, options)?;
            let mut polished = workspace.run_local(&solution.pose);
            polished.iterations += solution.iterations;
            Ok(polished)
        })
        .collect()
}

/// The noise the ranking measures fits against: declared, or estimated from the best fit's
/// residual (N - 6 degrees of freedom), never below `ambiguity_tolerance_m` (noiseless data).
pub(super) fn ranking_sigma(options: &PsaOptions, best_rms_m: f64, touches: usize) -> f64 {
    let estimated = if touches > 6 {
        best_rms_m * (touches as f64 / (touches - 6) as f64).sqrt()
    } else {
        best_rms_m
    };
    options
        .noise_sigma_m
        .unwrap_or(estimated)
        .max(options.ambiguity_tolerance_m)
}

/// -2 log-posterior up to a constant: RSS / sigma^2 plus the coherence prior.
fn score(solution: &LocalSolution, sigma_m: f64, touches: usize, options: &PsaOptions) -> f64 {
    let rss = solution.rms_m * solution.rms_m * touches as f64;
    let prior = if options.coherence {
        options.incoherence_penalty_chi2 * solution.incoherent as f64
    } else {
        0.0
    };
    rss / (sigma_m * sigma_m) + prior
}

/// Picks the best-scoring solution; other distinct solutions within the ambiguity margin make it
/// ambiguous.
pub(super) fn choose(
    solutions: Vec<LocalSolution>,
    start: &Isometry3<f64>,
    radius_m: f64,
    touches: usize,
    options: &PsaOptions,
) -> (LocalSolution, Vec<Candidate>) {
    let best_rms = solutions
        .iter()
        .map(|s| s.rms_m)
        .fold(f64::INFINITY, f64::min);
    let sigma = ranking_sigma(options, best_rms, touches);
    let mut scored: Vec<(f64, LocalSolution)> = solutions
        .into_iter()
        .map(|s| (score(&s, sigma, touches, options), s))
        .collect();
    scored.sort_by(|a, b| a.0.total_cmp(&b.0));
    let best_score = scored[0].0;
    let mut distinct: Vec<(f64, LocalSolution)> = Vec::new();
    for (score, solution) in scored {
        if score > best_score + options.ambiguity_chi2 {
            break;
        }
        let seen = distinct.iter().any(|(_, other)| {
            pose_distance(&other.pose, &solution.pose, radius_m) < options.distinct_pose_m
        });
        if !seen {
            distinct.push((score, solution));
        }
    }
    // The best fit is reported; among poses that fit exactly alike (a symmetric part's twins),
    // the one nearest the start, the user's nominal pose.
    let nearest_tie = distinct
        .iter()
        .enumerate()
        .filter(|(_, (score, _))| *score <= best_score + EXACT_TIE_CHI2)
        .min_by(|a, b| {
            pose_distance(&a.1.1.pose, start, radius_m).total_cmp(&pose_distance(
                &b.1.1.pose,
                start,
                radius_m,
            ))
        })
        .map_or(0, |(i, _)| i);
    let (_, best) = distinct.remove(nearest_tie);
    let others = distinct
        .into_iter()
        .map(|(_, solution)| Candidate {
            base_from_part: solution.pose,
            rms_m: solution.rms_m,
        })
        .collect();
    (best, others)
}
/// `count` rotations spread evenly over SO(3) (Alexa's super-Fibonacci spirals, CVPR 2022):
/// deterministic, no clustering at the poles as with Euler-angle grids.
pub fn spread_rotations(count: usize) -> Vec<UnitQuaternion<f64>> {
    let phi = std::f64::consts::SQRT_2;
    let psi = 1.533_751_168_755_204_3;
    (0..count)
        .map(|i| {
            let s = i as f64 + 0.5;
            let r = (s / count as f64).sqrt();
            let big_r = (1.0 - s / count as f64).sqrt();
            let alpha = 2.0 * std::f64::consts::PI * s / phi;
            let beta = 2.0 * std::f64::consts::PI * s / psi;
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                r * alpha.sin(),
                r * alpha.cos(),
                big_r * beta.sin(),
                big_r * beta.cos(),
            ))
        })
        .collect()
}
