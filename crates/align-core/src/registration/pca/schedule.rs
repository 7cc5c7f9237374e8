//! One run of the thesis's loop (filters, weights and a step per iteration while the search band
//! shrinks) and how the band shrinks: the thesis's cosine (eq. 33), its code's cosine squared,
//! or coarse to fine, as the local peers run (halving the band each time the pose settles in
//! it, the wide bands on coarser keypoints).

use nalgebra::{Isometry3, Point3, Vector3};

use super::matching::{Lookup, NO_HINT, correspond};
use super::model_to_scan::{ModelSamples, ModelToScanLevel, ScanTree, correspond_model_to_scan};
use super::{PcaOptions, step_for};
use crate::geometry::Mesh;
use crate::registration::convergence::{StopCriterion, pose_distance};
use crate::registration::sampling::voxel_representatives;

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

/// A halving band halves once a step moves the pose (the thesis's distance) by less than this
/// fraction of it: the pose has settled as far as the band can tell.
const SETTLED_FRACTION: f64 = 0.01;

/// A halving band halves after this many steps even when the pose still moves (clutter at the
/// band's edge can keep it sliding by more than [`SETTLED_FRACTION`]).
const STEPS_PER_BAND: usize = 15;

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

    fn at_band(&self, band_m: f64) -> f64 {
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

/// The keypoints at the coarser voxel sizes a halving run from `delta0_m` can use (voxel,
/// keypoints), finest first; none for a cosine schedule (the thesis's loop runs on one set) or a
/// band too narrow for any.
pub(super) fn coarser_levels(
    keypoints: &[Point3<f64>],
    delta0_m: f64,
    options: &PcaOptions,
) -> Vec<(f64, Vec<Point3<f64>>)> {
    if options.schedule != DeltaSchedule::Halving {
        return Vec::new();
    }
    COARSER_LEVELS
        .iter()
        .map(|factor| options.voxel_m * factor)
        .filter(|voxel_m| voxel_m * BAND_PER_LEVEL_VOXEL < delta0_m)
        .map(|voxel_m| (voxel_m, voxel_representatives(keypoints, voxel_m)))
        .collect()
}

/// Bands wider than this match model to scan when the run is given the levels' samples and
/// trees (see [`PcaOptions::model_to_scan_wide_bands`], off by default). Measured on the two CAD
/// corpora (`replay` bench with the option on, docs/cad-scan-trials.md): with 10 cm the local successes went 76 -> 75 and
/// 80 -> 83, ahead of or level with the better peer at every delta on both; with 5 cm 74 and 77,
/// with 2.4 cm (every band on a coarser level) 67 and 76, with 15 and 20 cm 74/83 and 74/81.
/// Matching both ways in those bands gave 76 and 84 but lost a 500 mm scan a peer found.
pub(super) const MODEL_TO_SCAN_ABOVE_M: f64 = 0.1;

/// The model samples and scan tree of each of `levels` (voxel, keypoints) whose bands, in a
/// halving run from `delta0_m`, reach beyond [`MODEL_TO_SCAN_ABOVE_M`]; `None` for the others,
/// the finest level always among them (the bands that set the precision match scan to model).
pub(super) fn model_to_scan_levels(
    mesh: &Mesh,
    levels: &[(f64, &[Point3<f64>])],
    delta0_m: f64,
) -> Vec<Option<ModelToScanLevel>> {
    levels
        .iter()
        .enumerate()
        .map(|(index, (voxel_m, keypoints))| {
            // A level takes the bands from BAND_PER_LEVEL_VOXEL of its voxels up to where the
            // next coarser one takes over.
            let widest_band_m = levels
                .get(index + 1)
                .map_or(delta0_m, |(coarser_m, _)| coarser_m * BAND_PER_LEVEL_VOXEL);
            (index > 0 && widest_band_m > MODEL_TO_SCAN_ABOVE_M).then(|| ModelToScanLevel {
                samples: ModelSamples::new(mesh, *voxel_m),
                tree: ScanTree::new(keypoints),
            })
        })
        .collect()
}

/// One run of the thesis's loop on keypoint levels (voxel, keypoints), finest first (voxel 0,
/// so that every band may use it): each step runs on the coarsest level whose voxel the step's
/// band exceeds [`BAND_PER_LEVEL_VOXEL`] times. A band of decimetres holds the part's whole
/// neighbourhood, and at the fine voxel a 500 mm local run spent seconds matching it exactly;
/// the narrow bands at the end, which set the precision, run on the finest. A level with an
/// entry in `model_to_scan` (empty: none) matches model to scan in its bands wider than
/// [`MODEL_TO_SCAN_ABOVE_M`].
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
    let mut last_band_checked = pose;
    while iterations < options.max_iterations {
        delta = band.next(options);
        iterations += 1;
        let level = levels
            .iter()
            .rposition(|(voxel_m, _)| voxel_m * BAND_PER_LEVEL_VOXEL < delta)
            .unwrap_or(0);
        let reachable = &mut reachable[level];
        reachable.narrow_to(delta);
        reachable.update(levels[level].1, &pose, &mut hints[level]);
        let lookup = Lookup {
            slack: slack.at_band(delta),
            exact_within_band_fraction: slack.exact_within_band_fraction,
            ..Lookup::exact(options.parallel)
        };
        let matches = match model_to_scan
            .get(level)
            .and_then(Option::as_ref)
            .filter(|_| delta > MODEL_TO_SCAN_ABOVE_M)
        {
            Some(model_to_scan) => {
                correspond_model_to_scan(model_to_scan, &pose, delta, options.parallel)
            }
            None => correspond(
                mesh,
                &reachable.points,
                &pose,
                delta,
                (&lower, &upper),
                lookup,
                &mut reachable.hints,
            ),
        };
        if matches.len() < 6 {
            break;
        }
        let Some(step) = step_for(&matches, options.step, radius_m) else {
            break;
        };
        let previous = pose;
        pose = step * pose;
        let moved_m = pose_distance(&previous, &pose, radius_m);
        let last_band = band.in_last_band();
        band.stepped(moved_m, delta);
        if last_band && moved_m <= FIXED_POINT_FRACTION * options.tolerance_m {
            converged = true;
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
            .filter(|&i| (keypoints[i] - centre).norm() <= limit)
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
mod tests {
    use super::*;

    #[test]
    fn both_cosine_schedules_run_from_delta0_to_delta_min_in_100_iterations() {
        for schedule in [DeltaSchedule::Cosine, DeltaSchedule::CosineSquared] {
            let options = PcaOptions {
                schedule,
                ..PcaOptions::default()
            };
            assert!((delta_at(0, 0.5, &options) - 0.5).abs() < 1e-15);
            assert!((delta_at(100, 0.5, &options) - 0.01).abs() < 1e-15);
            assert!((delta_at(250, 0.5, &options) - 0.01).abs() < 1e-15);
        }
        let cos = PcaOptions {
            schedule: DeltaSchedule::Cosine,
            ..PcaOptions::default()
        };
        let squared = PcaOptions {
            schedule: DeltaSchedule::CosineSquared,
            ..PcaOptions::default()
        };
        assert!(delta_at(50, 0.5, &squared) < delta_at(50, 0.5, &cos));
    }

    #[test]
    fn a_halving_band_halves_when_the_pose_settles_or_after_its_steps_and_ends_at_delta_min() {
        let options = PcaOptions {
            schedule: DeltaSchedule::Halving,
            ..PcaOptions::default()
        };
        let mut band = Band::new(0.08, &options);
        // Still moving by more than a hundredth of the band: the band holds...
        for _ in 0..STEPS_PER_BAND - 1 {
            let delta = band.next(&options);
            assert_eq!(delta, 0.08);
            band.stepped(0.01, delta);
        }
        // ...until its steps are spent.
        band.stepped(0.01, 0.08);
        assert_eq!(band.next(&options), 0.04);
        // Settled: halves at once, and never below delta_min.
        band.stepped(1e-5, 0.04);
        assert_eq!(band.next(&options), 0.02);
        band.stepped(1e-5, 0.02);
        assert_eq!(band.next(&options), 0.01);
        assert!(!band.at_end());
        band.stepped(1e-5, 0.01);
        assert_eq!(band.next(&options), 0.01);
        assert!(band.at_end());
    }

    /// Points on the five faces of a 200 x 100 x 150 mm box a scanner above it sees, 5 mm apart.
    fn box_scan() -> (Mesh, Vec<Point3<f64>>) {
        let size = [0.2, 0.1, 0.15];
        let mesh = Mesh::cuboid(size).expect("a box");
        let half = size.map(|s| s / 2.0);
        let mut points = Vec::new();
        let steps = |extent: f64| (0..=(extent / 0.005) as i32).map(move |i| f64::from(i) * 0.005);
        for x in steps(size[0]) {
            for y in steps(size[1]) {
                points.push(Point3::new(x - half[0], y - half[1], half[2]));
            }
            for z in steps(size[2]) {
                points.push(Point3::new(x - half[0], -half[1], z - half[2]));
                points.push(Point3::new(x - half[0], half[1], z - half[2]));
            }
        }
        for y in steps(size[1]) {
            for z in steps(size[2]) {
                points.push(Point3::new(-half[0], y - half[1], z - half[2]));
                points.push(Point3::new(half[0], y - half[1], z - half[2]));
            }
        }
        (mesh, points)
    }

    #[test]
    fn a_halving_run_that_never_stands_still_ends_after_its_last_band_steps() {
        let (mesh, points) = box_scan();
        let start = Isometry3::translation(0.02, -0.01, 0.005);
        let restless = PcaOptions {
            schedule: DeltaSchedule::Halving,
            max_iterations: 1000,
            // No step is ever below it: the pose never stands still.
            tolerance_m: -1.0,
            ..PcaOptions::default()
        };
        let run = run_schedule(&mesh, &points, &start, 0.05, &restless, 1.0);
        // Bands of 50, 25, 12.5 and 10 mm, which settle in two steps or fewer each from 2 cm
        // off, then LAST_BAND_STEPS in the last, when its progress is looked at (with 30 the run
        // took 35 steps).
        assert!(!run.converged);
        assert!(
            run.iterations < restless.max_iterations && run.iterations <= 4 * 2 + LAST_BAND_STEPS,
            "{} iterations",
            run.iterations
        );
        assert!(pose_distance(&run.pose, &Isometry3::identity(), mesh.radius_m()) < 1e-6);
        // A run that stands still ends well before.
        let settled = run_schedule(&mesh, &points, &start, 0.05, &PcaOptions::default(), 1.0);
        assert!(settled.converged && settled.iterations < run.iterations);
    }

    #[test]
    fn a_run_in_its_last_band_ends_at_the_first_step_that_does_not_move() {
        let (mesh, points) = box_scan();
        // From the truth in the last band (1 cm): the first step moves by nothing, and the
        // stopping window would have waited for `window` more.
        let options = PcaOptions::default();
        let run = run_schedule(&mesh, &points, &Isometry3::identity(), 0.01, &options, 1.0);
        assert!(run.converged);
        assert_eq!(run.iterations, 1);
        // A band that still halves does not end on a still step: 2 and 1 cm bands.
        let run = run_schedule(&mesh, &points, &Isometry3::identity(), 0.02, &options, 1.0);
        assert!(run.converged);
        assert_eq!(run.iterations, 2);
    }

    #[test]
    fn narrowed_keypoints_keep_every_one_a_narrow_band_can_match() {
        let (mesh, _) = box_scan();
        let (lower, upper) = mesh.bounds();
        let mut rng = crate::rng::SplitMix64::new(3);
        let keypoints: Vec<Point3<f64>> = (0..5000)
            .map(|_| Point3::from(rng.unit_vector() * (0.8 * rng.uniform())))
            .collect();
        let pose = Isometry3::new(Vector3::new(0.02, -0.01, 0.0), Vector3::new(0.0, 0.0, 0.3));
        let mut reachable = Reachable::new(&lower, &upper, 0.5);
        let mut hints = vec![NO_HINT; keypoints.len()];
        reachable.update(&keypoints, &pose, &mut hints);
        let kept_wide = reachable.points.len();
        for band_m in [0.5, 0.2, 0.05, 0.01] {
            reachable.narrow_to(band_m);
            reachable.update(&keypoints, &pose, &mut hints);
            // Every keypoint inside the part's box grown by the band is still there.
            let in_band_box = keypoints.iter().filter(|p| {
                let in_part = pose.inverse() * *p;
                (0..3).all(|axis| {
                    in_part[axis] >= lower[axis] - band_m && in_part[axis] <= upper[axis] + band_m
                })
            });
            for point in in_band_box {
                assert!(reachable.points.contains(point), "band {band_m}");
            }
        }
        // And the 1 cm band keeps far fewer than the first band did.
        assert!(
            2 * reachable.points.len() < kept_wide,
            "{} of {kept_wide}",
            reachable.points.len()
        );
    }

    #[test]
    fn only_a_halving_run_from_a_wide_band_gets_coarser_keypoints() {
        let keypoints: Vec<Point3<f64>> = (0..200)
            .map(|i| Point3::new(f64::from(i) * 0.001, 0.0, 0.0))
            .collect();
        let halving = PcaOptions {
            schedule: DeltaSchedule::Halving,
            ..PcaOptions::default()
        };
        let cosine = PcaOptions {
            schedule: DeltaSchedule::Cosine,
            ..PcaOptions::default()
        };
        let voxels = |levels: Vec<(f64, Vec<Point3<f64>>)>| -> Vec<f64> {
            levels.iter().map(|(voxel_m, _)| *voxel_m).collect()
        };
        assert!(coarser_levels(&keypoints, 0.5, &cosine).is_empty());
        // 5 mm keypoints: 10 and 20 mm levels, each for bands over 2.4 of its voxels.
        assert_eq!(
            voxels(coarser_levels(&keypoints, 0.5, &halving)),
            [0.01, 0.02]
        );
        assert_eq!(
            voxels(coarser_levels(&keypoints, 0.05, &halving)),
            [0.01, 0.02]
        );
        assert_eq!(voxels(coarser_levels(&keypoints, 0.03, &halving)), [0.01]);
        assert_eq!(voxels(coarser_levels(&keypoints, 0.025, &halving)), [0.01]);
        assert!(coarser_levels(&keypoints, 0.024, &halving).is_empty());
        let levels = coarser_levels(&keypoints, 0.5, &halving);
        assert!(levels[0].1.len() < keypoints.len() && levels[1].1.len() < levels[0].1.len());
    }
}
