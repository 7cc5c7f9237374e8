//! One run of the thesis's loop (filters, weights and a step per iteration while the search band
//! shrinks) and how the band shrinks: the thesis's cosine (eq. 33), its code's cosine squared,
//! or coarse to fine, as the local peers run (halving the band each time the pose settles in
//! it, the wide bands on coarser keypoints).

use nalgebra::{Isometry3, Point3, Vector3};
use rayon::prelude::*;

use super::PcaOptions;
use super::matching::{Lookup, Match, NO_HINT, correspond};
use super::model_to_scan::{ModelSamples, ModelToScanLevel, ScanTree, correspond_model_to_scan};
use super::planes::{large_planes, off_the_planes};
use super::step::{WEAK_DIRECTION_FRACTION, step_along};
use crate::geometry::Mesh;
use crate::registration::convergence::{StopCriterion, pose_distance};
use crate::registration::sampling::voxel_representatives;
use crate::rng::SplitMix64;

/// How delta shrinks over a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeltaSchedule {
    /// delta_i = (delta0 - delta_min) cos(i / n * pi / 2) + delta_min (eq. 33).
    Cosine,
    /// delta_i = (delta0 - delta_min) cos^2(i / n * pi / 2) + delta_min: shrinks faster early.
    CosineSquared,
    /// Coarse to fine: the band holds while the pose still moves in it and halves once a step
    /// moves the pose by less than [`SETTLED_FRACTION`] of it (or after
    /// [`STEPS_PER_BAND`] steps), down to delta_min; bands more than [`BAND_PER_LEVEL_VOXEL`]
    /// voxels of a coarser keypoint level wide run on that level. The cosine bands shrink
    /// at a fixed pace, so a run spends a hundred steps in them whether the pose moves or not;
    /// on the CAD scans the same successes came in half the time (docs/cad-scan-trials.md).
    Halving,
}

/// How a local run matches in the bands it runs on a coarser keypoint level (see
/// [`PcaOptions::wide_band_matching`]).
///
/// Scan to model, every keypoint in the band pulls the part, so the floor and a box beside it
/// decide a wide band's step by their number: on robot links no setting had been tuned on
/// (TIAGo Pro, Z1, Panda; `scripts/unseen-parts.sh`), TIAGo links 50 mm off ended 140-490 mm
/// away (one lying link's first step: 72 of its 182 matches on clutter, 27 mm off the part
/// against 2.3 mm for its own points), and the local stage found 60 of 200 scans where
/// small_gicp found 99. Model to scan, each of the part's points counts once, but the faces the
/// scanner never saw are pulled to whatever is near, and the big ABB links were lost. Local
/// successes on the `replay` bench's corpora (the four of the ABB, xArm7 and SO-ARM100 links /
/// the unseen set A): scan to model 322 / 60, model to scan 283 / 84, both ways 315 / 84 (with
/// the scan's set weighted twice: 323 / 80; half: 306 / 86). On set B, held out until this was
/// chosen, both ways and scan to model 89 each, ahead of or level with both peers at every
/// delta with both ways only (docs/cad-scan-trials.md, fourteenth session).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WideBandMatching {
    /// Each scan keypoint in the band to its closest point on the part, as the thesis and the
    /// narrow bands match.
    ScanToModel,
    /// Points sampled on the part (one per occupied voxel of the level) each to the nearest scan
    /// keypoint in the band, as Open3D and small_gicp match.
    ModelToScan,
    /// Both sets, the scan-to-model matches' weights scaled so that their total is the
    /// model-to-scan matches' total.
    BothWays,
}

/// A halving band halves once a step moves the pose (the thesis's distance) by less than this
/// fraction of it: the pose has settled as far as the band can tell.
const SETTLED_FRACTION: f64 = 0.01;

/// A halving band halves after this many steps even when the pose still moves (clutter at the
/// band's edge can keep it sliding by more than [`SETTLED_FRACTION`]). In the wide bands the
/// steps after the first few jitter by millimetres to centimetres without going anywhere. On the
/// four CAD corpora (800 scans, `replay` bench, docs/cad-scan-trials.md) 8 steps against 15 gave
/// 322 local successes against 314 (12: 315, 10: 316, 6: 307; 8 with 15 kept in the bands
/// over 10 cm: 316) and median times 15-25 % shorter at 50-1000 mm.
const STEPS_PER_BAND: usize = 8;

