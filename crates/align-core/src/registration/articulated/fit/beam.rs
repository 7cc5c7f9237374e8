//! The first search down the tree: each joint searched from every state of a beam seeded by
//! the base hypotheses, the decided links settled, the best states kept.

use nalgebra::{Isometry3, Point3};
use rayon::prelude::*;

use super::RobotFitOptions;
use super::context::FitContext;
use super::joint_search::Candidate;
use super::placed::{FloorMarks, Placed, coverage_beside_floor};
use super::refine::{Refinement, SETTLE_DAMPING, refine, refine_links};
use super::tree::{Window, search_order};
use crate::registration::articulated::body::ArticulatedBody;
use crate::registration::pca::on_a_plane;

/// Iterations of the refinement of the decided links after each joint of the beam search.
const SETTLE_ITERATIONS: usize = 6;

/// Points the beam scores its states on (a stride sample of the coarse keypoints).
const BEAM_SCORE_POINTS: usize = 3000;

/// Values of a joint the beam search follows from each of its states (the best local maxima).
const PEAKS_PER_STATE: usize = 3;

/// A state of the beam search: the base pose and every joint's value.
type BeamState = (Isometry3<f64>, Vec<f64>);

/// The states one joint's searches lead to, each with the index in `beam` of the state it came
/// from: each state with each of its candidate values (and the partner's and deferred joints'
/// values), and a state whose search found nothing to score unchanged; reached twice, a state is
/// kept once. `None` when no state's search found anything: the joint is then left out of the
/// decided links.
///
/// A state whose search has nothing to score (no keypoint near the joint that the links above
/// it leave unexplained) keeps the joint where it is. Dropped, it took a right base with it: on
/// the ABB IRB 1600 at 1000 mm (`robot-scans --seed 91`, scene 0) the true base led the beam
/// by 193 points to 129 until the wrist's pair search, with the forearm half a turn off about
/// its roll, found no point beside it, and only the states from other bases went on.
pub(super) fn next_states(
    beam: &[BeamState],
    searched: Vec<Vec<Candidate>>,
    parameter: usize,
    options: &RobotFitOptions,
) -> Option<Vec<(BeamState, usize)>> {
    let mut next: Vec<(BeamState, usize)> = Vec::new();
    let mut unsearched = Vec::new();
    for (from, ((base, q), candidates)) in beam.iter().zip(searched).enumerate() {
        if candidates.is_empty() {
            unsearched.push(((*base, q.clone()), from));
        }
        for candidate in candidates {
            let mut q = q.clone();
            q[parameter] = candidate.value;
            for (other, value) in candidate.partner.into_iter().chain(candidate.deferred) {
                q[other] = value;
            }
            // States that reached the same configuration are settled once.
            let state = (*base, q);
            if !next
                .iter()
                .any(|(other, _)| same_state(other, &state, options))
            {
                next.push((state, from));
            }
        }
    }
    if next.is_empty() {
        return None;
    }
    for (state, from) in unsearched {
        if !next
            .iter()
            .any(|(other, _)| same_state(other, &state, options))
        {
            next.push((state, from));
        }
    }
    Some(next)
}

/// A settled state of the beam: its score, the state and the base hypothesis it descends from.
pub(super) type ScoredState = (i64, BeamState, usize);

/// The states the beam goes on with: the `width` best-scored distinct states and, at the first
/// cut (`each_hypothesis`), each base hypothesis's best distinct state as well, best first.
///
/// After the first joint only the base and the first link are decided, and the places a folded
/// arm offers them may explain more than the true one: on the UR10 with CAD links (`robot-scans
/// --seed 20`, scene 3 at 500 mm) the base stood on the floor at its place scored 16 keypoints
/// against 18-28 for the other hypotheses' states and was 11th of 39, below the six kept. Each
/// hypothesis is judged with its arm by the next joint's cut; the beam is as wide as before
/// from there.
pub(super) fn keep_best(
    mut scored: Vec<ScoredState>,
    width: usize,
    each_hypothesis: bool,
    options: &RobotFitOptions,
) -> Vec<(BeamState, usize)> {
    // Stable: among equal scores the order of the searches decides, as if one by one.
    scored.sort_by_key(|s| std::cmp::Reverse(s.0));
    let mut kept: Vec<(BeamState, usize)> = Vec::new();
    for (_, state, origin) in scored {
        let full = kept.len() >= width;
        if full && !(each_hypothesis && kept.iter().all(|(_, o)| *o != origin)) {
            continue;
        }
        // Two hypotheses that reached the same configuration would spend the beam twice.
        if !kept
            .iter()
            .any(|(other, _)| same_state(other, &state, options))
        {
            kept.push((state, origin));
        }
    }
    kept
}

