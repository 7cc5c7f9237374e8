//! The global part of Point Cloud Alignment: short runs from many starts (turns of the start,
//! poses a point-pair-feature detection finds, translations of the start), each scored by how
//! much of the scan it explains, for starts too far from the truth for one run.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::consensus::score_noise;
use super::{
    Coarse, PcaOptions, SAME_POSE_FRACTION_OF_RADIUS, Uniqueness, consensus, run_schedule,
};
use crate::geometry::Mesh;
use crate::registration::convergence::pose_distance;
use crate::registration::ppf::{PpfModel, PpfOptions, detected_alike};
use crate::registration::psa::spread_rotations;
use crate::registration::sampling::voxel_representatives;

/// The exploration's short runs may match a keypoint to a surface point up to this factor
/// farther than the closest. Their band is as wide as the user's delta (half a metre and more),
/// so most of their keypoints are clutter far off the part, where an exact answer opens every
/// node of the mesh's tree that the sphere through the best triangle meets: exact, those
/// queries were 95% of a 500 mm alignment's time.
pub(super) const EXPLORATION_SLACK: f64 = 1.5;

/// Global exploration for large deltas: short runs on coarse keypoints from the start and from
/// the start turned about the part's centroid by rotations spread over the ball the user's delta
/// allows; returns the ends of the runs with their consensus, best first, and how many runs
/// were made.
pub(super) fn explore(
    mesh: &Mesh,
    coarse: &Coarse,
    start: &Isometry3<f64>,
    delta0_m: f64,
    options: &PcaOptions,
    exploring: Exploring,
) -> (Vec<(f64, Isometry3<f64>)>, usize) {
    let max_angle = (1.2 * delta0_m / mesh.radius_m()).min(std::f64::consts::PI);
    explore_turns(mesh, coarse, start, max_angle, delta0_m, options, exploring)
}

/// What an exploration adds to its turns of the start, and how exactly its runs match.
#[derive(Debug, Clone, Copy)]
pub(super) struct Exploring<'a> {
    /// More starts (the detection's poses).
    pub(super) detected: &'a [Isometry3<f64>],
    /// 1, or [`EXPLORATION_SLACK`] (see [`super::matching::correspond`]).
    pub(super) slack: f64,
    /// The runs keep the large planes the score leaves out (see [`super::planes`]). The runs
    /// about a found pose look for its twins, and a twin of a part resting on the floor rests
    /// on it too: with the floor's points a symmetric box's runs reached its half-turn twin,
    /// without them none did (`tests/pca.rs`). The runs from a far start leave them out: the
    /// floor pulled thin parts flat into it (docs/cad-scan-trials.md: 128 against 136 of 200
    /// scans with them kept in every run).
    pub(super) runs_keep_planes: bool,
    /// A run from the start itself, besides its turns. Off when the local stage runs from the
    /// start instead (`PcaOptions::local_candidate`): it gets there at least as surely as a
    /// short run on coarse keypoints, and both would cost a 50 mm alignment its time twice.
    pub(super) from_start: bool,
    /// When no spread rotation is within reach, the start turned by half the reach each way
    /// about the part's axes (see `PcaOptions::small_turns`).
    pub(super) small_turns: bool,
}

impl Exploring<'_> {
    /// Turns only, matched exactly: the runs around a found pose, and the robot fit's base
    /// candidates, whose tables (docs/articulated-trials.md) were measured so.
    pub(super) const EXACT: Exploring<'static> = Exploring {
        detected: &[],
        slack: 1.0,
        runs_keep_planes: true,
        from_start: true,
        small_turns: false,
    };
}

/// From a delta of this fraction of the part's radius on, the exploration is wide: it also runs
/// from poses a point-pair-feature detection finds (turns of the start alone leave the
/// translation to the runs, which a band that wide pulls into the clutter), and its far queries
/// take [`EXPLORATION_SLACK`].
const WIDE_DELTA_PER_RADIUS: f64 = 0.5;

