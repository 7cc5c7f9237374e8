//! Scan points on a plane larger than the part cannot be the part. A thin part laid flat on the
//! floor's points, with its underside on them, explains more of a cluttered scan than the part
//! where it really is: in the SO-ARM100 misses of the CAD scan trials the pose found explained
//! 70-109 floor keypoints and the truth 41-81 keypoints of the part (docs/cad-scan-trials.md).
//! No face of the part can hold more of the scan than the part's whole surface does, so such a
//! plane's points are taken out of the exploration's coarse keypoints: its short runs are not
//! pulled by them and its score does not count them. The full-resolution keypoints of the final
//! run keep them: there the band is narrow and the edge rejection drops the floor at the part's
//! foot.

use nalgebra::{Point3, Vector3};

use crate::geometry::Mesh;
use crate::rng::SplitMix64;

/// A point this close to a plane lies on it: six standard deviations of the scanner noise the
/// corpora measure (0.5 mm), and a fifth of a coarse keypoint's voxel.
const ON_PLANE_M: f64 = 0.003;

/// Random planes tried for each large plane: with the floor a third of a cell's scan, the
/// chance that none of them is drawn from three floor points is (1 - 1/27)^256, below 1e-4.
const HYPOTHESES: usize = 256;

/// The hypotheses are counted on at most this many keypoints (evenly spaced in the list).
const SAMPLE: usize = 4000;

/// Planes looked for: a floor, and walls or a table behind the part.
const MAX_PLANES: usize = 3;

/// A plane is too large for the part above this many times the keypoints its whole surface
/// could hold: a face seen at a voxel boundary may fill two layers of voxels.
const LARGER_THAN_PART: f64 = 2.0;

/// `coarse` (keypoints one per voxel of `voxel_m`) without the points of every plane holding
/// more of the scan than the part's whole surface could ([`LARGER_THAN_PART`] times its area
/// over a voxel's face).
pub fn without_large_planes(
    mut coarse: Vec<Point3<f64>>,
    mesh: &Mesh,
    voxel_m: f64,
) -> Vec<Point3<f64>> {
    let planes = large_planes(&coarse, mesh, voxel_m);
    coarse.retain(|p| !on_a_plane(p, &planes));
    coarse
}

/// The planes [`without_large_planes`] takes out of `coarse` (a point on each and its unit
/// normal), largest first: each the plane most of the points left lie on, while it holds more
/// of them than the part's whole surface could.
pub(super) fn large_planes(
    coarse: &[Point3<f64>],
    mesh: &Mesh,
    voxel_m: f64,
) -> Vec<(Point3<f64>, Vector3<f64>)> {
    let part_area = mesh.area_m2();
    let most_keypoints = LARGER_THAN_PART * part_area / (voxel_m * voxel_m);
    let mut kept = coarse.to_vec();
    let mut rng = SplitMix64::new(0x9e37_79b9_7f4a_7c15 ^ kept.len() as u64);
    let mut planes = Vec::new();
    for _ in 0..MAX_PLANES {
        let Some((origin, normal)) = largest_plane(&kept, &mut rng) else {
            break;
        };
        let on = |p: &Point3<f64>| (p - origin).dot(&normal).abs() <= ON_PLANE_M;
        let count = kept.iter().filter(|p| on(p)).count();
        if (count as f64) <= most_keypoints {
            break;
        }
        kept.retain(|p| !on(p));
        planes.push((origin, normal));
    }
    planes
}

/// Whether `point` lies on one of `planes`.
pub(super) fn on_a_plane(point: &Point3<f64>, planes: &[(Point3<f64>, Vector3<f64>)]) -> bool {
    planes
        .iter()
        .any(|(origin, normal)| (point - origin).dot(normal).abs() <= ON_PLANE_M)
}

/// The plane through three of `points` that most of a sample of them lie on, as a point on it
/// and its unit normal.
fn largest_plane(
    points: &[Point3<f64>],
    rng: &mut SplitMix64,
) -> Option<(Point3<f64>, Vector3<f64>)> {
    if points.len() < 3 {
        return None;
    }
    let stride = points.len().div_ceil(SAMPLE).max(1);
    let sample: Vec<&Point3<f64>> = points.iter().step_by(stride).collect();
    let pick = |rng: &mut SplitMix64| {
        let index = ((rng.uniform() * points.len() as f64) as usize).min(points.len() - 1);
        points[index]
    };
    let mut best: Option<(usize, Point3<f64>, Vector3<f64>)> = None;
    for _ in 0..HYPOTHESES {
        let (a, b, c) = (pick(rng), pick(rng), pick(rng));
        let Some(normal) = (b - a).cross(&(c - a)).try_normalize(1e-12) else {
            continue;
        };
        let count = sample
            .iter()
            .filter(|p| (**p - a).dot(&normal).abs() <= ON_PLANE_M)
            .count();
        if best.as_ref().is_none_or(|(most, _, _)| count > *most) {
            best = Some((count, a, normal));
        }
    }
    best.map(|(_, origin, normal)| (origin, normal))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(
        size: usize,
        step_m: f64,
        to_point: impl Fn(f64, f64) -> Point3<f64>,
    ) -> Vec<Point3<f64>> {
        (0..size)
            .flat_map(|i| (0..size).map(move |j| (i as f64 * step_m, j as f64 * step_m)))
            .map(|(u, v)| to_point(u, v))
            .collect()
    }

    #[test]
    fn a_floor_larger_than_the_part_is_taken_out_and_the_part_stays() {
        // A 0.1 m cube (0.06 m^2 of surface) standing on a 1.2 m floor seen at 15 mm.
        let part = Mesh::cuboid([0.1, 0.1, 0.1]).unwrap();
        let mut points = grid(80, 0.015, |u, v| Point3::new(u - 0.6, v - 0.6, 0.0));
        let top = grid(7, 0.015, |u, v| Point3::new(u - 0.05, v - 0.05, 0.1));
        let side = grid(7, 0.015, |u, v| Point3::new(0.05, u - 0.05, v + 0.005));
        points.extend(&top);
        points.extend(&side);
        let kept = without_large_planes(points, &part, 0.015);
        assert_eq!(kept.len(), top.len() + side.len());
    }

    #[test]
    fn a_plane_no_larger_than_the_part_is_kept() {
        // The same floor under a part with ten times its area: the floor could be its face.
        let part = Mesh::cuboid([1.0, 1.0, 1.0]).unwrap();
        let points = grid(80, 0.015, |u, v| Point3::new(u, v, 0.0));
        let count = points.len();
        assert_eq!(without_large_planes(points, &part, 0.015).len(), count);
    }
}
