//! The search of one joint's value (with its partner when it spins its own links in place)
//! around the current one: a coarse grid, then a fine one around the best local maxima.

use nalgebra::{Isometry3, Point3, Vector3};
use rayon::prelude::*;

use super::context::FitContext;
use super::placed::{Placed, reach_m};
use super::tree::{Window, axis_of, child_parameter, spins_in_place};
use crate::registration::articulated::body::ArticulatedBody;

/// Points the coarse level of a joint search scores candidates on (a stride sample).
const COARSE_SEARCH_POINTS: usize = 1500;
/// Points the fine level scores on: enough that a step of the fine grid changes the count.
const FINE_SEARCH_POINTS: usize = 4000;
/// Fine keypoints in reach of the moved links a joint search considers, at most (a stride
/// sample): four times the fine level's, so that its sample stays full when the links not moved
/// explain most of them.
const IN_REACH_POINTS: usize = 16000;

/// A value for a searched joint (and for its partner when it spins its own links in place),
/// with how many scan points its links explain.
#[derive(Debug, Clone, Copy)]
pub(super) struct Candidate {
    pub(super) value: f64,
    pub(super) partner: Option<(usize, f64)>,
    /// A further joint's value the search settled first (see
    /// [`FitContext::global_joint_candidates`]).
    pub(super) deferred: Option<(usize, f64)>,
    pub(super) score: i64,
}

impl FitContext<'_> {
    /// Sets `q[parameter]` (and its partner's value) to the best candidate of
    /// [`Self::joint_candidates`] (of [`Self::global_joint_candidates`] when the start is not
    /// local).
    pub(super) fn search_joint(
        &self,
        world_from_root: &Isometry3<f64>,
        q: &mut [f64],
        parameter: usize,
    ) {
        let candidates = if self.global {
            self.global_joint_candidates(world_from_root, q, parameter, 1)
        } else {
            self.joint_candidates(world_from_root, q, parameter, 1)
        };
        if let Some(best) = candidates.first() {
            q[parameter] = best.value;
            for (other, value) in best.partner.into_iter().chain(best.deferred) {
                q[other] = value;
            }
        }
    }
}

/// Indices of the local maxima of coarse `scores` over `values` (scores above zero), best first
/// (ties to the value nearest `current`), those with at least half the best score, at most
/// `count`; and the best score.
pub(super) fn coarse_peaks(
    values: &[f64],
    scores: &[(i64, Option<f64>)],
    current: f64,
    count: usize,
) -> (Vec<usize>, i64) {
    let mut peaks: Vec<usize> = (0..values.len())
        .filter(|&i| {
            let left = i.checked_sub(1).map_or(i64::MIN, |l| scores[l].0);
            let right = scores.get(i + 1).map_or(i64::MIN, |r| r.0);
            scores[i].0 > 0 && scores[i].0 >= left && scores[i].0 >= right
        })
        .collect();
    // Higher scores first; between equal scores the value nearer the current one.
    peaks.sort_by(|&a, &b| {
        scores[b].0.cmp(&scores[a].0).then(
            (values[a] - current)
                .abs()
                .total_cmp(&(values[b] - current).abs()),
        )
    });
    let best = peaks.first().map_or(0, |&i| scores[i].0);
    peaks.retain(|&i| 2 * scores[i].0 >= best);
    peaks.truncate(count.max(1));
    (peaks, best)
}

