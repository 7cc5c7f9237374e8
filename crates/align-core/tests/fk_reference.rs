//! Forward kinematics of the shipped robots against independent references written from the
//! published tables: the classic standard-DH matrix product for the UR10/UR10e, and a chain of
//! elementary rotations derived by hand from the KUKA dimension drawing for the iiwa 14.

use align_core::robots::ShippedRobot;
use nalgebra::{Matrix3, Matrix4, Vector3};
use rand::{Rng, SeedableRng, rngs::StdRng};
use std::f64::consts::FRAC_PI_2;

/// (a, d, alpha) per joint, copied from Universal Robots' DH page (not from our URDF).
const UR10_DH: [(f64, f64, f64); 6] = [
    (0.0, 0.1273, FRAC_PI_2),
    (-0.612, 0.0, 0.0),
    (-0.5723, 0.0, 0.0),
    (0.0, 0.163941, FRAC_PI_2),
    (0.0, 0.1157, -FRAC_PI_2),
    (0.0, 0.0922, 0.0),
];
const UR10E_DH: [(f64, f64, f64); 6] = [
    (0.0, 0.1807, FRAC_PI_2),
    (-0.6127, 0.0, 0.0),
    (-0.57155, 0.0, 0.0),
    (0.0, 0.17415, FRAC_PI_2),
    (0.0, 0.11985, -FRAC_PI_2),
    (0.0, 0.11655, 0.0),
];

/// The textbook standard-DH link transform Rz(theta) Tz(d) Tx(a) Rx(alpha), written out.
fn dh_matrix(theta: f64, a: f64, d: f64, alpha: f64) -> Matrix4<f64> {
    let (st, ct) = theta.sin_cos();
    let (sa, ca) = alpha.sin_cos();
    Matrix4::new(
        ct,
        -st * ca,
        st * sa,
        a * ct, //
        st,
        ct * ca,
        -ct * sa,
        a * st, //
        0.0,
        sa,
        ca,
        d, //
        0.0,
        0.0,
        0.0,
        1.0,
    )
}

fn dh_forward(table: &[(f64, f64, f64)], q: &[f64]) -> Matrix4<f64> {
    table
        .iter()
        .zip(q)
        .fold(Matrix4::identity(), |acc, (&(a, d, alpha), &theta)| {
            acc * dh_matrix(theta, a, d, alpha)
        })
}

fn rot_y(angle: f64) -> Matrix3<f64> {
    let (s, c) = angle.sin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}

