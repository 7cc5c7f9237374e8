//! Hierarchical alignment of a robot in a scan (thesis 3.5, proposed there, built here): the base
//! pose and the joint values, each link constrained by its parent.
//!
//! 0. The scan's isolated returns are left out (`isolated_min_neighbours`): a point whose
//!    keypoint voxel has fewer than three occupied voxels within two of it, as a scanner's
//!    spurious returns along its rays and the mixed pixels streaked across a depth gap are.
//! 1. Base hypotheses: the whole robot at the start joints aligned as one rigid part with Point
//!    Cloud Alignment (its filters, weights, schedule and exploration); and, when delta exceeds
//!    a third of the proximal links' radius and the start is not near, the best few rigid
//!    alignments of the proximal links (the base and what only the first joint moves), which
//!    do not depend on the other joints: from runs that start at the start turned (the
//!    exploration) and at translations of it on a grid, screened (the start may be off by more
//!    than those links are big, and a run in a band that wide settles on whatever else it
//!    holds); and where the scan shows a floor, the places where the base alone, stood on it,
//!    is voted for by the keypoints at its height (`standing.rs`: a rigid run of the base with
//!    the first joint's link settles on other shapes of the shoulder's girth).
//! 2. Down the tree, a beam search: each joint's value by a 1-D search (coarse grid, then fine
//!    around each of the best local maxima) scored by how many scan points the links it moves
//!    explain (points buried inside a link count against it; points another link explains
//!    count only where the moved links come nearer), with everything above it fixed; on the
//!    coarse keypoints, or on the fine ones where few coarse ones are in reach (a wrist). A
//!    link is only ever placed where its parent allows, which is what the independent alignment
//!    lacked. After each joint the decided links (those every joint above has been searched
//!    for) are settled by a few damped refinement steps, and the `beam_width` states whose
//!    decided links explain the most points go on: a joint misled by links below it that are
//!    still far off survives as a runner-up until those links decide; a state whose search
//!    finds nothing to score goes on with the joint where it is. From a start that is not
//!    global each base hypothesis's best state also goes on past the first joint (the base and
//!    one link are too little to judge a base by; `beam::keep_best`). The survivors are ranked
//!    after a few refinement steps, a survivor whose steps took a joint out of its window as it
//!    was before them. From a start neither
//!    near nor global the floor's points never count for the base in those scores (a base set
//!    down on the floor beside its place explains the floor under it), and count for the other
//!    links only where their surface faces up (not under an arm lying on the floor).
//! 3. All together: Gauss-Newton point-to-plane steps over the base pose and every joint, on
//!    cos-weighted points within a band that shrinks to `band_min_m`, each point assigned to
//!    its nearest link surface; the joints are searched once more near the answer
//!    (`search_passes`).
//! 4. Half turns: a joint whose window allows it is tried turned by pi with the joints below it
//!    searched again (a spherical wrist reaches the same poses as (a + pi, -b, c + pi)), and
//!    kept when the links that joint moves then explain more fine keypoints where the two
//!    states differ (`contrast_among`); after a round that kept a flip, another round. A base
//!    that is not round about the first joint is turned about its axis with that joint turned
//!    back (`base_turn_check`): the base's turn shows only on the base, and no step leaves it
//!    once the base's features lie beyond the band.
//! 5. Last, the same steps on every keypoint against the exact link surfaces; then, when delta
//!    exceeds 0.18 times the robot's radius, a second look (`second_look`) at each joint whose
//!    window reaches an eighth of a turn (after a global search a quarter turn, and at each
//!    joint that spins its own links in place): searched with its child over its window from
//!    the final state, each candidate refined and kept when it explains `min_link_points` more
//!    where it differs, and the half turns tried again when the look moved a joint. The
//!    half-turn states that were not kept give the `twin`, refined the same way before it is
//!    called ambiguous.
//! 6. The joints of the small links at the end of the chain (reaching at most 0.15 m from the
//!    axis, with at most 1500 fine keypoints near them that no other link explains: a wrist and
//!    its flange) are swept over a whole turn, coarse on the distance grids and then densely in
//!    a narrow band about the coarse peaks (`distal_sweep`; a value is taken when it explains
//!    more by the square root of what the state explains, or, where the scan pins the joint
//!    and does not pin it at the state, by 4 or by a gain most of the keypoints agree on), and
//!    everything is refined once more in a band of `polish_band_m` (5 mm), which the mixed
//!    pixels beside a small link's silhouette mostly miss.
//!
//! When delta is at most 0.18 of the robot's radius (at the start joints) the start is near:
//! the searches from it settle every joint in its basin, so the beam keeps `near_beam_width`
//! states and follows two values of a joint from each, the joints are searched
//! `near_search_passes` times, a joint that spins its own links in place keeps its value for
//! the refinements to settle (it is not searched with the next joint), and there is no second
//! look. The rigid alignment of the whole
//! robot ends with its exploration's run (coarse keypoints, down to its narrowest band) rather
//! than running again on the fine keypoints (`PcaOptions::fine_run`): with the joints still
//! wrong it cannot come closer, and the searches settle the base with them.
//!
//! When delta exceeds the robot's radius (at the start joints) the start is not local: the
//! robot may be turned by more than a radian and each joint be anywhere in a window of up to a
//! half turn. Two stages then change. The proximal links are detected anywhere the root may be
//! by point pair features ([`crate::registration::ppf`], every reference's vote merged) instead
//! of slid into place from the start; and each joint is searched together with its child on a
//! grid fine enough that the value nearest the truth puts their links within the band, scored
//! only on the links those two place (a joint whose two links turn in place about it, an upper
//! arm standing on the axis of a round shoulder, is searched after its child, together with its
//! grandchild).
//!
//! The searches and every refinement but the last ask each link's signed-distance grid (5 mm
//! cells, built once with the [`ArticulatedBody`]) instead of its mesh: a few memory reads
//! instead of a BVH descent, with a millimetre of blur at edges that the last refinement, on
//! the exact surfaces, removes.
//!
//! Nothing is invented: a joint whose links hold too few points, or whose motion the points do
//! not constrain (a cylinder turning about its own axis), keeps its start value and is reported.

