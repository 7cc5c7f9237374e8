//! Point Cloud Alignment (thesis 3.1.3): move a part's mesh until it matches a scanner cloud that
//! also holds everything else in the cell.
//!
//! The cloud is downsampled once to voxel centroids. Each iteration then keeps the keypoints
//! inside the part's bounding box grown by delta (cut-off filter) and within delta of its surface
//! (measure filter), weights each by w = cos(d / delta * pi / 2), so that points at the edge of
//! the search band fade out instead of jumping in and out, and moves the part by a weighted step.
//! Delta shrinks from the user's bound delta0 to delta_min (the thesis: over 100 iterations; by
//! default halving each time the pose settles, the wide bands on coarser keypoints, see
//! [`DeltaSchedule`]), so the search starts wide and coarse and ends narrow, with the clutter
//! far outside the band.
//!
//! Steps: the thesis's weighted SVD ([`PcaStep::PointToPoint`]), or (default) the weighted
//! linearised point-to-plane step, which converges in a few iterations once the part is close,
//! so the stopping criterion ends the run long before the schedule does.

use std::borrow::Cow;
use std::time::Instant;

use nalgebra::{Isometry3, Point3};

mod consensus;
mod exploration;
mod hop;
mod local_reach;
mod look_again;
mod matching;
mod model_to_scan;
mod planes;
mod polish;
mod schedule;
mod step;
mod tie_break;
pub(crate) mod uncertainty;

pub use self::consensus::scan_consensus;
use self::consensus::{Coarse, consensus, score_noise};
use self::exploration::{
    EXPLORATION_SLACK, Exploring, detected_starts, explore, is_wide, runs_around, uniqueness,
};
pub use self::exploration::{pose_candidates, pose_candidates_spread};
use self::hop::{HopStarts, hop, hop_from_the_end};
use self::local_reach::{local_first_band, within_local_reach};
pub(crate) use self::look_again::align_cloud_pose;
use self::look_again::{Located, locate_looking_again};
use self::matching::{Lookup, correspond, near_surface};
pub(crate) use self::model_to_scan::ModelSamples;
pub use self::planes::without_large_planes as without_planes_larger_than;
pub use self::planes::{floor_plane, on_a_plane, without_floor_under};
use self::polish::polish;
pub use self::schedule::{DeltaSchedule, WideBandMatching};
use self::schedule::{
    RunSlack, ScheduleRun, coarser_levels, coarser_without_large_planes, model_to_scan_levels,
    run_schedule, run_schedule_on_levels, wide_band_samples,
};
use self::tie_break::{Undecided, decide_finely, local_end_ahead};
use self::uncertainty::cloud_uncertainty;
use super::sampling::{voxel_centroids, voxel_representatives};
use crate::geometry::{Mesh, PrincipalSpread};
use crate::registration::Alignment;
use crate::registration::uncertainty::{PoseUncertainty, UncertaintyError};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PcaStep {
    PointToPoint,
    PointToPlane,
}

