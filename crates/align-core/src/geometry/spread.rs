//! How far a set of points spreads in each direction, and whether a size is plausible for a part
//! a cobot handles: the checks that turn degenerate geometry and unit mistakes into clear
//! errors and warnings instead of confident wrong answers.

use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};

/// The principal axes of a point set: standard deviations along them, largest first.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrincipalSpread {
    pub centroid: Point3<f64>,
    /// Standard deviation along each axis, m, in decreasing order.
    pub sigma_m: [f64; 3],
    /// Unit axes matching `sigma_m`.
    pub axes: [Vector3<f64>; 3],
}

impl PrincipalSpread {
    /// `None` for an empty set.
    pub fn of(points: impl IntoIterator<Item = Point3<f64>>) -> Option<Self> {
        let points: Vec<Point3<f64>> = points.into_iter().collect();
        if points.is_empty() {
            return None;
        }
        let count = points.len() as f64;
        let centroid = Point3::from(
            points
                .iter()
                .fold(Vector3::zeros(), |sum, p| sum + p.coords)
                / count,
        );
        let covariance = points.iter().fold(Matrix3::zeros(), |sum, p| {
            let offset = p - centroid;
            sum + offset * offset.transpose()
        }) / count;
        let eigen = SymmetricEigen::new(covariance);
        let mut order = [0, 1, 2];
        order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
        Some(Self {
            centroid,
            // Rounding can make a zero eigenvalue slightly negative.
            sigma_m: order.map(|i| eigen.eigenvalues[i].max(0.0).sqrt()),
            axes: order.map(|i| eigen.eigenvectors.column(i).into_owned()),
        })
    }
}

/// The least-squares plane through `points`: their centroid and the unit normal along which
/// they spread least (the scatter's smallest eigenvector). `None` for fewer than three points.
/// The sign of the normal is whatever the eigen solver returns.
pub fn plane_through(points: &[Point3<f64>]) -> Option<(Point3<f64>, Vector3<f64>)> {
    if points.len() < 3 {
        return None;
    }
    let mean = points
        .iter()
        .fold(Vector3::zeros(), |sum, p| sum + p.coords)
        / points.len() as f64;
    let scatter = points.iter().fold(Matrix3::zeros(), |sum, p| {
        let d = p.coords - mean;
        sum + d * d.transpose()
    });
    let eigen = scatter.symmetric_eigen();
    let normal = eigen
        .eigenvectors
        .column(eigen.eigenvalues.imin())
        .normalize();
    Some((Point3::from(mean), normal))
}

/// A part a cobot handles and a scanner sees: from 1 mm to 10 m across. Outside that range the
/// number is far more likely a unit mistake (mm read as m gives 1000x, m read as mm 1/1000x)
/// than a real part.
pub const PLAUSIBLE_PART_SIZE_M: (f64, f64) = (1e-3, 10.0);

/// Unit scales (file unit to m) a file is likely written in, the most common first.
const LIKELY_UNIT_SCALES: [(f64, &str); 4] =
    [(1e-3, "mm"), (1.0, "m"), (0.0254, "inches"), (1e-2, "cm")];

/// A length for a person: "300 km", "0.3 mm", "1.20 m".
pub fn human_length(length_m: f64) -> String {
    if length_m >= 1e3 {
        format!("{:.0} km", length_m / 1e3)
    } else if length_m >= 1.0 {
        format!("{length_m:.2} m")
    } else {
        format!("{:.3} mm", length_m * 1e3)
    }
}

/// The warning for a `what` (e.g. "the mesh") `size_m` across when that size is implausible for
/// a part, `None` when it is plausible. With the `unit_scale` the file was read with, the warning
/// names the scale that would make the size plausible.
pub fn implausible_size_warning(
    what: &str,
    size_m: f64,
    unit_scale: Option<f64>,
) -> Option<String> {
    let (smallest_m, largest_m) = PLAUSIBLE_PART_SIZE_M;
    if (smallest_m..=largest_m).contains(&size_m) {
        return None;
    }
    let bound = if size_m < smallest_m {
        "under 1 mm"
    } else {
        "over 10 m"
    };
    let mut warning = format!(
        "{what} is {} across ({bound}, implausible for a part): is its unit right?",
        human_length(size_m)
    );
    let Some(scale) = unit_scale else {
        warning.push_str(" A file in mm needs a unit scale of 0.001, one in m of 1");
        return Some(warning);
    };
    let size_in_file_units = size_m / scale;
    let likely = LIKELY_UNIT_SCALES.iter().find(|(candidate, _)| {
        *candidate != scale && (smallest_m..=largest_m).contains(&(size_in_file_units * candidate))
    });
    if let Some((likely_scale, unit)) = likely {
        warning.push_str(&format!(
            " If the file is in {unit}, its scale is {likely_scale}, not {scale}"
        ));
    }
    Some(warning)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plane_through_points_on_a_tilted_plane_is_that_plane() {
        let normal = Vector3::new(1.0, -2.0, 3.0).normalize();
        let across = normal.cross(&Vector3::x()).normalize();
        let along = normal.cross(&across);
        let origin = Point3::new(0.3, -0.1, 0.7);
        let points: Vec<Point3<f64>> = (0..25)
            .map(|i| {
                let (u, v) = (f64::from(i % 5) * 0.01, f64::from(i / 5) * 0.02);
                origin + u * across + v * along
            })
            .collect();
        let (centroid, fitted) = plane_through(&points).unwrap();
        assert!((fitted.dot(&normal).abs() - 1.0).abs() < 1e-12, "{fitted}");
        assert!((centroid - origin).dot(&normal).abs() < 1e-12);
        assert_eq!(plane_through(&points[..2]), None);
    }

    #[test]
    fn spread_finds_the_line_and_the_plane() {
        let line = (0..10).map(|i| Point3::new(i as f64, 2.0 * i as f64, 0.0));
        let spread = PrincipalSpread::of(line).unwrap();
        assert!(spread.sigma_m[0] > 1.0 && spread.sigma_m[1] < 1e-9);
        assert!(
            (spread.axes[0]
                .dot(&Vector3::new(1.0, 2.0, 0.0).normalize())
                .abs()
                - 1.0)
                .abs()
                < 1e-9
        );
        let plane = (0..100).map(|i| Point3::new((i % 10) as f64, (i / 10) as f64, 3.0));
        let spread = PrincipalSpread::of(plane).unwrap();
        assert!(spread.sigma_m[1] > 1.0 && spread.sigma_m[2] < 1e-9);
        assert!((spread.axes[2].z.abs() - 1.0).abs() < 1e-9);
    }

    #[test]
    fn implausible_sizes_name_the_likely_scale() {
        assert_eq!(implausible_size_warning("the mesh", 0.3, Some(1e-3)), None);
        let km = implausible_size_warning("the mesh", 300e3, Some(1000.0)).unwrap();
        assert!(
            km.contains("300 km across") && km.contains("in mm, its scale is 0.001, not 1000"),
            "{km}"
        );
        let tiny = implausible_size_warning("the mesh", 0.3e-3, Some(1e-3)).unwrap();
        assert!(
            tiny.contains("under 1 mm") && tiny.contains("in m, its scale is 1"),
            "{tiny}"
        );
    }
}
