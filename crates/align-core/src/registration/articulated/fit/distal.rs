//! The last look at the small links at the end of the chain (a wrist and its flange): each of
//! their joints swept densely on the fine keypoints in a narrow band.
//!
//! The searches score in a band of three keypoint voxels and the refinements weigh points up to
//! a centimetre off: a wrist whose only off-axis feature is a flange 65 mm from the joint turns
//! 0.1 rad before it leaves either. On the ABB IRB 1600 in ray-cast scans (crates/cad-scans,
//! `robot-scans`) the search left joint 5 0.1-0.3 rad off with its flange's 15-40 keypoints still
//! inside those bands, and the refinement did not move it: link_5 7-12 mm off.
//!
//! The sweep grades each keypoint by its distance within its narrow band rather than counting
//! it: in one ray-cast scene the wrist shows on 62 keypoints no other link explains, and 57 of
//! them lay within the band at the true joint 5 against 52 where the fit had left it, 0.12 rad
//! off (0.4 mm against 1.6 mm rms). A count could not tell them apart by the gain it asks.

use nalgebra::{Isometry3, Point3};
use rayon::prelude::*;

use super::context::FitContext;
use super::placed::{Distances, Placed};
use super::refine::refine;
use super::report::final_state;
use super::tree::{Window, search_order};

/// A joint is swept when the fine keypoints near the links it moves that no other link explains
/// are at most this many: the small links at the end of the chain. A large link's refinement
/// has points enough to pull it into place, and sweeping it would cost a fit's time.
const SWEPT_POINTS_MAX: usize = 1500;

/// The sweep's coarse pass steps this many narrow bands at the farthest point and grades in a
/// band this many times as wide, on the distance grids; the fine pass then steps one band, from
/// exact queries, about the coarse values near its best, its best few peaks and the state.
const COARSE_STEP_BANDS: f64 = 4.0;

/// The coarse pass's peaks the fine pass searches about, besides the state.
const FINE_CENTRES: usize = 3;

/// How far the fine pass searches about each centre, in coarse steps each way: the coarse
/// band's peak can sit a step or so from the narrow band's.
const FINE_REACH_COARSE_STEPS: f64 = 2.0;

/// The least graded gain for which a swept value is taken where the scan pins the joint and does
/// not pin it at the state (a count of keypoints would need as many). In a ray-cast scene of the
/// ABB IRB 1600 at 1000 mm (`robot-scans --seed 20 --scene 1 --first-trial 4`) the fit left
/// joint 5 0.43 rad off, where the scan does not pin it, so the report set it unseen; the true
/// value, which the scan pins, graded 6.8 more on 65 free keypoints, short of the 8 the square
/// root asks, a margin for a choice between two values both pinned.
const PINNED_GAIN_MIN: f64 = 4.0;

/// A joint is swept only when its links reach at most this far from its axis, m: a wrist's
/// (the ABB IRB 1600's joint 5 0.11 m, its flange 0.07 m), not a forearm's, whose links hold
/// points enough for the refinement and whose sweep costs a fit's time.
const SWEPT_REACH_MAX_M: f64 = 0.15;

