//! The correspondence step of the PCA loop: the cut-off and measure filters, each kept keypoint's
//! closest surface point (exact, or approximate far off the part) and its weight.

use nalgebra::{Isometry3, Point3, Vector3};
use rayon::prelude::*;

use crate::geometry::Mesh;

/// One kept keypoint: where it is (base), its surface correspondence (base) and normal.
#[derive(Debug, Clone, Copy)]
pub(super) struct Match {
    pub(super) point: Point3<f64>,
    pub(super) surface: Point3<f64>,
    pub(super) normal: Vector3<f64>,
    pub(super) distance: f64,
    pub(super) weight: f64,
}

const EDGE_REJECTION_M: f64 = 1e-3;

/// How [`correspond`] finds each keypoint's surface point.
#[derive(Debug, Clone, Copy)]
pub(super) struct Lookup {
    /// Parallel over the keypoints (rayon).
    pub(super) parallel: bool,
    /// 1: the closest surface point; more: one up to that factor farther (see
    /// [`EXPLORATION_SLACK`](super::exploration::EXPLORATION_SLACK)).
    pub(super) slack: f64,
    /// A slack lookup's answers within this fraction of the band (or [`EXACT_WITHIN_M`], if
    /// farther) are made exact.
    pub(super) exact_within_band_fraction: f64,
}

impl Lookup {
    pub(super) fn exact(parallel: bool) -> Self {
        Self {
            parallel,
            slack: 1.0,
            exact_within_band_fraction: 0.0,
        }
    }
}

/// A slack lookup's answers nearer the surface than this are made exact.
const EXACT_WITHIN_M: f64 = 0.02;

/// No triangle remembered for a keypoint yet.
pub(super) const NO_HINT: u32 = u32::MAX;

/// Cut-off and measure filters, then the surface correspondence and weight of each keypoint.
/// `hints` (one per keypoint, or empty) remember each keypoint's triangle between the steps of
/// a run: an approximate run answers its far queries from them in one projection, an exact one
/// starts its search bounded by them (the same answers, fewer nodes opened).
pub(super) fn correspond(
    mesh: &Mesh,
    keypoints: &[Point3<f64>],
    pose: &Isometry3<f64>,
    delta: f64,
    (lower, upper): (&Point3<f64>, &Point3<f64>),
    lookup: Lookup,
    hints: &mut [u32],
) -> Vec<Match> {
    let part_from_base = pose.inverse();
    let one = |point: &Point3<f64>, hint: Option<&mut u32>| -> Option<Match> {
        let in_part = part_from_base * point;
        if !in_grown_box(&in_part, lower, upper, delta) {
            return None;
        }
        let closest = if lookup.slack > 1.0 {
            let remembered = hint.as_ref().map(|h| **h).filter(|&h| h != NO_HINT);
            let found =
                mesh.closest_point_within_slack(&in_part, delta, lookup.slack, remembered)?;
            if let Some(hint) = hint {
                *hint = found.triangle;
            }
            // Near the surface the exact answer, bounded by the approximate one (a short
            // search): the points that hold the part in place must pull along the right
            // normals, or the runs end short of their optimum and score below it.
            let exact_within_m = EXACT_WITHIN_M.max(lookup.exact_within_band_fraction * delta);
            if found.signed_distance.abs() <= exact_within_m {
                mesh.closest_point_within(&in_part, found.signed_distance.abs() + 1e-9)
                    .unwrap_or(found)
            } else {
                found
            }
        } else if let Some(hint) = hint {
            // The exact answer, its search bounded from the start by the triangle this
            // keypoint matched at the previous step: a step moves the part by a little, so that
            // triangle is near the best and the descent opens a handful of nodes.
            let remembered = Some(*hint).filter(|&h| h != NO_HINT);
            let found = mesh.closest_point_within_hinted(&in_part, delta, remembered)?;
            *hint = found.triangle;
            found
        } else {
            mesh.closest_point_within(&in_part, delta)?
        };
        let distance = closest.signed_distance.abs();
        // A point whose nearest surface is an edge or corner, more than a millimetre off, lies
        // beyond the part: typically the floor or a fixture meeting it. Such points only drag
        // the part's edges towards the clutter.
        if !closest.on_face && distance > EDGE_REJECTION_M {
            return None;
        }
        let weight = (distance / delta * std::f64::consts::FRAC_PI_2).cos();
        (weight > 0.0).then(|| Match {
            point: *point,
            surface: pose * closest.point,
            normal: pose.rotation * closest.normal,
            distance,
            weight,
        })
    };
    match (lookup.parallel, hints.len() == keypoints.len()) {
        (true, true) => keypoints
            .par_iter()
            .zip(hints.par_iter_mut())
            .filter_map(|(point, hint)| one(point, Some(hint)))
            .collect(),
        (true, false) => keypoints
            .par_iter()
            .filter_map(|point| one(point, None))
            .collect(),
        (false, true) => keypoints
            .iter()
            .zip(hints.iter_mut())
            .filter_map(|(point, hint)| one(point, Some(hint)))
            .collect(),
        (false, false) => keypoints
            .iter()
            .filter_map(|point| one(point, None))
            .collect(),
    }
}