/// A halving run that has not stood still after this many steps in its last band ends there
/// unless it has moved on by [`LAST_BAND_PROGRESS_FRACTION`] of the band since (and is then
/// looked at again after as many more): one that still moves by more than the tolerance but
/// goes nowhere is cycling between correspondences (points at the band's edge going in and
/// out), and ran on to `max_iterations`: on the CAD scans most runs that did so were misses.
/// One that slides on (a nearly round part turning about its axis, where each step is small)
/// goes on: the ABB's base in a 1000 mm CAD scan (trial 183) turned 0.17 rad into place in 185
/// steps (the run and the polish), and ended 73 mm off when every run was cut after 30
/// (docs/cad-scan-trials.md). The polish after the run settles the pose in its own band.
/// The steps are counted from the last band's settling (a step under [`SETTLED_FRACTION`] of
/// it, or [`STEPS_PER_BAND`] steps). With 30 a miss spent 32-255 steps in the last band; with
/// 10, both CAD corpora kept their successes, locally and in full (`replay` bench,
/// docs/cad-scan-trials.md). Counting 10 from the band's first step, or 15 from its settling,
/// lost a full alignment: the IRB 1600's link 5 at 50 mm ended 5 mm off instead of 0.5 mm.
const LAST_BAND_STEPS: usize = 10;

/// A step in the last band that moves the pose by less than this fraction of the tolerance
/// (5 um by default) ends the run: the correspondences, and so the next steps, are the same to
/// within it, and the stopping window would only have waited for those steps. On both CAD
/// corpora (`replay` bench) every success stayed and the poses moved by at most 1.3 um; the
/// scenes' median time ratio was 0.8-0.94 at 50-100 mm (docs/cad-scan-trials.md).
pub(super) const FIXED_POINT_FRACTION: f64 = 0.1;

/// A run in its last band that comes back to the pose of up to this many steps before has
/// entered a cycle and ends (see `run_schedule_on_levels`).
const CYCLE_PERIODS: usize = 3;

/// See [`LAST_BAND_STEPS`]: a tenth of the 1 cm band is the success bar of the CAD scans.
const LAST_BAND_PROGRESS_FRACTION: f64 = 0.1;

/// A band runs on a coarser keypoint level only when it is more than this many of that level's
/// voxels wide: with the 5 mm keypoints, a 25 mm band on the 10 mm level and a 50 mm band on the
/// 20 mm one (the peers' coarse-to-fine stages use a voxel of a third of their band, 8 and
/// 17 mm there). With three voxels (25 mm on the 5 mm keypoints, 50 mm on the 10 mm ones) a
/// 50 mm local run spent three fifths of its time in those two bands (a trace, not kept); with
/// this and the last band's shorter look ([`LAST_BAND_STEPS`]), on both CAD corpora the same
/// successes but one more (at 50 mm), and a per-scene median time ratio of 0.73-0.97 at
/// 50-100 mm (`replay` bench, docs/cad-scan-trials.md). The 3 cm run that ends a full
/// alignment after its exploration is given the fine keypoints only (see `locate`).
const BAND_PER_LEVEL_VOXEL: f64 = 2.4;

/// The coarser keypoint levels of a halving run, as multiples of the options' voxel.
const COARSER_LEVELS: [f64; 2] = [2.0, 4.0];

/// The band of step `iteration` of a cosine schedule (the halving one keeps its own, see
/// [`Band`]).
pub(super) fn delta_at(iteration: usize, delta0: f64, options: &PcaOptions) -> f64 {
    let delta_min = options.delta_min_m.min(delta0);
    let fraction = (iteration as f64 / options.schedule_iterations.max(1) as f64).min(1.0);
    let cos = (fraction * std::f64::consts::FRAC_PI_2).cos();
    let shape = match options.schedule {
        DeltaSchedule::CosineSquared => cos * cos,
        DeltaSchedule::Cosine | DeltaSchedule::Halving => cos,
    };
    (delta0 - delta_min) * shape + delta_min
}

/// Where a run stands in its schedule.
struct Band {
    schedule: DeltaSchedule,
    delta0_m: f64,
    delta_min_m: f64,
    /// Cosine schedules: the step count along the schedule (it jumps to the end once the pose
    /// stands still). Halving: 0 until the last band has settled, then the schedule's length.
    position: usize,
    schedule_iterations: usize,
    /// Halving: the band and the steps taken in it.
    halving_m: f64,
    steps_in_band: usize,
}

