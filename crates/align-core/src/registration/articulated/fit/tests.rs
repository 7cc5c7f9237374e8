//! Unit tests of the fit's stages on small robots of primitives and on the shipped UR10.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use super::base::{round_base_axis, turned_towards};
use super::context::{FitContext, Keypoints};
use super::contrast::{SAMPLES_PER_LINK, placed_apart};
use super::distal::{fine_values, highest_peaks};
use super::joint_search::{SweptTubes, distinct_values, spread_scores};
use super::placed::{Distances, Placed};
use super::tree::Window;
use super::{RobotFitOptions, align_robot};
use crate::geometry::{Mesh, SurfacePoint};
use crate::kinematics::{PackageMap, RobotModel};
use crate::registration::articulated::body::{ArticulatedBody, JointAxis};
use crate::registration::sampling::voxel_representatives;
use crate::robots::ShippedRobot;
use crate::trials::robot_scan::{RobotScanOptions, scan_robot};
use crate::trials::{TrialRng, random_displacement};

/// A robot of primitives whose wrist turns between the two plates of its forearm's fork, a
/// millimetre from each (as an industrial robot's wrist sits in its forearm), with a flange
/// of 20 mm radius beyond it.
pub(super) const FORKED_WRIST_URDF: &str = r#"<robot name="forked_wrist">
  <link name="base"><visual><origin xyz="0 0 0.15"/><geometry><box size="0.4 0.4 0.3"/></geometry></visual></link>
  <link name="column"><visual><origin xyz="0.05 0 0.1"/><geometry><box size="0.3 0.25 0.2"/></geometry></visual></link>
  <link name="upper_arm"><visual><origin xyz="0 0 0.3"/><geometry><box size="0.1 0.12 0.6"/></geometry></visual></link>
  <link name="elbow"><visual><origin xyz="0.05 0 0"/><geometry><box size="0.2 0.14 0.14"/></geometry></visual></link>
  <link name="forearm">
    <visual><origin xyz="0.2 0 0" rpy="0 1.5707963 0"/><geometry><cylinder radius="0.045" length="0.4"/></geometry></visual>
    <visual><origin xyz="0.43 0.041 0"/><geometry><box size="0.06 0.01 0.06"/></geometry></visual>
    <visual><origin xyz="0.43 -0.041 0"/><geometry><box size="0.06 0.01 0.06"/></geometry></visual>
  </link>
  <link name="wrist"><visual><origin rpy="1.5707963 0 0"/><geometry><cylinder radius="0.028" length="0.07"/></geometry></visual></link>
  <link name="flange"><visual><origin xyz="0.025 0 0" rpy="0 1.5707963 0"/><geometry><cylinder radius="0.02" length="0.05"/></geometry></visual></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="column"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="column"/><child link="upper_arm"/>
    <origin xyz="0 0 0.2"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="upper_arm"/><child link="elbow"/>
    <origin xyz="0 0 0.6"/><axis xyz="0 1 0"/><limit lower="-2.5" upper="2.5" effort="1" velocity="1"/></joint>
  <joint name="j4" type="revolute"><parent link="elbow"/><child link="forearm"/>
    <origin xyz="0.15 0 0"/><axis xyz="1 0 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j5" type="revolute"><parent link="forearm"/><child link="wrist"/>
    <origin xyz="0.43 0 0"/><axis xyz="0 1 0"/><limit lower="-2.1" upper="2.1" effort="1" velocity="1"/></joint>
  <joint name="j6" type="revolute"><parent link="wrist"/><child link="flange"/>
    <origin xyz="0.028 0 0"/><axis xyz="1 0 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
</robot>"#;

