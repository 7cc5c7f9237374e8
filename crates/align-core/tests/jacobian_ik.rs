//! The geometric Jacobian against finite differences, and inverse kinematics round trips from
//! random reachable poses of the shipped robots.

use align_core::kinematics::{Chain, IkError, IkOptions};
use align_core::robots::ShippedRobot;
use nalgebra::{Isometry3, Vector3};
use rand::{Rng, SeedableRng, rngs::StdRng};

fn random_q(rng: &mut StdRng, chain: &Chain) -> Vec<f64> {
    chain
        .joints()
        .iter()
        .map(|joint| rng.random_range(joint.limits.lower..=joint.limits.upper))
        .collect()
}

/// Central differences of the tip position, and of the rotation as the rotation vector of
/// R(q + h) * R(q - h)^-1 / 2h, which is the angular velocity column.
fn finite_difference_jacobian(chain: &Chain, q: &[f64]) -> nalgebra::Matrix6xX<f64> {
    let step = 1e-6;
    let mut jacobian = nalgebra::Matrix6xX::zeros(q.len());
    for column in 0..q.len() {
        let mut plus = q.to_vec();
        let mut minus = q.to_vec();
        plus[column] += step;
        minus[column] -= step;
        let (a, b) = (
            chain.forward_unchecked(&plus),
            chain.forward_unchecked(&minus),
        );
        let linear = (a.translation.vector - b.translation.vector) / (2.0 * step);
        let angular = (a.rotation * b.rotation.inverse()).scaled_axis() / (2.0 * step);
        jacobian
            .fixed_view_mut::<3, 1>(0, column)
            .copy_from(&linear);
        jacobian
            .fixed_view_mut::<3, 1>(3, column)
            .copy_from(&angular);
    }
    jacobian
}

#[test]
fn jacobian_matches_finite_differences_on_every_shipped_robot() {
    let mut rng = StdRng::seed_from_u64(3);
    for robot in ShippedRobot::ALL {
        let chain = robot.chain().expect("chain");
        for _ in 0..200 {
            let q = random_q(&mut rng, &chain);
            let analytic = chain.jacobian(&q).expect("jacobian");
            let numeric = finite_difference_jacobian(&chain, &q);
            let error = (&analytic - &numeric).abs().max();
            assert!(
                error < 1e-7,
                "{}: max |J - J_fd| = {error:e} at {q:?}",
                robot.name()
            );
        }
    }
}

#[test]
fn jacobian_of_a_reversed_chain_matches_finite_differences() {
    // flange -> base crosses every joint upwards.
    let model = ShippedRobot::Ur10.model().expect("model");
    let chain = model.chain("tool0", "base_link").expect("chain");
    let mut rng = StdRng::seed_from_u64(5);
    for _ in 0..100 {
        let q = random_q(&mut rng, &chain);
        let error = (chain.jacobian(&q).expect("jacobian")
            - finite_difference_jacobian(&chain, &q))
        .abs()
        .max();
        assert!(error < 1e-7, "max |J - J_fd| = {error:e}");
    }
}

struct RoundTrips {
    solved: usize,
    failures: Vec<String>,
    worst_position_m: f64,
    worst_rotation_rad: f64,
}

/// Targets are FK of random configurations within the limits (so reachable); the solver starts
/// from an unrelated random configuration, not from the answer.
fn ik_round_trips(robot: ShippedRobot, count: usize, seed: u64) -> RoundTrips {
    let chain = robot.chain().expect("chain");
    let mut rng = StdRng::seed_from_u64(seed);
    let options = IkOptions::default();
    let mut result = RoundTrips {
        solved: 0,
        failures: Vec::new(),
        worst_position_m: 0.0,
        worst_rotation_rad: 0.0,
    };
    for trial in 0..count {
        let truth = random_q(&mut rng, &chain);
        let start = random_q(&mut rng, &chain);
        let target: Isometry3<f64> = chain.forward(&truth).expect("fk");
        match chain.inverse(&target, &start, &options) {
            Ok(solution) => {
                // Verify independently of the solver's own report.
                let reached = chain.forward(&solution.q).expect("fk");
                let position = (reached.translation.vector - target.translation.vector).norm();
                let rotation = reached.rotation.angle_to(&target.rotation);
                assert!(
                    chain.within_limits(&solution.q),
                    "solution outside the limits"
                );
                if position <= 1e-6 && rotation <= 1e-6 {
                    result.solved += 1;
                    result.worst_position_m = result.worst_position_m.max(position);
                    result.worst_rotation_rad = result.worst_rotation_rad.max(rotation);
                } else {
                    result.failures.push(format!(
                        "trial {trial}: reported solved but {position:e} m / {rotation:e} rad"
                    ));
                }
            }
            Err(error) => result.failures.push(format!("trial {trial}: {error}")),
        }
    }
    result
}