/// Whether `delta0_m` calls for the wide exploration on this part.
pub(super) fn is_wide(mesh: &Mesh, delta0_m: f64) -> bool {
    delta0_m >= WIDE_DELTA_PER_RADIUS * mesh.radius_m()
}

/// The detection's model samples, about, at most.
const DETECTION_MODEL_SAMPLES: f64 = 1500.0;

/// The band a run from a detected pose starts in, as a fraction of the part's radius: the same
/// as the runs about the found pose (see [`super::align_cloud`]), which start as close.
const DETECTED_BAND_PER_RADIUS: f64 = 0.5;

/// Detected poses tried, at most.
const DETECTED_STARTS: usize = 16;

/// The band the detected poses are scored in, in detection steps (the only value tried).
const DETECTION_SCORE_BAND_PER_STEP: f64 = 2.0;

/// Poses detected in the scan without its large planes, tried besides the [`DETECTED_STARTS`].
const DETECTED_OFF_PLANES_STARTS: usize = 8;

/// Poses of the detection without the large planes refined before they are ranked (see
/// [`detected_starts`]), the best by how they are detected; the only value tried.
const REFINED_OFF_PLANES_DETECTIONS: usize = 64;

/// From a delta of this many part radii on, the detection's poses without the large planes are
/// refined before they are ranked (see [`detected_starts`]). Chosen after the replays: below it
/// the refinement lost two scans and fitted one (a G1 torso at 1.02 radii, put on the box and
/// not flagged; the shipped SO-ARM100 upper arm of `crates/cad-scans/tests/recovery.rs` at 1.19,
/// flagged; a FingerEdu link at 1.09); from it, none of sets A-D was lost and three of set E's,
/// each flagged (docs/cad-scan-trials.md, forty-sixth session).
const REFINED_FROM_DELTA_PER_RADIUS: f64 = 1.5;

/// Steps of a detected pose's refinement, from a band of two detection steps: a band or two of
/// the halving schedule (`STEPS_PER_BAND` at most in each); the only value tried.
const REFINE_ITERATIONS: usize = 12;

/// From a delta of this many part radii on, the start may not overlap the part at all, and
/// the detection also runs without the large planes. Below it, on sets A-E, the second
/// detection fitted no scan and lost two (a Go2 calf and a Solo12 lower leg at 100 mm, delta
/// 0.93 and 0.75 radii), and on a small part's 50 mm scans it cost 0.2-0.5 s a scan
/// (docs/cad-scan-trials.md, forty-fourth session): its references all lie on the part,
/// whose pairs are many, where the floor's are mostly coplanar and skipped.
const OFF_PLANES_DELTA_PER_RADIUS: f64 = 1.0;

/// Two detected poses differing by less than this in rotation (and putting the centroid within
/// two detection steps, `ppf::detected_alike`) are one.
const SAME_POSE_RAD: f64 = 0.3;