#[test]
fn a_wrist_nested_in_its_forearms_fork_keeps_the_points_nearer_to_it() {
    let model = RobotModel::from_urdf_str(FORKED_WRIST_URDF, &PackageMap::new()).unwrap();
    let body = ArticulatedBody::from_model(&model).unwrap();
    let world_from_root = Isometry3::translation(0.2, -0.1, 0.0);
    let q_true = [0.0, 0.3, 0.4, 0.0, 0.6, 0.0];
    let cloud = scan_robot(
        &body,
        &world_from_root,
        &q_true,
        &RobotScanOptions::default(),
    );
    let options = RobotFitOptions::default();
    let fine = voxel_representatives(&cloud, options.voxel_m);
    let wrist_joint = 4;
    let moved = body.moved_by(wrist_joint);
    let others: Vec<usize> = (0..body.links().len())
        .filter(|link| !moved.contains(link))
        .collect();
    let placed = Placed::new(&body, &world_from_root, &q_true);
    let band = 3.0 * options.voxel_m;
    let on_wrist: Vec<&Point3<f64>> = fine
        .iter()
        .filter(|p| placed.supports(p, 0.002, &moved))
        .collect();
    let claimed: Vec<f64> = on_wrist
        .iter()
        .map(|p| {
            placed
                .distance_within(p, band, &others)
                .unwrap_or(f64::INFINITY)
        })
        .collect();
    // The fixture is what it says: the fork comes within the band of a third of the wrist's
    // points (of four fifths on the ABB IRB 1600's, where this was found).
    let within_band = claimed.iter().filter(|c| c.is_finite()).count();
    assert!(
        on_wrist.len() > 100 && 3 * within_band > on_wrist.len(),
        "{within_band} of {} wrist points near the fork",
        on_wrist.len()
    );
    // At the true value nearly all of them count for the wrist: they lie nearer to it.
    let counted: i64 = on_wrist
        .iter()
        .zip(&claimed)
        .map(|(p, &c)| placed.evidence_nearer(p, band, band, c, &moved))
        .sum();
    assert!(
        counted as f64 >= 0.9 * on_wrist.len() as f64,
        "{counted} of {} wrist points counted",
        on_wrist.len()
    );
    // And the fit finds the wrist from a radian away. (With every point near the fork taken
    // away it did here too, on the points left; on the ABB's wrist, where four fifths were
    // taken, it did not: 4 of 10 trials at 200 mm, docs/articulated-trials.md.)
    let mut q0 = q_true.to_vec();
    q0[wrist_joint] -= 1.0;
    let fit = align_robot(&body, &cloud, &world_from_root, &q0, 0.2, &options).unwrap();
    assert!(
        (fit.q[wrist_joint] - q_true[wrist_joint]).abs() < 0.01,
        "{:?}",
        fit.q
    );
}

#[test]
fn a_square_base_turned_with_joint_1_making_up_for_it_is_turned_back() {
    let model = RobotModel::from_urdf_str(FORKED_WRIST_URDF, &PackageMap::new()).unwrap();
    let body = ArticulatedBody::from_model(&model).unwrap();
    let options = RobotFitOptions::default();
    assert!(round_base_axis(&body, &[0.0; 6], &options).is_none());
    let truth = Isometry3::translation(0.2, -0.1, 0.0);
    let q_true = vec![0.0, 0.3, 0.4, 0.0, 0.6, 0.0];
    let cloud = scan_robot(&body, &truth, &q_true, &RobotScanOptions::default());
    let fine = voxel_representatives(&cloud, options.voxel_m);
    let coarse = voxel_representatives(&cloud, options.voxel_m * 3.0);
    let scan = Keypoints {
        coarse: &coarse,
        fine: &fine,
    };
    // The base turned by 0.25 rad about joint 1's axis (z through the root) and joint 1
    // turned back: every link above the base where it is, the base's corners 50 mm off.
    let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.25);
    let mut base = Isometry3::from_parts(truth.translation, turn * truth.rotation);
    let mut q = q_true.clone();
    q[0] -= 0.25;
    let above_true = body.link_poses(&truth, &q_true);
    let above_start = body.link_poses(&base, &q);
    assert!((above_true[1].translation.vector - above_start[1].translation.vector).norm() < 1e-9);
    let fit = FitContext {
        body: &body,
        scan,
        delta_m: 0.5,
        global: false,
        near: false,
        floor: None,
        stand_on: None,
        options: &options,
    };
    fit.base_turn_check(&mut base, &mut q);
    let yaw_error = base.rotation.angle_to(&truth.rotation);
    assert!(yaw_error < 0.01, "base still {yaw_error} rad off");
    assert!((q[0] - q_true[0]).abs() < 0.01, "joint 1 at {}", q[0]);
    // At the truth there is nothing to turn back.
    let mut still = truth;
    let mut still_q = q_true.clone();
    assert_eq!(fit.base_turn_check(&mut still, &mut still_q), 0);
    assert_eq!(still, truth);
}