#[derive(Debug, Clone, PartialEq)]
pub struct PcaOptions {
    pub step: PcaStep,
    pub schedule: DeltaSchedule,
    pub delta_min_m: f64,
    /// Iterations over which a cosine schedule's delta shrinks to `delta_min_m` (thesis: 100).
    pub schedule_iterations: usize,
    pub max_iterations: usize,
    /// Voxel edge of the keypoint downsampling, m.
    pub voxel_m: f64,
    /// Keypoints are voxel centroids (the thesis) rather than the cloud point nearest each
    /// centroid (default: centroids of voxels straddling an edge lie off the surface and bias
    /// the fit by a fraction of the voxel size).
    pub voxel_centroids: bool,
    /// A run stops once its pose lies within `tolerance_m` of each of the last `window` poses
    /// (thesis 2.1.4, whose window is 19) and its band has ended, or at once when a step in its
    /// last band moves the pose by under a tenth of `tolerance_m` (a fixed point).
    pub window: usize,
    pub tolerance_m: f64,
    /// Parallel correspondence search (rayon); off gives the single-thread timing.
    pub parallel: bool,
    /// Orientations explored around the start before the full run (0: none, the thesis's
    /// behaviour). Only those within the rotation delta allows are used.
    pub starts: usize,
    /// The exploration from the start matches keypoints far off the part approximately (up to
    /// 1.5 times the closest, exact within 2 cm of the surface) and, from a delta of half the
    /// part's radius, also runs
    /// from poses a point-pair-feature detection finds (default). Off: turns of the start only,
    /// matched exactly, as the robot fit's rigid stage was measured.
    pub wide_exploration: bool,
    /// After the schedule, a last run in a band fitted to the residuals (see [`polish`]):
    /// at the schedule's last band (1 cm) the floor and fixtures beside the part still pull it,
    /// and from the truth itself a fifth of the 50 mm CAD scans ended over 1 mm off
    /// (docs/cad-scan-trials.md). Off: the thesis's loop as it ends.
    pub polish: bool,
    /// The exploration's coarse keypoints leave out every plane of the scan too large to be a
    /// face of the part (a floor, a wall; see [`planes`]): its runs are not pulled by them and
    /// its score does not count them. Off: the floor counts as any clutter does, as the robot
    /// fit's rigid stages were measured.
    pub without_large_planes: bool,
    /// With an exploration, the local stage alone (as `starts` 0 runs it, its wide bands and
    /// polish) runs from the start in place of the exploration's short run from there, and its
    /// end is one more candidate, scored as the exploration's ends are (default); a tie goes to
    /// the exploration's end. The exploration's short runs use coarse keypoints in
    /// a band of delta: on the unseen CAD set A (`replay`) they missed 10 scans at 50-1000 mm
    /// that the local stage from the same start fitted, a flat link among them found upside
    /// down and called unique. When the local end wins it is the run the runs about the pose
    /// start from, not run again on the fine keypoints nor polished twice: it is that run
    /// already (set A at 50 mm: 38 -> 40 of 40, median 65 -> 47 ms). Off: the exploration's
    /// ends only, as the robot fit's rigid stage of the whole robot was measured.
    pub local_candidate: bool,
    /// After everything else, the local stage's end (`local_candidate`) is the pose when it
    /// explains clearly more of the scan than the pose found, at the scanner's scale (see
    /// `tie_break::local_end_ahead`). Off: the local end only competes by the coarse score.
    pub local_end_last_look: bool,
    /// After the run from the best start, runs from the found pose turned every way the delta
    /// allows: they reach a symmetric part's twin (for the uniqueness margin) and a better pose
    /// the exploration from the start missed. Off: no uniqueness is reported and the runs are
    /// saved, for a caller that only needs the pose brought near and tells twins apart itself
    /// (the robot fit's rigid stage of the whole robot).
    pub twin_search: bool,
    /// After the exploration, the run on the fine keypoints from three `delta_min_m` (default).
    /// Off: the exploration's best end is the pose (its runs end in the `delta_min_m` band, on
    /// keypoints of three voxels), for a caller that refines it itself and cannot use a finer
    /// one: the robot fit's rigid stage from a near start, whose joints are still wrong while
    /// it runs. Without an exploration (`starts` 0) the run is made anyway; after a local end
    /// that won (`local_candidate`) it is not, since that end is such a run's.
    pub fine_run: bool,
    /// Without an exploration (`starts` 0), the run matches the keypoints in the outer half of
    /// its band approximately while the band is wider than 5 cm, as the exploration's runs do
    /// (default; see `LOCAL_EXACT_WITHIN_BAND_M`). Off: every band exact, the thesis's loop as
    /// it was measured.
    pub wide_band_slack: bool,
    /// Without an exploration (`starts` 0), the run's first band is at most the part's radius
    /// (default): from a start half a metre or a metre off, a band of delta0 holds far more of
    /// the floor and the fixtures than of the part, and they decide where the wide bands' steps
    /// go (see `local_first_band`). Off: the first band is delta0, the thesis's loop.
    pub local_band_within_radius: bool,
    /// Without an exploration (`starts` 0), how the run matches in the bands it runs on a
    /// coarser keypoint level (24 mm and wider with the 5 mm voxel; see [`WideBandMatching`]).
    /// Default: both ways. The narrow bands, the polish and the exploration's runs match scan
    /// to model whatever this says.
    pub wide_band_matching: WideBandMatching,
    /// Matching both ways, the scan-to-model half of the wide bands leaves out the scan's
    /// planes larger than the part (a floor, a table, a wall; found once on the coarsest level,
    /// see [`planes`]); the model-to-scan half keeps them, so that a part lying on the floor is
    /// still held by it (default). Scan to model, the floor's points beside a part lying on it
    /// are each matched to the part's nearest face, and on round, finely tessellated links (the
    /// edge rejection never sees an edge there) they pull it into the floor and spin it about
    /// its axis: a TIAGo Pro arm link 3 mm off its truth at the start ended 228 mm off, its
    /// first step's rotation 96 % along the weakest direction of its normal equations.
    /// Local successes on the `replay` bench's corpora (the four of the ABB, xArm7 and SO-ARM100
    /// links / the unseen set A / set B): 315 / 84 / 89 with the planes, 352 / 111 / 107
    /// without (docs/cad-scan-trials.md, fifteenth session). Off: every keypoint in the band.
    pub wide_band_without_planes: bool,
    /// The wide bands' point-to-plane steps move the part only along the directions their
    /// matches constrain: a direction whose eigenvalue in the step's normal equations is under
    /// a hundredth of the largest is left as it is (default; see `point_to_plane`). In a band of
    /// centimetres on coarse keypoints, the spin of a nearly round link about its axis is held
    /// by a few of its features against the clutter's pull, and a step went wherever the
    /// clutter said. The narrow bands and the polish, on the fine keypoints, move along every
    /// direction. Local successes on the `replay` bench's corpora (the four / set A / set B),
    /// without the planes in the wide bands' scan half: 352 / 111 / 107 moving along every
    /// direction, 363 / 112 / 107 without the weak ones (docs/cad-scan-trials.md). Off: every
    /// direction.
    pub wide_band_skips_weak_directions: bool,
    /// When the exploration's score cannot tell the pose from its runner-up (ambiguous), the
    /// ends that score as well are run down to the scanner's scale as the pose was and counted
    /// again on the fine keypoints in the polish's band: one that explains clearly more is the
    /// pose, still flagged by the coarse score (default; see `tie_break`). Replayed on the three
    /// unseen CAD sets (`replay` bench, 600 scans): 184 / 167 / 163 successes -> 186 / 181 /
    /// 169, none lost, the same scans flagged ambiguous and the same confident misses
    /// (docs/cad-scan-trials.md). Off: the coarse score's best end is the pose.
    pub fine_tie_break: bool,
    /// When the polish ends with clearly more of its off-the-surface matches behind the surface
    /// than in front (inside the part's material, as between a shell's walls), starts a few
    /// millimetres off each way are polished too, and one that ends where the fine keypoints
    /// fit clearly better is the pose (default; see `hop`; until the thirty-seventh session
    /// "better" was "more of them within the narrowest band"). Replayed on the three unseen CAD
    /// sets (`replay` bench, 600 scans): set C 169 -> 174 successes, five scans of the TALOS
    /// arm's second link, a shell; sets A and B unchanged; none lost (docs/cad-scan-trials.md).
    /// Off: the polish's end is the pose.
    pub hop_out_of_the_material: bool,
    /// A full alignment (with the exploration) also hops from its final pose, shifted a few
    /// millimetres along each axis, wherever the polish ended; a start that fits the fine
    /// keypoints clearly better, point by point, is the pose (default; see `hop`). Replayed on
    /// the four unseen CAD sets (`replay` bench, 800 scans, with the point-by-point test for
    /// both hops): full successes A 186, B 182 unchanged, C 174 -> 175, the held-out set D
    /// 144 -> 146 (its two confident misses, Centauro links 3 mm off); local B +1, D +2; none
    /// lost. It cost the full alignment 20-35 ms at 50 mm, 2-12 ms less since its starts take
    /// two steps (docs/BENCHMARKS.md). Off: only ends inside the material hop.
    pub hop_near_misses: bool,
    /// A full alignment whose exploration had no turn within the delta's reach and whose polish
    /// ended in its widest band is aligned again with `small_turns` (default; see
    /// `look_again`). Replayed on the four unseen CAD sets: set B 182 -> 183 (scan 1), the
    /// others unchanged (docs/cad-scan-trials.md, thirty-eighth session). Off: no second look.
    pub look_again_when_unfit: bool,
    /// When no turn of the spread set is within the delta's reach, the exploration turns the
    /// start by half the reach each way about the part's three axes (six more runs). Off by
    /// default: the second look turns it on.
    pub small_turns: bool,
    /// The exploration's score counts a coarse keypoint on the part's surface only where the
    /// scan's normal there agrees with the surface's (default; see `consensus`): the floor and
    /// a box crossing a wrong pose's surface count for it no more. Off: every keypoint within
    /// the band counts, as the robot fit's rigid stages were measured.
    pub oriented_score: bool,
}

