//! A serial chain between any two links of a [`RobotModel`], compiled for fast evaluation:
//! consecutive fixed transforms are merged, so evaluating the chain costs one rotation or
//! translation and one transform product per moving joint.
//!
//! The path may run up the tree (from `base` towards a common ancestor) and then down (to `tip`);
//! a joint crossed upwards contributes the inverse of its transform, which is a motion about the
//! negated axis followed by the inverse of its origin.

use nalgebra::{Isometry3, Matrix6xX, Point3, Translation3, Unit, UnitQuaternion, Vector3};

use super::error::{KinematicsError, ModelError};
use super::model::{JointKind, JointLimits, RobotModel};

/// One movable joint of a chain, as the chain's joint vector orders them (base to tip).
#[derive(Debug, Clone, PartialEq)]
pub struct ChainJoint {
    pub name: String,
    pub kind: JointKind,
    pub limits: JointLimits,
    /// True when the path crosses this joint from child to parent.
    pub reversed: bool,
}

#[derive(Debug, Clone, PartialEq)]
pub(super) struct Segment {
    /// Joint axis in the frame just before the motion, negated for joints crossed upwards.
    pub(super) axis: Unit<Vector3<f64>>,
    pub(super) prismatic: bool,
    /// Fixed transform from the frame after this motion to the frame before the next one.
    pub(super) after: Isometry3<f64>,
    /// Mass carried rigidly by this segment (its links and everything hanging off them but not
    /// on the chain), kg.
    pub(super) mass_kg: f64,
    /// That mass times its centre of mass in the frame after this motion, kg m.
    pub(super) first_moment_kg_m: Vector3<f64>,
}

/// Forward kinematics, Jacobian and limits of the chain `base_link -> tip_link`.
#[derive(Debug, Clone, PartialEq)]
pub struct Chain {
    pub(super) base_link: String,
    pub(super) tip_link: String,
    pub(super) base_from_first: Isometry3<f64>,
    pub(super) segments: Vec<Segment>,
    pub(super) joints: Vec<ChainJoint>,
}

enum Step {
    Fixed(Isometry3<f64>),
    Motion(Unit<Vector3<f64>>, bool),
    /// A point mass (kg, centre in the current frame) moving with the current link.
    Mass(f64, Point3<f64>),
}

impl Chain {
    /// Builds the chain from `base` to `tip`; either may be any link of the model.
    pub fn new(model: &RobotModel, base: &str, tip: &str) -> Result<Self, ModelError> {
        let base_id = model.link_id(base)?;
        let tip_id = model.link_id(tip)?;
        let mut up = model.joints_to_root(base_id);
        let mut down = model.joints_to_root(tip_id);
        // Drop the shared part of the two root paths: what is left meets at the common ancestor.
        while let (Some(a), Some(b)) = (up.last(), down.last()) {
            if a != b {
                break;
            }
            up.pop();
            down.pop();
        }
        let root = |path: &[usize], from: usize| {
            path.last()
                .map_or(from, |&joint| model.joints()[joint].parent)
        };
        if root(&up, base_id) != root(&down, tip_id) {
            return Err(ModelError::NotConnected {
                base: base.to_owned(),
                tip: tip.to_owned(),
            });
        }
        let on_path: Vec<usize> = up.iter().chain(&down).copied().collect();
        let mut steps = Vec::new();
        let mut joints = Vec::new();
        let crossed = up
            .iter()
            .map(|&joint| (joint, true))
            .chain(down.iter().rev().map(|&joint| (joint, false)));
        for (joint_id, reversed) in crossed {
            let joint = &model.joints()[joint_id];
            let moving = match joint.kind {
                JointKind::Fixed => false,
                JointKind::Revolute | JointKind::Continuous | JointKind::Prismatic => true,
                JointKind::Floating | JointKind::Planar | JointKind::Spherical => {
                    return Err(ModelError::UnsupportedJointInChain {
                        joint: joint.name.clone(),
                        kind: joint.kind.name(),
                        base: base.to_owned(),
                        tip: tip.to_owned(),
                    });
                }
            };
            if let (true, Some(mimic)) = (moving, &joint.mimic) {
                return Err(ModelError::MimicInChain {
                    joint: joint.name.clone(),
                    master: mimic.joint.clone(),
                    base: base.to_owned(),
                    tip: tip.to_owned(),
                });
            }
            let prismatic = joint.kind == JointKind::Prismatic;
            if reversed {
                if moving {
                    steps.push(Step::Motion(-joint.axis, prismatic));
                }
                steps.push(Step::Fixed(joint.parent_from_joint.inverse()));
                steps.extend(attached_masses(model, joint.parent, &on_path));
            } else {
                steps.push(Step::Fixed(joint.parent_from_joint));
                if moving {
                    steps.push(Step::Motion(joint.axis, prismatic));
                }
                steps.extend(attached_masses(model, joint.child, &on_path));
            }
            if moving {
                joints.push(ChainJoint {
                    name: joint.name.clone(),
                    kind: joint.kind,
                    limits: joint.limits,
                    reversed,
                });
            }
        }
        let (base_from_first, segments) = compile(steps);
        Ok(Self {
            base_link: base.to_owned(),
            tip_link: tip.to_owned(),
            base_from_first,
            segments,
            joints,
        })
    }

