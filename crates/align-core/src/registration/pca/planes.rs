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

use crate::geometry::{Mesh, plane_through};
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

/// `coarse` without the floor a part stands on, however small the scan shows it: the plane
/// holding the most of `coarse` when it holds more than [`LARGER_THAN_PART`] times any flat
/// face of the part could and nearly all the scan lies on one side of it. The planes test of
/// [`without_large_planes`] leaves a floor holding fewer keypoints than the part's whole
/// surface: the project's own scans of the ABB IRB 1600 show 0.6 m^2 of floor around it, 3347
/// keypoints at 15 mm against the 3771 its base's 0.85 m^2 could hold, and its base was then
/// detected 0.4 m off (the `ppf_detection` bench). Only the part's largest face bounds a plane
/// of its own; and a plane with scan on both sides cuts through something standing on it.
pub fn without_floor_under(
    mut coarse: Vec<Point3<f64>>,
    mesh: &Mesh,
    voxel_m: f64,
) -> Vec<Point3<f64>> {
    if let Some(floor) = floor_plane(&coarse, mesh, voxel_m) {
        coarse.retain(|p| !on_a_plane(p, std::slice::from_ref(&floor)));
    }
    coarse
}

/// The floor under the scan, as [`without_floor_under`] finds it (a point on it and its unit
/// normal): the plane holding the most of `coarse` (keypoints one per voxel of `voxel_m`), when
/// it holds more than [`LARGER_THAN_PART`] times the largest flat face of `mesh` could and
/// nearly all the scan lies on one side of it. The normal points to that side, where what
/// stands on the floor and the scanner are. `None` when no plane is such a floor.
pub fn floor_plane(
    coarse: &[Point3<f64>],
    mesh: &Mesh,
    voxel_m: f64,
) -> Option<(Point3<f64>, Vector3<f64>)> {
    let most_keypoints = LARGER_THAN_PART * largest_face_area_m2(mesh) / (voxel_m * voxel_m);
    let mut rng = SplitMix64::new(0x5851_f42d_4c95_7f2d ^ coarse.len() as u64);
    let mut plane = largest_plane_by_neighbours(coarse, &mut rng)?;
    // Three points a few centimetres apart tilt the plane by their noise: metres away it leaves
    // the band. A least-squares plane through the points on it does not.
    for _ in 0..REFITS {
        match refit(coarse, &plane) {
            Some(refitted) => plane = refitted,
            None => break,
        }
    }
    let (origin, normal) = plane;
    let (mut on, mut above, mut below) = (0_usize, 0_usize, 0_usize);
    for p in coarse {
        let height_m = (p - origin).dot(&normal);
        match height_m {
            h if h.abs() <= ON_PLANE_M => on += 1,
            h if h > 0.0 => above += 1,
            _ => below += 1,
        }
    }
    let beyond = above.min(below) as f64;
    let up = if above >= below { normal } else { -normal };
    ((on as f64) > most_keypoints && beyond <= BEYOND_FLOOR * (above + below) as f64)
        .then_some((origin, up))
}

/// The share of a scan's points off the floor allowed on its far side: stray returns and
/// mixed pixels, which a scanner puts along the line of sight and so mostly above it.
const BEYOND_FLOOR: f64 = 0.02;

/// Neighbours a floor plane's three points are drawn within: a floor point's neighbours lie
/// mostly on the floor, so a plane through them is the floor's far more often than one through
/// three points drawn anywhere (with the floor a seventh of the scan, 1 in 350 of those).
const NEIGHBOURHOOD_M: f64 = 0.1;

/// The area of the part's largest flat face (m^2): the triangles lying, within [`ON_PLANE_M`],
/// in the plane of one of its largest triangles, summed.
fn largest_face_area_m2(mesh: &Mesh) -> f64 {
    let count = mesh.triangles().len() as u32;
    let mut by_area: Vec<u32> = (0..count).collect();
    by_area.sort_by(|a, b| mesh.triangle_area(*b).total_cmp(&mesh.triangle_area(*a)));
    let vertices: Vec<Point3<f64>> = mesh.vertices().collect();
    let corners = |t: u32| mesh.triangles()[t as usize].map(|v| vertices[v as usize]);
    by_area
        .iter()
        .take(FACE_SEEDS)
        .map(|&seed| {
            let normal = mesh.triangle_normal(seed);
            let origin = corners(seed)[0];
            (0..count)
                .filter(|&t| {
                    corners(t)
                        .iter()
                        .all(|v| (v - origin).dot(&normal).abs() <= ON_PLANE_M)
                })
                .map(|t| mesh.triangle_area(t))
                .sum::<f64>()
        })
        .fold(0.0, f64::max)
}

/// Least-squares refits of the floor's plane.
const REFITS: usize = 2;

/// The least-squares plane of the points of `coarse` within [`ON_PLANE_M`] of `plane`.
fn refit(
    coarse: &[Point3<f64>],
    (origin, normal): &(Point3<f64>, Vector3<f64>),
) -> Option<(Point3<f64>, Vector3<f64>)> {
    let on: Vec<Point3<f64>> = coarse
        .iter()
        .filter(|p| (*p - origin).dot(normal).abs() <= ON_PLANE_M)
        .copied()
        .collect();
    plane_through(&on)
}

/// The largest triangles whose planes [`largest_face_area_m2`] tries.
const FACE_SEEDS: usize = 64;