/// Poses of the part that the point pair features find in the cloud within what delta allows
/// from the start (its origin within the translations and turns of the thesis's scheme), for a
/// delta large enough to need them; none otherwise. Two detections, one model: in the whole
/// cloud, the [`DETECTED_STARTS`] that explain the most of the scan, and in the cloud without
/// its large planes, the [`DETECTED_OFF_PLANES_STARTS`] best of the poses the first ones do not
/// hold, from [`REFINED_FROM_DELTA_PER_RADIUS`] on each refined by a few steps before it is
/// ranked. `alignment_options` are the alignment's own, which the refinements start from.
///
/// In 36 cad-scans misses at 200-1000 mm whose truth no run reached, no merged pose of the
/// whole cloud's detection was within a tenth of the part's radius of the truth, and the part
/// was a piece of the scan of its own once the large planes were cut out
/// (docs/cad-scan-trials.md, forty-fourth session): a reference on a small link pairs mostly
/// with the floor around it, and without the planes with the link. The whole cloud's
/// detection stays: alone, the detection without the planes fitted 155 of set E's scans
/// against 160 with both (and lost five of set C's in the eighteenth session).
pub(super) fn detected_starts(
    mesh: &Mesh,
    cloud: &[Point3<f64>],
    coarse: &Coarse,
    start: &Isometry3<f64>,
    delta0_m: f64,
    alignment_options: &PcaOptions,
) -> Vec<Isometry3<f64>> {
    let radius_m = mesh.radius_m();
    if !is_wide(mesh, delta0_m) {
        return Vec::new();
    }
    let max_angle = (1.2 * delta0_m / radius_m).min(std::f64::consts::PI);
    // A turn about the centroid moves the origin by up to twice its distance from it.
    let reach_m = 1.2 * delta0_m + 2.0 * mesh.centroid().coords.norm();
    // A tenth of the radius resolves a small part's shape; on a large one the sample count is
    // capped instead, since the model's table grows with its square and the voting with it.
    let area_m2 = mesh.area_m2();
    let options = PpfOptions {
        step_m: (radius_m / 10.0)
            .clamp(0.006, 0.015)
            .max((area_m2 / DETECTION_MODEL_SAMPLES).sqrt()),
        ..PpfOptions::default()
    };
    let Some(model) = PpfModel::new(mesh, &options) else {
        return Vec::new();
    };
    // Applied before the votes are ranked: the poses a thin link's scan votes for most are
    // mostly turned further than delta allows (see `ppf_poses_where`).
    let within_turn = |pose: &Isometry3<f64>| pose.rotation.angle_to(&start.rotation) <= max_angle;
    // Votes count the scene references that agree on a pose, and on a thin link in clutter the
    // floor and the box agree on many: the near-true pose ranked 3rd to 158th by votes in the
    // 500-1000 mm cad-scans misses looked at. Ranked by how much of the scan the pose explains
    // (the exploration's consensus, in a band of two detection steps, as far as a detected
    // pose is from the one it stands for), the near-true pose was among the 16 kept in most.
    let band_m = DETECTION_SCORE_BAND_PER_STEP * options.step_m;
    let best_in = |scene: &[Point3<f64>]| {
        let detected = model.poses_where(
            scene,
            (&(start * Point3::origin()), reach_m),
            // Every merged pose: the votes do not pick the starts, the consensus below does.
            usize::MAX,
            SAME_POSE_RAD,
            &within_turn,
        );
        let mut scored: Vec<(f64, Isometry3<f64>)> = detected
            .par_iter()
            .map(|found| {
                let pose = found.world_from_model;
                (coarse.score_in_band(mesh, &pose, band_m), pose)
            })
            .collect();
        // Stable: poses that score alike keep their vote order.
        scored.sort_by(|a, b| b.0.total_cmp(&a.0));
        scored.into_iter().map(|(_, pose)| pose)
    };
    let mut starts: Vec<Isometry3<f64>> = best_in(cloud).take(DETECTED_STARTS).collect();
    let far = delta0_m >= OFF_PLANES_DELTA_PER_RADIUS * radius_m;
    if let Some(off_planes) = coarse.cloud_off_planes().filter(|_| far) {
        // Only poses the whole cloud's starts do not hold already (the detection's own test of
        // one pose): a run from one of those would repeat a run.
        let centroid = mesh.centroid();
        let held = |pose: &Isometry3<f64>| {
            starts
                .iter()
                .any(|kept| detected_alike(pose, kept, &centroid, options.step_m, SAME_POSE_RAD))
        };
        // Ranked as they are detected, a pose a few centimetres from the truth scores below
        // poses across the box and the floor's edges in the band of two detection steps (and
        // so, in most, does the truth itself): in eleven 500-1000 mm misses of sets A-E whose
        // truth no run reached, the detection nearest the truth (9-31 mm off) ranked 11th to
        // 146th in nine. A few steps from each bring it onto the part, where the score's
        // narrow band tells it from the clutter: refined, it ranked first or second in eight,
        // and fifth, behind poses that score as well, in one; the two ranked beyond the 64
        // refined stayed out (a probe, not kept; docs/cad-scan-trials.md, forty-sixth session).
        let refined_first = delta0_m >= REFINED_FROM_DELTA_PER_RADIUS * radius_m;
        let candidates: Vec<Isometry3<f64>> = best_in(off_planes)
            .filter(|pose| !held(pose))
            .take(if refined_first {
                REFINED_OFF_PLANES_DETECTIONS
            } else {
                DETECTED_OFF_PLANES_STARTS
            })
            .collect();
        if !refined_first {
            starts.extend(candidates);
            return starts;
        }
        let refine = PcaOptions {
            max_iterations: REFINE_ITERATIONS,
            window: 3,
            tolerance_m: 1e-4,
            parallel: false,
            ..alignment_options.clone()
        };
        let mut refined: Vec<(f64, Isometry3<f64>)> = candidates
            .par_iter()
            .map(|pose| {
                let run = run_schedule(mesh, coarse.scored(), pose, band_m, &refine, 1.0);
                (coarse.score(mesh, &run.pose), run.pose)
            })
            .collect();
        refined.sort_by(|a, b| b.0.total_cmp(&a.0));
        // Refined poses may meet: a start repeated would repeat a run.
        let mut new: Vec<Isometry3<f64>> = Vec::new();
        for (_, pose) in refined {
            if new.len() == DETECTED_OFF_PLANES_STARTS {
                break;
            }
            if !held(&pose)
                && !new.iter().any(|kept| {
                    detected_alike(&pose, kept, &centroid, options.step_m, SAME_POSE_RAD)
                })
            {
                new.push(pose);
            }
        }
        starts.extend(new);
    }
    starts
}