mod base;
mod beam;
#[cfg(test)]
mod beam_tests;
mod checks;
mod context;
mod contrast;
mod distal;
#[cfg(test)]
mod floor_tests;
mod global_search;
mod joint_search;
mod options;
mod placed;
#[cfg(test)]
mod placed_tests;
mod refine;
#[cfg(test)]
mod refine_tests;
mod report;
mod standing;
#[cfg(test)]
mod tests;
mod tree;
mod uncertainty;

use std::time::Instant;

use nalgebra::{Isometry3, Point3};

use super::body::ArticulatedBody;
use crate::geometry::Mesh;
use crate::registration::pca::{PcaError, PcaOptions, align_cloud_pose, floor_plane};
use crate::registration::sampling::{voxel_representatives, without_isolated};
use base::round_base_axis;
use context::{FitContext, Keypoints};
use refine::refine;
use report::final_state;
use tree::search_order;

pub use options::RobotFitOptions;
pub use report::{JointFit, LinkFit, RobotFit, RobotTwin};

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RobotFitError {
    #[error("the cloud is empty")]
    EmptyCloud,
    #[error("cloud point {0} is not finite")]
    NonFinitePoint(usize),
    #[error("delta must be finite and > 0, got {0}")]
    BadDelta(f64),
    #[error("the robot has {expected} joints ({names}), {got} start values were given")]
    JointCount {
        expected: usize,
        got: usize,
        names: String,
    },
    #[error("start value {value} of joint '{joint}' is not finite")]
    NonFiniteJoint { joint: String, value: f64 },
    #[error("the base pose is not finite")]
    NonFiniteBase,
    #[error(
        "no cloud point lies within {reach_m} m of the start base position: is the base pose right?"
    )]
    NothingInReach { reach_m: f64 },
    #[error("aligning the whole robot at the start joints failed: {0}")]
    Base(PcaError),
}