fn rot_z(angle: f64) -> Matrix3<f64> {
    let (s, c) = angle.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

/// LBR iiwa 14 R820 derived by hand: in the zero position the arm stands straight up, the odd
/// axes (A1, A3, A5, A7) point along base z and the even axes along base y, A4 opposite to A2 and
/// A6 (KUKA's convention, so that positive A2 and positive A4 bend the arm in opposite senses).
/// Lengths from the KUKA drawing: A2 at 0.36 m, A4 0.42 m above A2, A6 0.40 m above A4, flange
/// 0.126 m above A6. In the zero position the flange frame is parallel to the base frame.
fn iiwa_hand_forward(q: &[f64]) -> (Matrix3<f64>, Vector3<f64>) {
    let z = Vector3::z();
    let mut rotation = Matrix3::identity();
    let mut position = Vector3::zeros();
    let advance = |length: f64, rotation: &Matrix3<f64>, position: &mut Vector3<f64>| {
        *position += rotation * z * length;
    };
    rotation *= rot_z(q[0]);
    advance(0.36, &rotation, &mut position);
    rotation *= rot_y(q[1]);
    rotation *= rot_z(q[2]);
    advance(0.42, &rotation, &mut position);
    rotation *= rot_y(-q[3]);
    rotation *= rot_z(q[4]);
    advance(0.40, &rotation, &mut position);
    rotation *= rot_y(q[5]);
    rotation *= rot_z(q[6]);
    advance(0.126, &rotation, &mut position);
    (rotation, position)
}

fn random_q(rng: &mut StdRng, limits: &[(f64, f64)]) -> Vec<f64> {
    limits
        .iter()
        .map(|&(lower, upper)| rng.random_range(lower..=upper))
        .collect()
}

fn rotation_angle(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
    let relative = a.transpose() * b;
    let cos = ((relative.trace() - 1.0) / 2.0).clamp(-1.0, 1.0);
    // acos loses precision near 0; use the skew part for small angles.
    let skew = Vector3::new(
        relative[(2, 1)] - relative[(1, 2)],
        relative[(0, 2)] - relative[(2, 0)],
        relative[(1, 0)] - relative[(0, 1)],
    );
    (skew.norm() / 2.0).atan2(cos)
}

fn check_ur(robot: ShippedRobot, table: &[(f64, f64, f64)]) {
    let chain = robot.chain().expect("chain");
    let limits: Vec<_> = chain
        .joints()
        .iter()
        .map(|joint| (joint.limits.lower, joint.limits.upper))
        .collect();
    let mut rng = StdRng::seed_from_u64(7);
    let mut worst = (0.0f64, 0.0f64);
    for _ in 0..1000 {
        let q = random_q(&mut rng, &limits);
        let ours = chain.forward(&q).expect("fk").to_homogeneous();
        let reference = dh_forward(table, &q);
        let position_error =
            (ours.fixed_view::<3, 1>(0, 3) - reference.fixed_view::<3, 1>(0, 3)).norm();
        let rotation_error = rotation_angle(
            &ours.fixed_view::<3, 3>(0, 0).into(),
            &reference.fixed_view::<3, 3>(0, 0).into(),
        );
        worst = (worst.0.max(position_error), worst.1.max(rotation_error));
    }
    assert!(
        worst.0 <= 1e-9 && worst.1 <= 1e-9,
        "{}: worst {worst:?}",
        robot.name()
    );
}

#[test]
fn ur10_matches_standard_dh_over_1000_configurations() {
    check_ur(ShippedRobot::Ur10, &UR10_DH);
}

#[test]
fn ur10e_matches_standard_dh_over_1000_configurations() {
    check_ur(ShippedRobot::Ur10e, &UR10E_DH);
}

#[test]
fn ur10_zero_pose_is_the_stretched_arm_of_the_dh_drawing() {
    // At q = 0 the UR arm lies along base -x with the wrist offsets along -y, as UR's DH drawing
    // shows: x = a2 + a3, y = -(d4 + d6), z = d1 - d5.
    let chain = ShippedRobot::Ur10.chain().expect("chain");
    let tip = chain.forward(&[0.0; 6]).expect("fk").translation.vector;
    let expected = Vector3::new(-0.612 - 0.5723, -(0.163941 + 0.0922), 0.1273 - 0.1157);
    assert!((tip - expected).norm() < 1e-12, "{tip:?}");
}

#[test]
fn iiwa14_matches_hand_derived_chain_over_1000_configurations() {
    let chain = ShippedRobot::Iiwa14.chain().expect("chain");
    let limits: Vec<_> = chain
        .joints()
        .iter()
        .map(|joint| (joint.limits.lower, joint.limits.upper))
        .collect();
    let mut rng = StdRng::seed_from_u64(11);
    let mut worst = (0.0f64, 0.0f64);
    for _ in 0..1000 {
        let q = random_q(&mut rng, &limits);
        let ours = chain.forward(&q).expect("fk");
        let (rotation, position) = iiwa_hand_forward(&q);
        let position_error = (ours.translation.vector - position).norm();
        let rotation_error = rotation_angle(ours.rotation.to_rotation_matrix().matrix(), &rotation);
        worst = (worst.0.max(position_error), worst.1.max(rotation_error));
    }
    assert!(worst.0 <= 1e-9 && worst.1 <= 1e-9, "worst {worst:?}");
}

#[test]
fn joint_frames_end_at_the_tip_and_each_is_the_forward_kinematics_of_the_joints_before_it() {
    // The operator page draws the arm through these frames: the last must be the tip, and the
    // first joint's frame must not move with any joint.
    let chain = ShippedRobot::Ur10.chain().expect("chain");
    let q = [0.3, -1.2, 1.4, -1.8, -1.57, 0.2];
    let frames = chain.joint_frames_unchecked(&q);
    assert_eq!(frames.len(), 7);
    let tip = chain.forward(&q).expect("fk");
    assert!((frames[6].to_homogeneous() - tip.to_homogeneous()).norm() < 1e-12);
    let at_zero = chain.joint_frames_unchecked(&[0.0; 6]);
    assert!((frames[0].to_homogeneous() - at_zero[0].to_homogeneous()).norm() < 1e-12);
    // The shoulder sits d1 above the base on joint 1's axis, whatever the joints.
    assert!((frames[1].translation.vector.z - 0.1273).abs() < 1e-9);
}
