//! Standard Denavit-Hartenberg tables, as Universal Robots publishes its nominal kinematics and as
//! each UR controller reports its factory calibration (the primary interface's KINEMATICS_INFO:
//! the calibrated table, nominal plus the robot's own deltas).
//!
//! Frame i is frame i-1 times Rz(theta_i + q_i) Tz(d_i) Tx(a_i) Rx(alpha_i); frame 0 is the
//! controller's base frame and frame n its tool flange. The shipped UR descriptions place
//! `base_link` at frame 0 and `tool0` at frame n (robots/generate.py), so a chain between them
//! can take a calibrated table's geometry as it is ([`Chain::with_dh`]).

use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};

use super::Chain;
use super::chain::Segment;
use super::error::KinematicsError;

/// A standard DH table: one entry per revolute joint, rad and m.
#[derive(Debug, Clone, PartialEq)]
pub struct DhTable {
    pub theta: Vec<f64>,
    pub a: Vec<f64>,
    pub d: Vec<f64>,
    pub alpha: Vec<f64>,
}

impl DhTable {
    /// A table of `theta`, `a`, `d`, `alpha` rows of equal length with finite values.
    pub fn new(
        theta: Vec<f64>,
        a: Vec<f64>,
        d: Vec<f64>,
        alpha: Vec<f64>,
    ) -> Result<Self, KinematicsError> {
        let joints = theta.len();
        for (name, row) in [("theta", &theta), ("a", &a), ("d", &d), ("alpha", &alpha)] {
            if row.len() != joints {
                return Err(KinematicsError::Dh(format!(
                    "DH row {name} has {} values, theta has {joints}",
                    row.len()
                )));
            }
            if let Some((joint, value)) = row.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(KinematicsError::Dh(format!(
                    "DH {name}[{joint}] is not a finite number ({value})"
                )));
            }
        }
        Ok(Self { theta, a, d, alpha })
    }

    pub fn joints(&self) -> usize {
        self.theta.len()
    }

    /// This table plus `delta`, entry by entry: UR's calibration semantics (the controller's
    /// calibrated table is the nominal one plus the robot's deltas).
    pub fn plus(&self, delta: &DhTable) -> Result<Self, KinematicsError> {
        if delta.joints() != self.joints() {
            return Err(KinematicsError::Dh(format!(
                "a delta for {} joints cannot apply to a table of {}",
                delta.joints(),
                self.joints()
            )));
        }
        let add = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(x, y)| x + y).collect();
        Self::new(
            add(&self.theta, &delta.theta),
            add(&self.a, &delta.a),
            add(&self.d, &delta.d),
            add(&self.alpha, &delta.alpha),
        )
    }

    /// The fixed part of joint `i`'s transform: Rz(theta) Tz(d) Tx(a) Rx(alpha).
    fn link(&self, i: usize) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.0, 0.0, self.d[i]),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.theta[i]),
        ) * Isometry3::from_parts(
            Translation3::new(self.a[i], 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), self.alpha[i]),
        )
    }

    /// Frame n in frame 0 at joint values `q` (one per joint).
    pub fn forward(&self, q: &[f64]) -> Result<Isometry3<f64>, KinematicsError> {
        if q.len() != self.joints() {
            return Err(KinematicsError::JointCount {
                expected: self.joints(),
                got: q.len(),
                joints: "of the DH table".to_owned(),
            });
        }
        Ok(q.iter()
            .enumerate()
            .fold(Isometry3::identity(), |pose, (i, &value)| {
                pose * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), value) * self.link(i)
            }))
    }
}

/// The joint names of UR's ROS kinematics files, shoulder to flange.
pub const UR_KINEMATICS_JOINTS: [&str; 6] = [
    "shoulder",
    "upper_arm",
    "forearm",
    "wrist_1",
    "wrist_2",
    "wrist_3",
];