#[test]
fn a_grid_clamped_at_a_limit_is_scored_once_per_value_and_spread_back() {
    let grid = vec![-2.0, -2.0, -2.0, -1.5, -1.0, 2.0, 2.0];
    let distinct = distinct_values(grid.clone());
    assert_eq!(distinct, vec![-2.0, -1.5, -1.0, 2.0]);
    let scores: Vec<i64> = distinct.iter().map(|v| (v * 10.0) as i64).collect();
    assert_eq!(
        spread_scores(&grid, &distinct, &scores),
        vec![-20, -20, -20, -15, -10, 20, 20]
    );
}

/// The closest point of `surface` to a random point of the cube twice its radius about its
/// centroid: points all over a link, the faces it shows most drawn most often.
pub(super) fn random_surface_point(surface: &Mesh, rng: &mut TrialRng) -> SurfacePoint {
    surface.closest_point(&Point3::from(
        surface.centroid().coords
            + Vector3::new(
                rng.uniform() - 0.5,
                rng.uniform() - 0.5,
                rng.uniform() - 0.5,
            ) * surface.radius_m()
                * 2.0,
    ))
}

#[test]
fn the_grids_only_rule_links_out_of_exact_queries_and_approximate_the_rest_closely() {
    let body = ArticulatedBody::from_model(&ShippedRobot::Ur10.model().unwrap()).unwrap();
    let meshes_only = body.without_grids();
    let base = Isometry3::translation(0.2, -0.1, 0.0);
    let q = ShippedRobot::Ur10.home();
    let with_grids = Placed::new(&body, &base, &q);
    let exact = Placed::new(&meshes_only, &base, &q);
    let mut approximate = Placed::new(&body, &base, &q);
    approximate.exact = false;
    let all: Vec<usize> = (0..body.links().len()).collect();
    let mut rng = TrialRng::new(5);
    let (mut matched, mut worst_m) = (0, 0.0f64);
    for _ in 0..20_000 {
        // Points around the links' surfaces, within and beyond the bands asked for.
        let link = 1 + (rng.uniform() * (body.links().len() - 1) as f64) as usize;
        let Some(surface) = &body.links()[link].surface else {
            continue;
        };
        let on = random_surface_point(surface, &mut rng);
        let offset = (rng.uniform() - 0.3) * 0.05;
        let point = with_grids.poses[link] * (on.point + on.normal * offset);
        for band in [0.01, 0.018, 0.036] {
            let pruned = with_grids.nearest(&point, band, &all);
            let reference = exact.nearest(&point, band, &all);
            assert_eq!(
                pruned.map(|m| (m.link, m.distance.to_bits())),
                reference.map(|m| (m.link, m.distance.to_bits())),
                "{point} band {band}"
            );
            // Off the grid's blur at edges, the approximate answer is the same surface.
            if let (Some(a), Some(r)) = (approximate.nearest(&point, band, &all), reference)
                && a.link == r.link
            {
                matched += 1;
                worst_m = worst_m.max((a.distance - r.distance).abs());
            }
        }
    }
    assert!(matched > 20_000, "{matched}");
    // A cell diagonal (8.7 mm) bounds the interpolation error of a distance field; near
    // these links' edges it stays under 3 mm (1.9 mm on this seeded sample).
    assert!(worst_m < 0.003, "{worst_m}");
}