impl FitContext<'_> {
    /// Sweeps each revolute joint whose links reach at most [`SWEPT_REACH_MAX_M`] from its axis
    /// over a whole turn (half a turn each way, slid inside its limits). It scores the fine
    /// keypoints within the sweep's reach of the links it moves that no other link explains, at
    /// most [`SWEPT_POINTS_MAX`] of them, each graded by its distance within a band
    /// ([`Placed::closeness`]). Coarse to fine: the whole turn in steps that move the farthest
    /// point by [`COARSE_STEP_BANDS`] narrow bands (half a keypoint voxel each), graded in a band
    /// as wide on the distance grids; then steps of one narrow band graded in it from exact
    /// queries, about every coarse value within the coarse scores' noise of their best, the
    /// best [`FINE_CENTRES`] coarse peaks and the state. The best value,
    /// when it scores above the state by [`sweep_gain_needed`], is refined and kept when it
    /// still scores that much more on the same keypoints; or by [`PINNED_GAIN_MIN`], or by a
    /// gain most free keypoints agree on (`consistent_gain`), when the fine keypoints pin the
    /// joint there and not at the state (`pins`). A joint whose state
    /// leaves fewer free points unexplained than the square root's gain is not swept at all.
    /// Returns the iterations spent.
    ///
    /// Coarse to fine because the whole turn in narrow steps from exact queries cost the UR10's
    /// fit at 100 mm a third to a half more time (its two wrist joints: 260 and 150 values on 460
    /// and 145 points).
    ///
    /// A whole turn, not a window about the state: the searches can leave a wrist folded the
    /// other way (the ABB's joint 5 at -1.7 rad against 0.78 in a ray-cast scene at 500 mm),
    /// where a window of 0.46 rad each way never reaches the truth. Near starts too: in the
    /// ray-cast scans at 50 and 100 mm, four fits that left joint 5 off were found only by the
    /// whole turn (the window, given the same points, found none of them).
    pub(super) fn distal_sweep(
        &self,
        world_from_root: &mut Isometry3<f64>,
        q: &mut Vec<f64>,
    ) -> usize {
        let FitContext {
            body,
            scan,
            options,
            ..
        } = *self;
        let band = 0.5 * options.voxel_m;
        let mut iterations = 0;
        for parameter in search_order(body) {
            let placed = Placed::new(body, world_from_root, q);
            let Some(window) = Window::whole_turn(body, &placed, parameter, options.voxel_m) else {
                continue;
            };
            if window.reach_m > SWEPT_REACH_MAX_M {
                continue;
            }
            let moved: Vec<usize> = body
                .moved_by(parameter)
                .into_iter()
                .filter(|&l| body.links()[l].surface.is_some())
                .collect();
            let others: Vec<usize> = (0..body.links().len())
                .filter(|l| body.links()[*l].surface.is_some() && !moved.contains(l))
                .collect();
            // A turn moves a point by a chord: at most the diameter of its circle.
            let reach = 2.0 * window.reach_m + band;
            let near: Vec<Point3<f64>> = scan
                .fine
                .iter()
                .filter(|p| moved.iter().any(|&l| placed.within_reach(p, l, reach)))
                .copied()
                .collect();
            let free: Vec<Point3<f64>> = near
                .into_iter()
                .filter(|p| !placed.supports(p, band, &others))
                .collect();
            if free.is_empty() || free.len() > SWEPT_POINTS_MAX {
                continue;
            }
            // The free points' grades in `band`, with the links at `root` and `joints`.
            let grades_in = |root: &Isometry3<f64>, joints: &[f64], band: f64| -> Vec<f64> {
                let at = Placed::new(body, root, joints);
                free.iter()
                    .map(|p| at.closeness(p, band, band, &moved, Distances::Exact))
                    .collect()
            };
            let graded_in =
                |root: &Isometry3<f64>, joints: &[f64], band: f64, distances: Distances| -> f64 {
                    let at = Placed::new(body, root, joints);
                    free.iter()
                        .map(|p| at.closeness(p, band, band, &moved, distances))
                        .sum()
                };
            let graded_at = |value: f64, band: f64, distances: Distances| -> f64 {
                let mut trial = q.clone();
                trial[parameter] = value;
                graded_in(world_from_root, &trial, band, distances)
            };
            let score = |value: f64| graded_at(value, band, Distances::Exact);
            let current = q[parameter];
            let here_grades = grades_in(world_from_root, q, band);
            let here: f64 = here_grades.iter().sum();
            // A point grades at most 1: when even every free point at its best could not
            // gain what a swept value must, no value can, and the sweep would only cost
            // time. A converged wrist explains nearly all its points (the UR10's two wrist
            // joints in the bench's scene 448 of 460 and 138 of 145, against gains of 22
            // and 12 needed).
            if free.len() as f64 - here < sweep_gain_needed(here) {
                continue;
            }
            let coarse_band = COARSE_STEP_BANDS * band;
            let coarse_score = |value: f64| graded_at(value, coarse_band, Distances::Grids);
            // Steps that move the farthest point by the band, and the coarse pass's by its own.
            let step = band / window.reach_m;
            let coarse_step = COARSE_STEP_BANDS * step;
            let (lower, upper) = window.slid_span(body, current);
            let coarse_steps = (((upper - lower) / coarse_step).ceil() as usize).max(2);
            let coarse_values = window.slid_grid(body, current, coarse_steps);
            let coarse_scores: Vec<f64> = if options.parallel {
                coarse_values.par_iter().map(|&v| coarse_score(v)).collect()
            } else {
                coarse_values.iter().map(|&v| coarse_score(v)).collect()
            };
            let reach_about = FINE_REACH_COARSE_STEPS * coarse_step;
            // The coarse band cannot tell values within it apart: on the ABB IRB 1600's joint 5
            // in a ray-cast scene at 1000 mm the coarse scores lie within 1 of their best from
            // 0.27 to 0.81 rad, and the narrow band's peak, the truth, is at 0.78. Every value
            // within the scores' noise (the square root) of the best is searched finely, and
            // the best few peaks elsewhere and the state besides.
            let best_coarse = coarse_scores
                .iter()
                .copied()
                .fold(f64::NEG_INFINITY, f64::max);
            let level = best_coarse - best_coarse.max(0.0).sqrt();
            let near_best = coarse_values
                .iter()
                .zip(&coarse_scores)
                .filter(|&(_, &s)| s >= level)
                .map(|(&v, _)| v);
            let peaks = highest_peaks(
                &coarse_scores,
                FINE_CENTRES,
                FINE_REACH_COARSE_STEPS as usize,
            )
            .into_iter()
            .map(|i| coarse_values[i]);
            let centres: Vec<f64> = near_best.chain(peaks).chain([current]).collect();
            let values = fine_values(&centres, reach_about, step, (lower, upper));
            let scores: Vec<f64> = if options.parallel {
                values.par_iter().map(|&v| score(v)).collect()
            } else {
                values.iter().map(|&v| score(v)).collect()
            };
            let Some((best_index, &best_score)) =
                scores.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))
            else {
                continue;
            };
            let best = values[best_index];
            let needed = sweep_gain_needed(here);
            // Short of the gain, a value is still taken when the scan pins the joint there and
            // not where the state has it (`pins`).
            let by_pinning = best_score - here < needed;
            // The evidence the pinning rule asks of a value: a gain a count of keypoints would
            // need, or one most free points agree on (`consistent_gain`).
            let shown = |root: &Isometry3<f64>, joints: &[f64], gain: f64| {
                gain >= PINNED_GAIN_MIN
                    || consistent_gain(&here_grades, &grades_in(root, joints, band))
            };
            if by_pinning {
                let mut at_best = q.clone();
                at_best[parameter] = best;
                if !shown(world_from_root, &at_best, best_score - here)
                    || self.pins(world_from_root, q, parameter)
                {
                    continue;
                }
            }
            let mut trial_root = *world_from_root;
            let mut trial_q = q.clone();
            trial_q[parameter] = best;
            iterations += refine(
                body,
                scan.fine,
                &mut trial_root,
                &mut trial_q,
                options.band_min_m,
                options,
                true,
            );
            // `here` is the state's own score: the sweep's value at the current one.
            let gain = graded_in(&trial_root, &trial_q, band, Distances::Exact) - here;
            let taken = if by_pinning {
                shown(&trial_root, &trial_q, gain) && self.pins(&trial_root, &trial_q, parameter)
            } else {
                gain >= needed
            };
            if taken {
                *world_from_root = trial_root;
                *q = trial_q;
            }
        }
        iterations
    }

    /// Whether the fine keypoints pin `parameter` with the robot at `world_from_root` and `q`:
    /// what the fit's report would call it observed (`report::final_state`).
    fn pins(&self, world_from_root: &Isometry3<f64>, q: &[f64], parameter: usize) -> bool {
        final_state(self.body, self.scan.fine, world_from_root, q, self.options).observed[parameter]
    }
}