impl DhTable {
    /// Each joint's frame in its parent's (the base frame for the first), as UR's ROS
    /// descriptions take them from a kinematics file: joint i turns about its frame's z, and the
    /// last joint's frame is the flange.
    ///
    /// A calibrated table is written with its joint frames where they physically are: each
    /// frame slides along its own axis to the point nearest where `nominal` puts the joint, and
    /// turns about it to face as the nominal frame does (neither changes the kinematics, only
    /// how they are written), so that d offsets of hundreds of metres on parallel joints become
    /// millimetres. Refused when the table's flange is not on the last axis (a or alpha of the
    /// last joint non-zero), which such a file cannot express.
    pub fn joint_origins(&self, nominal: &DhTable) -> Result<Vec<Isometry3<f64>>, KinematicsError> {
        let n = self.joints();
        if nominal.joints() != n || n == 0 {
            return Err(KinematicsError::Dh(format!(
                "the tables have {n} and {} joints",
                nominal.joints()
            )));
        }
        // Joint frames at q = 0: joint i turns about z of DH frame i-1; the nominal ones as the
        // files write them, moved by d_i along the axis.
        let dh_frames = |table: &DhTable| -> Vec<Isometry3<f64>> {
            let mut frames = vec![Isometry3::identity()];
            for i in 0..table.joints() {
                let next = frames[i] * table.link(i);
                frames.push(next);
            }
            frames
        };
        let calibrated = dh_frames(self);
        let reference = dh_frames(nominal);
        let mut joints: Vec<Isometry3<f64>> = (0..n)
            .map(|i| {
                let target = reference[i]
                    * Isometry3::from_parts(
                        Translation3::new(0.0, 0.0, nominal.d[i]),
                        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), nominal.theta[i]),
                    );
                let frame = calibrated[i];
                let axis = frame.rotation * Vector3::z();
                let origin = frame.translation.vector;
                let along = axis.dot(&(target.translation.vector - origin));
                let x_target = target.rotation * Vector3::x();
                let x = (x_target - axis * axis.dot(&x_target))
                    .try_normalize(1e-9)
                    .unwrap_or_else(|| frame.rotation * Vector3::x());
                let rotation = UnitQuaternion::from_rotation_matrix(
                    &nalgebra::Rotation3::from_basis_unchecked(&[x, axis.cross(&x), axis]),
                );
                Isometry3::from_parts(Translation3::from(origin + axis * along), rotation)
            })
            .collect();
        // The last joint's frame is the flange: it must lie on the last axis.
        let flange = calibrated[n];
        let last = joints[n - 1];
        let off_axis = (flange.rotation * Vector3::z()).angle(&(last.rotation * Vector3::z()));
        let offset = flange.translation.vector - last.translation.vector;
        let sideways = (offset
            - (last.rotation * Vector3::z()) * (last.rotation * Vector3::z()).dot(&offset))
        .norm();
        if off_axis > 1e-9 || sideways > 1e-9 {
            return Err(KinematicsError::Dh(format!(
                "the flange is {:.3} mm and {:.3} mrad off the last joint's axis (a or alpha of the last joint not zero): a kinematics file cannot express that",
                sideways * 1e3,
                off_axis * 1e3
            )));
        }
        joints[n - 1] = flange;
        let mut origins = Vec::with_capacity(n);
        let mut parent = Isometry3::identity();
        for frame in joints {
            origins.push(parent.inverse() * frame);
            parent = frame;
        }
        Ok(origins)
    }
}

/// Joint vectors at which a chain must agree with a DH table before it takes the table's
/// geometry: a spread over each joint's range, deterministic.
const AGREEMENT_POSES: usize = 8;
/// How far apart a chain and its DH table may put the flange and still be the same robot, m.
const AGREEMENT_TOLERANCE_M: f64 = 1e-6;

