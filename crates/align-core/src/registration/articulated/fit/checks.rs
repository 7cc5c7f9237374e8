//! Checks after the search: half turns of a joint (with the joints below searched again), a
//! base turned with joint 1 making up for it, and a second look at joints whose window reaches
//! an eighth of a turn (after a global search, a quarter turn, or that spin their own links in
//! place).

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use rayon::prelude::*;

use super::RobotFitOptions;
use super::context::FitContext;
use super::contrast::{OwnedState, State};
use super::placed::{Placed, coverage, reach_m, within_swept_reach};
use super::refine::refine;
use super::report::RobotTwin;
use super::tree::{Window, search_order, spins_in_place};
use crate::registration::articulated::body::JointAxis;

/// Single-flip states a global fit turns once more (see [`FitContext::flip_check`]).
const FLIP_RUNNERS_UP: usize = 2;

/// States within the ambiguity margin [`FitContext::twin`] refines at most before it gives up
/// calling one a twin.
const TWINS_REFINED: usize = 3;

/// Rounds of single flips [`FitContext::flip_check`] makes at most (another only after one that
/// kept a flip).
const FLIP_ROUNDS: usize = 3;

/// Coarse turns of the base [`FitContext::base_turn_check`] looks at finely, from each band.
const BASE_TURN_PEAKS: usize = 4;

/// Coarse steps between two of those turns at least: twelve keypoint voxels at the base's
/// reach, so that one broad peak's noise does not fill them all.
const BASE_TURN_PEAK_STEPS: f64 = 4.0;

/// The window (each way) from which a joint gets a second look after a global search, rad.
const QUARTER_TURN: f64 = std::f64::consts::FRAC_PI_2;

/// The same after a local search, rad: the ABB IRB 1600's joint 4 at 200 mm, its window short
/// of a quarter turn each way, was left 0.9 rad off in 3 of 50 trials.
const EIGHTH_TURN: f64 = std::f64::consts::FRAC_PI_4;