fn check_inputs(
    body: &ArticulatedBody,
    cloud: &[Point3<f64>],
    world_from_root: &Isometry3<f64>,
    q0: &[f64],
    delta_m: f64,
) -> Result<(), RobotFitError> {
    if cloud.is_empty() {
        return Err(RobotFitError::EmptyCloud);
    }
    if let Some(index) = cloud
        .iter()
        .position(|p| !p.coords.iter().all(|c| c.is_finite()))
    {
        return Err(RobotFitError::NonFinitePoint(index));
    }
    if !(delta_m.is_finite() && delta_m > 0.0) {
        return Err(RobotFitError::BadDelta(delta_m));
    }
    let parameters = body.parameters();
    if q0.len() != parameters.len() {
        return Err(RobotFitError::JointCount {
            expected: parameters.len(),
            got: q0.len(),
            names: parameters
                .iter()
                .map(|p| p.name.as_str())
                .collect::<Vec<_>>()
                .join(", "),
        });
    }
    if let Some((value, parameter)) = q0
        .iter()
        .zip(parameters)
        .find(|(value, _)| !value.is_finite())
    {
        return Err(RobotFitError::NonFiniteJoint {
            joint: parameter.name.clone(),
            value: *value,
        });
    }
    let finite_base = world_from_root
        .translation
        .vector
        .iter()
        .all(|c| c.is_finite())
        && world_from_root
            .rotation
            .coords
            .iter()
            .all(|c| c.is_finite());
    if !finite_base {
        return Err(RobotFitError::NonFiniteBase);
    }
    Ok(())
}