impl Band {
    fn new(delta0_m: f64, options: &PcaOptions) -> Self {
        Self {
            schedule: options.schedule,
            delta0_m,
            delta_min_m: options.delta_min_m.min(delta0_m),
            position: 0,
            schedule_iterations: options.schedule_iterations,
            halving_m: delta0_m,
            steps_in_band: 0,
        }
    }

    /// The band of the next step; a cosine schedule moves along by one.
    fn next(&mut self, options: &PcaOptions) -> f64 {
        if self.schedule == DeltaSchedule::Halving {
            return self.halving_m;
        }
        let delta = delta_at(self.position, self.delta0_m, options);
        self.position += 1;
        delta
    }

    /// After a step that moved the pose by `moved_m` in a band of `delta_m`.
    fn stepped(&mut self, moved_m: f64, delta_m: f64) {
        if self.schedule != DeltaSchedule::Halving {
            return;
        }
        self.steps_in_band += 1;
        if moved_m <= SETTLED_FRACTION * delta_m || self.steps_in_band >= STEPS_PER_BAND {
            if self.halving_m <= self.delta_min_m {
                self.position = self.schedule_iterations;
            } else {
                self.halving_m = (self.halving_m / 2.0).max(self.delta_min_m);
                self.steps_in_band = 0;
            }
        }
    }

    /// The pose stands still: the narrowing only exists to keep the part's points in the band
    /// while it still moves, so the band goes to its end.
    fn skip_to_end(&mut self) {
        self.position = self.position.max(self.schedule_iterations);
        self.halving_m = self.delta_min_m;
    }

    /// The band will not change any more: the halving band has reached delta_min, or a cosine
    /// schedule its end.
    fn in_last_band(&self) -> bool {
        match self.schedule {
            DeltaSchedule::Halving => self.halving_m <= self.delta_min_m,
            // The step just taken ran at delta_at(position - 1), delta_min from the end on.
            DeltaSchedule::Cosine | DeltaSchedule::CosineSquared => {
                self.position > self.schedule_iterations
            }
        }
    }

    fn at_end(&self) -> bool {
        self.position >= self.schedule_iterations
    }
}

#[derive(Debug, Clone, Copy)]
pub(super) struct ScheduleRun {
    pub(super) pose: Isometry3<f64>,
    pub(super) iterations: usize,
    pub(super) converged: bool,
    pub(super) delta: f64,
}

/// How a run's lookups find each keypoint's surface point: up to `factor` times farther than the
/// closest (see [`Lookup::slack`]) while the band is wider than `exact_within_band_m`, exactly
/// from then on.
#[derive(Debug, Clone, Copy)]
pub(super) struct RunSlack {
    pub(super) factor: f64,
    pub(super) exact_within_band_m: f64,
    /// See [`Lookup::exact_within_band_fraction`].
    pub(super) exact_within_band_fraction: f64,
}

impl RunSlack {
    pub(super) const EXACT: Self = Self {
        factor: 1.0,
        exact_within_band_m: f64::INFINITY,
        exact_within_band_fraction: 0.0,
    };

    /// `factor` in every band.
    pub(super) fn always(factor: f64) -> Self {
        Self {
            factor,
            exact_within_band_m: 0.0,
            exact_within_band_fraction: 0.0,
        }
    }

    pub(super) fn at_band(&self, band_m: f64) -> f64 {
        if band_m > self.exact_within_band_m {
            self.factor
        } else {
            1.0
        }
    }
}

/// One run of the thesis's loop on `keypoints` alone (no coarser levels).
pub(super) fn run_schedule(
    mesh: &Mesh,
    keypoints: &[Point3<f64>],
    start: &Isometry3<f64>,
    delta0_m: f64,
    options: &PcaOptions,
    slack: f64,
) -> ScheduleRun {
    run_schedule_on_levels(
        mesh,
        &[(0.0, keypoints)],
        start,
        delta0_m,
        options,
        RunSlack::always(slack),
        &[],
    )
}