impl Chain {
    /// This chain with the geometry of `calibrated`, keeping its joints, limits and masses.
    ///
    /// The chain must be the robot `nominal` describes, frame 0 to frame n (`base_link` to
    /// `tool0` of a UR description): it is checked to put the flange where `nominal` does at
    /// several joint vectors. Each link's mass keeps its place in the base frame at q = 0: the
    /// calibrated frames may sit hundreds of metres along their axes (UR calibrations move the
    /// parallel joints' common normals and cancel the offsets), so the inertials cannot be
    /// copied frame to frame; along the axis that distance is no lever.
    pub fn with_dh(
        &self,
        nominal: &DhTable,
        calibrated: &DhTable,
    ) -> Result<Chain, KinematicsError> {
        let dof = self.dof();
        if nominal.joints() != dof || calibrated.joints() != dof {
            return Err(KinematicsError::Dh(format!(
                "the chain {} -> {} has {dof} joints, the DH tables {} and {}",
                self.base_link(),
                self.tip_link(),
                nominal.joints(),
                calibrated.joints()
            )));
        }
        if let Some(joint) = self.segments.iter().position(|s| s.prismatic) {
            return Err(KinematicsError::Dh(format!(
                "joint {} is prismatic; a DH table here describes revolute joints",
                self.joints()[joint].name
            )));
        }
        for pose in 0..AGREEMENT_POSES {
            let q: Vec<f64> = self
                .joints()
                .iter()
                .enumerate()
                .map(|(j, joint)| {
                    let (low, high) = (joint.limits.lower.max(-3.0), joint.limits.upper.min(3.0));
                    let fraction = ((pose * 7 + j * 3) % 11) as f64 / 10.0;
                    low + (high - low) * fraction
                })
                .collect();
            let from_chain = self.forward_unchecked(&q);
            let from_table = nominal.forward(&q)?;
            let apart = (from_chain.translation.vector - from_table.translation.vector).norm()
                + from_chain.rotation.angle_to(&from_table.rotation);
            if apart > AGREEMENT_TOLERANCE_M {
                return Err(KinematicsError::Dh(format!(
                    "the chain {} -> {} is not the robot of the nominal DH table (flange {:.3} mm apart at q = {q:.3?}): a calibration applies to the DH base frame and flange (a UR's base_link and tool0)",
                    self.base_link(),
                    self.tip_link(),
                    apart * 1e3
                )));
            }
        }
        // Each segment's frame after its motion, at q = 0, in both geometries.
        let zeros = vec![0.0; dof];
        let frames = |chain: &Chain| -> Vec<Isometry3<f64>> {
            let mut current = chain.base_from_first;
            chain
                .segments
                .iter()
                .zip(&zeros)
                .map(|(segment, &value)| {
                    current *= super::chain::motion(segment, value);
                    let frame = current;
                    current *= segment.after;
                    frame
                })
                .collect()
        };
        let nominal_frames = frames(self);
        let mut calibrated_chain = Chain {
            base_from_first: Isometry3::identity(),
            segments: (0..dof)
                .map(|i| Segment {
                    axis: Unit::new_unchecked(Vector3::z()),
                    prismatic: false,
                    after: calibrated.link(i),
                    mass_kg: 0.0,
                    first_moment_kg_m: Vector3::zeros(),
                })
                .collect(),
            ..self.clone()
        };
        let calibrated_frames = frames(&calibrated_chain);
        for (i, segment) in calibrated_chain.segments.iter_mut().enumerate() {
            let nominal_segment = &self.segments[i];
            segment.mass_kg = nominal_segment.mass_kg;
            if nominal_segment.mass_kg > 0.0 {
                let centre = nominal_segment.first_moment_kg_m / nominal_segment.mass_kg;
                let in_base = nominal_frames[i] * nalgebra::Point3::from(centre);
                let moved = calibrated_frames[i].inverse() * in_base;
                segment.first_moment_kg_m = nominal_segment.mass_kg * moved.coords;
            }
        }
        Ok(calibrated_chain)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::{PackageMap, RobotModel};
    use std::f64::consts::FRAC_PI_2;

    /// UR10e nominal DH (robots/generate.py).
    fn ur10e() -> DhTable {
        DhTable::new(
            vec![0.0; 6],
            vec![0.0, -0.6127, -0.57155, 0.0, 0.0, 0.0],
            vec![0.1807, 0.0, 0.0, 0.17415, 0.11985, 0.11655],
            vec![FRAC_PI_2, 0.0, 0.0, FRAC_PI_2, -FRAC_PI_2, 0.0],
        )
        .unwrap()
    }

    fn ur10e_chain() -> Chain {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../robots/ur10e.urdf");
        RobotModel::from_urdf_file(std::path::Path::new(path), &PackageMap::new())
            .unwrap()
            .chain("base_link", "tool0")
            .unwrap()
    }

    #[test]
    fn the_shipped_ur10e_is_its_dh_table_and_a_zero_delta_changes_nothing() {
        let chain = ur10e_chain();
        let nominal = ur10e();
        let same = chain.with_dh(&nominal, &nominal).unwrap();
        let q = [0.3, -1.2, 1.5, -0.9, 1.1, 0.4];
        let apart = chain.forward_unchecked(&q).translation.vector
            - same.forward_unchecked(&q).translation.vector;
        assert!(apart.norm() < 1e-12);
        let torques = chain.gravity_torques_nm(&q, None);
        let same_torques = same.gravity_torques_nm(&q, None);
        for (a, b) in torques.iter().zip(&same_torques) {
            assert!((a - b).abs() < 1e-9, "{torques:?} vs {same_torques:?}");
        }
    }

    #[test]
    fn large_cancelling_d_offsets_on_parallel_joints_keep_the_flange_and_the_torques() {
        // The shoulder's and elbow's common normal moved 440 m along the parallel axes and
        // back: the same robot, written differently.
        let chain = ur10e_chain();
        let nominal = ur10e();
        let mut far = nominal.clone();
        far.d[1] += 440.0;
        far.d[2] -= 440.0;
        let moved = chain.with_dh(&nominal, &far).unwrap();
        let q = [0.3, -1.2, 1.5, -0.9, 1.1, 0.4];
        let apart = chain.forward_unchecked(&q).translation.vector
            - moved.forward_unchecked(&q).translation.vector;
        assert!(apart.norm() < 1e-9, "{}", apart.norm());
        let torques = chain.gravity_torques_nm(&q, None);
        let moved_torques = moved.gravity_torques_nm(&q, None);
        for (a, b) in torques.iter().zip(&moved_torques) {
            assert!(
                (a - b).abs() < 1e-6 * a.abs().max(1.0),
                "{torques:?} vs {moved_torques:?}"
            );
        }
    }

    #[test]
    fn joint_origins_keep_the_kinematics_and_bring_far_frames_back() {
        let nominal = ur10e();
        let mut far = nominal.clone();
        far.d[1] += 440.0;
        far.d[2] -= 440.1;
        far.d[3] += 0.1;
        far.theta[1] += 0.002;
        far.alpha[2] += 0.001;
        for table in [&nominal, &far] {
            let origins = table.joint_origins(&nominal).unwrap();
            for k in 0..20 {
                let q: Vec<f64> = (0..6)
                    .map(|j| ((k * 7 + j * 5) % 13) as f64 * 0.4 - 2.4)
                    .collect();
                let from_origins =
                    origins
                        .iter()
                        .zip(&q)
                        .fold(Isometry3::identity(), |pose, (origin, &value)| {
                            pose * origin
                                * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), value)
                        });
                let expected = table.forward(&q).unwrap();
                assert!(
                    (from_origins.translation.vector - expected.translation.vector).norm() < 1e-9
                );
                assert!(from_origins.rotation.angle_to(&expected.rotation) < 1e-9);
            }
            // Written near the nominal places: no 440 m anywhere.
            for origin in &origins {
                assert!(origin.translation.vector.norm() < 1.0, "{origin}");
            }
        }
        // The nominal table gives the nominal file: shoulder at z = d1, forearm at x = a2.
        let origins = nominal.joint_origins(&nominal).unwrap();
        assert!((origins[0].translation.vector - Vector3::new(0.0, 0.0, 0.1807)).norm() < 1e-12);
        assert!((origins[2].translation.vector - Vector3::new(-0.6127, 0.0, 0.0)).norm() < 1e-12);
        let mut off = nominal.clone();
        off.a[5] = 0.01;
        assert!(off.joint_origins(&nominal).is_err());
    }

    #[test]
    fn a_chain_that_is_not_the_table_s_robot_is_refused() {
        let chain = ur10e_chain();
        let mut other = ur10e();
        other.a[1] = -0.612; // a UR10's upper arm
        let error = chain.with_dh(&other, &other).unwrap_err().to_string();
        assert!(
            error.contains("not the robot of the nominal DH table"),
            "{error}"
        );
        let error = DhTable::new(vec![0.0; 6], vec![0.0; 5], vec![0.0; 6], vec![0.0; 6])
            .unwrap_err()
            .to_string();
        assert!(error.contains("row a has 5 values"), "{error}");
        let error = DhTable::new(vec![f64::NAN; 6], vec![0.0; 6], vec![0.0; 6], vec![0.0; 6])
            .unwrap_err()
            .to_string();
        assert!(error.contains("theta[0]"), "{error}");
    }
}