/// Fits `body` to `cloud` (world frame) from the start base pose and joint values; `delta_m`
/// bounds how far any point of the robot is from where the start puts it.
pub fn align_robot(
    body: &ArticulatedBody,
    cloud: &[Point3<f64>],
    world_from_root_start: &Isometry3<f64>,
    q0: &[f64],
    delta_m: f64,
    options: &RobotFitOptions,
) -> Result<RobotFit, RobotFitError> {
    let started = Instant::now();
    check_inputs(body, cloud, world_from_root_start, q0, delta_m)?;
    let near = within_reach(body, cloud, world_from_root_start, delta_m, options)?;
    // The robot as one rigid mesh at the start (its tree built) does not depend on the scan:
    // made beside the scan's filtering and binning, mostly serial work.
    let (
        PreparedScan {
            near,
            keypoints,
            coarse,
        },
        start_mesh,
    ) = rayon::join(|| prepare_scan(near, options), || body.rigid_mesh(q0));
    let scan = Keypoints {
        coarse: &coarse,
        fine: &keypoints,
    };
    let global = start_mesh
        .as_ref()
        .is_some_and(|mesh| is_global(mesh, delta_m));
    let near_start = start_mesh
        .as_ref()
        .is_some_and(|mesh| delta_m <= NEAR_DELTA_PER_RADIUS * mesh.radius_m());
    // From a near start the exploration's run on the coarse keypoints brings the base near
    // enough: the searches and refinements that follow settle it with the joints, and the
    // rigid run on the fine keypoints took 10-30 ms of a 115 ms fit at 100 mm (a timing probe
    // of `articulated_starts`, docs/BENCHMARKS.md).
    let base_options = PcaOptions {
        fine_run: options.base.fine_run && !near_start,
        ..options.base.clone()
    };
    let whole = match &start_mesh {
        Some(mesh) => align_cloud_pose(mesh, &near, world_from_root_start, delta_m, &base_options)
            .map_err(RobotFitError::Base)?,
        None => *world_from_root_start,
    };
    // The floor's points, which a base set down on the floor beside its place explains as well
    // as its own, never count for the base in the beam's scores. A near start has one base
    // hypothesis, the whole robot's alignment, and no other place of the base to weigh
    // against it: its fit does without the plane search. Neither does the global search: its
    // base hypotheses are detected without the floor, and there, on the ABB IRB 1600 at 1000
    // mm, the floor-blind base lost one true place of 50 and a wrist (`robot-scans` seed 20,
    // scene 0 trial 0 and scene 1 trial 6; docs/articulated-trials.md).
    // The global search stands the base on the floor for more hypotheses all the same.
    let stand_on = start_mesh
        .as_ref()
        .filter(|_| !near_start)
        .and_then(|mesh| floor_plane(&coarse, mesh, 3.0 * options.voxel_m));
    let fit = FitContext {
        body,
        scan,
        delta_m,
        global,
        near: near_start,
        floor: stand_on.filter(|_| !global),
        stand_on,
        options,
    };
    let round_base = round_base_axis(body, q0, options);
    let mut hypotheses = vec![whole];
    hypotheses.extend(fit.proximal_candidates(
        &near,
        world_from_root_start,
        q0,
        round_base.as_ref(),
        &[whole],
    ));
    let (mut world_from_root, mut q) = fit.beam_search(&hypotheses, q0);
    // Until the last refinement the surfaces come from the links' distance grids: a
    // millimetre of blur at edges costs nothing while the joints are still being searched.
    let band0 = options.refine_band0_m();
    let coarse_refine = RobotFitOptions {
        max_iterations: 15,
        ..options.clone()
    };
    let mut iterations = refine(
        body,
        &coarse,
        &mut world_from_root,
        &mut q,
        band0,
        &coarse_refine,
        false,
    );
    // Again with every joint near: a joint searched while the links below it were far off is
    // searched once more.
    let passes = if near_start {
        options.near_search_passes
    } else {
        options.search_passes
    };
    for _ in 1..passes.max(1) {
        for parameter in search_order(body) {
            fit.search_joint(&world_from_root, &mut q, parameter);
        }
        iterations += refine(
            body,
            &coarse,
            &mut world_from_root,
            &mut q,
            band0,
            &coarse_refine,
            false,
        );
    }
    let (spent, mut others) = fit.flip_check(&mut world_from_root, &mut q);
    iterations += spent;
    if round_base.is_none() {
        iterations += fit.base_turn_check(&mut world_from_root, &mut q);
    }
    // Last, every keypoint against the exact surfaces, in the narrow band the refinements
    // before ended in (the state is within it).
    let refine_exactly = |world_from_root: &mut Isometry3<f64>, q: &mut Vec<f64>| {
        refine(
            body,
            &keypoints,
            world_from_root,
            q,
            options.band_min_m,
            options,
            true,
        )
    };
    iterations += refine_exactly(&mut world_from_root, &mut q);
    // From a near start the searches settle every joint in its basin (every trial measured):
    // the look would only cost time there. (A global start is never near.)
    if start_mesh.is_some() && !near_start {
        let looked_from = q.clone();
        iterations += fit.second_look(&mut world_from_root, &mut q);
        // A look that moved a joint may have moved a wrist to the true pose's twin (a
        // candidate of the elbow on the ABB IRB 1600 at 500 mm, trial 0), which the half turns
        // tried before the look cannot repair: they are tried again from where it ended.
        if q != looked_from {
            let flipped_from = q.clone();
            let (spent, more) = fit.flip_check(&mut world_from_root, &mut q);
            iterations += spent;
            others.extend(more);
            if q != flipped_from {
                iterations += refine_exactly(&mut world_from_root, &mut q);
            }
        }
    }
    // The small links at the end of the chain, swept densely in a narrow band: the searches and
    // refinements before leave them within their wide bands (`distal`).
    if start_mesh.is_some() && options.distal_sweep {
        iterations += fit.distal_sweep(&mut world_from_root, &mut q);
    }
    // Last, every link in a band a few noise widths wide: the mixed pixels a scanner leaves
    // beside silhouettes lie within the last band (a centimetre), and on a wrist of 60-120
    // keypoints they pulled joint 5 0.02 rad off (crates/cad-scans, `robot-scans`).
    if options.polish_band_m > 0.0 {
        // It starts converged: a few steps settle it.
        let polish = RobotFitOptions {
            band_min_m: options.polish_band_m,
            max_iterations: POLISH_ITERATIONS,
            ..options.clone()
        };
        iterations += refine(
            body,
            &keypoints,
            &mut world_from_root,
            &mut q,
            options.polish_band_m,
            &polish,
            true,
        );
    }
    // What the final state explains, once: the stages before only move it.
    let report::FinalState {
        matches,
        links,
        observed,
    } = final_state(body, &keypoints, &world_from_root, &q, options);
    for (parameter, seen) in observed.iter().enumerate() {
        if !seen {
            q[parameter] = q0[parameter];
        }
    }
    // A joint the scan does not show is not what tells a twin apart.
    for (_, other) in &mut others {
        for (parameter, seen) in observed.iter().enumerate() {
            if !seen {
                other[parameter] = q0[parameter];
            }
        }
    }
    let twin = fit.twin(&world_from_root, &q, &others, &observed);
    let with_base = round_base
        .and(search_order(body).first().copied())
        .filter(|&first| observed[first]);
    let placed = placed::Placed::new(body, &world_from_root, &q);
    let intervals = uncertainty::joint_intervals_95(body, &placed, &matches, &observed);
    let joints = body
        .parameters()
        .iter()
        .zip(&q)
        .zip(&observed)
        .zip(intervals)
        .enumerate()
        .map(|(index, (((parameter, &value), &observed), within_95))| {
            let turns_with_base = with_base == Some(index);
            JointFit {
                name: parameter.name.clone(),
                value,
                observed,
                turns_with_base,
                // The scan fixes the base's yaw plus this value, not each.
                within_95: within_95.filter(|_| !turns_with_base),
            }
        })
        .collect();
    let sum: f64 = matches.iter().map(|m| m.distance * m.distance).sum();
    Ok(RobotFit {
        world_from_root,
        q,
        links,
        joints,
        iterations,
        rms_m: (sum / matches.len().max(1) as f64).sqrt(),
        time_s: started.elapsed().as_secs_f64(),
        twin,
    })
}

