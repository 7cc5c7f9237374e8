//! Uniform downsampling of a point cloud by voxels (the thesis's keypoints, 3.1.1): the cloud's
//! points are binned into cubes of edge `voxel_m` and each occupied cube gives one keypoint,
//! either the centroid of its points or the cloud point nearest that centroid. Output is ordered
//! by voxel, so it is deterministic.

use std::collections::BTreeMap;

use nalgebra::{Point3, Vector3};

fn bins(cloud: &[Point3<f64>], voxel_m: f64) -> BTreeMap<(i64, i64, i64), Vec<usize>> {
    let mut voxels: BTreeMap<(i64, i64, i64), Vec<usize>> = BTreeMap::new();
    for (index, point) in cloud.iter().enumerate() {
        let key = (
            (point.x / voxel_m).floor() as i64,
            (point.y / voxel_m).floor() as i64,
            (point.z / voxel_m).floor() as i64,
        );
        voxels.entry(key).or_default().push(index);
    }
    voxels
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
    bins(cloud, voxel_m)
        .values()
        .map(|members| centroid(cloud, members))
        .collect()
}

/// Per occupied voxel, the cloud point nearest the voxel's centroid (as PCL's UniformSampling):
/// every keypoint is a measured point, so edges are not shaved.
pub fn voxel_representatives(cloud: &[Point3<f64>], voxel_m: f64) -> Vec<Point3<f64>> {
    if !(voxel_m > 0.0 && voxel_m.is_finite()) {
        return cloud.to_vec();
    }
    bins(cloud, voxel_m)
        .values()
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
}
