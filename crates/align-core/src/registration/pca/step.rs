//! One step of the loop from its matches: the weighted SVD (the thesis) or the linearised
//! point-to-plane step, whole or only along the directions the matches constrain.

use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};

use super::PcaStep;
use super::matching::Match;
use crate::registration::svd::weighted_svd;

/// One step of the loop from the matches: the weighted SVD or the point-to-plane step.
pub(super) fn step_for(matches: &[Match], step: PcaStep, radius_m: f64) -> Option<Isometry3<f64>> {
    step_along(matches, step, radius_m, 0.0)
}

/// A point-to-plane step's directions (of its normal equations' eigenvectors) whose eigenvalue is
/// under this fraction of the largest are left out of a wide band's step (see
/// `PcaOptions::wide_band_skips_weak_directions`).
pub(super) const WEAK_DIRECTION_FRACTION: f64 = 0.01;

/// [`step_for`], a point-to-plane step made only along the directions its matches constrain:
/// those whose eigenvalue is at least `weak_fraction` of the largest (0: all; a point-to-point
/// step is made whole).
pub(super) fn step_along(
    matches: &[Match],
    step: PcaStep,
    radius_m: f64,
    weak_fraction: f64,
) -> Option<Isometry3<f64>> {
    match step {
        PcaStep::PointToPoint => {
            let moving: Vec<_> = matches.iter().map(|m| m.surface).collect();
            let fixed: Vec<_> = matches.iter().map(|m| m.point).collect();
            let weights: Vec<_> = matches.iter().map(|m| m.weight).collect();
            weighted_svd(&moving, &fixed, &weights).ok()
        }
        PcaStep::PointToPlane => point_to_plane(matches, radius_m, weak_fraction),
    }
}

/// Weighted linearised point-to-plane step about the weighted centroid (rotation scaled by the
/// part radius for conditioning), applied exactly as a rotation and a translation. With
/// `weak_fraction` > 0 the step is the normal equations' solution in the span of their
/// eigenvectors whose eigenvalue is at least that fraction of the largest: a direction the
/// matches barely constrain (a round link's spin about its axis) is not moved along, as
/// degeneracy-aware ICP does (Zhang, Kaess and Singh, ICRA 2016).
fn point_to_plane(matches: &[Match], radius_m: f64, weak_fraction: f64) -> Option<Isometry3<f64>> {
    let total: f64 = matches.iter().map(|m| m.weight).sum();
    let centre = matches
        .iter()
        .fold(Vector3::zeros(), |sum, m| sum + m.surface.coords * m.weight)
        / total;
    let scale = radius_m.max(1e-9);
    let mut normal_matrix = Matrix6::zeros();
    let mut rhs = Vector6::zeros();
    for m in matches {
        let lever = (m.surface.coords - centre).cross(&m.normal) / scale;
        let row = Vector6::new(
            lever.x, lever.y, lever.z, m.normal.x, m.normal.y, m.normal.z,
        );
        let residual = m.normal.dot(&(m.point - m.surface));
        normal_matrix += row * row.transpose() * m.weight;
        rhs += row * (residual * m.weight);
    }
    // A little damping keeps a sliding direction (a flat scan of one face) from blowing up.
    let damping = normal_matrix.trace() * 1e-9;
    for i in 0..6 {
        normal_matrix[(i, i)] += damping;
    }
    // Not positive definite (no matches' weight): no step.
    let cholesky = normal_matrix.cholesky()?;
    let solution = if weak_fraction > 0.0 {
        let eigen = normal_matrix.symmetric_eigen();
        let largest = eigen.eigenvalues.max();
        eigen
            .eigenvalues
            .iter()
            .zip(eigen.eigenvectors.column_iter())
            .filter(|(value, _)| **value >= weak_fraction * largest)
            .fold(Vector6::zeros(), |sum, (value, direction)| {
                sum + direction * (direction.dot(&rhs) / value)
            })
    } else {
        cholesky.solve(&rhs)
    };
    let omega = Vector3::new(solution[0], solution[1], solution[2]) / scale;
    let translation = Vector3::new(solution[3], solution[4], solution[5]);
    let rotation = UnitQuaternion::from_scaled_axis(omega);
    let shift = centre + translation - rotation * centre;
    Some(Isometry3::from_parts(Translation3::from(shift), rotation))
}

#[cfg(test)]
mod tests {
    use nalgebra::Point3;

    use super::*;

    fn matched(surface: Vector3<f64>, normal: Vector3<f64>, off_m: f64, weight: f64) -> Match {
        Match {
            point: Point3::from(surface + normal * off_m),
            surface: Point3::from(surface),
            normal,
            distance: off_m.abs(),
            weight,
        }
    }

    #[test]
    fn a_step_leaves_out_the_direction_its_matches_barely_constrain_and_keeps_the_others() {
        // A cylinder 50 mm in radius along z, every point on it, and one lightly weighted match
        // on a flat beside it that turns the part about its axis: the spin is what the matches
        // barely constrain.
        let radius_m = 0.05;
        let mut matches = Vec::new();
        for k in 0..36 {
            let angle = k as f64 * std::f64::consts::TAU / 36.0;
            let normal = Vector3::new(angle.cos(), angle.sin(), 0.0);
            for z in [-0.1, 0.0, 0.1] {
                matches.push(matched(
                    normal * radius_m + Vector3::z() * z,
                    normal,
                    0.0,
                    1.0,
                ));
            }
        }
        matches.push(matched(Vector3::x() * radius_m, Vector3::y(), 0.005, 0.01));
        let whole = point_to_plane(&matches, radius_m, 0.0).unwrap();
        let constrained = point_to_plane(&matches, radius_m, WEAK_DIRECTION_FRACTION).unwrap();
        let whole_spin_rad = whole.rotation.scaled_axis().z;
        // The flat's 5 mm turn it a tenth of a radian; without the spin, what is left is the
        // flat's share of the well-constrained sideways shift.
        assert!(whole_spin_rad.abs() > 0.05, "{whole}");
        assert!(
            constrained.rotation.angle() < 1e-3 * whole_spin_rad.abs(),
            "{constrained}"
        );
        assert!(
            constrained.translation.vector.norm() < 1e-5,
            "{constrained}"
        );

        // A box's six faces constrain every direction: the same step either way.
        let mut rng = crate::rng::SplitMix64::new(5);
        let mut matches = Vec::new();
        for axis in 0..3 {
            for sign in [-1.0, 1.0] {
                let mut normal = Vector3::zeros();
                normal[axis] = sign;
                for _ in 0..20 {
                    let mut surface = Vector3::new(
                        rng.uniform() - 0.5,
                        rng.uniform() - 0.5,
                        rng.uniform() - 0.5,
                    ) * 0.1;
                    surface[axis] = 0.05 * sign;
                    matches.push(matched(surface, normal, 0.002 * (rng.uniform() - 0.3), 1.0));
                }
            }
        }
        let whole = point_to_plane(&matches, 0.09, 0.0).unwrap();
        let constrained = point_to_plane(&matches, 0.09, WEAK_DIRECTION_FRACTION).unwrap();
        assert!((whole.translation.vector - constrained.translation.vector).norm() < 1e-12);
        assert!(whole.rotation.angle_to(&constrained.rotation) < 1e-12);
        assert!(whole.translation.vector.norm() > 1e-4, "{whole}");
    }
}