/// The cloud's points that the robot can reach from where the start puts it: within its reach
/// of the root grown by twice delta and the narrow band.
fn within_reach(
    body: &ArticulatedBody,
    cloud: &[Point3<f64>],
    world_from_root_start: &Isometry3<f64>,
    delta_m: f64,
    options: &RobotFitOptions,
) -> Result<Vec<Point3<f64>>, RobotFitError> {
    let root = world_from_root_start * Point3::origin();
    let reach = body.max_reach_m() + 2.0 * delta_m + options.band_min_m;
    let near: Vec<Point3<f64>> = cloud
        .iter()
        .filter(|p| (*p - root).norm() <= reach)
        .copied()
        .collect();
    if near.is_empty() {
        return Err(RobotFitError::NothingInReach { reach_m: reach });
    }
    Ok(near)
}

/// The points in reach without the isolated returns, and their keypoints.
struct PreparedScan {
    near: Vec<Point3<f64>>,
    /// One per voxel of `voxel_m`.
    keypoints: Vec<Point3<f64>>,
    /// One per voxel of three times `voxel_m`.
    coarse: Vec<Point3<f64>>,
}

/// The points in reach without the isolated returns, and their fine and coarse keypoints.
fn prepare_scan(near: Vec<Point3<f64>>, options: &RobotFitOptions) -> PreparedScan {
    // A scan too sparse for the voxel (most points isolated) is kept whole: its strays
    // cannot be told from its surfaces that way.
    let crowded = without_isolated(&near, options.voxel_m, options.isolated_min_neighbours);
    let near = if 2 * crowded.len() >= near.len() {
        crowded
    } else {
        near
    };
    let (keypoints, coarse) = rayon::join(
        || voxel_representatives(&near, options.voxel_m),
        || voxel_representatives(&near, options.voxel_m * 3.0),
    );
    PreparedScan {
        near,
        keypoints,
        coarse,
    }
}