/// The runs of [`explore`] from `start` turned by up to `max_angle` (rad), each from a band of
/// `delta0_m`.
fn explore_turns(
    mesh: &Mesh,
    coarse: &Coarse,
    start: &Isometry3<f64>,
    max_angle: f64,
    delta0_m: f64,
    options: &PcaOptions,
    exploring: Exploring,
) -> (Vec<(f64, Isometry3<f64>)>, usize) {
    let run_points = if exploring.runs_keep_planes {
        &coarse.all
    } else {
        coarse.scored()
    };
    let short = PcaOptions {
        max_iterations: 40,
        window: 3,
        tolerance_m: 1e-5,
        ..options.clone()
    };
    let centre = mesh.centroid();
    let about_centre = Isometry3::translation(centre.x, centre.y, centre.z);
    let mut candidates = if exploring.from_start {
        vec![(*start, delta0_m)]
    } else {
        Vec::new()
    };
    // Only orientations within the rotation delta allows (with margin) are tried: scaling a
    // spread set into that ball was tried and is worse, since the consensus score then prefers
    // poses that rest a large face on the floor plane.
    let turned = |rotation: UnitQuaternion<f64>| {
        start
            * about_centre
            * Isometry3::from_parts(Translation3::identity(), rotation)
            * about_centre.inverse()
    };
    for rotation in spread_rotations(options.starts) {
        if rotation.angle() <= max_angle {
            candidates.push((turned(rotation), delta0_m));
        }
    }
    if exploring.small_turns && candidates.len() == usize::from(exploring.from_start) {
        let half_reach = SMALL_TURN_OF_REACH * max_angle;
        for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
            for sign in [-1.0, 1.0] {
                let rotation = UnitQuaternion::from_scaled_axis(axis * (sign * half_reach));
                candidates.push((turned(rotation), delta0_m));
            }
        }
    }
    // A detected pose is within a step or two of a pose of the part already: a run from it in
    // the band of a far start is pulled off into the clutter (on the step block at 500 mm, a
    // detection 9.5 mm from the truth ended 283 mm off, and nine trials in fifty failed so).
    let detected_band_m = delta0_m.min(DETECTED_BAND_PER_RADIUS * mesh.radius_m());
    candidates.extend(
        exploring
            .detected
            .iter()
            .map(|pose| (*pose, detected_band_m)),
    );
    // The runs share the threads; a run alone (a delta too small for any turn) takes them
    // itself, since it is then all the exploration does.
    let run_options = PcaOptions {
        parallel: options.parallel && candidates.len() < rayon::current_num_threads(),
        ..short.clone()
    };
    let mut scored: Vec<(f64, Isometry3<f64>)> = candidates
        .par_iter()
        .map(|(candidate, band_m)| {
            let run = run_schedule(
                mesh,
                run_points,
                candidate,
                *band_m,
                &run_options,
                exploring.slack,
            );
            (coarse.score(mesh, &run.pose), run.pose)
        })
        .collect();
    scored.sort_by(|a, b| b.0.total_cmp(&a.0));
    (scored, candidates.len() - usize::from(exploring.from_start))
}

