//! Weighted rigid registration of corresponding points (Arun, Huang and Blostein's SVD method with
//! weighted centroids, thesis eq. 8-13), with the reflection fix and a check that the points fix
//! the rotation at all.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RegistrationError {
    #[error("registration needs at least 3 points with positive weight, got {0}")]
    TooFewPoints(usize),
    #[error("point {index} or its weight is not finite")]
    NonFinite { index: usize },
    #[error(
        "the points are collinear (along {direction:?}): rotation about that line is not fixed"
    )]
    Collinear { direction: [f64; 3] },
    #[error("the measurements leave a degree of freedom free: {dof}")]
    Underconstrained { dof: String },
    #[error(
        "the point sets have different lengths ({moving} moving, {fixed} fixed, {weights} weights)"
    )]
    LengthMismatch {
        moving: usize,
        fixed: usize,
        weights: usize,
    },
}

/// The rigid transform `T` minimising `sum w_k |fixed_k - T moving_k|^2`.
pub fn weighted_svd(
    moving: &[Point3<f64>],
    fixed: &[Point3<f64>],
    weights: &[f64],
) -> Result<Isometry3<f64>, RegistrationError> {
    if moving.len() != fixed.len() || moving.len() != weights.len() {
        return Err(RegistrationError::LengthMismatch {
            moving: moving.len(),
            fixed: fixed.len(),
            weights: weights.len(),
        });
    }
    for (index, ((m, f), w)) in moving.iter().zip(fixed).zip(weights).enumerate() {
        let finite = m
            .coords
            .iter()
            .chain(f.coords.iter())
            .all(|c| c.is_finite());
        if !finite || !w.is_finite() || *w < 0.0 {
            return Err(RegistrationError::NonFinite { index });
        }
    }
    let used = weights.iter().filter(|&&w| w > 0.0).count();
    if used < 3 {
        return Err(RegistrationError::TooFewPoints(used));
    }
    let total: f64 = weights.iter().sum();
    let centroid = |points: &[Point3<f64>]| {
        points
            .iter()
            .zip(weights)
            .fold(Vector3::zeros(), |sum, (p, w)| sum + p.coords * *w)
            / total
    };
    let moving_centroid = centroid(moving);
    let fixed_centroid = centroid(fixed);
    let mut covariance = Matrix3::zeros();
    for ((m, f), w) in moving.iter().zip(fixed).zip(weights) {
        covariance += (m.coords - moving_centroid) * (f.coords - fixed_centroid).transpose() * *w;
    }
    check_not_collinear(moving, weights, &moving_centroid)?;
    let svd = covariance.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(RegistrationError::TooFewPoints(used));
    };
    let mut v = v_t.transpose();
    // R = V U^T may be a reflection when the data are planar or noisy; flipping the axis of the
    // smallest singular value gives the closest proper rotation.
    if (v * u.transpose()).determinant() < 0.0 {
        let smallest = svd
            .singular_values
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .map_or(2, |(index, _)| index);
        v.column_mut(smallest).neg_mut();
    }
    let rotation = Rotation3::from_matrix_unchecked(v * u.transpose());
    let rotation = UnitQuaternion::from_rotation_matrix(&rotation);
    let translation = fixed_centroid - rotation * moving_centroid;
    Ok(Isometry3::from_parts(
        Translation3::from(translation),
        rotation,
    ))
}

/// Collinear points leave the rotation about their line free; the SVD would return an arbitrary
/// answer there, so say so instead.
fn check_not_collinear(
    points: &[Point3<f64>],
    weights: &[f64],
    centroid: &Vector3<f64>,
) -> Result<(), RegistrationError> {
    let mut scatter = Matrix3::zeros();
    for (p, w) in points.iter().zip(weights) {
        let d = p.coords - centroid;
        scatter += d * d.transpose() * *w;
    }
    let eigen = scatter.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
    let largest = eigen.eigenvalues[order[0]];
    let second = eigen.eigenvalues[order[1]];
    if largest <= 0.0 || second <= largest * 1e-12 {
        let axis = eigen.eigenvectors.column(order[0]);
        return Err(RegistrationError::Collinear {
            direction: [axis[0], axis[1], axis[2]],
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_points() -> Vec<Point3<f64>> {
        vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.3, 0.0, 0.1),
            Point3::new(0.0, 0.2, -0.1),
            Point3::new(0.1, 0.1, 0.4),
            Point3::new(-0.2, 0.05, 0.0),
        ]
    }

    #[test]
    fn recovers_a_known_transform_exactly() {
        let truth = Isometry3::from_parts(
            Translation3::new(0.4, -0.2, 0.9),
            UnitQuaternion::from_euler_angles(2.5, -0.7, 1.9),
        );
        let moving = sample_points();
        let fixed: Vec<_> = moving.iter().map(|p| truth * p).collect();
        let found = weighted_svd(&moving, &fixed, &[1.0, 2.0, 0.5, 1.0, 3.0]).unwrap();
        assert!((found.translation.vector - truth.translation.vector).norm() < 1e-12);
        assert!(found.rotation.angle_to(&truth.rotation) < 1e-12);
    }

    #[test]
    fn planar_points_do_not_produce_a_reflection() {
        let moving = vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(1.0, 1.0, 0.0),
        ];
        let truth = Isometry3::rotation(Vector3::new(0.3, 0.2, 2.0));
        let fixed: Vec<_> = moving.iter().map(|p| truth * p).collect();
        let found = weighted_svd(&moving, &fixed, &[1.0; 4]).unwrap();
        assert!(found.rotation.to_rotation_matrix().matrix().determinant() > 0.0);
        assert!(found.rotation.angle_to(&truth.rotation) < 1e-12);
    }

    #[test]
    fn degenerate_inputs_name_the_problem() {
        let p = sample_points();
        assert_eq!(
            weighted_svd(&p[..2], &p[..2], &[1.0; 2]).unwrap_err(),
            RegistrationError::TooFewPoints(2)
        );
        assert_eq!(
            weighted_svd(&p[..3], &p[..3], &[1.0, 0.0, 1.0]).unwrap_err(),
            RegistrationError::TooFewPoints(2)
        );
        let line: Vec<_> = (0..4)
            .map(|i| Point3::new(i as f64, 2.0 * i as f64, 0.0))
            .collect();
        let error = weighted_svd(&line, &line, &[1.0; 4]).unwrap_err();
        assert!(error.to_string().contains("collinear"), "{error}");
        let mut bad = p.clone();
        bad[1].x = f64::NAN;
        assert_eq!(
            weighted_svd(&bad, &p, &[1.0; 5]).unwrap_err(),
            RegistrationError::NonFinite { index: 1 }
        );
    }
}