fn assert_round_trips(robot: ShippedRobot) {
    let result = ik_round_trips(robot, 1000, 17);
    println!(
        "{}: {}/1000 solved, worst {:e} m / {:e} rad; failures: {:?}",
        robot.name(),
        result.solved,
        result.worst_position_m,
        result.worst_rotation_rad,
        result.failures
    );
    assert!(
        result.solved >= 990,
        "{}: only {}/1000: {:?}",
        robot.name(),
        result.solved,
        result.failures
    );
}

#[test]
fn ur10_ik_round_trips_1000_random_reachable_poses() {
    assert_round_trips(ShippedRobot::Ur10);
}

#[test]
fn ur10e_ik_round_trips_1000_random_reachable_poses() {
    assert_round_trips(ShippedRobot::Ur10e);
}

#[test]
fn iiwa14_ik_round_trips_1000_random_reachable_poses() {
    assert_round_trips(ShippedRobot::Iiwa14);
}

#[test]
fn unreachable_target_is_reported_as_a_failure_with_the_closest_pose() {
    let chain = ShippedRobot::Ur10.chain().expect("chain");
    // 3 m away: the UR10 reaches 1.3 m.
    let target = Isometry3::translation(3.0, 0.0, 0.5);
    let options = IkOptions {
        max_attempts: 4,
        ..IkOptions::default()
    };
    let error = chain
        .inverse(&target, &[0.0; 6], &options)
        .expect_err("3 m is out of reach");
    let IkError::Unreachable {
        attempts,
        best_position_error_m,
        ref best_q,
        ..
    } = error
    else {
        panic!("expected Unreachable, got {error:?}");
    };
    assert_eq!(attempts, 4);
    // The closest point of a 1.3 m reach sphere is about 1.7 m short.
    assert!(
        best_position_error_m > 1.5 && best_position_error_m < 2.0,
        "{best_position_error_m}"
    );
    assert!(chain.within_limits(best_q));
    assert!(
        error
            .to_string()
            .contains("no joint configuration within the limits reaches the target")
    );
}

#[test]
fn ik_respects_joint_limits_when_the_unconstrained_answer_lies_outside() {
    // The iiwa's A4 is limited to +-120 deg. Ask for a pose whose only nearby solutions would need
    // more: the solver must either find another within limits or fail, never exceed the limits.
    let chain = ShippedRobot::Iiwa14.chain().expect("chain");
    let truth = [0.3, 0.8, -0.2, -2.05, 0.4, 1.2, 0.1];
    let target = chain.forward(&truth).expect("fk");
    let solution = chain
        .inverse(&target, &[0.0; 7], &IkOptions::default())
        .expect("reachable");
    assert!(chain.within_limits(&solution.q));
}

#[test]
fn position_only_ik_ignores_orientation() {
    let chain = ShippedRobot::Ur10.chain().expect("chain");
    let mut target = chain
        .forward(&[0.4, -1.0, 1.2, -0.5, 0.3, 0.2])
        .expect("fk");
    target.rotation = nalgebra::UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 2.0);
    let options = IkOptions {
        match_orientation: false,
        ..IkOptions::default()
    };
    let solution = chain
        .inverse(&target, &[0.0; 6], &options)
        .expect("reachable");
    let reached = chain.forward(&solution.q).expect("fk");
    assert!((reached.translation.vector - target.translation.vector).norm() < 1e-6);
}

#[test]
fn ik_rejects_bad_seeds_and_targets() {
    let chain = ShippedRobot::Ur10.chain().expect("chain");
    let error = chain
        .inverse(&Isometry3::identity(), &[0.0; 5], &IkOptions::default())
        .expect_err("5 values for 6 joints");
    assert!(
        error.to_string().starts_with("expected 6 joint values"),
        "{error}"
    );
    let target = Isometry3::translation(f64::NAN, 0.0, 0.0);
    let error = chain
        .inverse(&target, &[0.0; 6], &IkOptions::default())
        .expect_err("NaN target");
    assert_eq!(error.to_string(), "the IK target is not finite");
}