/// Which joints the scan pins with the robot at `world_from_root` and `q`, judged as
/// [`align_robot`] judges the state it ends in (the same keypoints from the same start and
/// delta, the same test; see [`JointFit::observed`]). For trials that know the truth: a joint
/// the fit reports unseen that the scan does not pin at the true pose either is one the scan
/// does not show; one it pins there is one the fit lost.
pub fn observed_joints_at(
    body: &ArticulatedBody,
    cloud: &[Point3<f64>],
    world_from_root_start: &Isometry3<f64>,
    delta_m: f64,
    world_from_root: &Isometry3<f64>,
    q: &[f64],
    options: &RobotFitOptions,
) -> Result<Vec<bool>, RobotFitError> {
    check_inputs(body, cloud, world_from_root_start, q, delta_m)?;
    let near = within_reach(body, cloud, world_from_root_start, delta_m, options)?;
    let keypoints = prepare_scan(near, options).keypoints;
    Ok(final_state(body, &keypoints, world_from_root, q, options).observed)
}

/// True when [`align_robot`] treats a start as not local and searches globally (detects the
/// proximal links, searches each joint with its child over its whole window): when delta
/// exceeds the robot's radius at the start joints, the robot may be turned by more than a
/// radian and its joints be anywhere in windows of up to a half turn each way.
pub fn searches_globally(body: &ArticulatedBody, q0: &[f64], delta_m: f64) -> bool {
    body.rigid_mesh(q0)
        .is_some_and(|mesh| is_global(&mesh, delta_m))
}

fn is_global(robot_at_start: &Mesh, delta_m: f64) -> bool {
    delta_m > GLOBAL_DELTA_PER_RADIUS * robot_at_start.radius_m()
}

/// The start is taken as not local when delta exceeds this fraction of the robot's radius at
/// the start joints (see [`align_robot`]): turns of the whole robot by more than a radian.
const GLOBAL_DELTA_PER_RADIUS: f64 = 1.0;

/// A start is near when delta is at most this fraction of the robot's radius at the start
/// joints: the searches from it settle every joint in its basin, so the fit searches with a
/// narrower beam (`near_beam_width` states, [`NEAR_PEAKS_PER_STATE`] values of a joint from
/// each), `near_search_passes` passes and no second look (`second_look`). The ABB IRB 1600
/// (radius 1.0 m) needed the look in 3 of 10 trials at 500 mm and in 4 of 50 at 200 mm
/// (docs/articulated-trials.md); none of 50 at 100 mm did. At 100 mm the look cost the UR10
/// 10-15% of its fit (`articulated_starts` bench) for nothing: the shipped robots' radii
/// (between 0.56 and 0.67 m) put 100 mm below this fraction. The narrower search: every link
/// 50/50 at 50 and 100 mm on the UR10, the iiwa14 and the ABB (docs/articulated-trials.md).
const NEAR_DELTA_PER_RADIUS: f64 = 0.18;

/// Iterations of the last refinement in the narrow band (`polish_band_m`).
const POLISH_ITERATIONS: usize = 8;

/// Values of a joint the beam search follows from each of its states when the start is near
/// (see [`NEAR_DELTA_PER_RADIUS`]).
const NEAR_PEAKS_PER_STATE: usize = 2;
