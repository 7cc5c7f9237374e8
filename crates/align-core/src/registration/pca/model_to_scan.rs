//! Model-to-scan matching for a local run's wide bands: points sampled on the part's surface each
//! find the nearest scan keypoint within the band, as the local peers (Open3D, small_gicp) match.
//! In a band of decimetres the scan's keypoints are mostly floor and fixtures; matched to the
//! part, they decide where the step goes by their number. Matched from the part, each of its
//! points counts once (see `WideBandMatching` in `schedule`).

use std::collections::HashMap;

use nalgebra::{Isometry3, Point3, Vector3};
use rayon::prelude::*;

use super::matching::{Match, NO_HINT};
use crate::geometry::Mesh;
use crate::registration::sampling::floor_index;
use crate::rng::SplitMix64;

/// Leaves of the tree hold at most this many points, searched one by one.
const LEAF_POINTS: usize = 8;

/// A k-d tree over a fixed set of points, stored implicitly: the node of a range of `order` is
/// its middle entry, split along the axis of its depth.
pub(super) struct ScanTree {
    points: Vec<Point3<f64>>,
    order: Vec<u32>,
}

impl ScanTree {
    pub(super) fn new(points: &[Point3<f64>]) -> Self {
        let mut order: Vec<u32> = (0..points.len() as u32).collect();
        build(points, &mut order, 0);
        Self {
            points: points.to_vec(),
            order,
        }
    }

    /// The nearest point within `max_m` of `query`, and its distance. With `hint`, the search
    /// is bounded from the start by the distance to point `hint` (the answer for this query's
    /// point at the previous step of a run: a step moves the part by a little, so it is near the
    /// nearest and the descent opens few nodes). A point as near as the hint keeps the hint.
    pub(super) fn nearest_within_hinted(
        &self,
        query: &Point3<f64>,
        max_m: f64,
        hint: Option<usize>,
    ) -> Option<(usize, f64)> {
        let mut best = (usize::MAX, max_m * max_m);
        if let Some(index) = hint.filter(|&i| i < self.points.len()) {
            let squared = (self.points[index] - query).norm_squared();
            if squared <= best.1 {
                best = (index, squared);
            }
        }
        self.search(0, self.order.len(), 0, query, &mut best);
        (best.0 != usize::MAX).then(|| (best.0, best.1.sqrt()))
    }

    fn search(
        &self,
        lo: usize,
        hi: usize,
        depth: usize,
        query: &Point3<f64>,
        best: &mut (usize, f64),
    ) {
        if hi - lo <= LEAF_POINTS {
            for &index in &self.order[lo..hi] {
                let squared = (self.points[index as usize] - query).norm_squared();
                if squared < best.1 {
                    *best = (index as usize, squared);
                }
            }
            return;
        }
        let mid = lo + (hi - lo) / 2;
        let index = self.order[mid] as usize;
        let point = &self.points[index];
        let squared = (point - query).norm_squared();
        if squared < best.1 {
            *best = (index, squared);
        }
        let axis = depth % 3;
        let offset = query[axis] - point[axis];
        let (near, far) = if offset < 0.0 {
            ((lo, mid), (mid + 1, hi))
        } else {
            ((mid + 1, hi), (lo, mid))
        };
        self.search(near.0, near.1, depth + 1, query, best);
        if offset * offset < best.1 {
            self.search(far.0, far.1, depth + 1, query, best);
        }
    }
}

fn build(points: &[Point3<f64>], order: &mut [u32], depth: usize) {
    if order.len() <= LEAF_POINTS {
        return;
    }
    let mid = order.len() / 2;
    let axis = depth % 3;
    order.select_nth_unstable_by(mid, |a, b| {
        points[*a as usize][axis].total_cmp(&points[*b as usize][axis])
    });
    let (left, right) = order.split_at_mut(mid);
    build(points, left, depth + 1);
    build(points, &mut right[1..], depth + 1);
}

/// A voxel's integer coordinates.
type VoxelKey = (i64, i64, i64);

/// Points on the part's surface about `spacing_m` apart (part frame), with their faces' normals.
pub(crate) struct ModelSamples {
    pub(crate) points: Vec<Point3<f64>>,
    pub(crate) normals: Vec<Vector3<f64>>,
}

impl ModelSamples {
    pub(crate) fn new(mesh: &Mesh, spacing_m: f64) -> Self {
        let mut rng = SplitMix64::new(0x5eed);
        let per_area = 4.0 / (spacing_m * spacing_m);
        let mut kept: HashMap<VoxelKey, (Point3<f64>, Vector3<f64>)> = HashMap::new();
        let vertices: Vec<Point3<f64>> = mesh.vertices().collect();
        for (t, corners) in mesh.triangles().iter().enumerate() {
            let area = mesh.triangle_area(t as u32);
            let expected = area * per_area;
            let count = expected.floor() as usize + usize::from(rng.uniform() < expected.fract());
            let [a, b, c] = corners.map(|i| vertices[i as usize]);
            let normal = mesh.triangle_normal(t as u32);
            for _ in 0..count {
                let (mut u, mut v) = (rng.uniform(), rng.uniform());
                if u + v > 1.0 {
                    (u, v) = (1.0 - u, 1.0 - v);
                }
                let point = a + (b - a) * u + (c - a) * v;
                let key = (
                    floor_index(point.x / spacing_m),
                    floor_index(point.y / spacing_m),
                    floor_index(point.z / spacing_m),
                );
                kept.entry(key).or_insert((point, normal));
            }
        }
        let mut pairs: Vec<_> = kept.into_iter().collect();
        pairs.sort_by_key(|(key, _)| *key);
        Self {
            points: pairs.iter().map(|(_, (p, _))| *p).collect(),
            normals: pairs.iter().map(|(_, (_, n))| *n).collect(),
        }
    }
}