/// The cut-off filter: `in_part` lies inside the part's box (`lower`, `upper`) grown by `delta`.
fn in_grown_box(
    in_part: &Point3<f64>,
    lower: &Point3<f64>,
    upper: &Point3<f64>,
    delta: f64,
) -> bool {
    (0..3).all(|axis| in_part[axis] >= lower[axis] - delta && in_part[axis] <= upper[axis] + delta)
}

/// The keypoints within `delta` of the part's surface at `pose` (inside the part's box grown by
/// `delta`, and nearer than `delta` to the surface, as [`correspond`] keeps them, edge points
/// included): what the check that the scan holds enough of the part near the start counts. No
/// surface point is needed, so a keypoint whose distance to the box's centre plus the box's half
/// diagonal is under `delta` (nearer than `delta` to every point of the part) is kept without a
/// search: from a start a metre off, most of them, whose searches each opened much of the tree
/// (25-35 ms of a 500-1000 mm local alignment on the CAD scans). The others ask whether any
/// triangle lies within `delta`, a descent that stops at the first one found.
pub(super) fn near_surface(
    mesh: &Mesh,
    keypoints: &[Point3<f64>],
    pose: &Isometry3<f64>,
    delta: f64,
    parallel: bool,
) -> Vec<Point3<f64>> {
    let (lower, upper) = mesh.bounds();
    let box_centre = Point3::from((lower.coords + upper.coords) / 2.0);
    let half_diagonal = ((upper - lower) / 2.0).norm();
    let part_from_base = pose.inverse();
    let near = |point: &&Point3<f64>| -> bool {
        let in_part = part_from_base * *point;
        if !in_grown_box(&in_part, &lower, &upper, delta) {
            return false;
        }
        if (in_part - box_centre).norm() + half_diagonal < delta {
            return true;
        }
        mesh.has_surface_within(&in_part, delta)
    };
    if parallel {
        keypoints.par_iter().filter(near).copied().collect()
    } else {
        keypoints.iter().filter(near).copied().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    #[test]
    fn near_surface_keeps_exactly_the_keypoints_within_delta_of_the_part() {
        let mesh = Mesh::cuboid([0.2, 0.1, 0.05]).expect("a box");
        let pose = Isometry3::new(Vector3::new(0.5, 0.2, 0.1), Vector3::new(0.1, -0.2, 0.7));
        let mut rng = SplitMix64::new(7);
        let keypoints: Vec<Point3<f64>> = (0..4000)
            .map(|_| pose * Point3::from(rng.unit_vector() * (1.5 * rng.uniform())))
            .collect();
        // From bands narrower than the part, where every keypoint is searched, to a metre, where
        // most are kept for lying near the box's centre.
        for delta in [0.01, 0.05, 0.3, 1.0] {
            let expected: Vec<Point3<f64>> = keypoints
                .iter()
                .filter(|p| {
                    let in_part = pose.inverse() * *p;
                    let (lower, upper) = mesh.bounds();
                    let inside_box = (0..3).all(|axis| {
                        in_part[axis] >= lower[axis] - delta && in_part[axis] <= upper[axis] + delta
                    });
                    inside_box && mesh.closest_point(&in_part).signed_distance.abs() < delta
                })
                .copied()
                .collect();
            for parallel in [false, true] {
                let found = near_surface(&mesh, &keypoints, &pose, delta, parallel);
                assert_eq!(found, expected, "delta {delta}, parallel {parallel}");
            }
            assert!(
                expected.len() > 20,
                "delta {delta}: {} kept",
                expected.len()
            );
        }
    }
}