/// The voxels of the coarser keypoint levels a halving run from `delta0_m` can use, finest
/// first; none for a cosine schedule (the thesis's loop runs on one set) or a band too narrow
/// for any.
pub(super) fn coarser_voxels(delta0_m: f64, options: &PcaOptions) -> Vec<f64> {
    if options.schedule != DeltaSchedule::Halving {
        return Vec::new();
    }
    COARSER_LEVELS
        .iter()
        .map(|factor| options.voxel_m * factor)
        .filter(|voxel_m| voxel_m * BAND_PER_LEVEL_VOXEL < delta0_m)
        .collect()
}

/// The keypoints at each of [`coarser_voxels`] (voxel, keypoints), finest first, binned on all
/// cores when `options.parallel`: each binning is mostly serial work.
pub(super) fn coarser_levels(
    keypoints: &[Point3<f64>],
    delta0_m: f64,
    options: &PcaOptions,
) -> Vec<(f64, Vec<Point3<f64>>)> {
    let level = |voxel_m: f64| (voxel_m, voxel_representatives(keypoints, voxel_m));
    let voxels = coarser_voxels(delta0_m, options);
    if options.parallel {
        voxels.into_par_iter().map(level).collect()
    } else {
        voxels.into_iter().map(level).collect()
    }
}

/// The part's samples for each of [`coarser_voxels`], for a local run that matches model to
/// scan in its wide bands (none when `options.wide_band_matching` is scan to model only). They
/// depend on the part alone, so that a local alignment samples the part while it bins the scan
/// (see `locate`).
pub(super) fn wide_band_samples(
    mesh: &Mesh,
    delta0_m: f64,
    options: &PcaOptions,
) -> Vec<ModelSamples> {
    if options.wide_band_matching == WideBandMatching::ScanToModel {
        return Vec::new();
    }
    let voxels = coarser_voxels(delta0_m, options);
    if options.parallel {
        voxels
            .into_par_iter()
            .map(|voxel_m| ModelSamples::new(mesh, voxel_m))
            .collect()
    } else {
        voxels
            .into_iter()
            .map(|voxel_m| ModelSamples::new(mesh, voxel_m))
            .collect()
    }
}

/// The model samples and scan tree of each of `levels` (voxel, keypoints) but the finest, for a
/// run that matches model to scan in the bands it runs on a coarser level (`None` for the finest:
/// the narrow bands, which set the precision, match scan to model); empty when `samples` (one
/// per coarser level, from [`wide_band_samples`]) is.
pub(super) fn model_to_scan_levels(
    levels: &[(f64, &[Point3<f64>])],
    samples: Vec<ModelSamples>,
    parallel: bool,
) -> Vec<Option<ModelToScanLevel>> {
    if samples.is_empty() {
        return Vec::new();
    }
    let coarser = levels.get(1..).unwrap_or_default();
    let trees: Vec<ScanTree> = if parallel {
        coarser
            .par_iter()
            .map(|(_, keypoints)| ScanTree::new(keypoints))
            .collect()
    } else {
        coarser
            .iter()
            .map(|(_, keypoints)| ScanTree::new(keypoints))
            .collect()
    };
    std::iter::once(None)
        .chain(
            samples
                .into_iter()
                .zip(trees)
                .map(|(samples, tree)| Some(ModelToScanLevel { samples, tree })),
        )
        .collect()
}

/// The coarser of `levels` (voxel, keypoints; all but the finest) without the points of the
/// planes larger than the part, found once on the coarsest level (see
/// `PcaOptions::wide_band_without_planes`): what the scan-to-model half of a run's wide bands
/// matches. Empty when there is no coarser level.
pub(super) fn coarser_without_large_planes(
    mesh: &Mesh,
    levels: &[(f64, &[Point3<f64>])],
) -> Vec<(f64, Vec<Point3<f64>>)> {
    let (Some(coarser), Some((coarsest_voxel_m, coarsest))) = (levels.get(1..), levels.last())
    else {
        return Vec::new();
    };
    let planes = large_planes(coarsest, mesh, *coarsest_voxel_m);
    coarser
        .iter()
        .map(|(voxel_m, points)| (*voxel_m, off_the_planes(points, &planes)))
        .collect()
}

