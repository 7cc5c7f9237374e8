//! Base hypotheses beyond the whole robot's rigid alignment: the proximal links aligned or
//! detected on their own, and a round base turned to the start's angle.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};

use super::RobotFitOptions;
use super::context::FitContext;
use super::tree::{axis_of, search_order, turns_in_place};
use crate::registration::articulated::body::{ArticulatedBody, JointAxis};
use crate::registration::convergence::pose_distance;
use crate::registration::pca::{
    pose_candidates, pose_candidates_spread, without_floor_under, without_planes_larger_than,
};
use crate::registration::ppf::ppf_poses;
use crate::registration::sampling::voxel_representatives;

impl FitContext<'_> {
    /// Base poses from rigid alignments of the proximal links (the base and the links only the
    /// first joint moves) when the start may be off by more than they are big; none otherwise. A
    /// base that looks the same at every angle about the first joint is turned to the start's
    /// angle about it: the scan cannot tell, and the joints below start nearest their own values.
    /// Where the scan shows a floor, the base stood on it where the scan's points vote for it
    /// ([`Self::standing_candidates`]), at places neither these nor `held` (the hypotheses
    /// held already) hold.
    pub(super) fn proximal_candidates(
        &self,
        cloud: &[Point3<f64>],
        world_from_root_start: &Isometry3<f64>,
        q0: &[f64],
        round_base: Option<&JointAxis>,
        held: &[Isometry3<f64>],
    ) -> Vec<Isometry3<f64>> {
        let FitContext {
            body,
            delta_m,
            global,
            near,
            options,
            ..
        } = *self;
        // A near start (see `NEAR_DELTA_PER_RADIUS`) never pays for the candidates, nor for the
        // proximal links' mesh: on the ABB IRB 1600 (7.8k triangles) building it took 6 ms of a
        // 100 mm fit (a timing probe, docs/BENCHMARKS.md).
        if options.base_candidates == 0 || near {
            return Vec::new();
        }
        let first = search_order(body).first().copied();
        let proximal: Vec<usize> = (0..body.links().len())
            .filter(|&l| body.movers(l).iter().all(|p| Some(*p) == first))
            .collect();
        let Some(mesh) = body.rigid_mesh_of(q0, &proximal) else {
            return Vec::new();
        };
        // For small deltas the whole robot's rigid alignment finds the proximal links' place; for
        // larger ones the other links, still at the wrong joint values, may pull it away. The
        // line was first set at three quarters of the proximal links' radius, from exploratory
        // runs where failures began near delta = radius. The ABB IRB 1600's base and first link
        // are 0.56 m in radius: at 200 mm the whole robot's alignment left its base 88 mm above
        // the floor in a ray-cast scan (`robot-scans --seed 77`, scene 2 trial 5), the only
        // hypothesis, out of reach of every stage after it. Now the line is a third of the
        // radius.
        if delta_m <= PROXIMAL_DELTA_PER_RADIUS * mesh.radius_m() {
            return Vec::new();
        }
        // The root moves by up to about twice delta (the robot turns about its centroid).
        let root_bound_m = 2.0 * delta_m;
        // A start that is not local has nothing near it to slide into place from: the links are
        // detected anywhere the root may be.
        let candidates: Vec<Isometry3<f64>> = if global {
            // The links no joint moves are where the root is, whatever the joints are: unless
            // they look the same at every angle about the first joint, they are detected alone.
            // With the first joint's link in the model at the start's value (at 1000 mm up to
            // a half turn off), its points voted for poses between that and the truth: on the
            // ABB IRB 1600 at 1000 mm (`robot-scans`, crates/cad-scans) the base was lost in 1
            // of 10 fits that way and in none of them detected alone (docs/articulated-trials.md).
            // A round base (the UR10's, the iiwa 14's) shows its turn only with that link.
            let base_alone = round_base.is_none().then(|| body.fixed_mesh(q0)).flatten();
            let detected_mesh = base_alone.as_ref().unwrap_or(&mesh);
            // A ray-cast scan's floor reaches metres around the robot: most of the detection's
            // references then lie on it, and the pairs they make with the robot's points vote
            // for poses of their own. In scenes 0, 1 and 3 of `robot-scans` at 1000 mm none of
            // the 40 best-voted poses of the ABB's base and link_1 lay within 0.1 m of the
            // truth; without the floor, the best-voted pose lay 22-166 mm from it (a probe, not
            // kept). No plane larger than the base and the first joint's link can be them.
            let step_m = options.detection.step_m;
            let mut scene =
                without_planes_larger_than(voxel_representatives(cloud, step_m), &mesh, step_m);
            // A floor too small for that test still outvotes a base detected alone: on the
            // project's own scans of the ABB its base was detected 0.4 m off, and 10 mm off
            // without the floor under it (`ppf_detection` bench); the fit found 49 of 50 at
            // 1000 mm, and finds 50 now (docs/articulated-trials.md).
            if let Some(base) = &base_alone {
                scene = without_floor_under(scene, base, step_m);
            }
            ppf_poses(
                detected_mesh,
                &scene,
                &(world_from_root_start * Point3::origin()),
                root_bound_m,
                &options.detection,
                options.detected_bases,
                DISTINCT_DETECTION_RAD,
            )
            .into_iter()
            .map(|pose| pose.world_from_model)
            .collect()
        } else {
            // The exploration's runs start where the start puts the links, turned; the spread's at
            // translations of it (the start may be off by more than the links are big). Each finds
            // the links where the other does not: with the exploration alone the ABB IRB 1600's
            // boxy base was lost in 9 of 10 trials at 500 mm (docs/articulated-trials.md); the
            // spread alone lost 3 of 50 UR10 trials at 500 mm in an exploratory build (sparser
            // screening keypoints) that the exploration finds.
            [pose_candidates_spread, pose_candidates]
                .into_iter()
                .flat_map(|candidates| {
                    candidates(
                        &mesh,
                        cloud,
                        world_from_root_start,
                        root_bound_m,
                        &options.proximal,
                        options.base_candidates,
                        DISTINCT_BASE_M,
                    )
                })
                .collect()
        };
        let standing = self.standing_candidates(
            world_from_root_start,
            q0,
            root_bound_m,
            round_base,
            options.base_candidates,
        );
        let turned = |poses: Vec<Isometry3<f64>>| match round_base {
            Some(axis) => poses
                .iter()
                .map(|c| turned_towards(c, world_from_root_start, axis))
                .collect(),
            None => poses,
        };
        let mut candidates = turned(candidates);
        // A place held already gains nothing from its standing twin but a state that differs by
        // a hair: on the ABB IRB 1600 (`robot-scans --seed 77`, scene 4 trial 0 at 500 mm), whose
        // whole-robot alignment found the base, such a twin won the beam with the wrist 0.05
        // rad off, where the scan hardly pins it.
        for stood in turned(standing) {
            let held = held
                .iter()
                .chain(&candidates)
                .any(|c| pose_distance(c, &stood, mesh.radius_m()) <= DISTINCT_BASE_M);
            if !held {
                candidates.push(stood);
            }
        }
        candidates
    }
}