impl Default for PcaOptions {
    fn default() -> Self {
        Self {
            step: PcaStep::PointToPlane,
            // Coarse to fine: on the CAD scans the same successes as eq. 33's cosine in about
            // two thirds of the time (docs/cad-scan-trials.md).
            schedule: DeltaSchedule::Halving,
            delta_min_m: 0.01,
            schedule_iterations: 100,
            max_iterations: 300,
            voxel_m: 0.005,
            voxel_centroids: false,
            // The thesis's 19 (its stopping criterion) kept a run in its last band for 14
            // steps after point-to-plane steps had settled in a handful; the polish after it
            // settles the pose in its own band. With 5 (and the last band's progress test in
            // `schedule`) each of the 200 CAD scans succeeded or failed as before, with the
            // same median error, in 0.6-0.9 of the local stage's median time per delta
            // (docs/cad-scan-trials.md).
            window: 5,
            // 50 um: well below the 1 mm success bar, above the jitter that noisy correspondences
            // and coplanar clutter (a floor flush with the part's base) leave in the pose.
            tolerance_m: 5e-5,
            parallel: true,
            starts: 48,
            wide_exploration: true,
            polish: true,
            without_large_planes: true,
            twin_search: true,
            local_candidate: true,
            local_end_last_look: true,
            fine_run: true,
            wide_band_slack: true,
            local_band_within_radius: true,
            wide_band_matching: WideBandMatching::BothWays,
            wide_band_without_planes: true,
            wide_band_skips_weak_directions: true,
            fine_tie_break: true,
            hop_out_of_the_material: true,
            hop_near_misses: true,
            look_again_when_unfit: true,
            small_turns: false,
            oriented_score: true,
        }
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PcaError {
    #[error("the cloud is empty")]
    EmptyCloud,
    #[error("cloud point {0} is not finite")]
    NonFinitePoint(usize),
    #[error("delta must be finite and > 0, got {0}")]
    BadDelta(f64),
    #[error(
        "only {kept} cloud points lie within delta = {delta_m} m of the part at the start pose (at least 6 needed): is the start pose right and delta large enough?"
    )]
    TooFewPoints { kept: usize, delta_m: f64 },
    #[error(
        "the {kept} cloud keypoints near the part lie on a line along ({dx:.3}, {dy:.3}, {dz:.3}) (base frame; spread across it {across_mm:.2} mm, the part's radius {radius_mm:.1} mm): the rotation about that line and the translation along it are unconstrained"
    )]
    Collinear {
        kept: usize,
        dx: f64,
        dy: f64,
        dz: f64,
        across_mm: f64,
        radius_mm: f64,
    },
    #[error(
        "the {kept} cloud keypoints near the part lie in one plane with normal ({nx:.3}, {ny:.3}, {nz:.3}) (base frame; spread off it {off_mm:.2} mm, the part's radius {radius_mm:.1} mm): the translation within that plane and the rotation about its normal are unconstrained"
    )]
    Planar {
        kept: usize,
        nx: f64,
        ny: f64,
        nz: f64,
        off_mm: f64,
        radius_mm: f64,
    },
}

