//! Errors of robot-model loading and chain construction. Every message names the URDF element
//! at fault so a user can find it in a file of several hundred lines.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("cannot read URDF '{path}': {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot parse URDF '{origin}': {message}")]
    Parse { origin: String, message: String },
    #[error(
        "URDF '{origin}' uses xacro macros; expand it first (xacro {origin} > robot.urdf) and load the result"
    )]
    Xacro { origin: String },
    #[error("robot '{robot}' has no links")]
    NoLinks { robot: String },
    #[error("link '{link}' is defined twice")]
    DuplicateLink { link: String },
    #[error("joint '{joint}' is defined twice")]
    DuplicateJoint { joint: String },
    #[error("joint '{joint}' names {role} link '{link}', which is not defined")]
    MissingLink {
        joint: String,
        role: &'static str,
        link: String,
    },
    #[error("no link named '{link}' in robot '{robot}' (links: {known})")]
    NoSuchLink {
        link: String,
        robot: String,
        known: String,
    },
    #[error("kinematic loop: {description}")]
    KinematicLoop { description: String },
    #[error("links '{base}' and '{tip}' are not connected by any chain of joints")]
    NotConnected { base: String, tip: String },
    #[error("joint '{joint}' has a zero-length axis")]
    ZeroAxis { joint: String },
    #[error("{element} has a non-finite {field} ({value})")]
    NonFinite {
        element: String,
        field: &'static str,
        value: String,
    },
    #[error("joint '{joint}' has lower limit {lower} above upper limit {upper}")]
    InvalidLimits {
        joint: String,
        lower: f64,
        upper: f64,
    },
    #[error("link '{link}' has a negative mass ({mass_kg} kg)")]
    NegativeMass { link: String, mass_kg: f64 },
    #[error(
        "joint '{joint}' on the chain {base} -> {tip} mimics joint '{master}'; mimic joints inside a chain are not supported"
    )]
    MimicInChain {
        joint: String,
        master: String,
        base: String,
        tip: String,
    },
    #[error(
        "joint '{joint}' on the chain {base} -> {tip} is {kind}; chains support revolute, continuous, prismatic and fixed joints"
    )]
    UnsupportedJointInChain {
        joint: String,
        kind: &'static str,
        base: String,
        tip: String,
    },
}

/// Errors of evaluating a chain at a joint configuration.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum KinematicsError {
    #[error("expected {expected} joint values ({joints}), got {got}")]
    JointCount {
        expected: usize,
        got: usize,
        joints: String,
    },
    #[error("joint value {index} ('{joint}') is not finite ({value})")]
    NonFiniteJoint {
        index: usize,
        joint: String,
        value: f64,
    },
    #[error("{0}")]
    Dh(String),
}
