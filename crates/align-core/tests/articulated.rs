//! Hierarchical alignment of the shipped robots in scanner-like clouds.

use align_core::registration::articulated::{ArticulatedBody, RobotFitOptions, align_robot};
use align_core::robots::ShippedRobot;
use align_core::trials::TrialRng;
use align_core::trials::robot_scan::{RobotScanOptions, scan_robot};
use align_core::trials::robot_trials::{perturb_robot, surface_deviation_m};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};

fn cell_pose() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.2, -0.1, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, 0.4),
    )
}

/// Fits from a perturbed start and returns the largest surface deviation over the visible links.
fn recover(
    robot: ShippedRobot,
    q_true: &[f64],
    scan: &RobotScanOptions,
    delta_m: f64,
    seed: u64,
) -> (f64, Vec<String>) {
    let body = ArticulatedBody::from_model(&robot.model().expect("shipped URDF loads"))
        .expect("shipped robot has surfaces");
    let truth = cell_pose();
    let cloud = scan_robot(&body, &truth, q_true, scan);
    let mut rng = TrialRng::new(seed);
    let (base, q0) = perturb_robot(&body, &truth, q_true, delta_m, &mut rng);
    let fit = align_robot(
        &body,
        &cloud,
        &base,
        &q0,
        delta_m,
        &RobotFitOptions::default(),
    )
    .expect("the fit runs");
    let fitted = body.link_poses(&fit.world_from_root, &fit.q);
    let true_poses = body.link_poses(&truth, q_true);
    let mut worst: f64 = 0.0;
    let mut report = Vec::new();
    for (index, link) in body.links().iter().enumerate() {
        let Some(mesh) = &link.surface else { continue };
        let error = surface_deviation_m(mesh, &fitted[index], &true_poses[index]);
        report.push(format!(
            "{} {:.3} mm ({} pts)",
            link.name,
            error * 1e3,
            fit.links[index].points
        ));
        if fit.links[index].visible {
            worst = worst.max(error);
        }
    }
    eprintln!(
        "{} seed {seed} delta {delta_m}: {:.3} s, {report:?}, joints {:?}",
        robot.name(),
        fit.time_s,
        fit.joints
    );
    (worst, report)
}

#[test]
fn ur10_recovers_from_a_small_perturbation_in_a_cluttered_scan() {
    let (worst, report) = recover(
        ShippedRobot::Ur10,
        &ShippedRobot::Ur10.home(),
        &RobotScanOptions::default(),
        0.05,
        3,
    );
    assert!(worst < 1e-3, "{report:?}");
}