#[test]
fn a_base_turned_about_its_first_axis_takes_the_start_angle_and_keeps_the_axis() {
    // The first joint's axis in the root frame: vertical, through (0.1, 0, 0).
    let axis = JointAxis {
        origin: Point3::new(0.1, 0.0, 0.0),
        axis: Vector3::z(),
        prismatic: false,
    };
    let start = Isometry3::from_parts(
        Translation3::new(0.5, -0.2, 0.0),
        UnitQuaternion::from_euler_angles(0.05, 0.0, 0.3),
    );
    // A candidate at the right place, tilted a little differently and turned 2 rad about
    // the axis.
    let candidate = Isometry3::from_parts(
        Translation3::new(0.52, -0.21, 0.01),
        UnitQuaternion::from_euler_angles(0.02, 0.01, 0.3),
    ) * Isometry3::translation(0.1, 0.0, 0.0)
        * Isometry3::rotation(Vector3::z() * 2.0)
        * Isometry3::translation(-0.1, 0.0, 0.0);
    let turned = turned_towards(&candidate, &start, &axis);
    // Points on the axis stay where they were.
    for height in [0.0, 0.3] {
        let on_axis = Point3::new(0.1, 0.0, height);
        assert!((turned * on_axis - candidate * on_axis).norm() < 1e-12);
    }
    // The turn left is the tilt only (about 0.03 rad), not the 2 rad about the axis.
    assert!(turned.rotation.angle_to(&start.rotation) < 0.05);
    assert!(candidate.rotation.angle_to(&start.rotation) > 1.9);
}

/// The forked-wrist robot with a box on its wrist, on the side away from joint 5's axis: under
/// the wrist's half turn (joint 4 + pi, joint 5 mirrored, joint 6 + pi) every other link and
/// the flange stay where they are and only the box moves, to the other side.
fn keyed_wrist_urdf(key_size_m: f64) -> String {
    FORKED_WRIST_URDF.replace(
        r#"<link name="wrist"><visual><origin rpy="1.5707963 0 0"/><geometry><cylinder radius="0.028" length="0.07"/></geometry></visual></link>"#,
        &format!(
            r#"<link name="wrist"><visual><origin rpy="1.5707963 0 0"/><geometry><cylinder radius="0.028" length="0.07"/></geometry></visual>
    <visual><origin xyz="0 0 {z}"/><geometry><box size="{s} {s} {s}"/></geometry></visual></link>"#,
            z = 0.028 + key_size_m / 2.0,
            s = key_size_m
        ),
    )
}

/// The robot of [`keyed_wrist_urdf`] scanned at `truth` with joints `q_true`, and a fit
/// context (delta 0.5 m) on the scan's keypoints for `run`.
fn with_keyed_wrist_scan<R>(
    key_size_m: f64,
    truth: &Isometry3<f64>,
    q_true: &[f64],
    global: bool,
    run: impl FnOnce(&FitContext) -> R,
) -> R {
    let options = RobotFitOptions::default();
    let urdf = keyed_wrist_urdf(key_size_m);
    let model = RobotModel::from_urdf_str(&urdf, &PackageMap::new()).unwrap();
    let body = ArticulatedBody::from_model(&model).unwrap();
    let cloud = scan_robot(&body, truth, q_true, &RobotScanOptions::default());
    let fine = voxel_representatives(&cloud, options.voxel_m);
    let coarse = voxel_representatives(&cloud, options.voxel_m * 3.0);
    run(&FitContext {
        body: &body,
        scan: Keypoints {
            coarse: &coarse,
            fine: &fine,
        },
        delta_m: 0.5,
        global,
        near: false,
        floor: None,
        stand_on: None,
        options: &options,
    })
}