/// Two search states closer than a keypoint voxel (base) and a milliradian (every joint).
fn same_state(a: &BeamState, b: &BeamState, options: &RobotFitOptions) -> bool {
    (a.0.translation.vector - b.0.translation.vector).norm() < options.voxel_m
        && a.0.rotation.angle_to(&b.0.rotation) < 1e-3
        && a.1.iter().zip(&b.1).all(|(x, y)| (x - y).abs() < 1e-3)
}

impl FitContext<'_> {
    /// The joints searched down the tree from each base hypothesis, keeping the `beam_width`
    /// states whose decided links (those every joint above has been searched for) explain the
    /// most scan points: a joint whose best value is wrong only because a link below it is still
    /// far off survives as a runner-up until the links below decide. Each surviving state is then
    /// refined, and the one explaining the most points wins.
    pub(super) fn beam_search(&self, hypotheses: &[Isometry3<f64>], q0: &[f64]) -> BeamState {
        let FitContext {
            body,
            scan,
            global,
            near,
            floor,
            options,
            ..
        } = *self;
        let (width, peaks_per_state) = if near {
            (options.near_beam_width, super::NEAR_PEAKS_PER_STATE)
        } else {
            (options.beam_width, PEAKS_PER_STATE)
        };
        let width = width.max(1);
        let stride = scan.coarse.len().div_ceil(BEAM_SCORE_POINTS).max(1);
        let sample: Vec<Point3<f64>> = scan.coarse.iter().step_by(stride).copied().collect();
        let band = 3.0 * options.voxel_m;
        let on_floor: Vec<bool> = match &floor {
            Some(plane) => sample
                .iter()
                .map(|p| on_a_plane(p, std::slice::from_ref(plane)))
                .collect(),
            None => Vec::new(),
        };
        // The states are ranked on what their links explain, the floor's points never counting
        // for the base and only where the other links face up (see `coverage_beside_floor`; no
        // floor is marked from a near or global start).
        let floor_marks = floor.map(|(_, up)| FloorMarks {
            on_floor: &on_floor,
            up,
        });
        let score = |base: &Isometry3<f64>, q: &[f64], links: &[usize]| {
            coverage_beside_floor(
                &Placed::new(body, base, q),
                &sample,
                floor_marks,
                links,
                band,
                options.parallel,
            )
        };
        let with_surface: Vec<usize> = (0..body.links().len())
            .filter(|&l| body.links()[l].surface.is_some())
            .collect();
        let mut beam: Vec<BeamState> = hypotheses.iter().map(|h| (*h, q0.to_vec())).collect();
        // The base hypothesis each state of the beam descends from.
        let mut origins: Vec<usize> = (0..hypotheses.len()).collect();
        let mut searched: Vec<usize> = Vec::new();
        for parameter in search_order(body) {
            // The states are searched side by side (each search is parallel too, but its last
            // few candidate values leave a core idle); merged in beam order, as if one by one.
            let peaks = width.min(peaks_per_state);
            let search = |(base, q): &BeamState| {
                if global {
                    self.global_joint_candidates(base, q, parameter, peaks)
                } else {
                    self.joint_candidates(base, q, parameter, peaks)
                }
            };
            let searched_states: Vec<Vec<Candidate>> = if options.parallel {
                beam.par_iter().map(search).collect()
            } else {
                beam.iter().map(search).collect()
            };
            let Some(next) = next_states(&beam, searched_states, parameter, options) else {
                continue;
            };
            searched.push(parameter);
            // Each hypothesis's best state is kept through the first cut from a start that is
            // not global (see `keep_best`); a global start's hypotheses are the detection's best
            // few dozen bases, and keeping each (40 states where 6 go on) cost the CAD UR10 37 %
            // more time at 1000 mm in ray-cast scans for one fit of ten (a probe,
            // docs/articulated-trials.md).
            let first_cut = searched.len() == 1 && !global;
            let decided: Vec<usize> = with_surface
                .iter()
                .copied()
                .filter(|&l| body.movers(l).iter().all(|p| searched.contains(p)))
                .collect();
            let settle = RobotFitOptions {
                max_iterations: SETTLE_ITERATIONS,
                ..options.clone()
            };
            let settle_band = 2.0 * band;
            let settle_one = |((mut base, mut q), from): (BeamState, usize)| {
                if settle.max_iterations > 0 {
                    refine_links(
                        body,
                        &sample,
                        &mut base,
                        &mut q,
                        &decided,
                        &Refinement {
                            options: &settle,
                            band0_m: settle_band,
                            damping: SETTLE_DAMPING,
                            exact: false,
                        },
                    );
                }
                (score(&base, &q, &decided), (base, q), origins[from])
            };
            let scored: Vec<ScoredState> = if options.parallel {
                next.into_par_iter().map(settle_one).collect()
            } else {
                next.into_iter().map(settle_one).collect()
            };
            (beam, origins) = keep_best(scored, width, first_cut, options)
                .into_iter()
                .unzip();
        }
        if beam.len() == 1 {
            return beam.pop().expect("one state");
        }
        // Enough to rank the survivors: the winner is refined on every coarse keypoint next.
        let refine_options = RobotFitOptions {
            max_iterations: 8,
            ..options.clone()
        };
        let band0 = options.refine_band0_m();
        // A survivor is ranked refined, unless the refinement took a joint out of the window
        // the start allows it: then as it was. On the ABB IRB 1600 at 200 mm (`robot-scans
        // --seed 91`, scene 1 trial 0) the 8 steps turned a state's forearm roll by 1.9 rad
        // along its nearly free roll, where delta allows 0.8, and that state won with its
        // wrist wrong.
        let rank = |(mut base, mut q): BeamState| {
            let halves = window_halves(body, &base, &q, self.delta_m, options.voxel_m);
            let before = (base, q.clone());
            refine(
                body,
                &sample,
                &mut base,
                &mut q,
                band0,
                &refine_options,
                false,
            );
            let (base, q) = if leaves_windows(&before.1, &q, &halves) {
                before
            } else {
                (base, q)
            };
            (score(&base, &q, &with_surface), base, q)
        };
        let ranked: Vec<(i64, Isometry3<f64>, Vec<f64>)> = if options.parallel {
            beam.into_par_iter().map(rank).collect()
        } else {
            beam.into_iter().map(rank).collect()
        };
        ranked
            .into_iter()
            .max_by_key(|(score, _, _)| *score)
            .map(|(_, base, q)| (base, q))
            .expect("the beam is never empty")
    }
}

/// Each parameter's window half-width at `base` and `q` ([`Window::new`]; infinite where a joint
/// has no placed axis): how far the start lets it move from there.
fn window_halves(
    body: &ArticulatedBody,
    base: &Isometry3<f64>,
    q: &[f64],
    delta_m: f64,
    voxel_m: f64,
) -> Vec<f64> {
    let placed = Placed::new(body, base, q);
    (0..q.len())
        .map(|parameter| {
            Window::new(body, &placed, parameter, delta_m, voxel_m)
                .map_or(f64::INFINITY, |(window, _)| window.half)
        })
        .collect()
}

/// Whether some parameter moved from `before` to `after` by more than its window's `halves`.
pub(super) fn leaves_windows(before: &[f64], after: &[f64], halves: &[f64]) -> bool {
    before
        .iter()
        .zip(after)
        .zip(halves)
        .any(|((b, a), half)| (a - b).abs() > *half)
}