/// Universal Robots' published figures: the nominal UR10 as its controller reports it, golden
/// flange positions from the ROS drivers' calibration tests, and three real calibrations.
// The numbers are kept digit for digit as published, and the controller's pi/2 is the
// 1.570796327 it reports, not the constant.
#[cfg(test)]
#[allow(clippy::excessive_precision, clippy::approx_constant)]
mod published {
    use super::*;

    /// The controller's pi/2.
    const PI_2: f64 = 1.570796327;

    fn ur10() -> DhTable {
        DhTable::new(
            vec![0.0; 6],
            vec![0.0, -0.612, -0.5723, 0.0, 0.0, 0.0],
            vec![0.1273, 0.0, 0.0, 0.163941, 0.1157, 0.0922],
            vec![PI_2, 0.0, 0.0, PI_2, -PI_2, 0.0],
        )
        .unwrap()
    }

    #[test]
    fn the_nominal_ur10_puts_the_flange_where_the_drivers_tests_expect() {
        let cases = [
            (
                [
                    -1.6007002035724084976209269370884,
                    -1.7271001974688928726209269370884,
                    -2.2029998938189905288709269370884,
                    -0.80799991289247685699592693708837,
                    1.59510004520416259765625,
                    -0.03099996248354131012092693708837,
                ],
                [-0.179925914147547, -0.606869755162764, 0.230789102067257],
            ),
            (
                [
                    1.32645022869110107421875,
                    2.426007747650146484375,
                    5.951572895050048828125,
                    1.27409040927886962890625,
                    -0.54105216661562138824592693708837,
                    0.122173048555850982666015625,
                ],
                [
                    0.39922988003280424074148413637886,
                    0.59688365069340565405298093537567,
                    -0.6677819040276375961440180617501,
                ],
            ),
        ];
        for (q, expected) in cases {
            let flange = ur10().forward(&q).unwrap().translation.vector;
            for axis in 0..3 {
                assert!(
                    (flange[axis] - expected[axis]).abs() < 1e-12,
                    "{flange:?} vs {expected:?}"
                );
            }
        }
    }

    #[test]
    fn real_calibrations_move_the_flange_millimetres_from_the_nominal_robot() {
        let mut state = 0x5eed_u64;
        let mut uniform = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for calibration in crate::corpus::calibrations::ur_driver_calibrations() {
            let name = format!("{}, {}", calibration.name, calibration.robot.name());
            let nominal = calibration.robot.nominal_dh().unwrap();
            let calibrated = calibration.calibrated().unwrap();
            let (mut sum, mut max) = (0.0, 0.0f64);
            let samples = 500;
            for _ in 0..samples {
                let q: Vec<f64> = (0..6).map(|_| (2.0 * uniform() - 1.0) * 3.1).collect();
                let offset = (nominal.forward(&q).unwrap().translation.vector
                    - calibrated.forward(&q).unwrap().translation.vector)
                    .norm();
                sum += offset;
                max = max.max(offset);
            }
            let mean = sum / samples as f64;
            println!("{name}: mean {:.2} mm, max {:.2} mm", mean * 1e3, max * 1e3);
            // Millimetres, never metres: the hundreds of metres of d cancel along the parallel
            // axes.
            assert!(
                mean > 2e-4 && mean < 1e-2 && max < 2e-2,
                "{name}: {mean} {max}"
            );
        }
    }
}
