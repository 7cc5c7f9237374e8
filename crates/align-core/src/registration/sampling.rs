//! Uniform downsampling of a point cloud by voxels (the thesis's keypoints, 3.1.1): the cloud's
//! points are binned into cubes of edge `voxel_m` and each occupied cube gives one keypoint,
//! either the centroid of its points or the cloud point nearest that centroid. Output is ordered
//! by voxel, so it is deterministic.

use nalgebra::{Point3, Vector3};
use rayon::slice::ParallelSliceMut;

type VoxelKey = (i64, i64, i64);

fn voxel_of(point: &Point3<f64>, voxel_m: f64) -> VoxelKey {
    (
        (point.x / voxel_m).floor() as i64,
        (point.y / voxel_m).floor() as i64,
        (point.z / voxel_m).floor() as i64,
    )
}

/// The cloud's points grouped by voxel: each group holds the indices of one voxel's points in
/// cloud order, the groups in key order. One sort of (key, index) pairs: a map of vectors,
/// allocated once per voxel, took a few milliseconds per 20k points, and the robot fit samples
/// its cloud several times.
struct Bins {
    order: Vec<usize>,
    ends: Vec<usize>,
}

/// A voxel index per axis packed in [`PACKED_BITS`] bits (offset by half their range), so that a
/// key is one `u64` whose order is the keys' lexicographic order.
const PACKED_BITS: u32 = 21;
const PACKED_OFFSET: i64 = 1 << (PACKED_BITS - 1);

/// `key` packed into one `u64` in the same order, or `None` when an index does not fit (a cloud
/// kilometres wide at a millimetre voxel, or an infinite coordinate; a NaN one bins at 0 on
/// both paths).
fn packed((x, y, z): VoxelKey) -> Option<u64> {
    let axis = |index: i64| {
        let shifted = index.checked_add(PACKED_OFFSET)?;
        (0..1 << PACKED_BITS)
            .contains(&shifted)
            .then_some(shifted as u64)
    };
    Some((axis(x)? << (2 * PACKED_BITS)) | (axis(y)? << PACKED_BITS) | axis(z)?)
}

/// Clouds at least this large are sorted on all cores.
const PARALLEL_SORT_POINTS: usize = 8192;

impl Bins {
    fn new(cloud: &[Point3<f64>], voxel_m: f64) -> Self {
        // Packed keys: a pair of 16 bytes with one comparison instead of 32 bytes with three,
        // sorted on all cores. A local alignment bins a cell's points near the part (20-40k)
        // and its keypoints at two coarser voxels: 9 ms of a 60 ms 50 mm CAD scan's alignment.
        let packed_keys: Option<Vec<(u64, usize)>> = cloud
            .iter()
            .enumerate()
            .map(|(index, point)| Some((packed(voxel_of(point, voxel_m))?, index)))
            .collect();
        match packed_keys {
            Some(keyed) => Self::from_sorted(sorted(keyed)),
            None => {
                let keyed: Vec<(VoxelKey, usize)> = cloud
                    .iter()
                    .enumerate()
                    .map(|(index, point)| (voxel_of(point, voxel_m), index))
                    .collect();
                Self::from_sorted(sorted(keyed))
            }
        }
    }

    /// From (key, index) pairs in order.
    fn from_sorted<K: PartialEq>(keyed: Vec<(K, usize)>) -> Self {
        let ends = (1..=keyed.len())
            .filter(|&i| i == keyed.len() || keyed[i].0 != keyed[i - 1].0)
            .collect();
        Self {
            order: keyed.into_iter().map(|(_, index)| index).collect(),
            ends,
        }
    }

    fn groups(&self) -> impl Iterator<Item = &[usize]> {
        let starts = std::iter::once(0).chain(self.ends.iter().copied());
        starts
            .zip(&self.ends)
            .map(|(start, &end)| &self.order[start..end])
    }
}

/// `keyed` in order. The index breaks ties, so the unstable sort keeps each voxel's points in
/// cloud order.
fn sorted<K: Ord + Send>(mut keyed: Vec<(K, usize)>) -> Vec<(K, usize)> {
    if keyed.len() >= PARALLEL_SORT_POINTS {
        keyed.par_sort_unstable();
    } else {
        keyed.sort_unstable();
    }
    keyed
}

