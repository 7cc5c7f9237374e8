//! A robot description loaded from URDF and checked once, so that chains built from it never meet
//! a NaN, a zero axis or a dangling link name.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix3, Unit, Vector3};

use super::error::ModelError;
use super::mesh_uri::PackageMap;
use crate::pose::isometry_from_xyz_rpy;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointKind {
    Revolute,
    Continuous,
    Prismatic,
    Fixed,
    Floating,
    Planar,
    Spherical,
}

impl JointKind {
    pub fn name(self) -> &'static str {
        match self {
            JointKind::Revolute => "revolute",
            JointKind::Continuous => "continuous",
            JointKind::Prismatic => "prismatic",
            JointKind::Fixed => "fixed",
            JointKind::Floating => "floating",
            JointKind::Planar => "planar",
            JointKind::Spherical => "spherical",
        }
    }

    fn from_urdf(kind: &urdf_rs::JointType) -> Self {
        match kind {
            urdf_rs::JointType::Revolute => JointKind::Revolute,
            urdf_rs::JointType::Continuous => JointKind::Continuous,
            urdf_rs::JointType::Prismatic => JointKind::Prismatic,
            urdf_rs::JointType::Fixed => JointKind::Fixed,
            urdf_rs::JointType::Floating => JointKind::Floating,
            urdf_rs::JointType::Planar => JointKind::Planar,
            urdf_rs::JointType::Spherical => JointKind::Spherical,
        }
    }
}