/// Runs from the found `pose` turned every way the delta allows, ends best first: a twin (a
/// symmetric part's other pose) that no run from the start reached shows up among them, and so
/// does a better pose the exploration from the start missed. A twin turned about the part's
/// centre fills nearly the same space: a band of half the part's radius keeps the clutter out.
///
/// With no turn of the spread set within the delta's reach, these are two runs from the found
/// pose itself (9-14 ms of a large part's 50 mm alignment, a probe): they were left out in a
/// trial and a Z1 link at 100 mm ended 49 mm off instead of 0.2 mm (the run from the found
/// pose in the delta's band had carried it to the truth), and a Solo12 shin at 50 mm lost its
/// ambiguity flag. With the run without the large planes alone, the cylinder of
/// `crates/cad-scans/tests/refusals.rs` at 50 mm (no turn in reach) was called unique in two of
/// its three scans: both runs are needed even then (docs/cad-scan-trials.md, forty-first
/// session).
pub(super) fn runs_around(
    mesh: &Mesh,
    coarse: &Coarse,
    pose: &Isometry3<f64>,
    delta0_m: f64,
    options: &PcaOptions,
) -> Vec<(f64, Isometry3<f64>)> {
    let max_angle = (1.2 * delta0_m / mesh.radius_m()).min(std::f64::consts::PI);
    let band = delta0_m.min(0.5 * mesh.radius_m());
    // Exact: with the slack these runs found the twin of a symmetric box in no start
    // (crates/align-core/tests/pca.rs, before answers near the surface were made exact), and
    // their band is narrow, so cheap anyway. Run with the large planes and without: with the
    // floor's points a symmetric box's runs reached its half-turn twin, which rests on the
    // floor as well (crates/align-core/tests/pca.rs), and without them none did; with them
    // only, one of three cylinder scans was reported unique (crates/cad-scans/tests/
    // refusals.rs).
    let around_with = |runs_keep_planes: bool| {
        let exploring = Exploring {
            runs_keep_planes,
            ..Exploring::EXACT
        };
        explore_turns(mesh, coarse, pose, max_angle, band, options, exploring).0
    };
    // Both sets at once: a part with no turn in the delta's reach runs one run a set, which
    // left a core idle (docs/BENCHMARKS.md, thirty-ninth session).
    let mut around = match (options.without_large_planes, options.parallel) {
        (true, true) => {
            let (mut with, without) = rayon::join(|| around_with(true), || around_with(false));
            with.extend(without);
            with
        }
        (true, false) => [around_with(true), around_with(false)].concat(),
        (false, _) => around_with(true),
    };
    around.sort_by(|a, b| b.0.total_cmp(&a.0));
    around
}

/// The small turns (see [`Exploring::small_turns`]) are this fraction of the delta's reach.
const SMALL_TURN_OF_REACH: f64 = 0.5;

/// Starts spread in translation that [`pose_candidates_spread`] screens, at most.
const SPREAD_STARTS: usize = 512;

