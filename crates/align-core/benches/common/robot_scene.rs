//! The scene both robot-alignment benches fit in: the trials' root pose, the robot at home, a
//! cluttered scan of about 20k points (the trials' scene, spacing scaled).

use align_core::registration::articulated::ArticulatedBody;
use align_core::robots::ShippedRobot;
use align_core::trials::robot_scan::{RobotScanOptions, scan_robot_of_about};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};

pub struct RobotScene {
    pub body: ArticulatedBody,
    pub world_from_root: Isometry3<f64>,
    pub cloud: Vec<Point3<f64>>,
}

/// Where the trials put a robot's root (`ips trials`): 0.2 m off the cell origin, turned 0.4 rad.
pub fn trial_root_pose() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.2, -0.1, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, 0.4),
    )
}

pub fn robot_scene(robot: ShippedRobot) -> RobotScene {
    let world_from_root = trial_root_pose();
    let model = robot.model().expect("shipped");
    let body = ArticulatedBody::from_model(&model).expect("surfaces");
    let cloud = scan_robot_of_about(
        &body,
        &world_from_root,
        &robot.home(),
        &RobotScanOptions::default(),
        20_000,
    );
    RobotScene {
        body,
        world_from_root,
        cloud,
    }
}