/// Position limits (rad or m; infinite for continuous joints), speed (rad/s or m/s) and effort
/// (N m or N) of a joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimits {
    pub lower: f64,
    pub upper: f64,
    pub velocity: f64,
    pub effort: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Mimic {
    pub joint: String,
    pub multiplier: f64,
    pub offset: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Joint {
    pub name: String,
    pub kind: JointKind,
    pub parent: usize,
    pub child: usize,
    /// The joint frame (equal to the child link frame at zero joint value) in the parent link.
    pub parent_from_joint: Isometry3<f64>,
    pub axis: Unit<Vector3<f64>>,
    pub limits: JointLimits,
    pub mimic: Option<Mimic>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Inertial {
    pub mass_kg: f64,
    pub link_from_com: Isometry3<f64>,
    /// Inertia tensor about the centre of mass in the `link_from_com` frame, kg m^2.
    pub inertia_kg_m2: Matrix3<f64>,
}

#[derive(Debug, Clone, PartialEq)]
pub enum Geometry {
    Box {
        size_m: [f64; 3],
    },
    Cylinder {
        radius_m: f64,
        length_m: f64,
    },
    Capsule {
        radius_m: f64,
        length_m: f64,
    },
    Sphere {
        radius_m: f64,
    },
    Mesh {
        uri: String,
        scale: [f64; 3],
        /// The mesh file on this machine, or why it could not be found. Kinematics never needs
        /// the file, so a missing mesh is reported, not fatal.
        resolved: Result<PathBuf, String>,
    },
}

#[derive(Debug, Clone, PartialEq)]
pub struct Shape {
    pub link_from_shape: Isometry3<f64>,
    pub geometry: Geometry,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Link {
    pub name: String,
    pub inertial: Option<Inertial>,
    pub visuals: Vec<Shape>,
    pub collisions: Vec<Shape>,
}

/// A validated kinematic tree.
#[derive(Debug, Clone)]
pub struct RobotModel {
    pub name: String,
    links: Vec<Link>,
    joints: Vec<Joint>,
    link_index: HashMap<String, usize>,
    /// The joint whose child is each link (`None` for roots).
    parent_joint: Vec<Option<usize>>,
}

impl RobotModel {
    /// Loads a URDF file; relative and `package://` mesh URIs are resolved against the file's
    /// folder and `packages`.
    pub fn from_urdf_file(path: &Path, packages: &PackageMap) -> Result<Self, ModelError> {
        let text = std::fs::read_to_string(path).map_err(|source| ModelError::Read {
            path: path.to_owned(),
            source,
        })?;
        let origin = path.display().to_string();
        let urdf_dir = path.parent().map(|dir| {
            if dir.as_os_str().is_empty() {
                Path::new(".")
            } else {
                dir
            }
        });
        Self::from_urdf_text(&text, &origin, urdf_dir, packages)
    }

    /// Loads URDF text; `origin` names it in errors, `urdf_dir` anchors relative mesh URIs.
    pub fn from_urdf_str(text: &str, packages: &PackageMap) -> Result<Self, ModelError> {
        Self::from_urdf_text(text, "<string>", None, packages)
    }

    fn from_urdf_text(
        text: &str,
        origin: &str,
        urdf_dir: Option<&Path>,
        packages: &PackageMap,
    ) -> Result<Self, ModelError> {
        if text.contains("<xacro:") {
            return Err(ModelError::Xacro {
                origin: origin.to_owned(),
            });
        }
        let robot = urdf_rs::read_from_string(text).map_err(|error| ModelError::Parse {
            origin: origin.to_owned(),
            message: error.to_string(),
        })?;
        Self::from_urdf(&robot, urdf_dir, packages)
    }

    fn from_urdf(
        robot: &urdf_rs::Robot,
        urdf_dir: Option<&Path>,
        packages: &PackageMap,
    ) -> Result<Self, ModelError> {
        if robot.links.is_empty() {
            return Err(ModelError::NoLinks {
                robot: robot.name.clone(),
            });
        }
        let mut link_index = HashMap::new();
        let mut links = Vec::with_capacity(robot.links.len());
        for link in &robot.links {
            if link_index.insert(link.name.clone(), links.len()).is_some() {
                return Err(ModelError::DuplicateLink {
                    link: link.name.clone(),
                });
            }
            links.push(convert_link(link, urdf_dir, packages)?);
        }
        let mut joints: Vec<Joint> = Vec::with_capacity(robot.joints.len());
        let mut parent_joint = vec![None; links.len()];
        for urdf_joint in &robot.joints {
            if joints.iter().any(|joint| joint.name == urdf_joint.name) {
                return Err(ModelError::DuplicateJoint {
                    joint: urdf_joint.name.clone(),
                });
            }
            let joint = convert_joint(urdf_joint, &link_index)?;
            if let Some(other) = parent_joint[joint.child] {
                let other: &Joint = &joints[other];
                return Err(ModelError::KinematicLoop {
                    description: format!(
                        "link '{}' is the child of both joint '{}' and joint '{}'",
                        links[joint.child].name, other.name, joint.name
                    ),
                });
            }
            parent_joint[joint.child] = Some(joints.len());
            joints.push(joint);
        }
        let model = Self {
            name: robot.name.clone(),
            links,
            joints,
            link_index,
            parent_joint,
        };
        model.check_acyclic()?;
        Ok(model)
    }

    /// With at most one parent per link, a loop is a cycle of parent pointers: walking up from
    /// any link must reach a root within as many steps as there are links.
    fn check_acyclic(&self) -> Result<(), ModelError> {
        for start in 0..self.links.len() {
            let mut link = start;
            let mut steps = 0;
            while let Some(joint) = self.parent_joint[link] {
                link = self.joints[joint].parent;
                steps += 1;
                if steps > self.links.len() {
                    let cycle = self.describe_cycle(start);
                    return Err(ModelError::KinematicLoop {
                        description: format!("the joints {cycle} form a cycle"),
                    });
                }
            }
        }
        Ok(())
    }

    fn describe_cycle(&self, start: usize) -> String {
        // Walk far enough to be inside the cycle, then collect it once.
        let mut link = start;
        for _ in 0..self.links.len() {
            link = self.parent_of(link).unwrap_or(link);
        }
        let first = link;
        let mut names = Vec::new();
        while let Some(joint) = self.parent_joint[link] {
            names.push(format!("'{}'", self.joints[joint].name));
            link = self.joints[joint].parent;
            if link == first {
                break;
            }
        }
        names.join(", ")
    }

    fn parent_of(&self, link: usize) -> Option<usize> {
        self.parent_joint[link].map(|joint| self.joints[joint].parent)
    }

    pub fn links(&self) -> &[Link] {
        &self.links
    }

    pub fn joints(&self) -> &[Joint] {
        &self.joints
    }

    pub fn link(&self, name: &str) -> Option<&Link> {
        self.link_index.get(name).map(|&index| &self.links[index])
    }

    pub fn joint(&self, name: &str) -> Option<&Joint> {
        self.joints.iter().find(|joint| joint.name == name)
    }

    /// Index of a link, or an error listing the links there are.
    pub fn link_id(&self, name: &str) -> Result<usize, ModelError> {
        self.link_index
            .get(name)
            .copied()
            .ok_or_else(|| ModelError::NoSuchLink {
                link: name.to_owned(),
                robot: self.name.clone(),
                known: self
                    .links
                    .iter()
                    .map(|link| link.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
            })
    }

    /// The joint whose child is `link`, if any.
    pub fn parent_joint(&self, link: usize) -> Option<&Joint> {
        self.parent_joint[link].map(|joint| &self.joints[joint])
    }

    /// Joints from `link` up to its root, nearest first.
    pub(crate) fn joints_to_root(&self, link: usize) -> Vec<usize> {
        let mut path = Vec::new();
        let mut current = link;
        while let Some(joint) = self.parent_joint[current] {
            path.push(joint);
            current = self.joints[joint].parent;
        }
        path
    }

    /// Mesh URIs that could not be resolved to files, as `link 'x': reason` lines.
    pub fn mesh_problems(&self) -> Vec<String> {
        let mut problems = Vec::new();
        for link in &self.links {
            for shape in link.visuals.iter().chain(&link.collisions) {
                if let Geometry::Mesh {
                    resolved: Err(reason),
                    ..
                } = &shape.geometry
                {
                    problems.push(format!("link '{}': {reason}", link.name));
                }
            }
        }
        problems.dedup();
        problems
    }
}

fn finite_vec3(
    values: [f64; 3],
    element: impl Fn() -> String,
    field: &'static str,
) -> Result<[f64; 3], ModelError> {
    if values.iter().all(|value| value.is_finite()) {
        Ok(values)
    } else {
        Err(ModelError::NonFinite {
            element: element(),
            field,
            value: format!("{} {} {}", values[0], values[1], values[2]),
        })
    }
}

fn finite(
    value: f64,
    element: impl Fn() -> String,
    field: &'static str,
) -> Result<f64, ModelError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(ModelError::NonFinite {
            element: element(),
            field,
            value: value.to_string(),
        })
    }
}

fn convert_pose(
    pose: &urdf_rs::Pose,
    element: impl Fn() -> String,
) -> Result<Isometry3<f64>, ModelError> {
    let xyz = finite_vec3(pose.xyz.0, &element, "origin xyz")?;
    let rpy = finite_vec3(pose.rpy.0, &element, "origin rpy")?;
    Ok(isometry_from_xyz_rpy(xyz, rpy))
}

fn convert_joint(
    joint: &urdf_rs::Joint,
    link_index: &HashMap<String, usize>,
) -> Result<Joint, ModelError> {
    let element = || format!("joint '{}'", joint.name);
    let find = |link: &str, role| {
        link_index
            .get(link)
            .copied()
            .ok_or_else(|| ModelError::MissingLink {
                joint: joint.name.clone(),
                role,
                link: link.to_owned(),
            })
    };
    let parent = find(&joint.parent.link, "parent")?;
    let child = find(&joint.child.link, "child")?;
    let kind = JointKind::from_urdf(&joint.joint_type);
    let parent_from_joint = convert_pose(&joint.origin, element)?;
    let axis_xyz = finite_vec3(joint.axis.xyz.0, element, "axis")?;
    let axis = Vector3::from(axis_xyz);
    let moves = !matches!(kind, JointKind::Fixed | JointKind::Floating);
    let axis = match Unit::try_new(axis, 1e-12) {
        Some(axis) => axis,
        None if moves => {
            return Err(ModelError::ZeroAxis {
                joint: joint.name.clone(),
            });
        }
        None => Vector3::z_axis(),
    };
    let limits = convert_limits(joint, kind)?;
    let mimic = match &joint.mimic {
        Some(mimic) => Some(Mimic {
            joint: mimic.joint.clone(),
            multiplier: finite(mimic.multiplier.unwrap_or(1.0), element, "mimic multiplier")?,
            offset: finite(mimic.offset.unwrap_or(0.0), element, "mimic offset")?,
        }),
        None => None,
    };
    Ok(Joint {
        name: joint.name.clone(),
        kind,
        parent,
        child,
        parent_from_joint,
        axis,
        limits,
        mimic,
    })
}

fn convert_limits(joint: &urdf_rs::Joint, kind: JointKind) -> Result<JointLimits, ModelError> {
    let limit = &joint.limit;
    let not_nan = |value: f64, field| {
        if value.is_nan() {
            Err(ModelError::NonFinite {
                element: format!("joint '{}'", joint.name),
                field,
                value: value.to_string(),
            })
        } else {
            Ok(value)
        }
    };
    let mut limits = JointLimits {
        lower: not_nan(limit.lower, "limit lower")?,
        upper: not_nan(limit.upper, "limit upper")?,
        velocity: not_nan(limit.velocity, "limit velocity")?,
        effort: not_nan(limit.effort, "limit effort")?,
    };
    if kind == JointKind::Continuous {
        limits.lower = f64::NEG_INFINITY;
        limits.upper = f64::INFINITY;
    }
    if limits.lower > limits.upper {
        return Err(ModelError::InvalidLimits {
            joint: joint.name.clone(),
            lower: limits.lower,
            upper: limits.upper,
        });
    }
    Ok(limits)
}

fn convert_link(
    link: &urdf_rs::Link,
    urdf_dir: Option<&Path>,
    packages: &PackageMap,
) -> Result<Link, ModelError> {
    let element = || format!("link '{}'", link.name);
    let mass_kg = finite(link.inertial.mass.value, element, "mass")?;
    if mass_kg < 0.0 {
        return Err(ModelError::NegativeMass {
            link: link.name.clone(),
            mass_kg,
        });
    }
    let inertial = if mass_kg > 0.0 {
        let i = &link.inertial.inertia;
        let inertia = Matrix3::new(
            i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz,
        );
        if inertia.iter().any(|value| !value.is_finite()) {
            return Err(ModelError::NonFinite {
                element: element(),
                field: "inertia",
                value: format!("{inertia:?}"),
            });
        }
        Some(Inertial {
            mass_kg,
            link_from_com: convert_pose(&link.inertial.origin, || {
                format!("link '{}' inertial", link.name)
            })?,
            inertia_kg_m2: inertia,
        })
    } else {
        None
    };
    let shape = |origin: &urdf_rs::Pose, geometry: &urdf_rs::Geometry, what: &str| {
        let element = || format!("link '{}' {what}", link.name);
        Ok::<_, ModelError>(Shape {
            link_from_shape: convert_pose(origin, element)?,
            geometry: convert_geometry(geometry, urdf_dir, packages),
        })
    };
    Ok(Link {
        name: link.name.clone(),
        inertial,
        visuals: link
            .visual
            .iter()
            .map(|visual| shape(&visual.origin, &visual.geometry, "visual"))
            .collect::<Result<_, _>>()?,
        collisions: link
            .collision
            .iter()
            .map(|collision| shape(&collision.origin, &collision.geometry, "collision"))
            .collect::<Result<_, _>>()?,
    })
}

fn convert_geometry(
    geometry: &urdf_rs::Geometry,
    urdf_dir: Option<&Path>,
    packages: &PackageMap,
) -> Geometry {
    match geometry {
        urdf_rs::Geometry::Box { size } => Geometry::Box { size_m: size.0 },
        urdf_rs::Geometry::Cylinder { radius, length } => Geometry::Cylinder {
            radius_m: *radius,
            length_m: *length,
        },
        urdf_rs::Geometry::Capsule { radius, length } => Geometry::Capsule {
            radius_m: *radius,
            length_m: *length,
        },
        urdf_rs::Geometry::Sphere { radius } => Geometry::Sphere { radius_m: *radius },
        urdf_rs::Geometry::Mesh { filename, scale } => Geometry::Mesh {
            uri: filename.clone(),
            scale: scale.map_or([1.0; 3], |scale| scale.0),
            resolved: packages.resolve(filename, urdf_dir),
        },
    }
}