#[test]
fn a_wrist_twin_is_reported_ambiguous_only_when_the_scan_barely_tells_it_apart() {
    let truth = Isometry3::translation(0.2, -0.1, 0.0);
    let q_true = vec![0.0, 0.3, 0.4, 0.2, 0.6, 0.3];
    let mut twin_q = q_true.clone();
    twin_q[3] += PI;
    twin_q[4] = -twin_q[4];
    twin_q[5] -= PI;
    let twin_of = |key_size_m: f64| {
        with_keyed_wrist_scan(key_size_m, &truth, &q_true, true, |fit| {
            let body = fit.body;
            let flange = body
                .links()
                .iter()
                .position(|l| l.name == "flange")
                .unwrap();
            let (at_fit, at_twin) = (
                body.link_poses(&truth, &q_true),
                body.link_poses(&truth, &twin_q),
            );
            let mesh = body.links()[flange].surface.as_ref().unwrap();
            assert!(mesh.deviation_m(&at_fit[flange], &at_twin[flange]) < 1e-6);
            let observed = vec![true; q_true.len()];
            // The round flange spun half a turn leaves every link's surface where it was, but
            // moves the flange's vertices: not the fit's state (nor is the twin).
            let mut spun_q = q_true.clone();
            spun_q[5] += PI;
            let at_spun = body.link_poses(&truth, &spun_q);
            for ((link, at), spun) in body.links().iter().zip(&at_fit).zip(&at_spun) {
                if let Some(surface) = &link.surface {
                    assert!(surface.deviation_m(at, spun) < 1e-6, "{}", link.name);
                }
            }
            for other in [&spun_q, &twin_q] {
                assert!(!fit.vertices_within(
                    (&truth, &q_true),
                    (&truth, other),
                    fit.options.voxel_m
                ));
            }
            // The state it started from, identical to the fit, is no twin.
            assert_eq!(
                fit.twin(&truth, &q_true, &[(truth, q_true.clone())], &observed),
                None
            );
            // Nor is a copy a few millimetres off, the fit at the keypoints' resolution: scored as
            // it is, it explains nearly as much and would be called ambiguous.
            let mut near_q = q_true.clone();
            near_q[2] += 0.004;
            let (fit_there, near_there) =
                fit.contrast((&truth, &q_true), (&truth, &near_q)).unwrap();
            assert!(fit_there - near_there < 12, "{fit_there} {near_there}");
            assert_eq!(
                fit.twin(&truth, &q_true, &[(truth, near_q.clone())], &observed),
                None
            );
            // Within a keypoint voxel at every vertex, it is not even refined.
            assert!(fit.vertices_within((&truth, &q_true), (&truth, &near_q), fit.options.voxel_m));
            fit.twin(
                &truth,
                &q_true,
                &[(truth, q_true.clone()), (truth, twin_q.clone())],
                &observed,
            )
            .unwrap()
        })
    };
    // A 6 mm key: a keypoint or two the twin does not explain.
    let small = twin_of(0.006);
    assert!(small.coverage <= small.fit_coverage, "{small:?}");
    assert!(small.ambiguous, "{small:?}");
    // A 60 mm block: the scan tells the twin apart.
    let large = twin_of(0.06);
    assert!(large.fit_coverage - large.coverage > 10, "{large:?}");
    assert!(!large.ambiguous, "{large:?}");
}

/// The ABB IRB 1600 at 500 mm: a base turned about joint 1 (joint 1 turned back) while the wrist
/// sits at its twin. Flipping the wrist back and refining also settles the base; scored on every
/// link that differs, the base's points carry the flip whichever way the wrist goes.
#[test]
fn a_flip_is_judged_on_the_links_its_joint_moves() {
    let truth = Isometry3::translation(0.2, -0.1, 0.0);
    let q_true = vec![0.0, 0.3, 0.4, 0.2, 0.6, 0.3];
    with_keyed_wrist_scan(0.06, &truth, &q_true, false, |fit| {
        // The true wrist on a base turned 0.1 rad about joint 1's axis (the root's z), joint 1
        // turned back: every link but the base where it truly is.
        let turned_base = truth * UnitQuaternion::from_euler_angles(0.0, 0.0, 0.1);
        let mut q_turned = q_true.clone();
        q_turned[0] -= 0.1;
        assert_eq!(
            fit.differing_links(
                (&truth, &q_true),
                (&turned_base, &q_turned),
                &(0..fit.body.links().len()).collect::<Vec<_>>()
            ),
            vec![0]
        );
        // The wrist's twin on the true base.
        let mut twin_q = q_true.clone();
        twin_q[3] += PI;
        twin_q[4] = -twin_q[4];
        twin_q[5] -= PI;
        let now = (&turned_base, q_turned.as_slice());
        let flipped = (&truth, twin_q.as_slice());
        let (on_all_now, on_all_flipped) = fit.contrast(now, flipped).unwrap();
        assert!(on_all_flipped > on_all_now, "{on_all_now} {on_all_flipped}");
        let wrist_links = fit.body.moved_by(3);
        let (now_score, flipped_score) = fit.contrast_among(now, flipped, &wrist_links).unwrap();
        assert!(
            now_score > flipped_score + 12,
            "{now_score} {flipped_score}"
        );
    });
}

