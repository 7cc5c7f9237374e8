//! The robot descriptions shipped with the project (`robots/*.urdf`, generated from published
//! nominal parameters by `robots/generate.py`, which cites every source). They are compiled in,
//! so every binary can use them without locating files.

use crate::kinematics::{Chain, DhTable, ModelError, PackageMap, RobotModel};

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

    /// The nominal standard DH table the URDF was generated from (UR's published parameters,
    /// as in robots/generate.py): what a UR controller's calibration is a delta to. `None` for
    /// robots that do not publish one.
    pub fn nominal_dh(self) -> Option<DhTable> {
        use std::f64::consts::FRAC_PI_2;
        let alpha = vec![FRAC_PI_2, 0.0, 0.0, FRAC_PI_2, -FRAC_PI_2, 0.0];
        let (a, d) = match self {
            ShippedRobot::Ur10 => (
                vec![0.0, -0.612, -0.5723, 0.0, 0.0, 0.0],
                vec![0.1273, 0.0, 0.0, 0.163941, 0.1157, 0.0922],
            ),
            ShippedRobot::Ur10e => (
                vec![0.0, -0.6127, -0.57155, 0.0, 0.0, 0.0],
                vec![0.1807, 0.0, 0.0, 0.17415, 0.11985, 0.11655],
            ),
            ShippedRobot::Iiwa14 => return None,
        };
        DhTable::new(vec![0.0; 6], a, d, alpha).ok()
    }

    /// The shipped robot whose nominal DH table `chain` is (its base and flange frames and
    /// geometry), if any: the table a controller's calibration is a delta to.
    pub fn matching_dh(chain: &Chain) -> Option<(ShippedRobot, DhTable)> {
        Self::ALL.into_iter().find_map(|robot| {
            let table = robot.nominal_dh()?;
            chain.with_dh(&table, &table).ok().map(|_| (robot, table))
        })
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

    #[test]
    fn each_ur_is_its_nominal_dh_table_and_only_that_one() {
        for robot in [ShippedRobot::Ur10, ShippedRobot::Ur10e] {
            let chain = robot.chain().unwrap();
            let (found, _) = ShippedRobot::matching_dh(&chain).unwrap();
            assert_eq!(found, robot);
        }
        assert!(ShippedRobot::matching_dh(&ShippedRobot::Iiwa14.chain().unwrap()).is_none());
    }
}