/// [`pose_candidates`] for a start that may be off by more than the part is big (`bound_m`, the
/// largest distance of the part's origin from where the start puts it, beyond its radius). A
/// run from the start in a band that wide is pulled by everything the band holds (a neighbouring
/// object, the rest of a robot) and settles where the part is not: on a boxy robot base the best
/// such end scored 600-700 where the true pose scores 930-960 (exploratory runs). The runs start
/// instead from the start moved to the points of a cubic grid within `bound_m` (spacing half the
/// part's radius, coarser where that would make more than [`SPREAD_STARTS`]), each in a band of
/// one spacing: a short run on sparse keypoints screens them, and the best `4 count` distinct
/// ends run again as the exploration's runs do.
pub fn pose_candidates_spread(
    mesh: &Mesh,
    cloud: &[Point3<f64>],
    start: &Isometry3<f64>,
    bound_m: f64,
    options: &PcaOptions,
    count: usize,
    distinct_m: f64,
) -> Vec<Isometry3<f64>> {
    let radius_m = mesh.radius_m();
    // A ball of radius bound holds about 4.19 (bound / spacing)^3 grid points.
    let crowded_m = bound_m * (4.19 / SPREAD_STARTS as f64).cbrt();
    let spacing_m = (radius_m / 2.0).max(crowded_m);
    if !(spacing_m.is_finite() && spacing_m > 0.0) {
        return Vec::new();
    }
    let steps = (bound_m / spacing_m).floor() as i32;
    let mut starts = Vec::new();
    for i in -steps..=steps {
        for j in -steps..=steps {
            for k in -steps..=steps {
                let offset = Vector3::new(f64::from(i), f64::from(j), f64::from(k)) * spacing_m;
                if offset.norm() <= bound_m {
                    starts.push(Isometry3::from_parts(
                        Translation3::from(start.translation.vector + offset),
                        start.rotation,
                    ));
                }
            }
        }
    }
    // The screening's keypoints: a sixth of the part's radius apart (some hundred on its
    // surface), between the exploration's spacing and twice it.
    let sparse_m = (radius_m / 6.0)
        .max(options.voxel_m * 3.0)
        .min(options.voxel_m * 6.0);
    let sparse = voxel_representatives(cloud, sparse_m);
    let keypoints = voxel_representatives(cloud, options.voxel_m * 3.0);
    let band = (options.voxel_m * 2.0).max(options.delta_min_m * 0.3);
    let screen = PcaOptions {
        schedule_iterations: 10,
        max_iterations: 10,
        window: 3,
        tolerance_m: 1e-4,
        parallel: false,
        ..options.clone()
    };
    let mut screened: Vec<(f64, Isometry3<f64>)> = starts
        .par_iter()
        .map(|start| {
            let run = run_schedule(mesh, &sparse, start, spacing_m, &screen, 1.0);
            (consensus(mesh, &sparse, &run.pose, 2.0 * band), run.pose)
        })
        .collect();
    screened.sort_by(|a, b| b.0.total_cmp(&a.0));
    let finalists = distinct_poses(screened, 4 * count, radius_m, distinct_m);
    let short = PcaOptions {
        max_iterations: 40,
        window: 3,
        tolerance_m: 1e-5,
        parallel: false,
        ..options.clone()
    };
    let mut scored: Vec<(f64, Isometry3<f64>)> = finalists
        .par_iter()
        .map(|pose| {
            let run = run_schedule(mesh, &keypoints, pose, spacing_m / 2.0, &short, 1.0);
            (consensus(mesh, &keypoints, &run.pose, band), run.pose)
        })
        .collect();
    scored.sort_by(|a, b| b.0.total_cmp(&a.0));
    distinct_poses(scored, count, radius_m, distinct_m)
}

/// The poses of `scored` (best first) no two within `distinct_m` (thesis pose distance), at most
/// `count`.
fn distinct_poses(
    scored: Vec<(f64, Isometry3<f64>)>,
    count: usize,
    radius_m: f64,
    distinct_m: f64,
) -> Vec<Isometry3<f64>> {
    let mut kept: Vec<Isometry3<f64>> = Vec::new();
    for (_, pose) in scored {
        if kept.len() == count {
            break;
        }
        if kept
            .iter()
            .all(|k| pose_distance(k, &pose, radius_m) > distinct_m)
        {
            kept.push(pose);
        }
    }
    kept
}

