//! Unit tests of the exact queries bounded by a remembered triangle
//! ([`super::placed::Placed::nearest_hinted`]) and of the points a turn of the base can reach
//! ([`super::placed::within_swept_reach`]).

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

use super::placed::{NO_HINT, Placed, SurfaceHint, coverage, within_swept_reach};
use super::tests::random_surface_point;
use crate::registration::articulated::ArticulatedBody;
use crate::robots::ShippedRobot;
use crate::trials::TrialRng;

/// A refinement's step moves the robot a little and each keypoint keeps the triangle it
/// matched before: the hinted answer must be the unhinted one, bit for bit, including where the
/// hint is on another link, farther than the closest surface, or an edge the unhinted query
/// rejects. Points near and inside the UR10's links, and near where two links meet, in the
/// bands the exact refinements use.
#[test]
fn a_remembered_triangle_changes_no_exact_answer() {
    let body = ArticulatedBody::from_model(&ShippedRobot::Ur10.model().unwrap()).unwrap();
    let base = Isometry3::translation(0.2, -0.1, 0.0);
    let q = ShippedRobot::Ur10.home();
    let before = Placed::new(&body, &base, &q);
    // The next step: the base shifted by a millimetre and turned a little, the joints moved.
    let moved_base = Isometry3::from_parts(
        Translation3::new(0.0007, -0.0005, 0.0004),
        UnitQuaternion::from_scaled_axis(Vector3::new(0.001, -0.0015, 0.002)),
    ) * base;
    let moved_q: Vec<f64> = q.iter().map(|v| v + 0.004).collect();
    let after = Placed::new(&body, &moved_base, &moved_q);
    let all: Vec<usize> = (0..body.links().len()).collect();
    let mut rng = TrialRng::new(11);
    let (mut hinted, mut tight) = (0, 0);
    for _ in 0..6000 {
        let link = (rng.uniform() * body.links().len() as f64) as usize;
        let Some(surface) = &body.links()[link].surface else {
            continue;
        };
        let on = random_surface_point(surface, &mut rng);
        // Mostly within a millimetre or two (noise), some farther out and some inside.
        let offset = (rng.uniform() - 0.2) * if rng.uniform() < 0.7 { 0.003 } else { 0.02 };
        let point = before.poses[link] * (on.point + on.normal * offset);
        for band in [0.005, 0.01] {
            let mut hint = NO_HINT;
            let _ = before.nearest_hinted(&point, band, &all, &mut hint);
            if hint != NO_HINT {
                hinted += 1;
            }
            let reference = after.nearest(&point, band, &all);
            let mut carried = hint;
            let answer = after.nearest_hinted(&point, band, &all, &mut carried);
            assert_eq!(
                answer.map(|m| (m.link, m.distance.to_bits(), m.surface)),
                reference.map(|m| (m.link, m.distance.to_bits(), m.surface)),
                "{point} band {band} hint {hint:?}"
            );
            if answer.is_some_and(|m| m.distance < 0.001) {
                tight += 1;
            }
            // A hint from anywhere else on the robot changes nothing either.
            let mut stranger = SurfaceHint::of(link as u32 ^ 1, (rng.uniform() * 200.0) as u32);
            let answer = after.nearest_hinted(&point, band, &all, &mut stranger);
            assert_eq!(
                answer.map(|m| (m.link, m.distance.to_bits(), m.surface)),
                reference.map(|m| (m.link, m.distance.to_bits(), m.surface)),
                "{point} band {band}"
            );
        }
    }
    // The bound is used: most points carried a hint, and many lie within its millimetre.
    assert!(hinted > 6000, "{hinted}");
    assert!(tight > 2000, "{tight}");
}

/// The base-turn check scores turns of the links fixed to the root on the keypoints those links
/// can reach at some turn: every turn's score over them must be its score over all keypoints.
/// Points on and near every link of the UR10 (most beyond the base's reach) and scattered in
/// its box, turns of any size about a tilted axis beside the base, both bands the check uses.
#[test]
fn the_points_a_turn_can_reach_score_every_turn_as_all_points_do() {
    let body = ArticulatedBody::from_model(&ShippedRobot::Ur10.model().unwrap()).unwrap();
    let base = Isometry3::from_parts(
        Translation3::new(0.3, -0.2, 0.05),
        UnitQuaternion::from_scaled_axis(Vector3::new(0.02, -0.03, 0.4)),
    );
    let q = ShippedRobot::Ur10.home();
    let placed = Placed::new(&body, &base, &q);
    let fixed: Vec<usize> = (0..body.links().len())
        .filter(|&l| body.movers(l).is_empty() && body.links()[l].surface.is_some())
        .collect();
    assert!(!fixed.is_empty());
    let mut rng = TrialRng::new(29);
    let mut sample = Vec::new();
    for _ in 0..4000 {
        let link = (rng.uniform() * body.links().len() as f64) as usize;
        let Some(surface) = &body.links()[link].surface else {
            continue;
        };
        let on = random_surface_point(surface, &mut rng);
        let offset = (rng.uniform() - 0.3) * 0.03;
        sample.push(placed.poses[link] * (on.point + on.normal * offset));
    }
    for _ in 0..1000 {
        let box_point = Vector3::new(rng.uniform() - 0.5, rng.uniform() - 0.5, rng.uniform());
        sample.push(base * Point3::from(box_point * 1.5));
    }
    let origin = base * Point3::new(0.01, -0.02, 0.0);
    let direction = Unit::new_normalize(base.rotation * Vector3::new(0.05, 0.02, 1.0));
    let voxel = 0.006;
    let reachable = within_swept_reach(&placed, &sample, &fixed, &origin, &direction, 3.0 * voxel);
    // The base is a small part of the robot: most points are left out.
    assert!(
        reachable.len() * 3 < sample.len(),
        "{} of {}",
        reachable.len(),
        sample.len()
    );
    let about = Translation3::from(origin.coords);
    let mut counted = 0;
    for _ in 0..30 {
        let theta = (rng.uniform() - 0.5) * 2.0 * std::f64::consts::PI;
        let turn = about * UnitQuaternion::from_axis_angle(&direction, theta) * about.inverse();
        let turned = turn * base;
        for band in [voxel, 3.0 * voxel] {
            let all = coverage(&body, &sample, &turned, &q, &fixed, band, false);
            let some = coverage(&body, &reachable, &turned, &q, &fixed, band, false);
            assert_eq!(some, all, "turn {theta} band {band}");
            counted += all.abs();
        }
    }
    // The turns are scored on points the base explains or buries, not on none.
    assert!(counted > 1000, "{counted}");
}
