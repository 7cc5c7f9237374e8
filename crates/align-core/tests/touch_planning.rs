//! The 3-2-1 touch planner on the shipped robots: every planned touch puts the ball on the
//! surface with the probe within its tilt of the inward normal, the approach pose backs off along
//! the probe axis, and the touches fix all six degrees of freedom of the part.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use align_core::pose::isometry_from_xyz_rpy;
use align_core::robots::ShippedRobot;
use align_core::trials::parts::step_block;
use align_core::trials::planning::{PlanError, PlanOptions, plan_touches};
use nalgebra::{DMatrix, Isometry3};

const RADIUS_M: f64 = 0.003;

fn tcp() -> Isometry3<f64> {
    isometry_from_xyz_rpy([0.0, 0.0, 0.15], [0.0; 3])
}

fn check_plan(robot: ShippedRobot, base_from_part: Isometry3<f64>) {
    let part = step_block().unwrap();
    let chain = robot.chain().unwrap();
    let options = PlanOptions::default();
    let plan = plan_touches(
        &part.mesh,
        &base_from_part,
        &chain,
        &tcp(),
        RADIUS_M,
        1.0,
        &robot.home(),
        &options,
    )
    .unwrap_or_else(|error| panic!("{}: {error}", robot.name()));
    assert_eq!(plan.len(), options.touches);
    let mut jacobian = DMatrix::zeros(plan.len(), 6);
    for (row, touch) in plan.iter().enumerate() {
        let surface = part.mesh.closest_point(&touch.point_in_part);
        assert!(
            (surface.point - touch.point_in_part).norm() < 1e-9,
            "on the surface"
        );
        let centre_in_part = touch.point_in_part + touch.normal_in_part * RADIUS_M;
        let base_from_tcp = chain.forward(&touch.q_contact).unwrap() * tcp();
        let centre = base_from_tcp.translation.vector;
        let expected = (base_from_part * centre_in_part).coords;
        assert!(
            (centre - expected).norm() < 1e-6,
            "ball centre {centre} vs {expected}"
        );
        let probe = base_from_tcp.rotation * nalgebra::Vector3::z();
        let inward = base_from_part.rotation * -touch.normal_in_part;
        let tilt = probe.angle(&inward);
        assert!((tilt - touch.tilt_rad).abs() < 1e-6 && tilt <= options.max_tilt_rad + 1e-9);
        let back = chain.forward(&touch.q_approach).unwrap() * tcp();
        let retreat = back.translation.vector - centre;
        assert!(
            (retreat + probe * options.approach_m).norm() < 1e-6,
            "approach along the probe"
        );
        // d(signed distance)/d(pose): translation along the normal, rotation about the point.
        let n = touch.normal_in_part;
        let p = touch.point_in_part.coords;
        let moment = p.cross(&n);
        for k in 0..3 {
            jacobian[(row, k)] = n[k];
            jacobian[(row, 3 + k)] = moment[k];
        }
    }
    let singular = jacobian.singular_values();
    let smallest = singular.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(
        smallest > 1e-3,
        "{}: the touches leave a degree of freedom nearly free ({singular:?})",
        robot.name()
    );
}

#[test]
fn ur10_plans_a_3_2_1_set_on_the_step_block() {
    check_plan(
        ShippedRobot::Ur10,
        isometry_from_xyz_rpy([0.62, -0.25, 0.02], [0.0, 0.0, 0.35]),
    );
}

#[test]
fn iiwa14_plans_a_3_2_1_set_on_the_step_block() {
    check_plan(
        ShippedRobot::Iiwa14,
        isometry_from_xyz_rpy([0.5, -0.2, 0.02], [0.0, 0.0, 0.35]),
    );
}

#[test]
fn a_part_out_of_reach_or_too_few_touches_is_refused() {
    let part = step_block().unwrap();
    let robot = ShippedRobot::Ur10;
    let chain = robot.chain().unwrap();
    let far = isometry_from_xyz_rpy([5.0, 0.0, 0.0], [0.0; 3]);
    let error = plan_touches(
        &part.mesh,
        &far,
        &chain,
        &tcp(),
        RADIUS_M,
        1.0,
        &robot.home(),
        &PlanOptions::default(),
    )
    .unwrap_err();
    assert_eq!(error, PlanError::NoPrimaryFace);
    let error = plan_touches(
        &part.mesh,
        &isometry_from_xyz_rpy([0.62, -0.25, 0.02], [0.0; 3]),
        &chain,
        &tcp(),
        RADIUS_M,
        1.0,
        &robot.home(),
        &PlanOptions {
            touches: 5,
            ..PlanOptions::default()
        },
    )
    .unwrap_err();
    assert_eq!(error, PlanError::TooFewTouches(5));
}
