//! A session file resolved into what the alignment needs: the chain, the tool, the part's mesh
//! and the touches in the base frame. The file's shape is [`protocol::session`] (DESIGN.md 6.3).

use std::path::{Path, PathBuf};

use align_core::geometry::Mesh;
use align_core::io::read_mesh;
use align_core::kinematics::{Chain, DhTable, PackageMap, PointMass, RobotModel};
use align_core::pose::isometry_from_xyz_rpy;
use align_core::registration::psa::{Face, Touch};
use align_core::tool::Tool;
use nalgebra::{Isometry3, Point3, Vector3};
use protocol::Pose;
use protocol::session::{FORMAT, Inspection, RobotSection, SessionFile};

use crate::BadInput;

/// A session with everything resolved.
#[derive(Debug)]
pub struct LoadedSession {
    pub file: SessionFile,
    /// `None` when the session has no robot (every inspection gives its flange pose).
    pub chain: Option<Chain>,
    pub tool: Tool,
    pub mesh: Mesh,
    pub faces: Vec<Face>,
    pub base_from_part_nominal: Isometry3<f64>,
    pub touches: Vec<Touch>,
    /// The robot section's joint corrections, applied to every inspection's joints.
    pub corrections: JointCorrections,
}

fn pose(section: &Pose, what: &str) -> Result<Isometry3<f64>, BadInput> {
    if section
        .xyz
        .iter()
        .chain(&section.rpy)
        .all(|v| v.is_finite())
    {
        Ok(isometry_from_xyz_rpy(section.xyz, section.rpy))
    } else {
        Err(BadInput(format!("{what} has a non-finite value")))
    }
}

impl LoadedSession {
    /// The robot base frame every pose is relative to: the robot's `base_link`, or `base` for a
    /// session of flange poses without a robot.
    pub fn base_frame(&self) -> &str {
        self.file
            .robot
            .as_ref()
            .map_or("base", |robot| robot.base_link.as_str())
    }

    pub fn load(path: &Path) -> Result<Self, BadInput> {
        let text = std::fs::read_to_string(path).map_err(|error| {
            BadInput(format!("cannot read session '{}': {error}", path.display()))
        })?;
        let file = parse_session_file(&text, &path.display().to_string())?;
        let folder = path.parent().unwrap_or(Path::new("."));
        Self::resolve(file, folder)
    }

    /// Resolves `file`; a `robot.kinematics` in it (the controller's calibrated DH table)
    /// replaces the description's geometry when joints become flange poses.
    pub fn resolve(file: SessionFile, folder: &Path) -> Result<Self, BadInput> {
        let relative = |p: &str| -> PathBuf { folder.join(p) };
        let chain = match &file.robot {
            Some(robot) => {
                let mut packages = PackageMap::new();
                for (name, dir) in &robot.package_dirs {
                    packages.insert(name.clone(), relative(dir));
                }
                let model = RobotModel::from_urdf_file(&relative(&robot.urdf), &packages)
                    .map_err(BadInput::new)?;
                Some(
                    model
                        .chain(&robot.base_link, &robot.tip_link)
                        .map_err(BadInput::new)?,
                )
            }
            None => None,
        };
        let chain = match (
            chain,
            file.robot.as_ref().and_then(|r| r.kinematics.as_ref()),
        ) {
            (Some(chain), Some(kinematics)) => Some(
                Calibration::for_chain(kinematics, &chain)
                    .and_then(|calibration| calibration.apply(&chain))
                    .map_err(|reason| BadInput(format!("robot.kinematics: {reason}")))?,
            ),
            (chain, _) => chain,
        };
        let tool = Tool::new(
            pose(&file.tool.tcp, "tool.tcp")?,
            file.tool.tip_radius,
            file.tool.mass,
        )
        .map_err(BadInput::new)?;
        let soup =
            read_mesh(&relative(&file.part.mesh), file.part.mesh_scale).map_err(BadInput::new)?;
        let mesh = Mesh::new(&soup.vertices, &soup.triangles)
            .map_err(|error| BadInput(format!("part mesh '{}': {error}", file.part.mesh)))?;
        let faces = file
            .part
            .faces
            .iter()
            .map(|face| Face {
                name: face.name.clone(),
                normal: Vector3::from(face.normal),
                point: Point3::from(face.point),
            })
            .collect();
        let base_from_part_nominal = pose(&file.part.nominal_pose, "part.nominal_pose")?;
        if let Some(sigma) = file.noise_sigma
            && !(sigma.is_finite() && sigma >= 0.0)
        {
            return Err(BadInput(format!(
                "noise_sigma must be finite and >= 0, got {sigma}"
            )));
        }
        let corrections = match (&file.robot, &chain) {
            (Some(robot), Some(chain)) => JointCorrections::new(robot, chain, &tool)?,
            _ => JointCorrections::default(),
        };
        let mut touches = Vec::with_capacity(file.inspections.len());
        for inspection in &file.inspections {
            let corrected = corrections.corrected_inspection(inspection, chain.as_ref());
            let base_from_flange = base_from_flange(&corrected, chain.as_ref())?;
            let base_from_tcp = tool.base_from_tcp(&base_from_flange);
            touches.push(Touch {
                id: inspection.id.clone(),
                point: Point3::from(base_from_tcp.translation.vector),
                // The probe points along the TCP's z axis: that is the direction it travels into
                // the surface.
                approach: Some(base_from_tcp.rotation * Vector3::z()),
                face: inspection.face.clone(),
            });
        }
        Ok(Self {
            file,
            chain,
            tool,
            mesh,
            faces,
            base_from_part_nominal,
            touches,
            corrections,
        })
    }
}

