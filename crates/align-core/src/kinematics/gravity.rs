//! Gravity loads on a chain's joints from the URDF link inertials and a payload at the tip.
//! Joint compliance makes a robot sag by these torques, which the diagnosis fits
//! (`joint_compliance`).

use nalgebra::{Point3, Vector3};

use super::chain::{Chain, motion};

/// Standard gravity, m/s^2 (ISO 80000-3).
pub const STANDARD_GRAVITY_M_S2: f64 = 9.80665;

/// A point mass carried by the chain's tip link, e.g. a tool.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointMass {
    pub mass_kg: f64,
    pub com_in_tip: Point3<f64>,
}

impl Chain {
    /// The torque (N m; N for a prismatic joint) gravity exerts about each joint at `q`, with
    /// gravity along -z of the chain's base frame: the links' masses (including those joined to
    /// chain links off the chain, at zero joint value) plus `payload` at the tip.
    ///
    /// The sign follows the joint axis: it is -dV/dq_j with V the potential energy, so a joint
    /// of compliance c (rad per N m) deflects by +c * tau, i.e. sags the way gravity pulls.
    /// Masses fixed before the first moving joint load none.
    pub fn gravity_torques_nm(&self, q: &[f64], payload: Option<&PointMass>) -> Vec<f64> {
        debug_assert_eq!(q.len(), self.dof());
        let gravity = Vector3::new(0.0, 0.0, -STANDARD_GRAVITY_M_S2);
        // Per segment: joint axis and a point on it, and the segment's mass and first moment,
        // all in the base frame.
        let mut axes = Vec::with_capacity(self.dof());
        let mut loads = Vec::with_capacity(self.dof());
        let mut base_from_current = self.base_from_first;
        for (index, (segment, &value)) in self.segments.iter().zip(q).enumerate() {
            let axis = base_from_current.rotation * segment.axis.into_inner();
            axes.push((
                axis,
                base_from_current.translation.vector,
                segment.prismatic,
            ));
            let base_from_moved = base_from_current * motion(segment, value);
            let mut mass_kg = segment.mass_kg;
            let mut first_moment = segment.first_moment_kg_m;
            if let (Some(payload), true) = (payload, index + 1 == self.dof()) {
                mass_kg += payload.mass_kg;
                first_moment += payload.mass_kg * (segment.after * payload.com_in_tip).coords;
            }
            loads.push((
                mass_kg,
                base_from_moved.rotation * first_moment
                    + mass_kg * base_from_moved.translation.vector,
            ));
            base_from_current = base_from_moved * segment.after;
        }
        // Sweep from the tip: joint j carries every segment from j on.
        let mut torques = vec![0.0; self.dof()];
        let (mut mass_kg, mut first_moment) = (0.0, Vector3::zeros());
        for j in (0..self.dof()).rev() {
            mass_kg += loads[j].0;
            first_moment += loads[j].1;
            let (axis, origin, prismatic) = axes[j];
            torques[j] = if prismatic {
                axis.dot(&(mass_kg * gravity))
            } else {
                // Sum of (c_i - o) x m_i g, projected on the axis.
                axis.dot(&((first_moment - mass_kg * origin).cross(&gravity)))
            };
        }
        torques
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::{PackageMap, RobotModel};
    use crate::robots::ShippedRobot;

    /// Two horizontal-axis links in the x-z plane: joint 1 at the origin, joint 2 at the end of
    /// the 0.5 m first link, a second link of 0.4 m; each mass at its link's middle, and a
    /// fixed-joint child of the second link carrying 0.5 kg at its end (off the chain).
    const TWO_LINK: &str = r#"<robot name="two_link">
      <link name="base"/>
      <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
        <origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/>
        <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
      <link name="l1"><inertial><origin xyz="0.25 0 0"/><mass value="2.0"/>
        <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
      <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
        <origin xyz="0.5 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/>
        <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
      <link name="l2"><inertial><origin xyz="0.2 0 0"/><mass value="1.0"/>
        <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
      <joint name="tip_fixed" type="fixed"><parent link="l2"/><child link="tip"/>
        <origin xyz="0.4 0 0" rpy="0 0 0"/></joint>
      <link name="tip"/>
      <joint name="weight_fixed" type="fixed"><parent link="l2"/><child link="weight"/>
        <origin xyz="0.4 0 0" rpy="0 0 0"/></joint>
      <link name="weight"><inertial><origin xyz="0 0 0"/><mass value="0.5"/>
        <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>
    </robot>"#;

    #[test]
    fn two_link_arm_matches_the_hand_computation() {
        let model = RobotModel::from_urdf_str(TWO_LINK, &PackageMap::new()).unwrap();
        let chain = model.chain("base", "tip").unwrap();
        let (q1, q2) = (0.3_f64, -0.7_f64);
        let payload = PointMass {
            mass_kg: 0.2,
            com_in_tip: Point3::new(0.1, 0.0, 0.0),
        };
        let torques = chain.gravity_torques_nm(&[q1, q2], Some(&payload));
        // A turn by q about +y takes x to (cos q, 0, -sin q), so a mass m at horizontal reach
        // x from a joint, pulled by (0, 0, -m g), feels (r x F)_y = z F_x - x F_z = m g x: a
        // positive torque, the way a positive turn lowers it.
        let g = STANDARD_GRAVITY_M_S2;
        let reach_2 = |l: f64| l * (q1 + q2).cos();
        let joint_2 = 1.0 * g * reach_2(0.2) + 0.5 * g * reach_2(0.4) + 0.2 * g * reach_2(0.5);
        let distal_mass_kg = 1.0 + 0.5 + 0.2;
        let joint_1 = 2.0 * g * 0.25 * q1.cos() + distal_mass_kg * g * 0.5 * q1.cos() + joint_2;
        assert!(
            (torques[1] - joint_2).abs() < 1e-9,
            "{torques:?} vs {joint_2}"
        );
        assert!(
            (torques[0] - joint_1).abs() < 1e-9,
            "{torques:?} vs {joint_1}"
        );
    }

    /// Potential energy of every link's mass plus the payload, from forward kinematics of the
    /// chain to each link: independent of the per-segment bookkeeping under test.
    fn potential_energy_j(
        model: &RobotModel,
        robot: ShippedRobot,
        q: &[f64],
        payload: &PointMass,
    ) -> f64 {
        let base = robot.base_link();
        let mut energy = 0.0;
        for link in model.links() {
            let Some(inertial) = &link.inertial else {
                continue;
            };
            let chain = model.chain(base, &link.name).unwrap();
            let base_from_link = chain.forward(&q[..chain.dof()]).unwrap();
            let com = base_from_link * Point3::from(inertial.link_from_com.translation.vector);
            energy += inertial.mass_kg * STANDARD_GRAVITY_M_S2 * com.z;
        }
        let tip = model.chain(base, robot.flange_link()).unwrap();
        let com = tip.forward(q).unwrap() * payload.com_in_tip;
        energy + payload.mass_kg * STANDARD_GRAVITY_M_S2 * com.z
    }

    #[test]
    fn shipped_robots_match_finite_differences_of_potential_energy() {
        let payload = PointMass {
            mass_kg: 1.3,
            com_in_tip: Point3::new(0.02, -0.01, 0.12),
        };
        for robot in ShippedRobot::ALL {
            let model = robot.model().unwrap();
            let chain = robot.chain().unwrap();
            let q: Vec<f64> = (0..chain.dof())
                .map(|j| 0.4 - 0.37 * j as f64 + 0.1 * (j * j) as f64)
                .collect();
            let torques = chain.gravity_torques_nm(&q, Some(&payload));
            for j in 0..chain.dof() {
                let step = 1e-6;
                let (mut plus, mut minus) = (q.clone(), q.clone());
                plus[j] += step;
                minus[j] -= step;
                let derivative = (potential_energy_j(&model, robot, &plus, &payload)
                    - potential_energy_j(&model, robot, &minus, &payload))
                    / (2.0 * step);
                assert!(
                    (torques[j] + derivative).abs() < 1e-5 * (1.0 + derivative.abs()),
                    "{} joint {j}: {} vs -dV/dq {}",
                    robot.name(),
                    torques[j],
                    -derivative
                );
            }
            // The first joint of each shipped arm turns about the vertical: gravity cannot
            // load it.
            assert!(torques[0].abs() < 1e-9, "{}: {torques:?}", robot.name());
        }
    }
}