/// As [`largest_plane`], with each plane through a point and two of its neighbours within
/// [`NEIGHBOURHOOD_M`] (drawn from the counted sample).
fn largest_plane_by_neighbours(
    points: &[Point3<f64>],
    rng: &mut SplitMix64,
) -> Option<(Point3<f64>, Vector3<f64>)> {
    let stride = points.len().div_ceil(SAMPLE).max(1);
    let sample: Vec<&Point3<f64>> = points.iter().step_by(stride).collect();
    if sample.len() < 3 {
        return None;
    }
    let draw =
        |rng: &mut SplitMix64, len: usize| ((rng.uniform() * len as f64) as usize).min(len - 1);
    most_supported_plane(&sample, || {
        let a = sample[draw(rng, sample.len())];
        let near: Vec<&Point3<f64>> = sample
            .iter()
            .copied()
            .filter(|p| (*p - a).norm_squared() <= NEIGHBOURHOOD_M * NEIGHBOURHOOD_M)
            .collect();
        if near.len() < 3 {
            return None;
        }
        Some((
            *a,
            *near[draw(rng, near.len())],
            *near[draw(rng, near.len())],
        ))
    })
}

/// Of [`HYPOTHESES`] planes, each through three points `triple` draws (`None`: no plane this
/// time), the one most of `sample` lies on, as a point on it and its unit normal.
fn most_supported_plane(
    sample: &[&Point3<f64>],
    mut triple: impl FnMut() -> Option<(Point3<f64>, Point3<f64>, Point3<f64>)>,
) -> Option<(Point3<f64>, Vector3<f64>)> {
    let mut best: Option<(usize, Point3<f64>, Vector3<f64>)> = None;
    for _ in 0..HYPOTHESES {
        let Some((a, b, c)) = triple() else {
            continue;
        };
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

/// `points` without those on one of `planes`.
pub(super) fn off_the_planes(
    points: &[Point3<f64>],
    planes: &[(Point3<f64>, Vector3<f64>)],
) -> Vec<Point3<f64>> {
    points
        .iter()
        .filter(|p| !on_a_plane(p, planes))
        .copied()
        .collect()
}

/// Whether `point` lies on one of `planes`.
pub fn on_a_plane(point: &Point3<f64>, planes: &[(Point3<f64>, Vector3<f64>)]) -> bool {
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
    most_supported_plane(&sample, || Some((pick(rng), pick(rng), pick(rng))))
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

    /// A 0.4 m cube's top and two sides, standing on the floor at z = 0, at 15 mm.
    fn standing_cube() -> Vec<Point3<f64>> {
        let mut points = grid(27, 0.015, |u, v| Point3::new(u - 0.2, v - 0.2, 0.4));
        points.extend(grid(27, 0.015, |u, v| Point3::new(0.2, u - 0.2, v + 0.005)));
        points.extend(grid(27, 0.015, |u, v| {
            Point3::new(u - 0.2, -0.2, v + 0.005)
        }));
        points
    }

    #[test]
    fn a_floor_smaller_than_the_part_is_taken_out_when_everything_stands_on_it() {
        // 0.81 m^2 of floor (3600 keypoints) under a part of 0.96 m^2 (4267 keypoints at
        // 15 mm): too small for the planes test, more than twice its largest face (0.16 m^2).
        let part = Mesh::cuboid([0.4, 0.4, 0.4]).unwrap();
        let cube = standing_cube();
        let mut points = grid(60, 0.015, |u, v| Point3::new(u - 0.45, v - 0.45, 0.0));
        points.extend(&cube);
        let floor_and_cube = points.len();
        assert_eq!(
            without_large_planes(points.clone(), &part, 0.015).len(),
            floor_and_cube
        );
        let (origin, normal) = floor_plane(&points, &part, 0.015).expect("a floor");
        // Up, towards the cube standing on it.
        assert!(
            normal.z > 1.0 - 1e-6 && origin.z.abs() < 1e-9,
            "{origin} {normal}"
        );
        // The same scan upside down: the normal still points to the cube.
        let flipped: Vec<Point3<f64>> =
            points.iter().map(|p| Point3::new(p.x, p.y, -p.z)).collect();
        let (_, normal) = floor_plane(&flipped, &part, 0.015).expect("a floor");
        assert!(normal.z < -1.0 + 1e-6, "{normal}");
        assert_eq!(without_floor_under(points, &part, 0.015), cube);
    }

    #[test]
    fn a_plane_with_scan_on_both_sides_is_not_a_floor() {
        // The same floor through the middle of the cube: the part's lower half lies below it.
        let part = Mesh::cuboid([0.4, 0.4, 0.4]).unwrap();
        let mut points = grid(60, 0.015, |u, v| Point3::new(u - 0.45, v - 0.45, 0.0));
        points.extend(standing_cube().iter().map(|p| p - Vector3::z() * 0.2));
        assert_eq!(floor_plane(&points, &part, 0.015), None);
        let count = points.len();
        assert_eq!(without_floor_under(points, &part, 0.015).len(), count);
    }

    #[test]
    fn a_floor_no_larger_than_the_parts_largest_face_is_kept() {
        // 0.12 m^2 of floor under a cube whose faces are 0.16 m^2 each.
        let part = Mesh::cuboid([0.4, 0.4, 0.4]).unwrap();
        let mut points = grid(23, 0.015, |u, v| Point3::new(u - 0.17, v - 0.17, 0.0));
        points.extend(standing_cube());
        let count = points.len();
        assert_eq!(without_floor_under(points, &part, 0.015).len(), count);
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