fn centroid(cloud: &[Point3<f64>], members: &[usize]) -> Point3<f64> {
    let sum = members
        .iter()
        .fold(Vector3::zeros(), |sum, &i| sum + cloud[i].coords);
    Point3::from(sum / members.len() as f64)
}

/// Centroids of the occupied voxels of edge `voxel_m` (`voxel_m <= 0` returns the cloud).
/// Averaging lowers noise, but where a voxel straddles an edge its centroid lies off the surface.
pub fn voxel_centroids(cloud: &[Point3<f64>], voxel_m: f64) -> Vec<Point3<f64>> {
    if !(voxel_m > 0.0 && voxel_m.is_finite()) {
        return cloud.to_vec();
    }
    Bins::new(cloud, voxel_m)
        .groups()
        .map(|members| centroid(cloud, members))
        .collect()
}

/// Per occupied voxel, the cloud point nearest the voxel's centroid (as PCL's UniformSampling):
/// every keypoint is a measured point, so edges are not shaved.
pub fn voxel_representatives(cloud: &[Point3<f64>], voxel_m: f64) -> Vec<Point3<f64>> {
    if !(voxel_m > 0.0 && voxel_m.is_finite()) {
        return cloud.to_vec();
    }
    Bins::new(cloud, voxel_m)
        .groups()
        .map(|members| {
            let centre = centroid(cloud, members);
            members
                .iter()
                .map(|&i| cloud[i])
                .min_by(|a, b| {
                    (a - centre)
                        .norm_squared()
                        .total_cmp(&(b - centre).norm_squared())
                })
                .unwrap_or(centre)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_in_one_voxel_become_their_centroid() {
        let cloud = [
            Point3::new(0.001, 0.001, 0.001),
            Point3::new(0.003, 0.001, 0.001),
            Point3::new(0.012, 0.0, 0.0),
        ];
        let sampled = voxel_centroids(&cloud, 0.01);
        assert_eq!(sampled.len(), 2);
        assert!((sampled[0] - Point3::new(0.002, 0.001, 0.001)).norm() < 1e-15);
        assert_eq!(voxel_centroids(&cloud, 0.0).len(), 3);
        let representatives = voxel_representatives(&cloud, 0.01);
        assert_eq!(representatives.len(), 2);
        assert!(cloud.contains(&representatives[0]));
    }

    #[test]
    fn the_sorted_bins_group_as_a_map_of_voxels_does() {
        let mut state = 99u64;
        let mut uniform = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        // Above the parallel sort's size; at 1e-7 m the indices (up to 5e6) do not pack and the
        // tuples are sorted instead.
        let cloud: Vec<Point3<f64>> = (0..3 * PARALLEL_SORT_POINTS)
            .map(|_| Point3::new(uniform(), uniform() * 0.3, uniform() * 0.1))
            .collect();
        for voxel_m in [1e-7, 0.006, 0.02, 0.09] {
            let mut map: std::collections::BTreeMap<VoxelKey, Vec<usize>> = Default::default();
            for (index, point) in cloud.iter().enumerate() {
                map.entry(voxel_of(point, voxel_m)).or_default().push(index);
            }
            let bins = Bins::new(&cloud, voxel_m);
            let grouped: Vec<&[usize]> = bins.groups().collect();
            let expected: Vec<&[usize]> = map.values().map(Vec::as_slice).collect();
            assert_eq!(grouped, expected, "voxel {voxel_m}");
        }
        assert_eq!(Bins::new(&[], 0.01).groups().count(), 0);
    }

    #[test]
    fn packed_keys_order_as_the_keys_do_and_refuse_what_does_not_fit() {
        let limit = PACKED_OFFSET;
        let keys = [
            (-limit, 0, 0),
            (-1, limit - 1, -limit),
            (-1, limit - 1, 5),
            (0, -3, 7),
            (0, -2, -limit),
            (limit - 1, limit - 1, limit - 1),
        ];
        let packed_keys: Vec<u64> = keys.iter().map(|&k| packed(k).expect("fits")).collect();
        assert!(packed_keys.windows(2).all(|pair| pair[0] < pair[1]));
        for key in [
            (limit, 0, 0),
            (0, -limit - 1, 0),
            (0, 0, i64::MAX),
            (i64::MIN, 0, 0),
        ] {
            assert_eq!(packed(key), None, "{key:?}");
        }
    }
}
