//! Whether the touches fix the part: a touch set whose surface normals leave a rigid motion free
//! is refused with that motion named, instead of returning an arbitrary pose.

use nalgebra::{Isometry3, Vector3};

use super::local::{Matching, Workspace};
use crate::registration::RegistrationError;

/// Refuses touch sets whose surface normals leave a rigid motion unconstrained: the smallest
/// eigenvalue of the point-to-plane normal matrix (rotation scaled by the part radius) is
/// negligible. The eigenvector names the free motion.
pub(super) fn check_constrained(
    workspace: &mut Workspace<'_>,
    start: &Isometry3<f64>,
) -> Result<(), RegistrationError> {
    workspace.correspond(start, Matching::Plain);
    let (normal_matrix, _, centre) = workspace.normal_equations();
    let eigen = normal_matrix.symmetric_eigen();
    let (smallest, value) = eigen
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .map(|(index, value)| (index, *value))
        .unwrap_or((0, 0.0));
    let largest = eigen.eigenvalues.iter().copied().fold(0.0, f64::max);
    if value > largest * 1e-9 {
        return Ok(());
    }
    let direction = eigen.eigenvectors.column(smallest);
    let rotation = Vector3::new(direction[0], direction[1], direction[2]);
    let translation = Vector3::new(direction[3], direction[4], direction[5]);
    // Rounded first so that -0.0001 prints as 0.000, not -0.000.
    let round = |c: f64| (c * 1000.0).round() / 1000.0 + 0.0;
    let fmt =
        |v: &Vector3<f64>| format!("({:.3}, {:.3}, {:.3})", round(v.x), round(v.y), round(v.z));
    let dof = if rotation.norm() < 1e-6 {
        format!(
            "translation along {} in the base frame (no touch has a normal along it)",
            fmt(&translation.normalize())
        )
    } else if translation.norm() < 1e-6 {
        format!(
            "rotation about the axis {} through ({:.4}, {:.4}, {:.4}) m in the base frame",
            fmt(&rotation.normalize()),
            centre.x,
            centre.y,
            centre.z
        )
    } else {
        format!(
            "a combined rotation about {} and translation along {} (base frame)",
            fmt(&rotation.normalize()),
            fmt(&translation.normalize())
        )
    };
    Err(RegistrationError::Underconstrained { dof })
}