    pub fn base_link(&self) -> &str {
        &self.base_link
    }

    pub fn tip_link(&self) -> &str {
        &self.tip_link
    }

    /// Number of joint values the chain takes.
    pub fn dof(&self) -> usize {
        self.joints.len()
    }

    pub fn joints(&self) -> &[ChainJoint] {
        &self.joints
    }

    pub fn joint_names(&self) -> Vec<&str> {
        self.joints
            .iter()
            .map(|joint| joint.name.as_str())
            .collect()
    }

    /// Checks the length and finiteness of a joint vector.
    pub fn check_joints(&self, q: &[f64]) -> Result<(), KinematicsError> {
        if q.len() != self.dof() {
            return Err(KinematicsError::JointCount {
                expected: self.dof(),
                got: q.len(),
                joints: self.joint_names().join(", "),
            });
        }
        match q.iter().position(|value| !value.is_finite()) {
            Some(index) => Err(KinematicsError::NonFiniteJoint {
                index,
                joint: self.joints[index].name.clone(),
                value: q[index],
            }),
            None => Ok(()),
        }
    }

    /// True when every joint value lies within its position limits.
    pub fn within_limits(&self, q: &[f64]) -> bool {
        self.joints
            .iter()
            .zip(q)
            .all(|(joint, &value)| value >= joint.limits.lower && value <= joint.limits.upper)
    }

    /// Clamps joint values to their position limits in place.
    pub fn clamp_to_limits(&self, q: &mut [f64]) {
        for (joint, value) in self.joints.iter().zip(q.iter_mut()) {
            *value = value.clamp(joint.limits.lower, joint.limits.upper);
        }
    }

    /// `base_from_tip` at joint values `q`, after checking them.
    pub fn forward(&self, q: &[f64]) -> Result<Isometry3<f64>, KinematicsError> {
        self.check_joints(q)?;
        Ok(self.forward_unchecked(q))
    }

    /// `base_from_tip` for a joint vector already known to be valid (hot loops).
    pub fn forward_unchecked(&self, q: &[f64]) -> Isometry3<f64> {
        debug_assert_eq!(q.len(), self.dof());
        let mut base_from_current = self.base_from_first;
        for (segment, &value) in self.segments.iter().zip(q) {
            base_from_current = base_from_current * motion(segment, value) * segment.after;
        }
        base_from_current
    }

    /// The frame of each joint just before its motion, then the tip: `dof + 1` poses in the
    /// base frame, e.g. to draw the arm as a line through its joints. Joints missing from a
    /// short `q` are left out.
    pub fn joint_frames_unchecked(&self, q: &[f64]) -> Vec<Isometry3<f64>> {
        let mut frames = Vec::with_capacity(self.segments.len() + 1);
        let mut base_from_current = self.base_from_first;
        for (segment, &value) in self.segments.iter().zip(q) {
            frames.push(base_from_current);
            base_from_current = base_from_current * motion(segment, value) * segment.after;
        }
        frames.push(base_from_current);
        frames
    }

