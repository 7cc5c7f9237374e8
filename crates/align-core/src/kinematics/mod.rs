//! Robot kinematics from URDF: loading and validating descriptions ([`RobotModel`]), serial
//! chains between any two links with forward kinematics and the geometric Jacobian ([`Chain`]),
//! damped-least-squares inverse kinematics ([`Chain::inverse`]) and the gravity torques on the
//! joints from the links' inertials ([`Chain::gravity_torques_nm`]).
//!
//! URDF conventions: a joint's origin places the joint frame in the parent link frame, `rpy` is
//! fixed-axis X-Y-Z, the axis is normalised on load, and the child link frame is the joint frame
//! moved by the joint value (rotation about the axis, or translation along it).

mod chain;
mod dh;
mod error;
mod gravity;
mod ik;
mod mesh_uri;
mod model;

pub use chain::{Chain, ChainJoint};
pub use dh::{DhTable, UR_KINEMATICS_JOINTS};
pub use error::{KinematicsError, ModelError};
pub use gravity::{PointMass, STANDARD_GRAVITY_M_S2};
pub use ik::{IkError, IkOptions, IkSolution};
pub use mesh_uri::PackageMap;
pub use model::{
    Geometry, Inertial, Joint, JointKind, JointLimits, Link, Mimic, RobotModel, Shape,
};

impl RobotModel {
    /// The chain from `base` to `tip` (see [`Chain::new`]).
    pub fn chain(&self, base: &str, tip: &str) -> Result<Chain, ModelError> {
        Chain::new(self, base, tip)
    }
}