/// A cloud spread (standard deviation of the points near the part) below this fraction of the
/// part's radius in some direction does not constrain the pose in it. A face seen whole spreads
/// about 0.3 of its length (a uniform strip of length L has sigma L/sqrt(12)), and even a corner
/// of a part seen from one side spreads several percent of its radius, while scanner noise off a
/// plane or a line is a millimetre or less: 1% of a 150 mm radius is 1.5 mm, above the noise and
/// far below any real view of two faces.
const MIN_SPREAD_OF_RADIUS: f64 = 0.01;

/// Refuses points near the part that cannot fix its pose: all on a line or in one plane.
fn check_constrains_pose(points: &[Point3<f64>], radius_m: f64) -> Result<(), PcaError> {
    let Some(spread) = PrincipalSpread::of(points.iter().copied()) else {
        return Ok(());
    };
    let min_spread_m = MIN_SPREAD_OF_RADIUS * radius_m;
    let (kept, radius_mm) = (points.len(), radius_m * 1e3);
    if spread.sigma_m[1] < min_spread_m {
        let along = spread.axes[0];
        return Err(PcaError::Collinear {
            kept,
            dx: along.x,
            dy: along.y,
            dz: along.z,
            across_mm: spread.sigma_m[1] * 1e3,
            radius_mm,
        });
    }
    if spread.sigma_m[2] < min_spread_m {
        let normal = spread.axes[2];
        return Err(PcaError::Planar {
            kept,
            nx: normal.x,
            ny: normal.y,
            nz: normal.z,
            off_mm: spread.sigma_m[2] * 1e3,
            radius_mm,
        });
    }
    Ok(())
}