    /// Geometric Jacobian in the base frame at the tip origin: rows 0-2 map joint rates to the
    /// tip's linear velocity, rows 3-5 to its angular velocity.
    pub fn jacobian(&self, q: &[f64]) -> Result<Matrix6xX<f64>, KinematicsError> {
        self.check_joints(q)?;
        Ok(self.jacobian_unchecked(q).1)
    }

    /// The tip pose and Jacobian together, sharing one pass over the chain.
    pub fn jacobian_unchecked(&self, q: &[f64]) -> (Isometry3<f64>, Matrix6xX<f64>) {
        let mut jacobian = Matrix6xX::zeros(self.dof());
        let mut axes = Vec::with_capacity(self.dof());
        let mut base_from_current = self.base_from_first;
        for (segment, &value) in self.segments.iter().zip(q) {
            axes.push((
                base_from_current.rotation * segment.axis.into_inner(),
                base_from_current.translation.vector,
            ));
            base_from_current = base_from_current * motion(segment, value) * segment.after;
        }
        let tip = base_from_current.translation.vector;
        for (column, (segment, (axis, origin))) in self.segments.iter().zip(axes).enumerate() {
            let (linear, angular) = if segment.prismatic {
                (axis, Vector3::zeros())
            } else {
                (axis.cross(&(tip - origin)), axis)
            };
            jacobian
                .fixed_view_mut::<3, 1>(0, column)
                .copy_from(&linear);
            jacobian
                .fixed_view_mut::<3, 1>(3, column)
                .copy_from(&angular);
        }
        (base_from_current, jacobian)
    }
}

pub(super) fn motion(segment: &Segment, value: f64) -> Isometry3<f64> {
    if segment.prismatic {
        Isometry3::from_parts(
            Translation3::from(segment.axis.into_inner() * value),
            UnitQuaternion::identity(),
        )
    } else {
        Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(&segment.axis, value),
        )
    }
}

/// Point masses of `link` and of every link joined to it other than through the chain's own
/// joints, as `Step::Mass` in `link`'s frame. Joints off the chain are taken at zero: their
/// values are not part of the chain's joint vector.
fn attached_masses(model: &RobotModel, link: usize, on_path: &[usize]) -> Vec<Step> {
    let mut masses = Vec::new();
    let mut pending = vec![(link, Isometry3::identity())];
    let mut visited = vec![link];
    while let Some((current, frame_from_current)) = pending.pop() {
        if let Some(inertial) = &model.links()[current].inertial {
            let com = frame_from_current * Point3::from(inertial.link_from_com.translation.vector);
            masses.push(Step::Mass(inertial.mass_kg, com));
        }
        for (index, joint) in model.joints().iter().enumerate() {
            if on_path.contains(&index) {
                continue;
            }
            let neighbour = if joint.parent == current {
                Some((joint.child, frame_from_current * joint.parent_from_joint))
            } else if joint.child == current {
                Some((
                    joint.parent,
                    frame_from_current * joint.parent_from_joint.inverse(),
                ))
            } else {
                None
            };
            match neighbour {
                Some((next, frame_from_next)) if !visited.contains(&next) => {
                    visited.push(next);
                    pending.push((next, frame_from_next));
                }
                _ => {}
            }
        }
    }
    masses
}

fn compile(steps: Vec<Step>) -> (Isometry3<f64>, Vec<Segment>) {
    let mut prefix = Isometry3::identity();
    let mut segments: Vec<Segment> = Vec::new();
    for step in steps {
        match step {
            Step::Fixed(transform) => match segments.last_mut() {
                Some(segment) => segment.after *= transform,
                None => prefix *= transform,
            },
            Step::Motion(axis, prismatic) => segments.push(Segment {
                axis,
                prismatic,
                after: Isometry3::identity(),
                mass_kg: 0.0,
                first_moment_kg_m: Vector3::zeros(),
            }),
            // `after` so far is the transform from the frame after the motion to the current
            // link; masses before the first motion never move and load no joint.
            Step::Mass(mass_kg, com) => {
                if let Some(segment) = segments.last_mut() {
                    segment.mass_kg += mass_kg;
                    segment.first_moment_kg_m += mass_kg * (segment.after * com).coords;
                }
            }
        }
    }
    (prefix, segments)
}