/// One run of the thesis's loop on keypoint levels (voxel, keypoints), finest first (voxel 0,
/// so that every band may use it): each step runs on the coarsest level whose voxel the step's
/// band exceeds [`BAND_PER_LEVEL_VOXEL`] times. A band of decimetres holds the part's whole
/// neighbourhood, and at the fine voxel a 500 mm local run spent seconds matching it exactly;
/// the narrow bands at the end, which set the precision, run on the finest. A level with an
/// entry in `model_to_scan` (empty: none) matches model to scan, or both ways, as
/// `options.wide_band_matching` says.
pub(super) fn run_schedule_on_levels(
    mesh: &Mesh,
    levels: &[(f64, &[Point3<f64>])],
    start: &Isometry3<f64>,
    delta0_m: f64,
    options: &PcaOptions,
    slack: RunSlack,
    model_to_scan: &[Option<ModelToScanLevel>],
) -> ScheduleRun {
    let (lower, upper) = mesh.bounds();
    let mut hints: Vec<Vec<u32>> = levels
        .iter()
        .map(|(_, keypoints)| vec![NO_HINT; keypoints.len()])
        .collect();
    let mut reachable: Vec<Reachable> = levels
        .iter()
        .map(|_| Reachable::new(&lower, &upper, delta0_m))
        .collect();
    // Each model sample's keypoint at the last step, per level (see correspond_model_to_scan).
    let mut sample_hints: Vec<Vec<u32>> = model_to_scan
        .iter()
        .map(|level| {
            level
                .as_ref()
                .map_or(Vec::new(), |l| vec![NO_HINT; l.samples.points.len()])
        })
        .collect();
    let radius_m = mesh.radius_m();
    let mut pose = *start;
    let mut stop = StopCriterion::new(options.window, options.tolerance_m, radius_m);
    stop.update(&pose);
    let mut iterations = 0;
    let mut converged = false;
    let mut band = Band::new(delta0_m, options);
    let mut delta = delta0_m;
    let mut still = 0;
    let mut last_band_steps = 0;
    // The last band's latest poses and the steps that reached them, oldest first.
    let mut recent_last_band: Vec<(Isometry3<f64>, f64)> = Vec::new();
    let mut last_band_checked = pose;
    // The last step's matches times its level's voxel area, its thinning undone: a level of
    // another voxel would match about this over its own voxel's area (see MATCHES_PER_STEP).
    let mut matched_voxel_area: Option<f64> = None;
    while iterations < options.max_iterations {
        delta = band.next(options);
        iterations += 1;
        let level = levels
            .iter()
            .rposition(|(voxel_m, _)| voxel_m * BAND_PER_LEVEL_VOXEL < delta)
            .unwrap_or(0);
        let voxel_m = levels[level].0.max(options.voxel_m);
        let reachable = &mut reachable[level];
        reachable.narrow_to(delta);
        if let Some(area) = matched_voxel_area {
            reachable.thin_to(thinning_for(area / (voxel_m * voxel_m)));
        }
        reachable.update(levels[level].1, &pose, &mut hints[level]);
        let lookup = Lookup {
            slack: slack.at_band(delta),
            exact_within_band_fraction: slack.exact_within_band_fraction,
            ..Lookup::exact(options.parallel)
        };
        let scan_to_model = |reachable: &mut Reachable| {
            correspond(
                mesh,
                &reachable.points,
                &pose,
                delta,
                (&lower, &upper),
                lookup,
                &mut reachable.hints,
            )
        };
        let (matches, keypoints_matched) = match model_to_scan.get(level).and_then(Option::as_ref) {
            Some(model_to_scan) => {
                let mut matches = correspond_model_to_scan(
                    model_to_scan,
                    &pose,
                    delta,
                    options.parallel,
                    &mut sample_hints[level],
                );
                // Model to scan alone matches no keypoint: nothing to thin the next level by.
                let mut keypoints_matched = None;
                if options.wide_band_matching == WideBandMatching::BothWays {
                    let mut from_scan = scan_to_model(reachable);
                    keypoints_matched = Some(from_scan.len());
                    balance_weights(&matches, &mut from_scan);
                    matches.extend(from_scan);
                }
                (matches, keypoints_matched)
            }
            None => {
                let matches = scan_to_model(reachable);
                let keypoints_matched = Some(matches.len());
                (matches, keypoints_matched)
            }
        };
        if matches.len() < 6 {
            break;
        }
        if let Some(keypoints) = keypoints_matched {
            matched_voxel_area = Some((keypoints * reachable.stride) as f64 * voxel_m * voxel_m);
        }
        let weak_fraction = if level > 0 && options.wide_band_skips_weak_directions {
            WEAK_DIRECTION_FRACTION
        } else {
            0.0
        };
        let Some(step) = step_along(&matches, options.step, radius_m, weak_fraction) else {
            break;
        };
        let previous = pose;
        pose = step * pose;
        let moved_m = pose_distance(&previous, &pose, radius_m);
        let last_band = band.in_last_band();
        if last_band {
            if recent_last_band.len() > CYCLE_PERIODS {
                recent_last_band.remove(0);
            }
            recent_last_band.push((pose, moved_m));
        }
        band.stepped(moved_m, delta);
        if last_band && moved_m <= FIXED_POINT_FRACTION * options.tolerance_m {
            converged = true;
            break;
        }
        // A cycle: the pose is back within the fixed point's reach of where it was two or three
        // steps ago, so the correspondences are those of then and the run would go round until
        // the last band's progress check (a few keypoints at the band's edge, or between a face
        // and an edge, going in and out in turn). It has settled as far as the cycle's steps are
        // short; traced runs on the CAD scans went round for 10-30 steps (docs/cad-scan-trials.md).
        if last_band
            && let Some(period) = cycle_period(
                &recent_last_band,
                radius_m,
                FIXED_POINT_FRACTION * options.tolerance_m,
            )
        {
            converged = recent_last_band
                .iter()
                .rev()
                .take(period)
                .all(|(_, moved_m)| *moved_m <= options.tolerance_m);
            break;
        }
        if stop.update(&pose) && band.at_end() {
            converged = true;
            break;
        }
        if band.schedule == DeltaSchedule::Halving && band.at_end() {
            if last_band_steps == 0 {
                last_band_checked = pose;
            }
            last_band_steps += 1;
            if last_band_steps % LAST_BAND_STEPS == 0 {
                let progress_m = pose_distance(&last_band_checked, &pose, radius_m);
                if progress_m < LAST_BAND_PROGRESS_FRACTION * delta {
                    break;
                }
                last_band_checked = pose;
            }
        }
        still = if moved_m <= options.tolerance_m {
            still + 1
        } else {
            0
        };
        if still >= 3 {
            band.skip_to_end();
        }
    }
    ScheduleRun {
        pose,
        iterations,
        converged,
        delta,
    }
}

