//! Articulated objects in scans: a robot described by URDF with link geometry ([`body`]) fitted
//! to a point cloud as a base pose plus joint values, children constrained by parents ([`fit`]).

pub mod body;
pub mod fit;

pub use body::{ArticulatedBody, BodyError, BodyLink, BodyParameter};
pub use fit::{
    JointFit, LinkFit, RobotFit, RobotFitError, RobotFitOptions, RobotTwin, align_robot,
    observed_joints_at, searches_globally,
};
