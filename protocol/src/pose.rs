//! The one pose type on the wire and in files.

use serde::{Deserialize, Serialize};

/// A pose `a_from_b`: position x, y, z (m) and fixed-axis roll, pitch, yaw (rad), as session
/// files, requests and reports write it. Reports of an alignment add the homogeneous 4x4
/// `matrix` (rows) so a reader needs no Euler convention; elsewhere it is absent.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub xyz: [f64; 3],
    pub rpy: [f64; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub matrix: Option<[[f64; 4]; 4]>,
}

impl Pose {
    /// A pose without the matrix.
    pub fn new(xyz: [f64; 3], rpy: [f64; 3]) -> Self {
        Self {
            xyz,
            rpy,
            matrix: None,
        }
    }

    /// The index of the first non-finite value, named as in a message (`xyz[1]`), if any.
    pub fn first_non_finite(&self) -> Option<String> {
        for (name, values) in [("xyz", self.xyz), ("rpy", self.rpy)] {
            if let Some(index) = values.iter().position(|v| !v.is_finite()) {
                return Some(format!("{name}[{index}]"));
            }
        }
        None
    }
}