/// The joint searches score only the points in the tori their links sweep ([`SweptTubes`]),
/// which must leave out no point that could count: a point outside them counts 0 at every value
/// of the joint and of its partner, here with the UR10's wrist 1 (wrist 2 as its partner) and
/// its shoulder lift (no partner).
#[test]
fn a_point_outside_the_swept_tubes_counts_nothing_at_any_value() {
    let body = ArticulatedBody::from_model(&ShippedRobot::Ur10.model().unwrap()).unwrap();
    let world_from_root = Isometry3::translation(0.1, 0.2, 0.0);
    let q = [0.3, -1.2, 1.4, -0.8, 1.1, 0.4];
    let placed = Placed::new(&body, &world_from_root, &q);
    let band = 0.015;
    let mut rng = TrialRng::new(3);
    for (parameter, partner) in [(3, Some(4)), (1, None)] {
        let moved = body.moved_by(parameter);
        let partner_links = partner.map_or(Vec::new(), |p| body.moved_by(p));
        let turned_alone: Vec<usize> = moved
            .iter()
            .filter(|link| !partner_links.contains(link))
            .copied()
            .collect();
        let tubes = SweptTubes::new(
            &body,
            &placed,
            parameter,
            &turned_alone,
            partner.map(|p| (p, partner_links.as_slice())),
            band,
        )
        .unwrap();
        let points: Vec<Point3<f64>> = (0..3000)
            .map(|_| {
                world_from_root
                    * Point3::new(
                        2.6 * rng.uniform() - 1.3,
                        2.6 * rng.uniform() - 1.3,
                        1.9 * rng.uniform() - 0.3,
                    )
            })
            .collect();
        let (mut left_out, mut counted) = (0, 0);
        for _ in 0..20 {
            let mut trial = q.to_vec();
            trial[parameter] += 6.0 * (rng.uniform() - 0.5);
            if let Some(partner) = partner {
                trial[partner] += 6.0 * (rng.uniform() - 0.5);
            }
            let at = Placed::new(&body, &world_from_root, &trial);
            for point in &points {
                let evidence = at.evidence(point, band, band, &moved);
                if !tubes.hold(point) {
                    assert_eq!(evidence, 0, "joint {parameter} at {trial:?}: {point:?}");
                    left_out += 1;
                } else if evidence != 0 {
                    counted += 1;
                }
            }
        }
        // Both sides of the test must happen: points left out, and points that count.
        assert!(
            left_out > 0 && counted > 0,
            "{left_out} left out, {counted} counted"
        );
    }
}

/// The forked-wrist robot and the index of its base link (a 0.4 m box from z = 0 to 0.3).
pub(super) fn forked_wrist_and_its_base() -> (ArticulatedBody, usize) {
    let model = RobotModel::from_urdf_str(FORKED_WRIST_URDF, &PackageMap::new()).unwrap();
    let body = ArticulatedBody::from_model(&model).unwrap();
    let base = link_named(&body, "base");
    (body, base)
}