#[derive(Debug, Clone, PartialEq)]
pub struct PcaResult {
    /// Its rms and max are of the points kept in the last iteration; its starts count the start
    /// plus the exploration's runs.
    pub alignment: Alignment,
    pub keypoints: usize,
    pub kept: usize,
    pub final_delta_m: f64,
    /// How clearly the pose beats the best different pose the exploration found; `None` without
    /// an exploration (a local run) or when every run ended at this pose.
    pub uniqueness: Option<Uniqueness>,
    /// The pose's covariance from its last matches (see `uncertainty`), or why there is none.
    pub uncertainty: Result<PoseUncertainty, UncertaintyError>,
}

/// The pose's score (the consensus: coarse keypoints within a band of the part's surface, less
/// those inside it) against the best-scoring end of the exploration that is a different pose.
#[derive(Debug, Clone, PartialEq)]
pub struct Uniqueness {
    pub score: f64,
    pub runner_up_score: f64,
    pub runner_up: Isometry3<f64>,
    /// (score - runner-up's) / score.
    pub margin: f64,
    /// True when the runner-up scores within the scores' sampling noise (2 sqrt(score)) of the
    /// pose: the scan cannot tell the two apart (a symmetric part, or too little of it seen).
    pub ambiguous: bool,
}

/// A local run's bands this narrow or narrower are matched exactly, and in wider ones the points
/// within [`LOCAL_EXACT_WITHIN_BAND_FRACTION`] of the band (see [`RunSlack`]). Measured on the
/// 200 CAD scans (`replay` bench, docs/cad-scan-trials.md): exact, 61 successes; with the slack
/// (exact within 2 cm only, as the exploration) 69 in 0.36-0.50 of the time at 500-1000 mm, but on
/// the 20-triangle step block at 150 mm 6 of 30 against 17 exact: a slack answer there is often
/// another face, whose normal sends the step astray. Exact within half the band: 72 successes in
/// 0.7-0.75 of the exact time at 200-1000 mm, and on the step block 27/19/13 of 30 at
/// 100/150/200 mm against 28/17/5 exact.
const LOCAL_EXACT_WITHIN_BAND_M: f64 = 0.05;
const LOCAL_EXACT_WITHIN_BAND_FRACTION: f64 = 0.5;

/// Two ends of the exploration are the same pose unless some point of the part lies this far
/// apart, as a fraction of the part's radius. The score cannot tell poses within its band (a
/// centimetre) apart, and the short runs end up to a centimetre or two off the optimum; a twin
/// of a symmetric part (a quarter or half turn) moves its points by one or two radii.
const SAME_POSE_FRACTION_OF_RADIUS: f64 = 0.3;

/// Aligns the part's mesh to `cloud` (base frame) from `base_from_part_start`, with `delta0_m`
/// the user's bound on how far the start is from the truth.
pub fn align_cloud(
    mesh: &Mesh,
    cloud: &[Point3<f64>],
    base_from_part_start: &Isometry3<f64>,
    delta0_m: f64,
    options: &PcaOptions,
) -> Result<PcaResult, PcaError> {
    let started = Instant::now();
    let Located {
        run,
        keypoints,
        starts,
        uniqueness,
    } = locate_looking_again(mesh, cloud, base_from_part_start, delta0_m, options)?;
    let bounds = mesh.bounds();
    let final_matches = correspond(
        mesh,
        &keypoints,
        &run.pose,
        run.delta,
        (&bounds.0, &bounds.1),
        Lookup::exact(options.parallel),
        &mut [],
    );
    let (sum, max) = final_matches.iter().fold((0.0, 0.0f64), |(sum, max), m| {
        (sum + m.distance * m.distance, max.max(m.distance))
    });
    Ok(PcaResult {
        alignment: Alignment {
            base_from_part: run.pose,
            iterations: run.iterations,
            converged: run.converged,
            rms_m: (sum / final_matches.len().max(1) as f64).sqrt(),
            max_m: max,
            starts,
            time_s: started.elapsed().as_secs_f64(),
        },
        keypoints: keypoints.len(),
        kept: final_matches.len(),
        final_delta_m: run.delta,
        uniqueness,
        uncertainty: cloud_uncertainty(mesh, &final_matches, &run.pose),
    })
}