/// The first joint's axis (root frame) when the links no joint moves look the same at every
/// angle about it (a round base): the scan then shows the base's turn about that axis and the
/// joint's value only as their sum.
pub(super) fn round_base_axis(
    body: &ArticulatedBody,
    q0: &[f64],
    options: &RobotFitOptions,
) -> Option<JointAxis> {
    let first = *search_order(body).first()?;
    let root_poses = body.link_poses(&Isometry3::identity(), q0);
    let axis = axis_of(body, &root_poses, first)?;
    let fixed: Vec<usize> = (0..body.links().len())
        .filter(|&l| body.movers(l).is_empty())
        .collect();
    (!axis.prismatic && turns_in_place(body, &root_poses, &fixed, &axis, options.min_observability))
        .then_some(axis)
}

/// Proximal candidates are searched when delta exceeds this fraction of the proximal links'
/// radius and the start is not near (see [`FitContext::proximal_candidates`]).
const PROXIMAL_DELTA_PER_RADIUS: f64 = 1.0 / 3.0;

/// Base candidates closer than this (thesis pose distance) are one.
const DISTINCT_BASE_M: f64 = 0.05;

/// Detected base poses that turn the proximal links by less than this are one (and no closer
/// than two detection steps).
const DISTINCT_DETECTION_RAD: f64 = 0.3;

/// `world_from_root` turned about `axis` (root frame) to the orientation nearest `towards`'s:
/// the turn a base that looks the same at every angle about its first joint cannot show.
pub(super) fn turned_towards(
    world_from_root: &Isometry3<f64>,
    towards: &Isometry3<f64>,
    axis: &JointAxis,
) -> Isometry3<f64> {
    let wanted = world_from_root.rotation.inverse() * towards.rotation;
    let direction = axis.axis.normalize();
    let angle = 2.0
        * wanted
            .quaternion()
            .vector()
            .dot(&direction)
            .atan2(wanted.quaternion().w);
    let about = Translation3::from(axis.origin.coords);
    *world_from_root * about * UnitQuaternion::from_scaled_axis(direction * angle) * about.inverse()
}