/// The indices of the `count` highest local maxima of `scores`, no two within `apart` indices
/// of each other (a plateau is one peak), highest first.
pub(super) fn highest_peaks(scores: &[f64], count: usize, apart: usize) -> Vec<usize> {
    let mut maxima: Vec<usize> = (0..scores.len())
        .filter(|&i| {
            let left = i.checked_sub(1).map_or(f64::NEG_INFINITY, |l| scores[l]);
            let right = scores.get(i + 1).copied().unwrap_or(f64::NEG_INFINITY);
            scores[i] >= left && scores[i] >= right
        })
        .collect();
    maxima.sort_by(|&a, &b| scores[b].total_cmp(&scores[a]));
    let mut peaks: Vec<usize> = Vec::with_capacity(count);
    for index in maxima {
        if peaks.len() == count {
            break;
        }
        if peaks.iter().all(|&p| p.abs_diff(index) > apart) {
            peaks.push(index);
        }
    }
    peaks
}

/// Values `step` apart (or a little less) over `centre +- reach` for each of `centres`, inside
/// `span`; overlapping intervals are merged, so no value is scored twice.
pub(super) fn fine_values(centres: &[f64], reach: f64, step: f64, span: (f64, f64)) -> Vec<f64> {
    let (lower, upper) = span;
    let mut intervals: Vec<(f64, f64)> = centres
        .iter()
        .map(|&c| ((c - reach).max(lower), (c + reach).min(upper)))
        .filter(|(a, b)| a <= b)
        .collect();
    intervals.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut merged: Vec<(f64, f64)> = Vec::with_capacity(intervals.len());
    for (a, b) in intervals {
        match merged.last_mut() {
            Some(last) if a <= last.1 + step => last.1 = last.1.max(b),
            _ => merged.push((a, b)),
        }
    }
    merged
        .into_iter()
        .flat_map(|(a, b)| {
            // Less a hair, so that rounding does not add a step to a whole number of them.
            let steps = ((b - a) / step - 1e-9).ceil().max(1.0) as usize;
            (0..=steps).map(move |i| a + (b - a) * i as f64 / steps as f64)
        })
        .collect()
}

