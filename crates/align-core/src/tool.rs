//! The tool on the flange: where its centre point is, the radius of its ball tip and its mass.
//! A touch inspection is the TCP frame, `base_from_flange * flange_from_tcp`; the contact point
//! lies one tip radius from it along the surface normal.

use nalgebra::{Isometry3, Point3};

#[derive(Debug, Clone, PartialEq)]
pub struct Tool {
    pub flange_from_tcp: Isometry3<f64>,
    pub tip_radius_m: f64,
    pub mass_kg: f64,
    /// Centre of mass of the tool in the flange frame; with `mass_kg` it loads the joints.
    pub com_in_flange: Point3<f64>,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ToolError {
    #[error("tool {field} must be finite and >= 0, got {value}")]
    Negative { field: &'static str, value: f64 },
    #[error("tool {field} is not finite")]
    NonFinite { field: &'static str },
}

impl Default for Tool {
    /// A bare flange: TCP at the flange, a point tip and no mass.
    fn default() -> Self {
        Self {
            flange_from_tcp: Isometry3::identity(),
            tip_radius_m: 0.0,
            mass_kg: 0.0,
            com_in_flange: Point3::origin(),
        }
    }
}

impl Tool {
    /// A validated tool; the centre of mass defaults to the TCP origin.
    pub fn new(
        flange_from_tcp: Isometry3<f64>,
        tip_radius_m: f64,
        mass_kg: f64,
    ) -> Result<Self, ToolError> {
        let tcp_finite = flange_from_tcp
            .translation
            .vector
            .iter()
            .all(|v| v.is_finite())
            && flange_from_tcp
                .rotation
                .coords
                .iter()
                .all(|v| v.is_finite());
        if !tcp_finite {
            return Err(ToolError::NonFinite { field: "tcp" });
        }
        for (field, value) in [("tip_radius", tip_radius_m), ("mass", mass_kg)] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(ToolError::Negative { field, value });
            }
        }
        Ok(Self {
            flange_from_tcp,
            tip_radius_m,
            mass_kg,
            com_in_flange: Point3::from(flange_from_tcp.translation.vector),
        })
    }

    /// The inspection frame: the TCP in the robot base frame.
    pub fn base_from_tcp(&self, base_from_flange: &Isometry3<f64>) -> Isometry3<f64> {
        base_from_flange * self.flange_from_tcp
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::isometry_from_xyz_rpy;

    #[test]
    fn inspection_frame_composes_flange_then_tcp() {
        let tool = Tool::new(
            isometry_from_xyz_rpy([0.0, 0.0, 0.12], [0.0; 3]),
            0.003,
            0.4,
        )
        .expect("valid tool");
        let base_from_flange =
            isometry_from_xyz_rpy([0.5, 0.0, 0.3], [std::f64::consts::PI, 0.0, 0.0]);
        let tcp = tool.base_from_tcp(&base_from_flange).translation.vector;
        // The flange points down (rolled by pi), so the TCP is 0.12 m below it.
        assert!((tcp - nalgebra::Vector3::new(0.5, 0.0, 0.18)).norm() < 1e-12);
    }

    #[test]
    fn rejects_negative_radius_and_nan_mass() {
        let error = Tool::new(Isometry3::identity(), -0.001, 0.0).unwrap_err();
        assert_eq!(
            error.to_string(),
            "tool tip_radius must be finite and >= 0, got -0.001"
        );
        let error = Tool::new(Isometry3::identity(), 0.0, f64::NAN).unwrap_err();
        assert_eq!(
            error.to_string(),
            "tool mass must be finite and >= 0, got NaN"
        );
    }
}
