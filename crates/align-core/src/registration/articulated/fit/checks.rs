//! Checks after the search: half turns of a joint (with the joints below searched again), a
//! base turned with joint 1 making up for it, and, after a global search, a second look at
//! joints that spin their own links in place.

use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use super::RobotFitOptions;
use super::context::FitContext;
use super::placed::{Placed, coverage, reach_m};
use super::refine::refine;
use super::report::{FinalState, RobotTwin, final_state};
use super::tree::{Window, search_order, spins_in_place};
use crate::registration::articulated::body::JointAxis;

/// Single-flip states a global fit turns once more (see [`FitContext::flip_check`]).
const FLIP_RUNNERS_UP: usize = 2;

/// A state is another pose of the robot when some link's surface moves more than this: the
/// trials' success threshold.
const TWIN_DISTINCT_M: f64 = 1e-3;

/// Vertices of a link compared for [`TWIN_DISTINCT_M`]: enough to see a surface move by a
/// millimetre, few enough to cost nothing beside the fit.
const TWIN_SAMPLES_PER_LINK: usize = 400;

/// [`crate::geometry::Mesh::deviation_m`] over at most [`TWIN_SAMPLES_PER_LINK`] vertices.
fn sampled_deviation_m(
    mesh: &crate::geometry::Mesh,
    a: &Isometry3<f64>,
    b: &Isometry3<f64>,
) -> f64 {
    let b_from_a = b.inverse() * a;
    let a_from_b = b_from_a.inverse();
    let count = mesh.vertices().count();
    let stride = count.div_ceil(TWIN_SAMPLES_PER_LINK).max(1);
    mesh.vertices()
        .step_by(stride)
        .map(|v| {
            let there = mesh.closest_point(&(b_from_a * v)).signed_distance.abs();
            let back = mesh.closest_point(&(a_from_b * v)).signed_distance.abs();
            there.max(back)
        })
        .fold(0.0, f64::max)
}