/// [`align_cloud`] up to its pose: the checks, the exploration, the run, the runs about the
/// found pose and the polish.
fn locate(
    mesh: &Mesh,
    cloud: &[Point3<f64>],
    base_from_part_start: &Isometry3<f64>,
    delta0_m: f64,
    options: &PcaOptions,
) -> Result<Located, PcaError> {
    if cloud.is_empty() {
        return Err(PcaError::EmptyCloud);
    }
    if let Some(index) = cloud
        .iter()
        .position(|p| !p.coords.iter().all(|c| c.is_finite()))
    {
        return Err(PcaError::NonFinitePoint(index));
    }
    if !(delta0_m.is_finite() && delta0_m > 0.0) {
        return Err(PcaError::BadDelta(delta0_m));
    }
    let local = options.starts == 0;
    // A local run's first band (see `schedule_from` below).
    let local_schedule_from = if options.local_band_within_radius {
        local_first_band(mesh, delta0_m, options)
    } else {
        delta0_m
    };
    let cropped;
    let cloud = if local {
        cropped = within_local_reach(mesh, cloud, base_from_part_start, delta0_m);
        cropped.as_slice()
    } else {
        cloud
    };
    let prepare_scan = || -> Result<Vec<Point3<f64>>, PcaError> {
        let keypoints = if options.voxel_centroids {
            voxel_centroids(cloud, options.voxel_m)
        } else {
            voxel_representatives(cloud, options.voxel_m)
        };
        // Every point within delta of the part counts here: seen from far off a small part,
        // most points' closest feature is an edge or a corner, and a scan with the part and the
        // floor within a metre of the start was refused for "1-2 points within delta"
        // (docs/cad-scan-trials.md).
        let first = near_surface(
            mesh,
            &keypoints,
            base_from_part_start,
            delta0_m,
            options.parallel,
        );
        if first.len() < 6 {
            return Err(PcaError::TooFewPoints {
                kept: first.len(),
                delta_m: delta0_m,
            });
        }
        check_constrains_pose(&first, mesh.radius_m())?;
        Ok(keypoints)
    };
    // The part's samples for the wide bands depend on the part alone: on two cores they are
    // drawn while the scan is binned, mostly serial work (docs/BENCHMARKS.md).
    // A local run (no exploration) from a wide band matches the outer half of the band
    // approximately until the band has narrowed to 5 cm: exact, its queries far off the
    // part were four fifths of a 1000 mm local alignment (see LOCAL_EXACT_WITHIN_BAND_M).
    let local_slack = if local && options.wide_band_slack {
        RunSlack {
            factor: EXPLORATION_SLACK,
            exact_within_band_m: LOCAL_EXACT_WITHIN_BAND_M,
            exact_within_band_fraction: LOCAL_EXACT_WITHIN_BAND_FRACTION,
        }
    } else {
        RunSlack::EXACT
    };
    let sample_part = || {
        if local {
            // A run whose first band matches approximately needs the mesh's facing tree:
            // built here, it costs the run nothing on two cores.
            if local_slack.at_band(local_schedule_from) > 1.0 {
                mesh.prepare_approximate_queries();
            }
            wide_band_samples(mesh, local_schedule_from, options)
        } else {
            Vec::new()
        }
    };
    let (keypoints, part_samples) = if options.parallel {
        rayon::join(prepare_scan, sample_part)
    } else {
        (prepare_scan(), sample_part())
    };
    let keypoints = keypoints?;
    let mut start = *base_from_part_start;
    let mut starts = 1;
    let mut schedule_from = local_schedule_from;
    let mut explored_ends: Vec<(f64, Isometry3<f64>)> = Vec::new();
    // The local stage's run, when its end is the best: it has run the schedule down to the
    // narrowest band on the fine keypoints and polished, all the run below would do again.
    let mut local_won: Option<ScheduleRun> = None;
    // The local stage's end whether it won or not, for the last comparison (see `local_end_ahead`).
    let mut local_end_run: Option<ScheduleRun> = None;
    let mut coarse: Option<Coarse> = None;
    if options.starts > 0 {
        let wide = options.wide_exploration && is_wide(mesh, delta0_m);
        // The scan's coarse keypoints and planes, the detection and the exploration, beside the
        // local stage, which needs none of them: serial, they took 6-9 ms of a 50 mm alignment
        // (a probe) before the two sides began (docs/BENCHMARKS.md, thirty-ninth session).
        let explore_here = || {
            let coarse = Coarse::new(mesh, cloud, options);
            let detected = if wide {
                detected_starts(
                    mesh,
                    cloud,
                    &coarse,
                    base_from_part_start,
                    delta0_m,
                    options,
                )
            } else {
                Vec::new()
            };
            // Below a wide delta the runs' bands are narrow and exact queries cheap; with the
            // slack, the one run a 50 mm step-block trial made ended 67 mm off
            // (docs/pca-trials.md).
            let exploring = Exploring {
                detected: &detected,
                slack: if wide { EXPLORATION_SLACK } else { 1.0 },
                runs_keep_planes: false,
                from_start: !options.local_candidate,
                small_turns: options.small_turns,
            };
            let explored = explore(
                mesh,
                &coarse,
                base_from_part_start,
                delta0_m,
                options,
                exploring,
            );
            (coarse, explored)
        };
        // The local stage's end, when it runs: a refusal there (too few points within its
        // reach) leaves the exploration's ends alone.
        let local_here = || {
            options
                .local_candidate
                .then(|| {
                    let local = PcaOptions {
                        starts: 0,
                        ..options.clone()
                    };
                    locate(mesh, cloud, base_from_part_start, delta0_m, &local).ok()
                })
                .flatten()
                .map(|located| located.run)
        };
        let ((made, (mut scored, explored)), local_end) = if options.parallel {
            rayon::join(explore_here, local_here)
        } else {
            (explore_here(), local_here())
        };
        let coarse = coarse.insert(made);
        if let Some(local_run) = local_end {
            local_end_run = Some(local_run);
            let pose = local_run.pose;
            scored.push((coarse.score(mesh, &pose), pose));
            // Stable: an end that scores as the local one does keeps its place before it.
            scored.sort_by(|a, b| b.0.total_cmp(&a.0));
            if scored.first().is_some_and(|(_, best)| *best == pose) {
                local_won = Some(local_run);
            }
        }
        start = scored.first().map_or(start, |(_, pose)| *pose);
        explored_ends = scored;
        starts += explored;
        // The exploration ended within a few voxels of its optimum: refining from a wide band
        // again would only let the clutter back in.
        schedule_from = delta0_m.min(3.0 * options.delta_min_m);
    }
    // The given keypoints as the finest level, voxel 0 so that every band may use them. After an
    // exploration the run starts at 3 cm, on the fine keypoints only: on 10 mm ones a small
    // link (the IRB 1600's flange in a 50 mm CAD scan) was carried 87 mm off a pose the
    // exploration had found within 0.2 mm (docs/cad-scan-trials.md).
    let coarser = if coarse.is_some() {
        Vec::new()
    } else {
        coarser_levels(&keypoints, schedule_from, options)
    };
    let levels: Vec<(f64, &[Point3<f64>])> = std::iter::once((0.0, keypoints.as_slice()))
        .chain(
            coarser
                .iter()
                .map(|(voxel_m, points)| (*voxel_m, points.as_slice())),
        )
        .collect();
    let mut polished_already = local_won.is_some();
    let fine_ran = local_won.is_none() && coarse.is_some() && options.fine_run;
    let mut run = if let Some(local_run) = local_won {
        local_run
    } else if coarse.is_some() && !options.fine_run {
        // The exploration's best end (`start` now) ended its run in the narrowest band.
        ScheduleRun {
            pose: start,
            iterations: 0,
            converged: true,
            delta: options.delta_min_m.min(delta0_m),
        }
    } else {
        let model_to_scan = if coarse.is_none() {
            model_to_scan_levels(&levels, part_samples, options.parallel)
        } else {
            Vec::new()
        };
        // The wide bands' scan-to-model half without the planes larger than the part.
        let planeless = if !model_to_scan.is_empty()
            && options.wide_band_without_planes
            && options.wide_band_matching == WideBandMatching::BothWays
        {
            coarser_without_large_planes(mesh, &levels)
        } else {
            Vec::new()
        };
        let run_levels: Vec<(f64, &[Point3<f64>])> = if planeless.is_empty() {
            levels.clone()
        } else {
            levels[..1]
                .iter()
                .copied()
                .chain(
                    planeless
                        .iter()
                        .map(|(voxel_m, points)| (*voxel_m, points.as_slice())),
                )
                .collect()
        };
        run_schedule_on_levels(
            mesh,
            &run_levels,
            &start,
            schedule_from,
            options,
            local_slack,
            &model_to_scan,
        )
    };
    // A fine run that explains less of the scan than the end it started from was carried off:
    // on a round link lying on the floor (the unseen set A, scan 70), the floor's points in its
    // 3 cm band spun the part and pulled it 412 mm off a pose the exploration had found within
    // 0.2 mm, to where it explained 3 of the 183 keypoints the end did. The end it started
    // from stays the pose, for the polish to settle. Replayed (docs/cad-scan-trials.md): set A
    // 181 -> 184 successes (scans 70, 109 and 151), held-out set B unchanged, nothing lost.
    if fine_ran
        && let Some(coarse) = &coarse
        && coarse.explains_less(mesh, &run.pose, &start)
    {
        run = ScheduleRun {
            pose: start,
            converged: true,
            delta: options.delta_min_m.min(delta0_m),
            ..run
        };
    }
    let mut uniqueness_found = None;
    if let Some(coarse) = coarse.as_ref().filter(|_| options.twin_search) {
        // Runs from the found pose turned every way the delta allows (see `runs_around`).
        let around = runs_around(mesh, coarse, &run.pose, delta0_m, options);
        let found_score = coarse.score(mesh, &run.pose);
        if let Some((better_score, better)) = around.first()
            && *better_score > found_score + score_noise(found_score)
        {
            let again = run_schedule_on_levels(
                mesh,
                &levels,
                better,
                schedule_from,
                options,
                RunSlack::EXACT,
                &[],
            );
            if coarse.score(mesh, &again.pose) > found_score {
                run = again;
                polished_already = false;
            }
        }
        explored_ends.extend(around);
        uniqueness_found = uniqueness(mesh, coarse, &run.pose, &explored_ends);
    }
    let mut hopped_already = false;
    if options.polish
        && !polished_already
        && let Some(polished) = polish(mesh, &keypoints, &run.pose, run.delta, options)
    {
        let last_band_m = run.delta;
        let settled_inside = polished.off_the_surface.mostly_behind();
        run = ScheduleRun {
            pose: polished.pose,
            iterations: run.iterations + polished.iterations,
            converged: run.converged && polished.converged,
            delta: polished.band_m,
        };
        if options.hop_out_of_the_material && settled_inside {
            hopped_already = true;
            // Off the large planes when they are known, as the coarse score counts.
            let counted: Cow<[Point3<f64>]> = match &coarse {
                Some(coarse) => Cow::Owned(coarse.off_the_planes(&keypoints)),
                None => Cow::Borrowed(&keypoints),
            };
            if let Some(better) = hop(
                mesh,
                &keypoints,
                &counted,
                &run,
                last_band_m,
                options,
                HopStarts::ShiftsAndTurns,
            ) {
                run = better;
            }
        }
    }
    // A full alignment hops from its final pose too, inside the material or not (see `hop`).
    if options.hop_near_misses
        && options.polish
        && !hopped_already
        && let Some(coarse) = &coarse
        && let Some(better) = hop_from_the_end(mesh, &keypoints, coarse, &run, delta0_m, options)
    {
        run = better;
    }
    // Poses the coarse score cannot tell apart, compared at the scanner's scale (see
    // `tie_break`): the one that fits clearly more of the scan is the pose, and the uniqueness
    // is measured again for it, with the pose it replaces among the others.
    if options.fine_tie_break
        && let Some(coarse) = &coarse
        && let Some(found) = uniqueness_found.as_ref().filter(|u| u.ambiguous)
        && let Some(better) = decide_finely(
            mesh,
            coarse,
            &keypoints,
            Undecided {
                run: &run,
                score: found.score,
                ends: &explored_ends,
            },
            schedule_from,
            options,
        )
    {
        explored_ends.push((coarse.score(mesh, &run.pose), run.pose));
        run = better;
        uniqueness_found = uniqueness(mesh, coarse, &run.pose, &explored_ends);
    }
    if options.local_end_last_look
        && let (Some(coarse), Some(local_run)) = (&coarse, local_end_run)
        && let Some(better) = local_end_ahead(mesh, coarse, &keypoints, &run, &local_run)
    {
        explored_ends.push((coarse.score(mesh, &run.pose), run.pose));
        run = better;
        uniqueness_found = uniqueness(mesh, coarse, &run.pose, &explored_ends);
    }
    Ok(Located {
        run,
        keypoints,
        starts,
        uniqueness: uniqueness_found,
    })
}