/// One coarse level's model samples and scan tree.
pub(super) struct ModelToScanLevel {
    pub(super) samples: ModelSamples,
    pub(super) tree: ScanTree,
}

/// Each model sample at `pose` matched to its nearest scan keypoint within `delta`. `hints`
/// (one per sample, or empty) remember each sample's keypoint between the steps of a run (see
/// [`ScanTree::nearest_within_hinted`]): the same matches with fewer nodes opened (on the
/// seed-42 CAD corpus's 50 mm successes, 3.4 ms of matching per alignment against 5.2 without;
/// an instrumented build, docs/BENCHMARKS.md).
pub(super) fn correspond_model_to_scan(
    level: &ModelToScanLevel,
    pose: &Isometry3<f64>,
    delta: f64,
    parallel: bool,
    hints: &mut [u32],
) -> Vec<Match> {
    let one = |i: usize, hint: Option<&mut u32>| -> Option<Match> {
        let surface = pose * level.samples.points[i];
        let remembered = hint
            .as_ref()
            .map(|h| **h)
            .filter(|&h| h != NO_HINT)
            .map(|h| h as usize);
        let (nearest, distance) = level
            .tree
            .nearest_within_hinted(&surface, delta, remembered)?;
        if let Some(hint) = hint {
            *hint = nearest as u32;
        }
        let weight = (distance / delta * std::f64::consts::FRAC_PI_2).cos();
        (weight > 0.0).then(|| Match {
            point: level.tree.points[nearest],
            surface,
            normal: pose.rotation * level.samples.normals[i],
            distance,
            weight,
        })
    };
    let count = level.samples.points.len();
    match (parallel, hints.len() == count) {
        (true, true) => hints
            .par_iter_mut()
            .enumerate()
            .filter_map(|(i, hint)| one(i, Some(hint)))
            .collect(),
        (true, false) => (0..count)
            .into_par_iter()
            .filter_map(|i| one(i, None))
            .collect(),
        (false, true) => hints
            .iter_mut()
            .enumerate()
            .filter_map(|(i, hint)| one(i, Some(hint)))
            .collect(),
        (false, false) => (0..count).filter_map(|i| one(i, None)).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tree_finds_the_nearest_point_within_the_bound_as_a_full_scan_does_hinted_or_not() {
        let mut rng = SplitMix64::new(3);
        let points: Vec<Point3<f64>> = (0..2000)
            .map(|_| Point3::new(rng.uniform(), rng.uniform() * 0.5, rng.uniform() * 0.2))
            .collect();
        let tree = ScanTree::new(&points);
        for _ in 0..500 {
            let query = Point3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 1.2;
            for max_m in [0.01, 0.05, 0.5] {
                let expected = points
                    .iter()
                    .enumerate()
                    .map(|(i, p)| (i, (p - query).norm()))
                    .filter(|(_, d)| *d <= max_m)
                    .min_by(|a, b| a.1.total_cmp(&b.1));
                let found = tree.nearest_within_hinted(&query, max_m, None);
                assert_eq!(found.map(|f| f.1), expected.map(|e| e.1), "{query} {max_m}");
                // Any hint, near or far, in range or not, gives the same distance.
                let hint = (rng.uniform() * 2100.0) as usize;
                let hinted = tree.nearest_within_hinted(&query, max_m, Some(hint));
                assert_eq!(
                    hinted.map(|f| f.1),
                    expected.map(|e| e.1),
                    "{query} {max_m} {hint}"
                );
                if let Some((index, _)) = expected {
                    let from_answer = tree.nearest_within_hinted(&query, max_m, Some(index));
                    assert_eq!(from_answer.map(|f| f.0), Some(index));
                }
            }
        }
        assert!(
            ScanTree::new(&[])
                .nearest_within_hinted(&Point3::origin(), 1.0, None)
                .is_none()
        );
    }

    #[test]
    fn model_samples_lie_on_the_surface_about_the_spacing_apart() {
        let mesh = Mesh::cuboid([0.2, 0.1, 0.05]).expect("a box");
        let samples = ModelSamples::new(&mesh, 0.01);
        // The box's 0.07 m2 at one sample per occupied 1 cm voxel: several hundred.
        assert!(samples.points.len() > 300, "{}", samples.points.len());
        for (point, normal) in samples.points.iter().zip(&samples.normals) {
            let closest = mesh.closest_point(point);
            assert!(closest.signed_distance.abs() < 1e-9);
            assert!((normal.norm() - 1.0).abs() < 1e-9);
        }
    }
}