/// The joint corrections a session's robot section declares (`joint_offsets`,
/// `joint_compliance`, `trigger_latency_s`), checked against its chain. With none, joints are
/// used as captured.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct JointCorrections {
    offsets_rad: Option<Vec<f64>>,
    compliance_rad_per_nm: Option<Vec<f64>>,
    latency_s: f64,
    payload: Option<PointMass>,
}

/// The longest capture latency a session may declare, s: longer is a unit mistake (ms).
const MAX_LATENCY_S: f64 = 1.0;

impl JointCorrections {
    fn new(robot: &RobotSection, chain: &Chain, tool: &Tool) -> Result<Self, BadInput> {
        let per_joint = |values: &Option<Vec<f64>>, key: &str| -> Result<(), BadInput> {
            let Some(values) = values else { return Ok(()) };
            if values.len() != chain.dof() {
                return Err(BadInput(format!(
                    "robot.{key} has {} values, the robot {} joints",
                    values.len(),
                    chain.dof()
                )));
            }
            match values.iter().position(|v| !v.is_finite()) {
                Some(index) => Err(BadInput(format!(
                    "robot.{key}[{index}] is not a finite number"
                ))),
                None => Ok(()),
            }
        };
        per_joint(&robot.joint_offsets, "joint_offsets")?;
        per_joint(&robot.joint_compliance, "joint_compliance")?;
        let latency_s = robot.trigger_latency_s.unwrap_or(0.0);
        if !(latency_s.is_finite() && latency_s.abs() <= MAX_LATENCY_S) {
            return Err(BadInput(format!(
                "robot.trigger_latency_s = {latency_s} must be finite and within +-{MAX_LATENCY_S} s (is it in ms?)"
            )));
        }
        Ok(Self {
            offsets_rad: robot.joint_offsets.clone(),
            compliance_rad_per_nm: robot.joint_compliance.clone(),
            latency_s,
            payload: Some(PointMass {
                mass_kg: tool.mass_kg,
                com_in_tip: tool.com_in_flange,
            }),
        })
    }

    /// True when no correction changes a joint.
    pub fn is_empty(&self) -> bool {
        self.offsets_rad.is_none() && self.compliance_rad_per_nm.is_none() && self.latency_s == 0.0
    }

    /// The joints the model uses for captured joints `q` (velocities `qd`): latency first
    /// (where the joints were at the touch), then the offsets and the gravity deflection, as the
    /// diagnosis models them.
    pub fn corrected(&self, q: &[f64], qd: Option<&[f64]>, chain: &Chain) -> Vec<f64> {
        let mut corrected = q.to_vec();
        if q.len() != chain.dof() {
            // base_from_flange refuses the inspection with the reason.
            return corrected;
        }
        if let Some(offsets) = &self.offsets_rad {
            corrected.iter_mut().zip(offsets).for_each(|(v, o)| *v += o);
        }
        if let Some(compliance) = &self.compliance_rad_per_nm {
            let torques = chain.gravity_torques_nm(q, self.payload.as_ref());
            for ((v, c), t) in corrected.iter_mut().zip(compliance).zip(torques) {
                *v += c * t;
            }
        }
        if let Some(qd) = qd.filter(|qd| qd.len() == q.len()) {
            corrected
                .iter_mut()
                .zip(qd)
                .for_each(|(v, d)| *v -= d * self.latency_s);
        }
        corrected
    }