/// Rigid poses of `mesh` in `cloud` within what `delta0_m` allows from `start`, best consensus
/// first, at most `count` of them and no two within `distinct_m` of each other (thesis pose
/// distance): the ends of the short runs of the exploration, for a caller that checks several.
pub fn pose_candidates(
    mesh: &Mesh,
    cloud: &[Point3<f64>],
    start: &Isometry3<f64>,
    delta0_m: f64,
    options: &PcaOptions,
    count: usize,
    distinct_m: f64,
) -> Vec<Isometry3<f64>> {
    let coarse = Coarse::new(mesh, cloud, options);
    let (scored, _) = explore(mesh, &coarse, start, delta0_m, options, Exploring::EXACT);
    distinct_poses(scored, count, mesh.radius_m(), distinct_m)
}

/// Whether two poses of the part are one for the uniqueness test: apart by at most
/// [`SAME_POSE_FRACTION_OF_RADIUS`] of its radius at its centroid and at its radius.
pub(super) fn same_pose(mesh: &Mesh, a: &Isometry3<f64>, b: &Isometry3<f64>) -> bool {
    let centre = mesh.centroid();
    let shift_m = (a * centre - b * centre).norm();
    let turn_m = a.rotation.angle_to(&b.rotation) * mesh.radius_m();
    shift_m.max(turn_m) <= SAME_POSE_FRACTION_OF_RADIUS * mesh.radius_m()
}

/// The pose against the best exploration end that is a different pose, scored alike.
pub(super) fn uniqueness(
    mesh: &Mesh,
    coarse: &Coarse,
    pose: &Isometry3<f64>,
    ends: &[(f64, Isometry3<f64>)],
) -> Option<Uniqueness> {
    let (runner_up_score, runner_up) = ends
        .iter()
        .filter(|(_, end)| !same_pose(mesh, end, pose))
        .max_by(|a, b| a.0.total_cmp(&b.0))?;
    let score = coarse.score(mesh, pose).max(*runner_up_score);
    let margin = if score > 0.0 {
        (score - runner_up_score) / score
    } else {
        0.0
    };
    Some(Uniqueness {
        score,
        runner_up_score: *runner_up_score,
        runner_up: *runner_up,
        margin,
        ambiguous: score - runner_up_score <= score_noise(score),
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    use super::{Exploring, explore};
    use crate::registration::convergence::pose_distance;
    use crate::registration::pca::PcaOptions;
    use crate::registration::pca::consensus::tests::step_block_beside_a_box;

    #[test]
    fn below_the_spread_sets_reach_the_small_turns_run_and_one_turns_back_to_the_truth() {
        let (mesh, truth, coarse) = step_block_beside_a_box();
        let options = PcaOptions::default();
        // A delta whose reach (1.2 delta / radius) is 0.3 rad, below the spread set's nearest
        // turn (36 degrees), and a start turned by half of it about the part's x axis.
        let delta_m = 0.25 * mesh.radius_m();
        let half_reach = 0.5 * 1.2 * delta_m / mesh.radius_m();
        let centre = mesh.centroid();
        let about_centre = Translation3::from(centre.coords);
        let tilt = UnitQuaternion::from_scaled_axis(Vector3::x() * half_reach);
        let start = truth * about_centre * tilt * about_centre.inverse();
        let exploring = |small_turns| Exploring {
            from_start: false,
            small_turns,
            ..Exploring::EXACT
        };
        let (ends, runs) = explore(&mesh, &coarse, &start, delta_m, &options, exploring(false));
        assert_eq!((ends.len(), runs), (0, 0));
        let (ends, runs) = explore(&mesh, &coarse, &start, delta_m, &options, exploring(true));
        assert_eq!((ends.len(), runs), (6, 6));
        let radius_m = mesh.radius_m();
        let best_off_m = pose_distance(&ends[0].1, &truth, radius_m);
        assert!(best_off_m < 1e-3, "the best end is {best_off_m} m off");
    }
}
