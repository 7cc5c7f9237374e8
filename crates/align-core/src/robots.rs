//! The robot descriptions shipped with the project (`robots/*.urdf`, generated from published
//! nominal parameters by `robots/generate.py`, which cites every source). They are compiled in,
//! so every binary can use them without locating files.

use crate::kinematics::{Chain, ModelError, PackageMap, RobotModel};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShippedRobot {
    Ur10,
    Ur10e,
    Iiwa14,
}

impl ShippedRobot {
    pub const ALL: [ShippedRobot; 3] = [
        ShippedRobot::Ur10,
        ShippedRobot::Ur10e,
        ShippedRobot::Iiwa14,
    ];

    /// Command-line name: `ur10`, `ur10e`, `iiwa14`.
    pub fn name(self) -> &'static str {
        match self {
            ShippedRobot::Ur10 => "ur10",
            ShippedRobot::Ur10e => "ur10e",
            ShippedRobot::Iiwa14 => "iiwa14",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|robot| robot.name() == name)
    }

    pub fn urdf(self) -> &'static str {
        match self {
            ShippedRobot::Ur10 => include_str!("../../../robots/ur10.urdf"),
            ShippedRobot::Ur10e => include_str!("../../../robots/ur10e.urdf"),
            ShippedRobot::Iiwa14 => include_str!("../../../robots/iiwa14.urdf"),
        }
    }

    /// The link the controller reports poses in.
    pub fn base_link(self) -> &'static str {
        match self {
            ShippedRobot::Ur10 | ShippedRobot::Ur10e => "base_link",
            ShippedRobot::Iiwa14 => "iiwa_link_0",
        }
    }

    /// The tool flange.
    pub fn flange_link(self) -> &'static str {
        match self {
            ShippedRobot::Ur10 | ShippedRobot::Ur10e => "tool0",
            ShippedRobot::Iiwa14 => "iiwa_link_ee",
        }
    }

    /// A pose the arm can hold without reaching its limits, and a good IK seed for a table in
    /// front of it: the UR "home" with the elbow up, the iiwa slightly bent.
    pub fn home(self) -> Vec<f64> {
        use std::f64::consts::FRAC_PI_2;
        match self {
            ShippedRobot::Iiwa14 => vec![0.0, 0.5, 0.0, -1.2, 0.0, 0.9, 0.0],
            ShippedRobot::Ur10 | ShippedRobot::Ur10e => {
                vec![0.0, -FRAC_PI_2, FRAC_PI_2, -FRAC_PI_2, -FRAC_PI_2, 0.0]
            }
        }
    }

    pub fn model(self) -> Result<RobotModel, ModelError> {
        RobotModel::from_urdf_str(self.urdf(), &PackageMap::new())
    }

    /// The base-to-flange chain.
    pub fn chain(self) -> Result<Chain, ModelError> {
        self.model()?.chain(self.base_link(), self.flange_link())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_shipped_robot_loads_with_inertials() {
        for robot in ShippedRobot::ALL {
            let model = robot.model().expect("shipped URDF loads");
            let chain = robot.chain().expect("shipped chain builds");
            assert_eq!(
                chain.dof(),
                if robot == ShippedRobot::Iiwa14 { 7 } else { 6 }
            );
            let moving_links_with_mass = model
                .joints()
                .iter()
                .filter(|joint| joint.kind != crate::kinematics::JointKind::Fixed)
                .filter(|joint| model.links()[joint.child].inertial.is_some())
                .count();
            assert_eq!(moving_links_with_mass, chain.dof(), "{}", robot.name());
            assert!(model.links().iter().all(|link| link.name.ends_with("tool0")
                || link.name.ends_with("_ee")
                || !link.collisions.is_empty()));
            assert_eq!(ShippedRobot::from_name(robot.name()), Some(robot));
        }
    }
}