    /// `inspection` with its joints corrected (unchanged when it gives a flange pose).
    pub fn corrected_inspection(
        &self,
        inspection: &Inspection,
        chain: Option<&Chain>,
    ) -> Inspection {
        let mut corrected = inspection.clone();
        if let (Some(q), Some(chain)) = (&inspection.q, chain)
            && !self.is_empty()
        {
            corrected.q = Some(self.corrected(q, inspection.qd.as_deref(), chain));
        }
        corrected
    }
}

/// A robot's factory calibration as its controller reports it: the calibrated DH table, the
/// nominal one it is a delta to, and the hash that names it.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    pub nominal: DhTable,
    pub calibrated: DhTable,
    pub hash: Option<String>,
}

impl Calibration {
    /// The controller's `kinematics` for the robot `chain` describes, or why it does not apply
    /// (the table is malformed, or the chain is not a robot whose nominal table is known).
    pub fn for_chain(
        kinematics: &protocol::calibration::ControllerKinematics,
        chain: &Chain,
    ) -> Result<Self, String> {
        kinematics.check()?;
        let calibrated = DhTable::new(
            kinematics.dh_theta.clone(),
            kinematics.dh_a.clone(),
            kinematics.dh_d.clone(),
            kinematics.dh_alpha.clone(),
        )
        .map_err(|error| error.to_string())?;
        let (_, nominal) = align_core::robots::ShippedRobot::matching_dh(chain).ok_or_else(|| {
            format!(
                "the session's chain {} -> {} is not a robot whose nominal DH table is known (UR10, UR10e)",
                chain.base_link(),
                chain.tip_link()
            )
        })?;
        // A calibration moves the flange millimetres; a table metres off is another robot.
        let probe = [0.3, -1.2, 1.4, -1.5, -1.4, 0.5];
        let apart = (nominal
            .forward(&probe)
            .map_err(|e| e.to_string())?
            .translation
            .vector
            - calibrated
                .forward(&probe)
                .map_err(|e| e.to_string())?
                .translation
                .vector)
            .norm();
        if apart > 0.05 {
            return Err(format!(
                "the controller's kinematics put the flange {:.0} mm from the description's: another robot model than the session's",
                apart * 1e3
            ));
        }
        Ok(Self {
            nominal,
            calibrated,
            hash: kinematics.hash.clone(),
        })
    }

    /// `chain` (the robot's description, base to flange) with the calibrated geometry.
    pub fn apply(&self, chain: &Chain) -> Result<Chain, String> {
        chain
            .with_dh(&self.nominal, &self.calibrated)
            .map_err(|error| error.to_string())
    }

    /// As a session file's `robot.kinematics`.
    pub fn to_kinematics(&self) -> protocol::calibration::ControllerKinematics {
        protocol::calibration::ControllerKinematics {
            dh_theta: self.calibrated.theta.clone(),
            dh_a: self.calibrated.a.clone(),
            dh_d: self.calibrated.d.clone(),
            dh_alpha: self.calibrated.alpha.clone(),
            hash: self.hash.clone(),
        }
    }

    /// How the status reply names it.
    pub fn describe(&self) -> String {
        format!(
            "calibrated ({}, from the controller)",
            self.hash.as_deref().unwrap_or("no hash")
        )
    }
}

/// Reads a session file's text, checking its format; `name` says where it came from in errors.
pub fn parse_session_file(text: &str, name: &str) -> Result<SessionFile, BadInput> {
    let file: SessionFile = serde_json::from_str(text)
        .map_err(|error| BadInput(format!("session '{name}': {error}")))?;
    if file.format != FORMAT {
        return Err(BadInput(format!(
            "session '{name}': format '{}' is not '{FORMAT}'",
            file.format
        )));
    }
    Ok(file)
}