/// Whether the free points' grades `to` gain on `from` consistently: the gain is at least
/// [`CONSISTENT_GAIN_Z`] times the root of the summed squared per-point changes, the spread the
/// gain would have if each point's change were as likely to go either way (a paired test). A
/// gain of 3.75 on 100 points that 15 points make and 1 gives back passes (z 3.1); the same
/// gain made by a few points moving a lot and others moving back does not.
fn consistent_gain(from: &[f64], to: &[f64]) -> bool {
    let (gain, squares) = from
        .iter()
        .zip(to)
        .map(|(a, b)| b - a)
        .fold((0.0, 0.0), |(sum, squares), d| (sum + d, squares + d * d));
    gain > 0.0 && gain >= CONSISTENT_GAIN_Z * squares.sqrt()
}

/// The paired test's threshold (`consistent_gain`): three standard deviations.
const CONSISTENT_GAIN_Z: f64 = 3.0;

/// How much more a swept value's graded score ([`Placed::closeness`]) must be than the
/// state's `score`: its square root, and at least 4 (as a count of keypoints would need).
fn sweep_gain_needed(score: f64) -> f64 {
    score.max(0.0).sqrt().ceil().max(4.0)
}

#[cfg(test)]
mod consistent_gain_tests {
    use super::consistent_gain;

    #[test]
    fn a_gain_most_points_make_is_consistent_and_one_a_few_make_against_the_rest_is_not() {
        // 100 points: 15 gain 0.25 each and one gives back 0.1 (gain 3.65, z 3.7).
        let from = vec![0.5; 100];
        let mut spread = from.clone();
        for grade in &mut spread[..15] {
            *grade += 0.25;
        }
        spread[15] -= 0.1;
        assert!(consistent_gain(&from, &spread));
        // Near the same gain from 4 points that gain 1 each while 3 others lose 0.1 each (z 1.8).
        let mut few = from.clone();
        for grade in &mut few[..4] {
            *grade += 1.0;
        }
        for grade in &mut few[4..7] {
            *grade -= 0.1;
        }
        assert!(!consistent_gain(&from, &few));
        // No change, or a loss however consistent, is no gain.
        assert!(!consistent_gain(&from, &from));
        let lower: Vec<f64> = from.iter().map(|g| g - 0.1).collect();
        assert!(!consistent_gain(&from, &lower));
        assert!(consistent_gain(&lower, &from));
    }
}
