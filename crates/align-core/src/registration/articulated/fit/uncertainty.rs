//! How sure the robot fit is of each joint: the covariance of the base pose and the observed
//! joints that the final matches imply, as the cloud alignment's report (`pca::uncertainty`)
//! does for one part, and each joint's 95 % interval from it.
//!
//! The rows are the refinement's ([`JacobianRows`]): each match's motion along its normal per
//! unit of every parameter estimated, the base's six and the observed joints'. With `s` the
//! residuals' robust scale (Tukey's biweight at the cloud polish's cutoff, [`biweight_scale`]) times
//! the cloud report's [`NOISE_CALIBRATION`], `Σ = s² (JᵀJ)⁻¹`. A direction the matches do not
//! constrain (a round base's yaw against its first joint, which the scan fixes only as a sum)
//! leaves the joints along it without an interval: reported, not guessed.
//!
//! The calibration was chosen on single parts' scans of third-party CAD; no real scan of a robot
//! has checked it. On the project's own robot scans the model is exact (the scanner sees the
//! very meshes the fit uses), so the tests there check the sums, not the calibration.

use nalgebra::{DMatrix, DVector, SymmetricEigen};

use super::placed::{Match, Placed};
use super::refine::JacobianRows;
use crate::registration::articulated::body::ArticulatedBody;
use crate::registration::pca::uncertainty::NOISE_CALIBRATION;
use crate::registration::robust_scale::{BIWEIGHT_C, MAD_TO_SIGMA, biweight_scale};
use crate::registration::uncertainty::{CONDITION_LIMIT, Z_95};

/// A joint whose unit direction has more than this component along a direction the matches
/// do not constrain has no interval of its own.
const FREE_COMPONENT: f64 = 1e-3;

/// Each parameter's 95 % half-width, in radians (metres for a prismatic joint): `None` where
/// `observed` is false, where the matches fix it only together with another parameter, or when
/// too few matches are left to measure their noise.
pub(super) fn joint_intervals_95(
    body: &ArticulatedBody,
    placed: &Placed,
    matches: &[Match],
    observed: &[bool],
) -> Vec<Option<f64>> {
    let parameters = body.parameters();
    let mut intervals = vec![None; parameters.len()];
    // The base's six, then the observed joints: an unobserved joint is held at its start.
    let columns: Vec<usize> = (0..6)
        .chain(
            (0..parameters.len())
                .filter(|&p| observed.get(p).copied().unwrap_or(false))
                .map(|p| 6 + p),
        )
        .collect();
    let signed: Vec<f64> = matches
        .iter()
        .map(|m| m.normal.dot(&(m.point - m.surface)))
        .collect();
    if signed.iter().any(|r| !r.is_finite()) {
        return intervals;
    }
    let Ok(scale) = biweight_scale(&signed, columns.len(), BIWEIGHT_C * MAD_TO_SIGMA) else {
        return intervals;
    };
    // Turns per this many metres of arc, so that every column is in metres and the matrix is
    // conditioned by the geometry, not the units.
    let arc_m = body.max_reach_m().max(1e-3);
    let rows = JacobianRows::new(body, placed, arc_m);
    let mut full = DVector::zeros(6 + parameters.len());
    let mut row = DVector::zeros(columns.len());
    let mut normal = DMatrix::zeros(columns.len(), columns.len());
    for (m, _) in matches.iter().zip(&scale.kept).filter(|(_, kept)| **kept) {
        rows.fill(m, full.as_mut_slice());
        for (entry, &column) in row.iter_mut().zip(&columns) {
            *entry = full[column];
        }
        normal.syger(1.0, &row, &row, 1.0);
    }
    normal.fill_upper_triangle_with_lower_triangle();
    let eigen = SymmetricEigen::new(normal);
    let largest = eigen.eigenvalues.max();
    if !(largest.is_finite() && largest > 0.0) {
        return intervals;
    }
    let sigma_m = scale.sigma_m * NOISE_CALIBRATION;
    for (index, &column) in columns.iter().enumerate().skip(6) {
        let mut variance = 0.0;
        let mut free = false;
        for (direction, &eigenvalue) in eigen.eigenvalues.iter().enumerate() {
            let component = eigen.eigenvectors[(index, direction)];
            if eigenvalue <= CONDITION_LIMIT * largest {
                free |= component.abs() > FREE_COMPONENT;
            } else {
                variance += component * component / eigenvalue;
            }
        }
        if free {
            continue;
        }
        let parameter = column - 6;
        // A turn's column is per `arc_m` of arc: its value in radians is the column's over it.
        let per_unit = if parameters[parameter].prismatic {
            1.0
        } else {
            1.0 / arc_m
        };
        intervals[parameter] = Some(Z_95 * sigma_m * variance.sqrt() * per_unit);
    }
    intervals
}