/// The flange pose an inspection stands for: forward kinematics of its joints, or the
/// `flange_pose` it gives. Exactly one of the two must be present.
pub fn base_from_flange(
    inspection: &Inspection,
    chain: Option<&Chain>,
) -> Result<Isometry3<f64>, BadInput> {
    let id = &inspection.id;
    {
        match (&inspection.q, &inspection.flange_pose) {
            (Some(_), Some(_)) => Err(BadInput(format!(
                "inspection '{id}' gives both q and flange_pose: give one"
            ))),
            (None, None) => Err(BadInput(format!(
                "inspection '{id}' gives neither q (joints) nor flange_pose"
            ))),
            (None, Some(pose)) => flange_pose(pose)
                .map_err(|reason| BadInput(format!("inspection '{id}': flange_pose {reason}"))),
            (Some(q), None) => {
                let chain = chain.ok_or_else(|| {
                    BadInput(format!(
                        "inspection '{id}' gives joints (q) but the session has no robot to turn them into a flange pose"
                    ))
                })?;
                chain
                    .forward(q)
                    .map_err(|error| BadInput(format!("inspection '{id}': {error}")))
            }
        }
    }
}

/// How far past a joint's limit a reported value may lie before it is refused, rad (or m): a
/// controller reports the measured position, which can overshoot a limit by encoder noise.
const LIMIT_TOLERANCE: f64 = 1e-3;

/// Checks an inspection as the service would have captured it from `chain`: its pose is
/// computable (one of `q` and `flange_pose`, the right joint count, finite values) and its joints
/// lie within their limits, where a value such as 1e300 or a joint in degrees shows.
pub fn check_inspection(inspection: &Inspection, chain: &Chain) -> Result<(), BadInput> {
    base_from_flange(inspection, Some(chain))?;
    let Some(q) = &inspection.q else {
        return Ok(());
    };
    for (joint, &value) in chain.joints().iter().zip(q) {
        let (lower, upper) = (joint.limits.lower, joint.limits.upper);
        if value < lower - LIMIT_TOLERANCE || value > upper + LIMIT_TOLERANCE {
            return Err(BadInput(format!(
                "inspection '{}': joint '{}' = {value} is outside its limits [{lower}, {upper}] (rad or m)",
                inspection.id, joint.name
            )));
        }
    }
    Ok(())
}

/// `[x, y, z, rx, ry, rz]` (m, rotation vector in rad) as an isometry. A rotation vector longer
/// than pi is refused rather than wrapped: controllers report angles in [0, pi], so a longer one
/// is a unit mistake (degrees) or a corrupt value.
pub fn flange_pose(pose: &[f64; 6]) -> Result<Isometry3<f64>, String> {
    if let Some(index) = pose.iter().position(|v| !v.is_finite()) {
        return Err(format!("has a non-finite value at position {index}"));
    }
    let rotation = Vector3::new(pose[3], pose[4], pose[5]);
    let angle = rotation.norm();
    if angle > std::f64::consts::PI + 1e-9 {
        return Err(format!(
            "has a rotation vector of {angle:.4} rad, over pi: is it in degrees?"
        ));
    }
    Ok(Isometry3::new(
        Vector3::new(pose[0], pose[1], pose[2]),
        rotation,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flange_poses_are_rotation_vectors_up_to_pi_and_finite() {
        let pose = flange_pose(&[0.1, 0.2, 0.3, 0.0, 0.0, std::f64::consts::FRAC_PI_2]);
        let pose = pose.expect("valid");
        assert!((pose.translation.vector - Vector3::new(0.1, 0.2, 0.3)).norm() < 1e-15);
        assert!((pose.rotation * Vector3::x() - Vector3::y()).norm() < 1e-12);
        let nan = flange_pose(&[0.1, f64::NAN, 0.3, 0.0, 0.0, 0.0]).expect_err("NaN");
        assert_eq!(nan, "has a non-finite value at position 1");
        let infinite = flange_pose(&[0.1, 0.2, 0.3, 0.0, f64::INFINITY, 0.0]).expect_err("inf");
        assert_eq!(infinite, "has a non-finite value at position 4");
        let degrees = flange_pose(&[0.1, 0.2, 0.3, 0.0, 0.0, 90.0]).expect_err("degrees");
        assert!(degrees.contains("over pi: is it in degrees?"), "{degrees}");
    }
}