impl FitContext<'_> {
    /// Values of `q[parameter]` whose links explain the most scan points that the other links do
    /// not (points buried inside a link count against it), searching a window that `delta_m`
    /// allows around the current value (coarse grid, then a finer one around each of the best
    /// `count` local maxima), best first. A joint that spins its own links in place is searched
    /// together with the next joint, whose links are the only ones that show its value; except
    /// from a near start (see [`FitContext::near`]), where it keeps its value (the only
    /// candidate) and the refinements after the next joint's search settle it from the links
    /// that show it.
    pub(super) fn joint_candidates(
        &self,
        world_from_root: &Isometry3<f64>,
        q: &[f64],
        parameter: usize,
        count: usize,
    ) -> Vec<Candidate> {
        let FitContext {
            body,
            scan,
            delta_m,
            options,
            ..
        } = *self;
        let moved = body.moved_by(parameter);
        let placed = Placed::new(body, world_from_root, q);
        let Some((window, origin)) =
            Window::new(body, &placed, parameter, delta_m, options.voxel_m)
        else {
            return Vec::new();
        };
        // From a near start a joint that spins its own links in place keeps its value: alone its
        // scores are flat (the beam followed two states a coarse step apart that the settling
        // made one), and its error moves the next joint's links by at most delta, within the
        // refinements' basin: the settling after the next joint's search (and every refinement
        // after it) takes it from there. The search together with the next joint, which far
        // starts need, tries every pair of the two grids (216 placements on the UR10's first
        // joint and its first two wrist joints), the most costly search of a fit at 100 mm.
        let spins = spins_in_place(body, &placed, parameter, options.min_observability);
        if self.near && spins {
            return vec![Candidate {
                value: q[parameter],
                partner: None,
                deferred: None,
                score: 0,
            }];
        }
        let others: Vec<usize> = (0..body.links().len())
            .filter(|link| !moved.contains(link))
            .collect();
        let coarse_band = 3.0 * options.voxel_m;
        let radius_m = window.reach_m.max(0.0) + window.sweep_m() + coarse_band;
        let in_reach = |points: &[Point3<f64>]| -> Vec<Point3<f64>> {
            points
                .iter()
                .filter(|p| (*p - origin).norm() <= radius_m)
                .copied()
                .collect()
        };
        // Points another link already explains (within the coarse band) are nobody else's to
        // claim: without this a small wrist link scores by lying on its parent's surface. (The
        // nearest-surface rule of the fine keypoints below, used here too, fills the samples with
        // the parents' points; in exploratory runs it lost a UR10 trial at 500 mm that this finds.)
        let mut nearby: Vec<(Point3<f64>, f64)> = in_reach(scan.coarse)
            .into_iter()
            .filter(|p| !placed.supports(p, coarse_band, &others))
            .map(|p| (p, f64::INFINITY))
            .collect();
        if nearby.len() < FINE_SEARCH_POINTS {
            // So few that the fine level would score every one: the coarse keypoints are then all
            // the search sees, and on them a small link (a wrist) is a handful of points, no more
            // than the outliers around it. The fine keypoints then, and a point belongs to the
            // nearest surface: one another link explains is the moved links' where they come
            // nearer to it (a wrist nested in its parent's fork would lose most of its points to
            // the band). A stride bounds the work where the window is wide.
            let fine = in_reach(scan.fine);
            let stride = fine.len().div_ceil(IN_REACH_POINTS).max(1);
            nearby = fine
                .into_iter()
                .step_by(stride)
                .map(|p| {
                    let claimed_m = placed
                        .distance_within(&p, coarse_band, &others)
                        .unwrap_or(f64::INFINITY);
                    (p, claimed_m)
                })
                .collect();
        }
        if nearby.is_empty() {
            return Vec::new();
        }
        let partner = if spins {
            child_parameter(body, parameter).and_then(|child| {
                Window::new(body, &placed, child, delta_m, options.voxel_m).map(|(w, _)| w)
            })
        } else {
            None
        };
        // The coarse level only has to find the right basin: a sample of the points does.
        let stride = nearby.len().div_ceil(COARSE_SEARCH_POINTS);
        let sample: Vec<(Point3<f64>, f64)> = nearby.iter().step_by(stride).copied().collect();
        let fine_stride = nearby.len().div_ceil(FINE_SEARCH_POINTS);
        let fine: Vec<(Point3<f64>, f64)> = nearby.iter().step_by(fine_stride).copied().collect();
        // Coarse steps move the farthest point by about a coarse voxel or more, at most 24 of them.
        let coarse_steps = ((2.0 * window.sweep_m() / coarse_band).ceil() as usize).clamp(4, 24);
        let coarse_step = 2.0 * window.half / coarse_steps as f64;
        // The coarse level's band, the widest either level scores in.
        let widest_band = (coarse_step * window.reach_m).max(coarse_band);
        let partner_links: Vec<usize> = partner
            .as_ref()
            .map_or(Vec::new(), |w| body.moved_by(w.parameter));
        let turned_alone: Vec<usize> = moved
            .iter()
            .filter(|link| !partner_links.contains(link))
            .copied()
            .collect();
        // Only the points some value of the joint can bring a moved link to are scored (the
        // scores are those of the whole samples): see [`SweptTubes`].
        let (sample, fine) = match SweptTubes::new(
            body,
            &placed,
            parameter,
            &turned_alone,
            partner
                .as_ref()
                .map(|w| (w.parameter, partner_links.as_slice())),
            widest_band,
        ) {
            Some(tubes) => {
                let swept = |points: Vec<(Point3<f64>, f64)>| -> Vec<(Point3<f64>, f64)> {
                    points.into_iter().filter(|(p, _)| tubes.hold(p)).collect()
                };
                (swept(sample), swept(fine))
            }
            None => (sample, fine),
        };
        // The coarse level tries every partner value at each value of the joint: only the points
        // that can count for one of them are scored. The links the partner does not move turn
        // with the joint alone; the partner's stay within their reach of its axis origin,
        // whatever its value (a point farther than a link's bounding sphere grown by the band
        // counts 0 in [`Placed::evidence`], so the scores are those of the whole sample). The
        // coarse level with a partner was three quarters of a fit's joint-search points.
        let near_any_partner_value = |trial: &[f64], band: f64| -> Vec<(Point3<f64>, f64)> {
            let at_value = Placed::new(body, world_from_root, trial);
            let partner_origin = partner
                .as_ref()
                .filter(|w| !body.parameters()[w.parameter].prismatic)
                .and_then(|w| axis_of(body, &at_value.poses, w.parameter))
                .map(|axis| axis.origin);
            let Some(origin) = partner_origin else {
                return sample.clone();
            };
            let partner_reach_m = reach_m(&at_value, &partner_links, &origin) + band;
            sample
                .iter()
                .filter(|(p, _)| {
                    (p - origin).norm() <= partner_reach_m
                        || turned_alone
                            .iter()
                            .any(|&link| at_value.within_reach(p, link, band))
                })
                .copied()
                .collect()
        };
        let count_points = |trial: &[f64], band: f64, points: &[(Point3<f64>, f64)]| -> i64 {
            let placed = Placed::new(body, world_from_root, trial);
            points
                .iter()
                .map(|(p, claimed_m)| {
                    placed.evidence_nearer(p, band, coarse_band, *claimed_m, &moved)
                })
                .sum()
        };
        let current = q[parameter];
        // `fine` for the fine grid about a coarse peak (the joint within one coarse step of
        // `centre`, the partner at `partner_value`): a moved link's bounding sphere moves by at
        // most its centre's distance from the joint's axis origin times that step (the step
        // itself for a prismatic joint), so the points farther than that and the band from
        // every sphere at the peak count 0 at every value of the grid.
        let near_fine_grid = |centre: f64,
                              partner_value: Option<f64>,
                              step: f64,
                              band: f64|
         -> Vec<(Point3<f64>, f64)> {
            let mut trial = q.to_vec();
            trial[parameter] = centre;
            if let (Some(partner), Some(value)) = (&partner, partner_value) {
                trial[partner.parameter] = value;
            }
            let at_peak = Placed::new(body, world_from_root, &trial);
            let prismatic = body.parameters()[parameter].prismatic;
            let grown: Vec<(usize, f64)> = moved
                .iter()
                .filter_map(|&link| {
                    let (sphere_centre, _) = at_peak.spheres[link]?;
                    let lever_m = if prismatic {
                        1.0
                    } else {
                        (sphere_centre - origin).norm()
                    };
                    Some((link, band + lever_m * step))
                })
                .collect();
            fine.iter()
                .filter(|(p, _)| {
                    grown
                        .iter()
                        .any(|&(link, reach)| at_peak.within_reach(p, link, reach))
                })
                .copied()
                .collect()
        };
        let score_grid = |candidates: &[f64],
                          band: f64,
                          partner_value: Option<f64>,
                          fine_points: Option<&[(Point3<f64>, f64)]>|
         -> Vec<(i64, Option<f64>)> {
            let coarse = fine_points.is_none();
            let score = |value: f64| -> (i64, Option<f64>) {
                let mut trial = q.to_vec();
                trial[parameter] = value;
                match (&partner, coarse) {
                    (Some(partner), true) => {
                        let near = near_any_partner_value(&trial, band);
                        distinct_values(partner.grid(body, q[partner.parameter], partner.half, 8))
                            .into_iter()
                            .map(|child| {
                                trial[partner.parameter] = child;
                                (count_points(&trial, band, &near), Some(child))
                            })
                            .max_by_key(|(score, _)| *score)
                            .unwrap_or((0, None))
                    }
                    _ => {
                        if let (Some(partner), Some(value)) = (&partner, partner_value) {
                            trial[partner.parameter] = value;
                        }
                        let points = fine_points.unwrap_or(&sample);
                        (count_points(&trial, band, points), partner_value)
                    }
                }
            };
            let distinct = distinct_values(candidates.to_vec());
            let scores: Vec<(i64, Option<f64>)> = if options.parallel {
                distinct.par_iter().map(|&v| score(v)).collect()
            } else {
                distinct.iter().map(|&v| score(v)).collect()
            };
            spread_scores(candidates, &distinct, &scores)
        };
        // Ties (a symmetric link) go to the value nearest the current one: never invent motion.
        let better = |a: &(f64, i64), b: &(f64, i64)| {
            a.1.cmp(&b.1)
                .then((b.0 - current).abs().total_cmp(&(a.0 - current).abs()))
        };
        let coarse_values = window.grid(body, current, window.half, coarse_steps);
        let band = widest_band;
        let coarse_scores = score_grid(&coarse_values, band, None, None);
        // Local maxima of the coarse scores, best first.
        let (peaks, _) = coarse_peaks(&coarse_values, &coarse_scores, current, count);
        let mut candidates: Vec<Candidate> = peaks
            .into_iter()
            .map(|peak| {
                let centre = coarse_values[peak];
                let partner_value = coarse_scores[peak].1;
                let steps = 8;
                let fine_step = 2.0 * coarse_step / steps as f64;
                let values = window.grid(body, centre, coarse_step, steps);
                let band = (fine_step * window.reach_m).max(coarse_band);
                let near = near_fine_grid(centre, partner_value, coarse_step, band);
                let scores = score_grid(&values, band, partner_value, Some(&near));
                let (value, score) = values
                    .iter()
                    .zip(&scores)
                    .map(|(&v, &(score, _))| (v, score))
                    .max_by(better)
                    .unwrap_or((centre, 0));
                Candidate {
                    value,
                    partner: partner
                        .as_ref()
                        .zip(partner_value)
                        .map(|(w, v)| (w.parameter, v)),
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
        candidates
    }
}

/// Where a revolute joint's moved links can be at any of its values: turning about the axis keeps
/// each point's height along it and distance from it, so a link's bounding sphere (grown by the
/// band) sweeps a torus, and the links a partner joint moves stay within their reach of the
/// partner's axis origin, which sweeps a circle. A point in no tube is farther than the band
/// from every moved link at every value, and counts 0 in [`Placed::evidence`].
pub(super) struct SweptTubes {
    origin: Point3<f64>,
    axis: Vector3<f64>,
    /// (height along the axis, distance from it, tube radius), m.
    tubes: Vec<(f64, f64, f64)>,
}

impl SweptTubes {
    /// `None` for a prismatic joint or partner (or one without an axis), whose links do not
    /// turn about it.
    pub(super) fn new(
        body: &ArticulatedBody,
        placed: &Placed,
        parameter: usize,
        turned_alone: &[usize],
        partner: Option<(usize, &[usize])>,
        band: f64,
    ) -> Option<Self> {
        let prismatic = |p: usize| body.parameters()[p].prismatic;
        if prismatic(parameter) || partner.is_some_and(|(p, _)| prismatic(p)) {
            return None;
        }
        let axis = axis_of(body, &placed.poses, parameter)?;
        let direction = axis.axis.try_normalize(1e-12)?;
        let mut swept = Self {
            origin: axis.origin,
            axis: direction,
            tubes: Vec::new(),
        };
        for &link in turned_alone {
            if let Some((centre, radius)) = placed.spheres[link] {
                let (height, distance) = swept.cylindrical(&centre);
                swept.tubes.push((height, distance, radius + band));
            }
        }
        if let Some((partner, partner_links)) = partner {
            let partner_origin = axis_of(body, &placed.poses, partner)?.origin;
            let reach = reach_m(placed, partner_links, &partner_origin);
            let (height, distance) = swept.cylindrical(&partner_origin);
            swept.tubes.push((height, distance, reach + band));
        }
        Some(swept)
    }

    /// Height along the axis and distance from it.
    fn cylindrical(&self, point: &Point3<f64>) -> (f64, f64) {
        let offset = point - self.origin;
        let height = offset.dot(&self.axis);
        (height, (offset - self.axis * height).norm())
    }

    pub(super) fn hold(&self, point: &Point3<f64>) -> bool {
        let (height, distance) = self.cylindrical(point);
        self.tubes.iter().any(|&(h, d, tube)| {
            let (dh, dd) = (height - h, distance - d);
            dh * dh + dd * dd <= tube * tube
        })
    }
}

/// `grid` (ascending, from [`Window::grid`]) without the repeats a joint limit leaves where the
/// window reaches past it: at 500 mm half the ABB IRB 1600's wrist grid was its limit.
pub(super) fn distinct_values(mut grid: Vec<f64>) -> Vec<f64> {
    grid.dedup();
    grid
}

/// The scores of `distinct` (= [`distinct_values`] of `grid`) laid out over `grid`.
pub(super) fn spread_scores<T: Copy>(grid: &[f64], distinct: &[f64], scores: &[T]) -> Vec<T> {
    let mut index = 0;
    grid.iter()
        .map(|value| {
            while distinct[index] != *value {
                index += 1;
            }
            scores[index]
        })
        .collect()
}
