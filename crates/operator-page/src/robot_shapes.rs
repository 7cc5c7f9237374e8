//! The robot's own shapes for the twin: each link's URDF visual primitives (box, cylinder,
//! sphere, capsule) in its link frame, and every link's pose at a joint sample. Mesh visuals are
//! not drawn (the page reads no files; the shipped descriptions use primitives), so a robot made
//! only of meshes shows as the line through its joints.

use std::collections::HashMap;
use std::path::Path;

use align_core::kinematics::{Geometry, JointKind, PackageMap, RobotModel};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use protocol::session::RobotSection;
use serde::Serialize;

/// One primitive of a link, in the link frame: what `GET /api/scene` lists under `robot_shapes`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ShapeDocument {
    pub link: String,
    /// `box`, `cylinder`, `sphere` or `capsule`; cylinders and capsules lie along z, as in URDF.
    pub kind: &'static str,
    /// Box: its edges; cylinder and capsule: radius, radius, length; sphere: radius three times.
    pub size_m: [f64; 3],
    pub xyz: [f64; 3],
    /// `[x, y, z, w]`.
    pub quaternion: [f64; 4],
}

/// A link's pose in the robot base frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LinkPose {
    pub link: String,
    pub xyz: [f64; 3],
    /// `[x, y, z, w]`.
    pub quaternion: [f64; 4],
}

fn pose_parts(pose: &Isometry3<f64>) -> ([f64; 3], [f64; 4]) {
    let t = pose.translation.vector;
    let q = pose.rotation.coords;
    ([t.x, t.y, t.z], [q.x, q.y, q.z, q.w])
}

/// The robot description, with the links below the base that have primitives to draw.
#[derive(Debug)]
pub struct RobotShapes {
    model: RobotModel,
    base: usize,
    /// Index into a joint sample of each chain joint, by name.
    sample_index: HashMap<String, usize>,
    shapes: Vec<ShapeDocument>,
    /// (link index, name) of every link with a shape.
    drawn: Vec<(usize, String)>,
}

impl RobotShapes {
    /// Loads the session's robot description; `chain_joints` names a joint sample's entries.
    pub fn load(robot: &RobotSection, folder: &Path, chain_joints: &[&str]) -> Option<Self> {
        let mut packages = PackageMap::new();
        for (name, dir) in &robot.package_dirs {
            packages.insert(name.clone(), folder.join(dir));
        }
        let model = RobotModel::from_urdf_file(&folder.join(&robot.urdf), &packages).ok()?;
        let base = model.link_id(&robot.base_link).ok()?;
        let mut shapes = Vec::new();
        let mut drawn = Vec::new();
        for (index, link) in model.links().iter().enumerate() {
            let before = shapes.len();
            for visual in &link.visuals {
                let (kind, size_m) = match &visual.geometry {
                    Geometry::Box { size_m } => ("box", *size_m),
                    Geometry::Cylinder { radius_m, length_m } => {
                        ("cylinder", [*radius_m, *radius_m, *length_m])
                    }
                    Geometry::Capsule { radius_m, length_m } => {
                        ("capsule", [*radius_m, *radius_m, *length_m])
                    }
                    Geometry::Sphere { radius_m } => ("sphere", [*radius_m; 3]),
                    Geometry::Mesh { .. } => continue,
                };
                let (xyz, quaternion) = pose_parts(&visual.link_from_shape);
                shapes.push(ShapeDocument {
                    link: link.name.clone(),
                    kind,
                    size_m,
                    xyz,
                    quaternion,
                });
            }
            if shapes.len() > before {
                drawn.push((index, link.name.clone()));
            }
        }
        let sample_index = chain_joints
            .iter()
            .enumerate()
            .map(|(i, name)| ((*name).to_owned(), i))
            .collect();
        let mut robot = Self {
            model,
            base,
            sample_index,
            shapes,
            drawn: Vec::new(),
        };
        // Links that do not hang below the base (a world link above it) are not drawn.
        robot.drawn = drawn
            .into_iter()
            .filter(|(index, _)| robot.base_from_link(*index, &[]).is_some())
            .collect();
        let drawn = &robot.drawn;
        robot
            .shapes
            .retain(|shape| drawn.iter().any(|(_, name)| *name == shape.link));
        Some(robot)
    }

    pub fn shapes(&self) -> &[ShapeDocument] {
        &self.shapes
    }

    /// The value of joint `name` in `q`: a chain joint's entry, a mimic joint's function of it,
    /// 0 for any other.
    fn joint_value(&self, name: &str, q: &[f64]) -> f64 {
        if let Some(value) = self.sample_index.get(name).and_then(|&i| q.get(i)) {
            return *value;
        }
        match self
            .model
            .joint(name)
            .and_then(|joint| joint.mimic.as_ref())
        {
            Some(mimic) => {
                let leader = self
                    .sample_index
                    .get(&mimic.joint)
                    .and_then(|&i| q.get(i))
                    .copied()
                    .unwrap_or(0.0);
                mimic.multiplier * leader + mimic.offset
            }
            None => 0.0,
        }
    }

    /// `base_from_link`, or `None` when the link does not hang below the base.
    fn base_from_link(&self, link: usize, q: &[f64]) -> Option<Isometry3<f64>> {
        let mut link_from_here = Isometry3::identity();
        let mut current = link;
        while current != self.base {
            let joint = self.model.parent_joint(current)?;
            let value = self.joint_value(&joint.name, q);
            let motion = match joint.kind {
                JointKind::Revolute | JointKind::Continuous => Isometry3::from_parts(
                    Translation3::identity(),
                    UnitQuaternion::from_axis_angle(&joint.axis, value),
                ),
                JointKind::Prismatic => Isometry3::from_parts(
                    Translation3::from(joint.axis.into_inner() * value),
                    UnitQuaternion::identity(),
                ),
                _ => Isometry3::identity(),
            };
            link_from_here = joint.parent_from_joint * motion * link_from_here;
            current = joint.parent;
        }
        Some(link_from_here)
    }

    /// Every drawn link's pose at joints `q`.
    pub fn link_poses(&self, q: &[f64]) -> Vec<LinkPose> {
        self.drawn
            .iter()
            .filter_map(|(index, name)| {
                let (xyz, quaternion) = pose_parts(&self.base_from_link(*index, q)?);
                Some(LinkPose {
                    link: name.clone(),
                    xyz,
                    quaternion,
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use align_core::robots::ShippedRobot;

    #[test]
    fn links_are_posed_as_the_chain_has_them() {
        let robots = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../robots");
        let section = RobotSection {
            urdf: "ur10.urdf".to_owned(),
            base_link: "base_link".to_owned(),
            tip_link: "tool0".to_owned(),
            package_dirs: Default::default(),
            kinematics: None,
            joint_offsets: None,
            joint_compliance: None,
            trigger_latency_s: None,
        };
        let chain = ShippedRobot::Ur10.chain().unwrap();
        let robot = RobotShapes::load(&section, &robots, &chain.joint_names()).unwrap();
        let q = [0.3, -1.2, 1.4, -1.8, -1.57, 0.2];
        let tool0 = robot.model.link_id("tool0").unwrap();
        let ours = robot.base_from_link(tool0, &q).unwrap();
        let theirs = chain.forward(&q).unwrap();
        assert!((ours.to_homogeneous() - theirs.to_homogeneous()).norm() < 1e-12);
        // Every link with a shape is posed, and every shape belongs to one.
        let posed = robot.link_poses(&q);
        assert!(posed.len() >= 6);
        assert!(
            robot
                .shapes()
                .iter()
                .all(|s| posed.iter().any(|p| p.link == s.link))
        );
    }
}