/// The index of `body`'s link called `name` (the test's own robot has it).
pub(super) fn link_named(body: &ArticulatedBody, name: &str) -> usize {
    (0..body.links().len())
        .find(|&l| body.links()[l].name == name)
        .unwrap_or_else(|| panic!("no link '{name}'"))
}

#[test]
fn closeness_grades_a_point_by_its_distance_where_evidence_only_counts_it() {
    let (body, base) = forked_wrist_and_its_base();
    let placed = Placed::new(&body, &Isometry3::identity(), &[0.0; 6]);
    let band = 0.003;
    // The base is a 0.4 m box from z = 0 to 0.3: its face x = 0.2, off it by `off_m` (negative
    // inside).
    let at = |off_m: f64| Point3::new(0.2 + off_m, 0.05, 0.1);
    let grade = |off_m: f64| placed.closeness(&at(off_m), band, band, &[base], Distances::Exact);
    for (off_m, expected) in [
        (0.0, 1.0),
        (0.0015, 0.75),
        (-0.0015, 0.75),
        (0.0029, 1.0 - (0.0029f64 / band).powi(2)),
    ] {
        assert!(
            (grade(off_m) - expected).abs() < 1e-9,
            "{off_m} m: {}",
            grade(off_m)
        );
        assert_eq!(placed.evidence(&at(off_m), band, band, &[base]), 1);
    }
    // Beyond the band it counts nothing; buried deep in the solid it counts against, as
    // evidence does.
    assert_eq!(grade(0.004), 0.0);
    assert_eq!(grade(-0.05), -2.0);
    assert_eq!(placed.evidence(&at(-0.05), band, band, &[base]), -2);
}

#[test]
fn a_whole_turn_near_a_limit_is_slid_inside_the_limits_not_clamped() {
    let body = ArticulatedBody::from_model(&ShippedRobot::Ur10.model().unwrap()).unwrap();
    let q = ShippedRobot::Ur10.home();
    let placed = Placed::new(&body, &Isometry3::identity(), &q);
    // The UR10's wrist_2 joint turns +-2 pi.
    let wrist_2 = 4;
    let info = &body.parameters()[wrist_2];
    assert_eq!(info.name, "wrist_2_joint");
    assert!((info.lower + TAU).abs() < 1e-9 && (info.upper - TAU).abs() < 1e-9);
    let window = Window::whole_turn(&body, &placed, wrist_2, 0.005).expect("a revolute joint");
    let near_lower = -6.2811;
    let grid = window.slid_grid(&body, near_lower, 100);
    assert_eq!(grid.len(), 101);
    assert_eq!(grid[0], info.lower);
    assert!(
        (grid[100] - (info.lower + TAU)).abs() < 1e-9,
        "{}",
        grid[100]
    );
    // The truth of the UR10's trial 33 at 500 mm, which centre +- pi clamped never reaches.
    assert!(grid.iter().any(|v| (v + FRAC_PI_2).abs() < 0.04));
    // Mid-range, the turn is centred on the value.
    let centred = window.slid_grid(&body, 0.5, 100);
    assert!((centred[0] - (0.5 - PI)).abs() < 1e-9 && (centred[100] - (0.5 + PI)).abs() < 1e-9);
}

#[test]
fn the_blurred_grade_from_the_grids_agrees_with_the_exact_one_on_a_face() {
    let (body, base) = forked_wrist_and_its_base();
    assert!(body.links()[base].grid.is_some());
    let placed = Placed::new(&body, &Isometry3::identity(), &[0.0; 6]);
    // The sweep's coarse band: four narrow bands of 3 mm.
    let band = 0.012;
    let at = |off_m: f64| Point3::new(0.2 + off_m, 0.05, 0.1);
    for off_m in [0.0, 0.004, -0.006, 0.0115, 0.015, -0.05] {
        let exact = placed.closeness(&at(off_m), band, band, &[base], Distances::Exact);
        let blurred = placed.closeness(&at(off_m), band, band, &[base], Distances::Grids);
        assert!(
            (exact - blurred).abs() < 0.01,
            "{off_m} m: {exact} exact, {blurred} blurred"
        );
    }
    assert_eq!(
        placed.closeness(&at(0.015), band, band, &[base], Distances::Grids),
        0.0
    );
    assert_eq!(
        placed.closeness(&at(-0.05), band, band, &[base], Distances::Grids),
        -2.0
    );
}