/// Scales `from_scan`'s weights so that their total is `from_model`'s: each direction has the
/// same say in a step however many of the band's keypoints are clutter. Left as they are when
/// either set weighs nothing.
fn balance_weights(from_model: &[Match], from_scan: &mut [Match]) {
    let model_total: f64 = from_model.iter().map(|m| m.weight).sum();
    let scan_total: f64 = from_scan.iter().map(|m| m.weight).sum();
    if model_total > 0.0 && scan_total > 0.0 {
        let scale = model_total / scan_total;
        for m in from_scan {
            m.weight *= scale;
        }
    }
}

/// The period of the cycle a run has entered, if it has: `recent` holds its latest poses and
/// the steps that reached them, oldest first, and the last pose is back within `reach_m` (the
/// thesis's distance for a part of `radius_m`) of the one that many steps before.
fn cycle_period(recent: &[(Isometry3<f64>, f64)], radius_m: f64, reach_m: f64) -> Option<usize> {
    let ((pose, _), earlier) = recent.split_last()?;
    earlier
        .iter()
        .rev()
        .position(|(before, _)| pose_distance(before, pose, radius_m) <= reach_m)
        .map(|back| back + 1)
}

/// A step matches about this many keypoints at most: a run whose level would match more keeps
/// one of every n (see [`kept_at_stride`]), and so does the polish. A link of the IRB 1600's
/// size matched 10-20 thousand 5 mm keypoints in each of its fine bands, which fix a pose to
/// microns with far fewer (docs/cad-scan-trials.md).
pub(super) const MATCHES_PER_STEP: f64 = 4000.0;

/// How many of a level's keypoints one kept stands for when a step would match `matches` of
/// them all (see [`MATCHES_PER_STEP`]).
pub(super) fn thinning_for(matches: f64) -> usize {
    thinning_to(matches, MATCHES_PER_STEP)
}