impl FitContext<'_> {
    /// After a global search: a joint whose own links turn in place about its axis (a nearly round
    /// link, such as a UR wrist) shows its angle only through the links after it, which may hold
    /// few points; searched while the joints above were still wrong it can settle on a wrong value
    /// that the refinement cannot leave. Each such joint is searched once more, with its child,
    /// from the final state; a candidate is kept only when, refined, it explains at least
    /// `min_link_points` more keypoints than the fit. Returns the iterations spent.
    pub(super) fn second_look(
        &self,
        world_from_root: &mut Isometry3<f64>,
        q: &mut Vec<f64>,
        state: &mut FinalState,
    ) -> usize {
        let FitContext {
            body,
            scan,
            options,
            ..
        } = *self;
        let mut iterations = 0;
        for parameter in search_order(body) {
            let placed = Placed::new(body, world_from_root, q);
            let spins = spins_in_place(body, &placed, parameter, options.min_observability);
            if !spins {
                continue;
            }
            let candidates = self.global_joint_candidates(world_from_root, q, parameter, 3);
            for candidate in candidates {
                let mut trial_q = q.clone();
                let mut trial_root = *world_from_root;
                trial_q[parameter] = candidate.value;
                for (other, value) in candidate.partner.into_iter().chain(candidate.deferred) {
                    trial_q[other] = value;
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
                let trial_state = final_state(body, scan.fine, &trial_root, &trial_q, options);
                if trial_state.matches.len() >= state.matches.len() + options.min_link_points {
                    *world_from_root = trial_root;
                    *q = trial_q;
                    *state = trial_state;
                    break;
                }
            }
        }
        iterations
    }

    /// Tries each revolute joint turned half a turn, with the joints below it searched again and
    /// everything refined, and keeps what explains the scan better. A wrist (or shoulder) whose
    /// three axes meet reaches the same link poses as (a + pi, -b, c + pi): continuous refinement
    /// cannot cross between the two, and on nearly symmetric links the searches may settle on the
    /// wrong one. Only joints whose window allows a half turn are tried.
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
    ) -> (usize, Vec<Isometry3<f64>>, Vec<Vec<f64>>) {
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
        let mut best = score(world_from_root, q);
        let mut iterations = 0;
        let mut runners_up: Vec<(i64, usize, Isometry3<f64>, Vec<f64>)> = Vec::new();
        let flip = |base: &Isometry3<f64>, q: &[f64], index: usize, iterations: &mut usize| {
            let (trial_base, trial_q, spent) = self.flipped(base, q, &order, index)?;
            *iterations += spent;
            Some((score(&trial_base, &trial_q), trial_base, trial_q))
        };
        let mut left: Vec<(Isometry3<f64>, Vec<f64>)> = Vec::new();
        for index in 0..order.len() {
            let Some((trial_score, trial_base, trial_q)) =
                flip(world_from_root, q, index, &mut iterations)
            else {
                continue;
            };
            if trial_score > best {
                best = trial_score;
                left.push((*world_from_root, q.clone()));
                *q = trial_q;
                *world_from_root = trial_base;
            } else {
                left.push((trial_base, trial_q.clone()));
                if global {
                    runners_up.push((trial_score, index, trial_base, trial_q));
                }
            }
        }
        runners_up.sort_by_key(|(trial_score, ..)| std::cmp::Reverse(*trial_score));
        runners_up.truncate(FLIP_RUNNERS_UP);
        for (_, first, base, first_q) in runners_up {
            for second in first + 1..order.len() {
                let Some((trial_score, trial_base, trial_q)) =
                    flip(&base, &first_q, second, &mut iterations)
                else {
                    continue;
                };
                if trial_score > best {
                    best = trial_score;
                    left.push((*world_from_root, q.clone()));
                    *q = trial_q;
                    *world_from_root = trial_base;
                } else {
                    left.push((trial_base, trial_q));
                }
            }
        }
        let (bases, qs) = left.into_iter().unzip();
        (iterations, bases, qs)
    }

    /// The best of `others` (states the flip check scored and left) that puts some link's
    /// surface more than [`TWIN_DISTINCT_M`] from where the fit has it, scored as the flip check
    /// scores (coarse keypoints within the narrowest band) against the fit: a wrist turned a half
    /// turn with the next joint mirrored, on links nearly symmetric under that turn, scores
    /// within a few keypoints of the truth, and the scan cannot tell the two apart. Ambiguous
    /// when the fit explains fewer than `min_link_points` keypoints more: the evidence the
    /// fit asks of a link to call it seen, and of a candidate to replace its state.
    pub(super) fn twin(
        &self,
        world_from_root: &Isometry3<f64>,
        q: &[f64],
        others_base: &[Isometry3<f64>],
        others_q: &[Vec<f64>],
    ) -> Option<RobotTwin> {
        let FitContext {
            body,
            scan,
            options,
            ..
        } = *self;
        let with_surface: Vec<usize> = (0..body.links().len())
            .filter(|&l| body.links()[l].surface.is_some())
            .collect();
        let score = |base: &Isometry3<f64>, q: &[f64]| {
            coverage(
                body,
                scan.coarse,
                base,
                q,
                &with_surface,
                options.band_min_m,
                options.parallel,
            )
        };
        let fit_poses = body.link_poses(world_from_root, q);
        let distinct = |base: &Isometry3<f64>, other_q: &[f64]| {
            let poses = body.link_poses(base, other_q);
            with_surface.iter().any(|&link| {
                let mesh = body.links()[link].surface.as_ref().expect("has surface");
                sampled_deviation_m(mesh, &fit_poses[link], &poses[link]) > TWIN_DISTINCT_M
            })
        };
        let fit_coverage = score(world_from_root, q);
        let mut scored: Vec<(i64, usize)> = others_q
            .iter()
            .enumerate()
            .map(|(i, other_q)| (score(&others_base[i], other_q), i))
            .collect();
        scored.sort_by_key(|(coverage, _)| std::cmp::Reverse(*coverage));
        let (coverage, index) = scored
            .into_iter()
            .find(|&(_, i)| distinct(&others_base[i], &others_q[i]))?;
        let margin = i64::try_from(options.min_link_points).unwrap_or(i64::MAX);
        Some(RobotTwin {
            world_from_root: others_base[index],
            q: others_q[index].clone(),
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
    /// explain (coarse steps, then fine ones around the best); the best is kept, and refined, when
    /// it explains `min_link_points` more than the state found. Returns the iterations spent.
    pub(super) fn base_turn_check(
        &self,
        world_from_root: &mut Isometry3<f64>,
        q: &mut Vec<f64>,
    ) -> usize {
        let FitContext {
            body,
            scan,
            delta_m,
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
        let score = |theta: f64, band: f64| -> Option<i64> {
            let (base, trial_q) = turned(theta)?;
            Some(coverage(
                body,
                scan.fine,
                &base,
                &trial_q,
                &fixed,
                band,
                options.parallel,
            ))
        };
        // Of the turns that explain about as many points as the best (within `margin`), the
        // smallest: a base symmetric under some turn (a square plate) scores its copies alike, and
        // the scan's noise must not pick one. Never invent motion.
        let best_of = |centre: f64, half: f64, step: f64, band: f64, margin: i64| {
            let steps = (half / step).ceil() as i64;
            let scored: Vec<(f64, i64)> = (-steps..=steps)
                .filter_map(|k| {
                    let theta = centre + k as f64 * step;
                    Some((theta, score(theta, band)?))
                })
                .collect();
            let best = scored.iter().map(|(_, s)| *s).max()?;
            scored
                .into_iter()
                .filter(|(_, s)| *s + margin >= best)
                .min_by(|a, b| a.0.abs().total_cmp(&b.0.abs()))
        };
        // Coarse steps move the base's farthest point by three keypoint voxels, scored in a band
        // as wide; fine ones by half a voxel, in a band of one voxel.
        let coarse_step = 3.0 * options.voxel_m / reach;
        let fine_step = 0.5 * options.voxel_m / reach;
        let margin = options.min_link_points as i64;
        let Some((coarse_best, _)) = best_of(0.0, half, coarse_step, 3.0 * options.voxel_m, margin)
        else {
            return 0;
        };
        let fine_band = options.voxel_m;
        let Some((theta, best)) = best_of(coarse_best, coarse_step, fine_step, fine_band, 0) else {
            return 0;
        };
        let Some(current) = score(0.0, fine_band) else {
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
