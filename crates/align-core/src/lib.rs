//! align-core: the numerical heart of cobot-align.
//!
//! Pure computation with no sockets and no async: robot kinematics from URDF descriptions
//! ([`kinematics`]), tool definitions ([`tool`]), pose conventions ([`pose`]) and the robot
//! descriptions the project ships ([`robots`]). Every service links this crate; everything here is
//! testable offline.
//!
//! Units are SI (m, rad, s, kg). Transforms are named `a_from_b`, so
//! `base_from_flange * flange_from_tcp` reads as a chain and `base_from_tcp * p_in_tcp` gives a
//! point in the base frame.

pub mod corpus;
pub mod diagnosis;
pub mod geometry;
pub mod guidance;
pub mod io;
pub mod kinematics;
pub mod pose;
pub mod registration;
pub mod rng;
pub mod robots;
pub mod tool;
pub mod trials;

pub use kinematics::{Chain, IkError, IkOptions, IkSolution, ModelError, PackageMap, RobotModel};
pub use tool::{Tool, ToolError};