/// [`thinning_for`] with at most about `per_step` matches a step.
pub(super) fn thinning_to(matches: f64, per_step: f64) -> usize {
    if matches.is_finite() && per_step >= 1.0 && matches > per_step {
        (matches / per_step).floor() as usize
    } else {
        1
    }
}

/// Whether keypoint `index` is among those kept at thinning `stride`: by a hash of the index,
/// so that the ones kept are spread over the cloud whatever its order, and the same ones at
/// every step.
pub(super) fn kept_at_stride(index: usize, stride: usize) -> bool {
    if stride <= 1 {
        return true;
    }
    // SplitMix64's first draw from the index: the same bits as a hash of it.
    SplitMix64::new(index as u64)
        .next_u64()
        .is_multiple_of(stride as u64)
}

/// A run's kept keypoints are filtered again when its band's reach falls below this fraction of
/// the reach they were filtered for (see [`Reachable::narrow_to`]).
const NARROWED_REACH_FRACTION: f64 = 0.8;

/// The keypoints a run can match, kept between its steps: a keypoint inside the part's box grown
/// by the run's band lies within `reach_m` of the box's centre, so one more than
/// `reach_m + margin_m` from where the centre was at the last filtering cannot match until the
/// centre has moved by more than `margin_m`. Exact: the matches, and their order, are those of
/// all the keypoints; a scan of a cell holds ten times more keypoints than the part's
/// neighbourhood, and each step tested every one against the box.
struct Reachable {
    box_centre: Point3<f64>,
    half_extent: Vector3<f64>,
    reach_m: f64,
    margin_m: f64,
    filtered_at: Option<Point3<f64>>,
    /// Indices into the run's keypoints, and those keypoints.
    indices: Vec<usize>,
    points: Vec<Point3<f64>>,
    /// Each kept keypoint's hint (empty without), copied back to the run's when refiltered.
    hints: Vec<u32>,
    /// One keypoint kept of every `stride` (see [`kept_at_stride`]).
    stride: usize,
}

impl Reachable {
    fn new(lower: &Point3<f64>, upper: &Point3<f64>, delta0_m: f64) -> Self {
        let half = (upper - lower) / 2.0;
        let reach_m = (half + Vector3::repeat(delta0_m)).norm();
        Self {
            box_centre: Point3::from((lower.coords + upper.coords) / 2.0),
            half_extent: half,
            reach_m,
            margin_m: 0.25 * reach_m,
            filtered_at: None,
            indices: Vec::new(),
            points: Vec::new(),
            hints: Vec::new(),
            stride: 1,
        }
    }

    /// Keeps one keypoint of every `stride` from the next filtering on.
    fn thin_to(&mut self, stride: usize) {
        if stride != self.stride {
            self.stride = stride;
            self.filtered_at = None;
        }
    }

    /// The run's band has narrowed to `band_m`: once the reach it gives is well below the one
    /// kept, the keypoints are filtered again with it. In the narrow bands at the end of a run
    /// from a wide start, the keypoints kept for the first band were several times those a step
    /// could match, and each step tested every one against the box (docs/cad-scan-trials.md).
    fn narrow_to(&mut self, band_m: f64) {
        let reach_m = (self.half_extent + Vector3::repeat(band_m)).norm();
        if reach_m < NARROWED_REACH_FRACTION * self.reach_m {
            self.reach_m = reach_m;
            self.margin_m = 0.25 * reach_m;
            self.filtered_at = None;
        }
    }

    fn update(&mut self, keypoints: &[Point3<f64>], pose: &Isometry3<f64>, hints: &mut [u32]) {
        let centre = pose * self.box_centre;
        if self
            .filtered_at
            .is_some_and(|at| (centre - at).norm() <= self.margin_m)
        {
            return;
        }
        for (&index, &hint) in self.indices.iter().zip(&self.hints) {
            hints[index] = hint;
        }
        let limit = self.reach_m + self.margin_m;
        self.indices = (0..keypoints.len())
            .filter(|&i| kept_at_stride(i, self.stride) && (keypoints[i] - centre).norm() <= limit)
            .collect();
        self.points = self.indices.iter().map(|&i| keypoints[i]).collect();
        self.hints = if hints.is_empty() {
            Vec::new()
        } else {
            self.indices.iter().map(|&i| hints[i]).collect()
        };
        self.filtered_at = Some(centre);
    }
}

#[cfg(test)]
#[path = "schedule_tests.rs"]
mod tests;