impl FitContext<'_> {
    /// A second look at joints the search may have left in the wrong basin, each searched once
    /// more with its child over its window ([`FitContext::global_joint_candidates`]) from the
    /// final state, every candidate refined and kept when it explains at least
    /// `min_link_points` more fine keypoints than the state so far, where the two differ on the
    /// links the joint moves ([`FitContext::contrast_among`]).
    ///
    /// - After a local search, the joints whose window reaches an eighth of a turn each way.
    ///   The ABB IRB 1600's joint 5 turns a nearly round housing, and only the small flange
    ///   shows its angle: in 2 of 10 trials at 500 mm the search left it 2 rad off. At 200 mm,
    ///   in 3 of 50 trials, it left joint 4 0.9 rad off with joint 5 making up for it (link_4
    ///   24-33 mm off), where the true wrist explains 2007 fine keypoints against 1109-1141;
    ///   joint 4's window there is between an eighth and a quarter turn each way.
    /// - After a global search, the joints whose window reaches a quarter turn each way (every
    ///   joint at 1000 mm): after the global search at 1000 mm 3 of 10 ended 4-12 mm off.
    /// - After a global search also the joints whose own links turn in place about their axis
    ///   (a nearly round link, such as a UR wrist), whatever their window. They show their angle
    ///   only through the links after them, which may hold few points; searched while the joints
    ///   above were still wrong they can settle on a wrong value the refinement cannot leave.
    ///
    /// Every candidate is tried, each against the state the ones before it left: the first
    /// candidate can be the true pose's wrist twin, which explains more than a wrong state, and
    /// the true pose only a later one. Returns the iterations spent.
    pub(super) fn second_look(
        &self,
        world_from_root: &mut Isometry3<f64>,
        q: &mut Vec<f64>,
    ) -> usize {
        let FitContext {
            body,
            scan,
            delta_m,
            global,
            options,
            ..
        } = *self;
        let mut iterations = 0;
        for parameter in search_order(body) {
            let placed = Placed::new(body, world_from_root, q);
            let looked_at = Window::new(body, &placed, parameter, delta_m, options.voxel_m)
                .is_some_and(|(window, _)| {
                    window.half >= if global { QUARTER_TURN } else { EIGHTH_TURN }
                })
                || (global && spins_in_place(body, &placed, parameter, options.min_observability));
            if !looked_at {
                continue;
            }
            let candidates = self.global_joint_candidates(world_from_root, q, parameter, 3);
            let moved = body.moved_by(parameter);
            for candidate in candidates {
                let mut trial_q = q.clone();
                let mut trial_root = *world_from_root;
                trial_q[parameter] = candidate.value;
                for (other, value) in candidate.partner.into_iter().chain(candidate.deferred) {
                    trial_q[other] = value;
                }
                // Within a keypoint voxel of the state on every link it moves, the candidate is
                // the state at the search grid's resolution, and refined it returns there: most
                // candidates are (a refinement costs about as much as the rest of the look).
                let nearby = self
                    .links_apart(
                        (world_from_root, q),
                        (&trial_root, &trial_q),
                        &moved,
                        options.voxel_m,
                    )
                    .is_empty();
                if nearby {
                    continue;
                }
                let mut spent = refine(
                    body,
                    scan.coarse,
                    &mut trial_root,
                    &mut trial_q,
                    options.refine_band0_m(),
                    &RobotFitOptions {
                        max_iterations: 15,
                        ..options.clone()
                    },
                    false,
                );
                spent += refine(
                    body,
                    scan.fine,
                    &mut trial_root,
                    &mut trial_q,
                    options.band_min_m,
                    options,
                    true,
                );
                iterations += spent;
                let gain = self
                    .contrast_among((world_from_root, q), (&trial_root, &trial_q), &moved)
                    .map_or(0, |(fit, trial)| trial - fit);
                if gain >= options.min_link_points as i64 {
                    *world_from_root = trial_root;
                    *q = trial_q;
                }
            }
        }
        iterations
    }

    /// Tries each revolute joint turned half a turn, with the joints below it searched again and
    /// everything refined, and keeps what explains the scan better. A wrist (or shoulder) whose
    /// three axes meet reaches the same link poses as (a + pi, -b, c + pi): continuous refinement
    /// cannot cross between the two, and on nearly symmetric links the searches may settle on the
    /// wrong one. Only joints whose window allows a half turn are tried. A flip is kept when it
    /// explains more fine keypoints where it and the state differ on the links the joint moves
    /// ([`FitContext::contrast_among`]). After a round that kept one, the joints are tried again
    /// (up to [`FLIP_ROUNDS`] rounds): a wrong wrist flips to the true pose's twin first (on the
    /// ABB IRB 1600 at 500 mm, 3 of 10 trials), and only a second turn of the same joint reaches
    /// the true pose.
    ///
    /// With `global`, the best flipped states that were not kept are each flipped once more at
    /// every later joint: where the joint limits stop just short of a half turn (the iiwa's 170
    /// degrees), the copy is not exact and the fit can sit on one pinned at the limits, with a
    /// chain of joints each a half turn off; turning one of them back alone leaves the rest of the
    /// chain explaining the scan no better, so only two flips together reach the true state.
    /// Returns the iterations, and every state it scored but did not keep (the one it started
    /// from, when a flip replaced it): where [`FitContext::twin`] looks for an equally good
    /// other pose.
    pub(super) fn flip_check(
        &self,
        world_from_root: &mut Isometry3<f64>,
        q: &mut Vec<f64>,
    ) -> (usize, Vec<OwnedState>) {
        let FitContext {
            body,
            scan,
            global,
            options,
            ..
        } = *self;
        let with_surface: Vec<usize> = (0..body.links().len())
            .filter(|&l| body.links()[l].surface.is_some())
            .collect();
        let band = options.band_min_m;
        let score = |base: &Isometry3<f64>, q: &[f64]| {
            coverage(
                body,
                scan.coarse,
                base,
                q,
                &with_surface,
                band,
                options.parallel,
            )
        };
        let order = search_order(body);
        let mut iterations = 0;
        let mut runners_up: Vec<(i64, usize, Isometry3<f64>, Vec<f64>)> = Vec::new();
        // The flips of `indices` from one state, each scored, with the iterations it spent.
        // Side by side: a flip is a search and a refinement that leave part of the second core
        // idle, and the flips from one state do not depend on each other.
        type Flipped = Option<(i64, Isometry3<f64>, Vec<f64>, usize)>;
        let flips = |base: &Isometry3<f64>, q: &[f64], indices: std::ops::Range<usize>| {
            let flip = |index: usize| -> Flipped {
                let (trial_base, trial_q, spent) = self.flipped(base, q, &order, index)?;
                // Only a global fit ranks its runners-up by it.
                let trial_score = if global {
                    score(&trial_base, &trial_q)
                } else {
                    0
                };
                Some((trial_score, trial_base, trial_q, spent))
            };
            let flipped: Vec<Flipped> = if options.parallel {
                indices.clone().into_par_iter().map(flip).collect()
            } else {
                indices.clone().map(flip).collect()
            };
            indices.zip(flipped)
        };
        let mut left: Vec<OwnedState> = Vec::new();
        // A flip replaces the state when it explains more where the two differ on the links the
        // flipped joint moves. Scored over every link, the large links' refinement noise decides
        // (see `super::contrast`); over every link that differs, a base settling into place
        // while a wrist flips carries the flip (an ABB IRB 1600 trial at 500 mm).
        let better = |index: usize, trial: State, now: State| {
            self.contrast_among(now, trial, &body.moved_by(order[index]))
                .is_some_and(|(now, flipped)| flipped > now)
        };
        // Again after a flip was kept: a wrist found wrong can be flipped to the true pose's
        // twin (which explains more than where it was), and only a second turn of the same joint
        // reaches the true pose.
        for round in 0..FLIP_ROUNDS {
            let mut kept = false;
            // The joints are tried in order, each from the state the ones before it left: the
            // flips after a kept one are made again from the new state (the ones made from the
            // old state, side by side with it, are dropped unseen, their iterations uncounted).
            let mut first = 0;
            while first < order.len() {
                let mut next = order.len();
                for (index, flipped) in flips(world_from_root, q, first..order.len()) {
                    let Some((trial_score, trial_base, trial_q, spent)) = flipped else {
                        continue;
                    };
                    iterations += spent;
                    if better(index, (&trial_base, &trial_q), (world_from_root, q)) {
                        left.push((*world_from_root, q.clone()));
                        *q = trial_q;
                        *world_from_root = trial_base;
                        kept = true;
                        next = index + 1;
                        break;
                    }
                    left.push((trial_base, trial_q.clone()));
                    if global && round == 0 {
                        runners_up.push((trial_score, index, trial_base, trial_q));
                    }
                }
                first = next;
            }
            if !kept {
                break;
            }
        }
        runners_up.sort_by_key(|(trial_score, ..)| std::cmp::Reverse(*trial_score));
        runners_up.truncate(FLIP_RUNNERS_UP);
        for (_, first, base, first_q) in runners_up {
            for (_, flipped) in flips(&base, &first_q, first + 1..order.len()) {
                let Some((_, trial_base, trial_q, spent)) = flipped else {
                    continue;
                };
                iterations += spent;
                if better(first, (&trial_base, &trial_q), (world_from_root, q)) {
                    left.push((*world_from_root, q.clone()));
                    *q = trial_q;
                    *world_from_root = trial_base;
                } else {
                    left.push((trial_base, trial_q));
                }
            }
        }
        (iterations, left)
    }

    /// The one of `others` (states the flip check scored and left) that comes nearest to
    /// explaining the scan as well as the fit where the two differ ([`FitContext::contrast`]),
    /// among those that put some link's surface more than [`super::contrast::DISTINCT_M`] from
    /// where the fit has it: a wrist turned a half turn with the next joint mirrored, on links
    /// nearly symmetric under that turn, explains nearly the same points, and the scan cannot tell
    /// the two apart. Ambiguous when the fit explains fewer than `min_link_points` keypoints more:
    /// the evidence the fit asks of a link to call it seen.
    ///
    /// The others were refined on the coarse keypoints only, the fit on every one against the
    /// exact surfaces. One within the margin is refined the same way before it is called a twin:
    /// a copy of the fit's own pose a few hundredths of a radian off would otherwise be reported
    /// as another pose that explains the scan as well (the ABB IRB 1600 at 500 mm, in half the
    /// trials). One within a keypoint voxel of the fit at every vertex is the fit, unrefined.
    /// Joints not `observed` keep the value they have (the start's).
    pub(super) fn twin(
        &self,
        world_from_root: &Isometry3<f64>,
        q: &[f64],
        others: &[OwnedState],
        observed: &[bool],
    ) -> Option<RobotTwin> {
        let FitContext {
            body,
            scan,
            options,
            ..
        } = *self;
        let fit = (world_from_root, q);
        let margin = i64::try_from(options.min_link_points).unwrap_or(i64::MAX);
        // (the fit's count, the other's) where they differ; `None` once refined into the fit.
        let mut scored: Vec<_> = others
            .iter()
            // Within a keypoint voxel of the fit at every vertex, a state is the fit at the
            // keypoints' resolution, and refined it returns there (as `second_look`'s candidates
            // do): the flip check's states of a joint the scan does not show, refined on the
            // coarse keypoints only, lie 1-3 mm from the fit on the CAD robots, and refining
            // each to find that out was 11-25 ms of a 100 mm fit (docs/BENCHMARKS.md).
            .filter(|(base, other_q)| !self.vertices_within(fit, (base, other_q), options.voxel_m))
            .filter_map(|(base, other_q)| {
                let counts = self.contrast(fit, (base, other_q))?;
                Some((Some(counts), *base, other_q.clone()))
            })
            .collect();
        let lead = |counts: &Option<(i64, i64)>| counts.map(|(fit, other)| fit - other);
        scored.sort_by_key(|(counts, ..)| lead(counts));
        for (refined, (counts, base, other_q)) in scored.iter_mut().enumerate() {
            if lead(counts).is_none_or(|lead| lead >= margin) || refined == TWINS_REFINED {
                break;
            }
            let unrefined = other_q.clone();
            refine(
                body,
                scan.fine,
                base,
                other_q,
                options.band_min_m,
                options,
                true,
            );
            for ((value, before), &seen) in other_q.iter_mut().zip(&unrefined).zip(observed) {
                if !seen {
                    *value = *before;
                }
            }
            *counts = self.contrast(fit, (base, other_q));
        }
        let ((fit_coverage, coverage), base, other_q) = scored
            .into_iter()
            .filter_map(|(counts, base, other_q)| Some((counts?, base, other_q)))
            .min_by_key(|((fit, other), ..)| fit - other)?;
        Some(RobotTwin {
            world_from_root: base,
            q: other_q,
            coverage,
            fit_coverage,
            ambiguous: fit_coverage - coverage < margin,
        })
    }

    /// A base that is not round about joint 1 shows its turn about that axis, but the fit can end
    /// with the base turned and joint 1 making up for it: every link above in place, only the
    /// base's own surface off. Once the base's features lie beyond the refinement's band no step
    /// leaves that state (the ABB IRB 1600 at 500 mm: base 78 mm off, link_1 within 1 mm, in two
    /// of ten trials). The base is turned about joint 1's axis over the window delta allows, joint
    /// 1 turned back by as much, and each turn scored by the keypoints the links fixed to the root
    /// explain (coarse steps in a coarse band and, from a start that is not near, in a fine one,
    /// then fine steps around each band's best few); the best is kept, and
    /// refined, when it explains `min_link_points` more than the state found. Returns the
    /// iterations spent.
    pub(super) fn base_turn_check(
        &self,
        world_from_root: &mut Isometry3<f64>,
        q: &mut Vec<f64>,
    ) -> usize {
        let FitContext {
            body,
            scan,
            delta_m,
            near,
            options,
            ..
        } = *self;
        let Some(&first) = search_order(body).first() else {
            return 0;
        };
        let placed = Placed::new(body, world_from_root, q);
        // Joint 1 alone must carry everything above the base: one joint it drives, on a fixed link.
        let driven: Vec<(JointAxis, f64)> = body
            .axes(&placed.poses)
            .into_iter()
            .flatten()
            .filter(|(_, parameter, _)| *parameter == first)
            .map(|(axis, _, multiplier)| (axis, multiplier))
            .collect();
        let [(axis, multiplier)] = driven.as_slice() else {
            return 0;
        };
        let Some(direction) = nalgebra::Unit::try_new(axis.axis, 1e-12) else {
            return 0;
        };
        if axis.prismatic || *multiplier == 0.0 {
            return 0;
        }
        let fixed: Vec<usize> = (0..body.links().len())
            .filter(|&l| body.movers(l).is_empty() && body.links()[l].surface.is_some())
            .collect();
        if fixed.is_empty() {
            return 0;
        }
        let reach = reach_m(&placed, &fixed, &axis.origin).max(options.voxel_m);
        let half = (2.0 * delta_m / reach).min(std::f64::consts::PI);
        let info = &body.parameters()[first];
        let about = Translation3::from(axis.origin.coords);
        let turned = |theta: f64| -> Option<(Isometry3<f64>, Vec<f64>)> {
            let value = q[first] - theta / multiplier;
            if !(info.lower..=info.upper).contains(&value) {
                return None;
            }
            let turn = about * UnitQuaternion::from_axis_angle(&direction, theta) * about.inverse();
            let mut trial_q = q.clone();
            trial_q[first] = value;
            Some((turn * *world_from_root, trial_q))
        };
        // Only the keypoints the fixed links can reach at some turn can count for or against
        // any turn: on the ABB IRB 1600 in a 20k-point scan, 7 065 of 15 529 (a probe, not
        // kept). The widest band any turn is scored in is the coarse one.
        let coarse_band = 3.0 * options.voxel_m;
        let reachable = within_swept_reach(
            &placed,
            scan.fine,
            &fixed,
            &axis.origin,
            &direction,
            coarse_band,
        );
        let score = |theta: f64, band: f64| -> Option<i64> {
            let (base, trial_q) = turned(theta)?;
            Some(coverage(
                body,
                &reachable,
                &base,
                &trial_q,
                &fixed,
                band,
                options.parallel,
            ))
        };
        let scored_about = |centre: f64, half: f64, step: f64, band: f64| -> Vec<(f64, i64)> {
            let steps = (half / step).ceil() as i64;
            (-steps..=steps)
                .filter_map(|k| {
                    let theta = centre + k as f64 * step;
                    Some((theta, score(theta, band)?))
                })
                .collect()
        };
        // Of the turns that explain about as many points as the best (within `margin`), the
        // smallest: a base symmetric under some turn (a square plate) scores its copies alike, and
        // the scan's noise must not pick one. Never invent motion.
        let smallest_near_best = |scored: &[(f64, i64)], margin: i64| {
            let best = scored.iter().map(|(_, s)| *s).max()?;
            scored
                .iter()
                .copied()
                .filter(|(_, s)| *s + margin >= best)
                .min_by(|a, b| a.0.abs().total_cmp(&b.0.abs()))
        };
        // Coarse steps move the base's farthest point by three keypoint voxels, scored in a band
        // as wide (and in the fine one); fine ones by half a voxel, in a band of one voxel.
        let coarse_step = 3.0 * options.voxel_m / reach;
        let fine_step = 0.5 * options.voxel_m / reach;
        let margin = options.min_link_points as i64;
        let fine_band = options.voxel_m;
        // The best few coarse turns, each at least [`BASE_TURN_PEAK_STEPS`] coarse steps from
        // the others, are looked at finely: the coarse band blurs a base's narrow fine peak and
        // scores a broad wrong one higher. The ABB IRB 1600's base ended 2.94 rad turned
        // (joint 1 making up for it, its own points at 2.5 mm rms against about 1 mm on the
        // links above) in a ray-cast scan at 1000 mm (`robot-scans` scene 0, trial 5): there
        // the check's coarse scores put a wrong turn 64 keypoints above the truth's, whose fine
        // score was 405 above the wrong one's (a probe, not kept).
        //
        // The coarse steps are scored in the fine band too, and its best few looked at as well:
        // a base whose features are smaller than the coarse band looks alike at every turn in
        // it. The UR10 with CAD links (a disc with four lugs and a cable outlet, 20 mm proud)
        // scored 586-615 at every coarse turn in a ray-cast scan at 500 mm (`robot-scans` scene
        // 1, trial 6), where the fine band gave its true turn, 0.54 rad from the fit's, 359
        // keypoints against 229 (a probe, not kept).
        let Some(current) = score(0.0, fine_band) else {
            return 0;
        };
        let separation = BASE_TURN_PEAK_STEPS * coarse_step;
        let mut peaks: Vec<f64> = Vec::new();
        // From a near start (one base hypothesis, the whole robot's alignment) the fine band is
        // not swept: there each band's best four cost the ABB IRB 1600's 100 mm fit some 12 %
        // (`articulated_starts` bench, a build not kept), and the fits it mended started at 500
        // mm. Elsewhere only the coarse turns that already explain more than the state found in
        // it are looked at.
        let bands: &[(f64, bool)] = if near {
            &[(coarse_band, false)]
        } else {
            &[(coarse_band, false), (fine_band, true)]
        };
        for &(band, only_better) in bands {
            let mut by_score = scored_about(0.0, half, coarse_step, band);
            if only_better {
                by_score.retain(|(_, score)| *score > current);
            }
            by_score.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.abs().total_cmp(&b.0.abs())));
            let mut band_peaks: Vec<f64> = Vec::new();
            for (theta, _) in by_score {
                if band_peaks.len() == BASE_TURN_PEAKS {
                    break;
                }
                if band_peaks.iter().all(|p| (p - theta).abs() >= separation) {
                    band_peaks.push(theta);
                }
            }
            // The same coarse turn from both bands is looked at once.
            for theta in band_peaks {
                if !peaks.contains(&theta) {
                    peaks.push(theta);
                }
            }
        }
        let fine: Vec<(f64, i64)> = peaks
            .iter()
            .filter_map(|&centre| {
                let around = scored_about(centre, 2.0 * coarse_step, fine_step, fine_band);
                smallest_near_best(&around, 0)
            })
            .collect();
        let Some((theta, best)) = smallest_near_best(&fine, margin) else {
            return 0;
        };
        if best < current + margin {
            return 0;
        }
        let Some((mut base, mut trial_q)) = turned(theta) else {
            return 0;
        };
        let spent = refine(
            body,
            scan.coarse,
            &mut base,
            &mut trial_q,
            options.refine_band0_m(),
            &RobotFitOptions {
                max_iterations: 15,
                ..options.clone()
            },
            false,
        );
        *world_from_root = base;
        *q = trial_q;
        spent
    }

    /// The state with the joint `order[index]` turned half a turn, the joints after it in `order`
    /// searched again and everything refined, with the iterations spent; `None` when the joint is
    /// prismatic or its window or limits do not allow a half turn.
    fn flipped(
        &self,
        world_from_root: &Isometry3<f64>,
        q: &[f64],
        order: &[usize],
        index: usize,
    ) -> Option<(Isometry3<f64>, Vec<f64>, usize)> {
        let FitContext {
            body,
            scan,
            delta_m,
            options,
            ..
        } = *self;
        let parameter = order[index];
        let info = &body.parameters()[parameter];
        if info.prismatic {
            return None;
        }
        let placed = Placed::new(body, world_from_root, q);
        let (window, _) = Window::new(body, &placed, parameter, delta_m, options.voxel_m)?;
        if window.half < std::f64::consts::FRAC_PI_2 {
            return None;
        }
        let turned = q[parameter] + std::f64::consts::PI;
        let turned = if turned > info.upper {
            turned - 2.0 * std::f64::consts::PI
        } else {
            turned
        };
        if turned < info.lower || turned > info.upper {
            return None;
        }
        let mut trial_q = q.to_vec();
        let mut trial_base = *world_from_root;
        trial_q[parameter] = turned;
        for &below in &order[index + 1..] {
            self.search_joint(&trial_base, &mut trial_q, below);
        }
        let refine_options = RobotFitOptions {
            max_iterations: 20,
            ..options.clone()
        };
        let spent = refine(
            body,
            scan.coarse,
            &mut trial_base,
            &mut trial_q,
            options.refine_band0_m(),
            &refine_options,
            false,
        );
        Some((trial_base, trial_q, spent))
    }
}
