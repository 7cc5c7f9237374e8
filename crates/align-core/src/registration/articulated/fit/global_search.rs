//! The joint search for a start that is not local: each joint together with its child over
//! its whole window, scored only on the links those two place.

use nalgebra::{Isometry3, Point3};
use rayon::prelude::*;

use super::context::FitContext;
use super::joint_search::{Candidate, coarse_peaks};
use super::placed::{Placed, reach_m};
use super::tree::{Window, axis_of, own_surfaces, revolute_child, turns_in_place};

/// Pairs of values (the searched joint's and its child's) a global joint search scores per
/// state at its coarse level, at most.
const GLOBAL_MAX_PAIRS: usize = 6000;

/// Keypoints a global joint search scores on, at most (a stride sample of those in reach).
const GLOBAL_SEARCH_POINTS: usize = 6000;

/// What a [`FitContext::pair_search`] scores: the links that turn rigidly with the searched
/// joint, and the joint below it searched together with it (its window and axis origin) with
/// the links that one places.
#[derive(Clone, Copy)]
struct JointPair<'a> {
    rigid: &'a [usize],
    partner: Option<&'a (Window, Point3<f64>)>,
    partner_links: &'a [usize],
}

impl FitContext<'_> {
    /// [`Self::joint_candidates`] for a start that is not local (every joint anywhere in a window
    /// of up to a half turn, the links below it too): the joint is searched together with its
    /// child, on a grid fine enough that the value nearest the truth puts their links within the
    /// band, and scored only on the links those two joints place. The links further down, at values
    /// still arbitrary, would otherwise score the joint by where they happen to lie (or be buried);
    /// and the wide band a coarse grid over a half turn needs cannot tell an arm in the air from
    /// one lying on the floor. When those links turn in place about the joint at the best pair (an
    /// upper arm standing on the axis of a round shoulder), the joint only shows through the
    /// grandchild's link: the child is searched first with the joint where it is, then the joint
    /// together with the grandchild.
    pub(super) fn global_joint_candidates(
        &self,
        world_from_root: &Isometry3<f64>,
        q: &[f64],
        parameter: usize,
        count: usize,
    ) -> Vec<Candidate> {
        let FitContext {
            body,
            delta_m,
            options,
            ..
        } = *self;
        let local = || self.joint_candidates(world_from_root, q, parameter, count);
        if body.parameters()[parameter].prismatic {
            return local();
        }
        let placed = Placed::new(body, world_from_root, q);
        let own = own_surfaces(body, parameter);
        let child = revolute_child(body, &placed, parameter, delta_m, options);
        let child_own = child
            .as_ref()
            .map_or(Vec::new(), |(w, _)| own_surfaces(body, w.parameter));
        if own.is_empty() && child_own.is_empty() {
            return local();
        }
        let (candidates, flat) = self.pair_search(
            world_from_root,
            q,
            parameter,
            JointPair {
                rigid: &own,
                partner: child.as_ref(),
                partner_links: &child_own,
            },
            count,
        );
        let (Some((child_window, _)), Some(best)) = (&child, candidates.first()) else {
            return candidates;
        };
        let mut at_best = q.to_vec();
        at_best[parameter] = best.value;
        if let Some((c, v)) = best.partner {
            at_best[c] = v;
        }
        let poses = body.link_poses(world_from_root, &at_best);
        let scored: Vec<usize> = own.iter().chain(&child_own).copied().collect();
        let degenerate = flat
            || axis_of(body, &poses, parameter).is_some_and(|axis| {
                turns_in_place(body, &poses, &scored, &axis, options.min_observability)
            });
        if !degenerate {
            return candidates;
        }
        // The child (with its own child) first, this joint where it is; then this joint with the
        // grandchild, the child's links turning with this joint.
        let mut trial = q.to_vec();
        let child_parameter = child_window.parameter;
        let child_child = revolute_child(body, &placed, child_parameter, delta_m, options);
        let child_child_own = child_child
            .as_ref()
            .map_or(Vec::new(), |(w, _)| own_surfaces(body, w.parameter));
        let Some(child_best) = self
            .pair_search(
                world_from_root,
                &trial,
                child_parameter,
                JointPair {
                    rigid: &child_own,
                    partner: child_child.as_ref(),
                    partner_links: &child_child_own,
                },
                1,
            )
            .0
            .into_iter()
            .next()
        else {
            return candidates;
        };
        trial[child_parameter] = child_best.value;
        if let Some((c, v)) = child_best.partner {
            trial[c] = v;
        }
        let at_child = Placed::new(body, world_from_root, &trial);
        let grandchild = revolute_child(body, &at_child, child_parameter, delta_m, options);
        let grandchild_own = grandchild
            .as_ref()
            .map_or(Vec::new(), |(w, _)| own_surfaces(body, w.parameter));
        self.pair_search(
            world_from_root,
            &trial,
            parameter,
            JointPair {
                rigid: &scored,
                partner: grandchild.as_ref(),
                partner_links: &grandchild_own,
            },
            count,
        )
        .0
        .into_iter()
        .map(|candidate| Candidate {
            deferred: Some((child_parameter, child_best.value)),
            ..candidate
        })
        .collect()
    }

    /// The 2-D search of [`Self::global_joint_candidates`]: `parameter` over its window and
    /// `pair.partner` (a joint below it) over its own, scored on `pair.rigid` and
    /// `pair.partner_links`; best first, at most `count`.
    fn pair_search(
        &self,
        world_from_root: &Isometry3<f64>,
        q: &[f64],
        parameter: usize,
        pair: JointPair,
        count: usize,
    ) -> (Vec<Candidate>, bool) {
        let FitContext {
            body,
            delta_m,
            options,
            ..
        } = *self;
        // Every joint anywhere in its window: the coarse keypoints, strided, are enough to find it.
        let keypoints = self.scan.coarse;
        let JointPair {
            rigid,
            partner,
            partner_links,
        } = pair;
        let placed = Placed::new(body, world_from_root, q);
        let Some((window, origin)) =
            Window::new(body, &placed, parameter, delta_m, options.voxel_m)
        else {
            return (Vec::new(), false);
        };
        let scored: Vec<usize> = rigid.iter().chain(partner_links).copied().collect();
        let band = 3.0 * options.voxel_m;
        // Turning the joint keeps every point's distance from its axis origin; the partner's links
        // stay within their reach of the partner's axis, wherever the joint puts that.
        let partner_reach = partner.map_or(0.0, |(_, o)| reach_m(&placed, partner_links, o));
        let reach = reach_m(&placed, rigid, &origin)
            .max(partner.map_or(0.0, |(_, o)| (o - origin).norm() + partner_reach))
            .max(options.voxel_m);
        let moved = body.moved_by(parameter);
        let others: Vec<usize> = (0..body.links().len())
            .filter(|link| !moved.contains(link))
            .collect();
        let nearby: Vec<Point3<f64>> = keypoints
            .iter()
            .filter(|p| (*p - origin).norm() <= reach + band)
            .filter(|p| !placed.supports(p, band, &others))
            .copied()
            .collect();
        if nearby.is_empty() {
            return (Vec::new(), false);
        }
        let stride = nearby.len().div_ceil(GLOBAL_SEARCH_POINTS);
        let nearby: Vec<Point3<f64>> = nearby.into_iter().step_by(stride).collect();
        // A step moves the farthest scored point by twice the band (fewer steps when the pairs
        // would exceed the cap).
        let motion = 2.0 * band;
        let mut steps = ((2.0 * window.half * reach / motion).ceil() as usize).max(4);
        let mut partner_steps = partner.map_or(1, |(w, _)| {
            ((2.0 * w.half * partner_reach.max(options.voxel_m) / motion).ceil() as usize).max(4)
        });
        let shrink = (GLOBAL_MAX_PAIRS as f64 / (steps * partner_steps) as f64)
            .sqrt()
            .min(1.0);
        steps = ((steps as f64 * shrink).ceil() as usize).max(4);
        if partner.is_some() {
            partner_steps = ((partner_steps as f64 * shrink).ceil() as usize).max(4);
        }
        let current = q[parameter];
        // Ties (a symmetric link) go to the value nearest the current one: never invent motion.
        let nearer = |a: f64, b: f64, to: f64| (b - to).abs().total_cmp(&(a - to).abs());
        // The best partner value for `value` (none without a partner).
        let score_value = |value: f64, partner_values: &[f64]| -> (i64, Option<f64>) {
            let mut trial = q.to_vec();
            trial[parameter] = value;
            let at_value = Placed::new(body, world_from_root, &trial);
            let partner_origin = partner
                .and_then(|(w, _)| axis_of(body, &at_value.poses, w.parameter))
                .map(|axis| axis.origin);
            // Only points that can lie near a scored link at this value are counted.
            let near_value: Vec<&Point3<f64>> = nearby
                .iter()
                .filter(|p| {
                    rigid.iter().any(|&l| at_value.within_reach(p, l, band))
                        || partner_origin.is_some_and(|o| (*p - o).norm() <= partner_reach + band)
                })
                .collect();
            let count_at = |trial: &[f64]| -> i64 {
                let placed = Placed::new(body, world_from_root, trial);
                near_value
                    .iter()
                    .map(|p| placed.evidence(p, band, band, &scored))
                    .sum()
            };
            match partner {
                Some((w, _)) => {
                    let partner_current = q[w.parameter];
                    partner_values
                        .iter()
                        .map(|&c| {
                            trial[w.parameter] = c;
                            (count_at(&trial), c)
                        })
                        .max_by(|a, b| a.0.cmp(&b.0).then(nearer(a.1, b.1, partner_current)))
                        .map_or((0, None), |(score, c)| (score, Some(c)))
                }
                None => (count_at(&trial), None),
            }
        };
        let coarse_step = 2.0 * window.half / steps as f64;
        let values = window.grid(body, current, window.half, steps);
        let partner_coarse: Vec<f64> = partner.map_or(Vec::new(), |(w, _)| {
            w.grid(body, q[w.parameter], w.half, partner_steps)
        });
        let partner_step = partner.map_or(0.0, |(w, _)| 2.0 * w.half / partner_steps as f64);
        let scores: Vec<(i64, Option<f64>)> = if options.parallel {
            values
                .par_iter()
                .map(|&v| score_value(v, &partner_coarse))
                .collect()
        } else {
            values
                .iter()
                .map(|&v| score_value(v, &partner_coarse))
                .collect()
        };
        let better = |a: &(f64, i64), b: &(f64, i64)| a.1.cmp(&b.1).then(nearer(a.0, b.0, current));
        let (peaks, best_coarse) = coarse_peaks(&values, &scores, current, count);
        // Most values explain nearly as much as the best: the links do not show the joint.
        let flat = best_coarse > 0
            && 3 * scores
                .iter()
                .filter(|s| 10 * s.0 >= 9 * best_coarse)
                .count()
                >= values.len();
        // Each peak again on a grid a quarter as coarse, in both joints.
        let mut candidates: Vec<Candidate> = peaks
            .into_iter()
            .map(|peak| {
                let fine_values = window.grid(body, values[peak], coarse_step, 8);
                let fine_partner: Vec<f64> = match (partner, scores[peak].1) {
                    (Some((w, _)), Some(c)) => w.grid(body, c, partner_step, 8),
                    _ => Vec::new(),
                };
                let (value, (score, partner_value)) = fine_values
                    .iter()
                    .map(|&v| (v, score_value(v, &fine_partner)))
                    .max_by(|a, b| better(&(a.0, a.1.0), &(b.0, b.1.0)))
                    .expect("a grid has values");
                Candidate {
                    value,
                    partner: partner
                        .zip(partner_value)
                        .map(|((w, _), c)| (w.parameter, c)),
                    deferred: None,
                    score,
                }
            })
            .collect();
        if candidates.is_empty() {
            candidates.push(Candidate {
                value: current,
                partner: None,
                deferred: None,
                score: 0,
            });
        }
        candidates.sort_by(|a, b| better(&(b.value, b.score), &(a.value, a.score)));
        (candidates, flat)
    }
}
