//! Unit tests of the exact queries bounded by a remembered triangle
//! ([`super::placed::Placed::nearest_hinted`]).

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use super::placed::{NO_HINT, Placed, SurfaceHint};
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