#[test]
fn the_sweeps_fine_pass_searches_about_the_highest_distinct_peaks_once_each() {
    // Maxima at 1 (3), the plateau 3-4 (5) and 7 (6): the plateau is one peak, and the peak at
    // 1 lies within two values of it.
    let scores = [1.0, 3.0, 2.0, 5.0, 5.0, 4.0, 0.0, 6.0, 1.0];
    assert_eq!(highest_peaks(&scores, 3, 2), vec![7, 3]);
    assert_eq!(highest_peaks(&scores, 3, 1), vec![7, 3, 1]);
    assert_eq!(highest_peaks(&scores, 1, 2), vec![7]);
    // Overlapping intervals are merged and cut at the span's ends.
    let values = fine_values(&[0.0, 0.1, 1.0], 0.1, 0.05, (-0.05, 2.0));
    assert!(values.windows(2).all(|w| w[0] < w[1]), "{values:?}");
    assert!((values[0] + 0.05).abs() < 1e-12);
    let first: Vec<&f64> = values.iter().filter(|&&v| v < 0.5).collect();
    let second: Vec<&f64> = values.iter().filter(|&&v| v > 0.5).collect();
    assert_eq!((first.len(), second.len()), (6, 5), "{values:?}");
    assert!((*first[5] - 0.2).abs() < 1e-12 && (*second[0] - 0.9).abs() < 1e-12);
    assert!(
        values
            .windows(2)
            .filter(|w| w[1] - w[0] < 0.5)
            .all(|w| w[1] - w[0] <= 0.05 + 1e-12)
    );
}

/// `placed_apart` answers without querying the vertices a move keeps within the bound: its
/// answer must be the one every vertex queried gives, on a box and on a cylinder (which its
/// own spin moves far without moving its surface), for moves from a hundredth of the bound to
/// ten times it.
#[test]
fn links_placed_apart_are_those_some_sampled_vertex_deviates_beyond_the_bound() {
    let (body, base) = forked_wrist_and_its_base();
    let flange = link_named(&body, "flange");
    let bound_m = 1e-3;
    let mut rng = TrialRng::new(41);
    let mut answers = [0usize; 2];
    for link in [base, flange] {
        let mesh = body.links()[link].surface.as_ref().unwrap();
        let stride = mesh.vertices().count().div_ceil(SAMPLES_PER_LINK).max(1);
        let radius_m = mesh.radius_m();
        for trial in 0..60 {
            let a = random_displacement(&mut rng, 0.1, 1.0);
            let size_m = bound_m * 10f64.powf(-2.0 + 3.0 * (trial % 20) as f64 / 19.0);
            // Every third move a spin about the flange's own axis (its x), far beyond the
            // bound at its rim.
            let b = if trial % 3 == 0 {
                a * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.5 + size_m)
            } else {
                a * random_displacement(&mut rng, size_m, radius_m)
            };
            let b_from_a = b.inverse() * a;
            let deviation_m = mesh
                .vertices()
                .step_by(stride)
                .map(|v| {
                    let there = mesh.closest_point(&(b_from_a * v)).signed_distance.abs();
                    let back = mesh
                        .closest_point(&(b_from_a.inverse() * v))
                        .signed_distance
                        .abs();
                    there.max(back)
                })
                .fold(0.0, f64::max);
            let apart = placed_apart(mesh, &a, &b, bound_m);
            assert_eq!(
                apart,
                deviation_m > bound_m,
                "link {link}, trial {trial}: deviation {deviation_m} m"
            );
            answers[usize::from(apart)] += 1;
        }
    }
    // Both answers came up (the test can tell a wrong one either way).
    assert!(answers.iter().all(|&n| n >= 10), "{answers:?}");
}
