//! Uniform downsampling of a point cloud by voxels (the thesis's keypoints, 3.1.1): the cloud's
//! points are binned into cubes of edge `voxel_m` and each occupied cube gives one keypoint,
//! either the centroid of its points or the cloud point nearest that centroid. Output is ordered
//! by voxel, so it is deterministic.

use std::collections::HashMap;

use nalgebra::{Point3, Vector3};
use rayon::slice::ParallelSliceMut;

use crate::geometry::PrincipalSpread;

type VoxelKey = (i64, i64, i64);

fn voxel_of(point: &Point3<f64>, voxel_m: f64) -> VoxelKey {
    (
        floor_index(point.x / voxel_m),
        floor_index(point.y / voxel_m),
        floor_index(point.z / voxel_m),
    )
}

/// `value.floor() as i64`, without the call: the baseline x86-64 target has no rounding
/// instruction, and `floor` was an eighth of binning a scan (perf). The conversion truncates
/// towards zero (and saturates, NaN to 0), so a negative value with a fraction is one above its
/// floor.
pub(crate) fn floor_index(value: f64) -> i64 {
    let truncated = value as i64;
    if (truncated as f64) > value {
        truncated.saturating_sub(1)
    } else {
        truncated
    }
}

/// The cloud's points grouped by voxel: each group holds the indices of one voxel's points in
/// cloud order, the groups in key order. One sort of (key, index) pairs: a map of vectors,
/// allocated once per voxel, took a few milliseconds per 20k points, and the robot fit samples
/// its cloud several times.
struct Bins {
    order: Vec<usize>,
    ends: Vec<usize>,
}

/// Voxel keys packed into one `u64` each, in the same order: each axis's index less the
/// cloud's lowest, in as many bits as the cloud's span on that axis needs. A cell's scan at 5 mm
/// spans a few hundred voxels per axis, so that a key takes about 27 bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Packing {
    lowest: VoxelKey,
    /// Bits of the y and z indices (x takes the rest).
    y_bits: u32,
    z_bits: u32,
    /// Bits of a packed key.
    total_bits: u32,
}

impl Packing {
    /// The packing of `keys`, or `None` when their spans need more than 64 bits together (a
    /// cloud kilometres wide at a micrometre voxel, or an infinite coordinate; a NaN one bins at
    /// 0).
    fn of(keys: &[VoxelKey]) -> Option<Self> {
        let (first, rest) = keys.split_first()?;
        let (lowest, highest) = rest.iter().fold((*first, *first), |(lo, hi), k| {
            (
                (lo.0.min(k.0), lo.1.min(k.1), lo.2.min(k.2)),
                (hi.0.max(k.0), hi.1.max(k.1), hi.2.max(k.2)),
            )
        });
        let bits = |low: i64, high: i64| -> Option<u32> {
            let span = high.checked_sub(low)?;
            Some(u64::BITS - (span as u64).leading_zeros())
        };
        let x_bits = bits(lowest.0, highest.0)?;
        let y_bits = bits(lowest.1, highest.1)?;
        let z_bits = bits(lowest.2, highest.2)?;
        let total_bits = x_bits + y_bits + z_bits;
        (total_bits <= u64::BITS).then_some(Self {
            lowest,
            y_bits,
            z_bits,
            total_bits,
        })
    }

    /// `key`, one of the keys the packing was made of.
    fn pack(&self, (x, y, z): VoxelKey) -> u64 {
        // The spans fit their bits, so the differences are small and non-negative.
        let offset = |index: i64, low: i64| index.wrapping_sub(low) as u64;
        let x = offset(x, self.lowest.0);
        let y = offset(y, self.lowest.1);
        let z = offset(z, self.lowest.2);
        // A shift by 64 (x alone taking every bit) is out of range for `<<`.
        let shifted = |value: u64, by: u32| value.checked_shl(by).unwrap_or(0);
        shifted(x, self.y_bits + self.z_bits) | shifted(y, self.z_bits) | z
    }
}

/// Clouds at least this large are sorted on all cores (keys that do not pack).
const PARALLEL_SORT_POINTS: usize = 8192;

impl Bins {
    fn new(cloud: &[Point3<f64>], voxel_m: f64) -> Self {
        let keys: Vec<VoxelKey> = cloud.iter().map(|p| voxel_of(p, voxel_m)).collect();
        match Packing::of(&keys) {
            Some(packing) => {
                // Packed keys in a radix sort: a few passes over the pairs instead of a
                // comparison sort on both cores. A local alignment bins a cell's points near the
                // part (30-65k) at 5 mm and its keypoints at two coarser voxels: binning took
                // 2.5-5 ms for the first and 2.4-4.7 ms for the other two, of a 30-90 ms
                // alignment on the CAD scans (an instrumented build, docs/BENCHMARKS.md).
                let keyed: Vec<(u64, usize)> = keys
                    .iter()
                    .enumerate()
                    .map(|(index, key)| (packing.pack(*key), index))
                    .collect();
                Self::from_sorted(radix_sorted(keyed, packing.total_bits))
            }
            None => {
                let keyed: Vec<(VoxelKey, usize)> = keys.into_iter().zip(0..).collect();
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

/// Bits of the key sorted by one pass of [`radix_sorted`].
const RADIX_BITS: u32 = 11;

/// `keyed` (its keys under 2^`key_bits`) in key order, each key's entries in the order they came
/// in: a least-significant-digit radix sort, stable, so that from cloud order each voxel keeps
/// its points in cloud order as [`sorted`] does.
fn radix_sorted(mut keyed: Vec<(u64, usize)>, key_bits: u32) -> Vec<(u64, usize)> {
    let mask = (1u64 << RADIX_BITS) - 1;
    let mut scratch = vec![(0u64, 0usize); keyed.len()];
    let mut shift = 0;
    while shift < key_bits {
        let digit = |key: u64| ((key >> shift) & mask) as usize;
        let mut starts = vec![0usize; 1 << RADIX_BITS];
        for (key, _) in &keyed {
            starts[digit(*key)] += 1;
        }
        // A digit every key shares leaves the order as it is.
        if !starts.contains(&keyed.len()) {
            let mut total = 0;
            for start in &mut starts {
                let count = *start;
                *start = total;
                total += count;
            }
            for &(key, index) in &keyed {
                let slot = &mut starts[digit(key)];
                scratch[*slot] = (key, index);
                *slot += 1;
            }
            std::mem::swap(&mut keyed, &mut scratch);
        }
        shift += RADIX_BITS;
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
        .map(|members| representative(cloud, members))
        .collect()
}

/// The member of a voxel nearest its centroid.
fn representative(cloud: &[Point3<f64>], members: &[usize]) -> Point3<f64> {
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
}

/// Points in a hash of cubic cells, for neighbourhood queries.
pub(crate) struct CellIndex {
    cell_m: f64,
    cells: HashMap<[i64; 3], Vec<usize>>,
}

/// The cubic cell of edge `cell_m` that `point` lies in.
pub(crate) fn cell_of(point: &Point3<f64>, cell_m: f64) -> [i64; 3] {
    [
        (point.x / cell_m).floor() as i64,
        (point.y / cell_m).floor() as i64,
        (point.z / cell_m).floor() as i64,
    ]
}

impl CellIndex {
    pub(crate) fn new(points: &[Point3<f64>], cell_m: f64) -> Self {
        let mut cells: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
        for (index, point) in points.iter().enumerate() {
            cells.entry(cell_of(point, cell_m)).or_default().push(index);
        }
        Self { cell_m, cells }
    }

    /// Indices of `points` within `radius_m` (at most the cell size) of `centre`.
    pub(crate) fn within<'a>(
        &'a self,
        points: &'a [Point3<f64>],
        centre: &'a Point3<f64>,
        radius_m: f64,
    ) -> impl Iterator<Item = usize> + 'a {
        let [x, y, z] = cell_of(centre, self.cell_m);
        (-1..=1)
            .flat_map(move |dx| (-1..=1).flat_map(move |dy| (-1..=1).map(move |dz| (dx, dy, dz))))
            .filter_map(move |(dx, dy, dz)| self.cells.get(&[x + dx, y + dy, z + dz]))
            .flatten()
            .copied()
            .filter(move |&i| (points[i] - centre).norm_squared() <= radius_m * radius_m)
    }
}

/// Fewest cloud points a surface normal is estimated from.
const NORMAL_MIN_POINTS: usize = 6;

/// A neighbourhood is a surface with a normal while its scatter's least eigenvalue is at most
/// this fraction of the middle one. A flat patch with a scanner's noise gives nearly none, a
/// patch bent round a thin rod more, the thinner the rod; where two faces meet at a right angle
/// (the ridge in the tests below) the fraction is above this bar, and the direction of least
/// spread there says nothing about either face.
const FLAT_ENOUGH: f64 = 0.2;

/// The unit normal of the surface of `cloud` at each point of `at`: the direction of least
/// spread of the cloud's points within `radius_m` of it, or `None` where they are too few or do
/// not lie on one surface (see [`FLAT_ENOUGH`]). A scan has no reliable sign for its normals, so
/// neither has this.
pub fn surface_normals_at(
    cloud: &[Point3<f64>],
    at: &[Point3<f64>],
    radius_m: f64,
) -> Vec<Option<Vector3<f64>>> {
    use rayon::prelude::*;
    if !(radius_m > 0.0 && radius_m.is_finite()) || cloud.is_empty() {
        return vec![None; at.len()];
    }
    let index = CellIndex::new(cloud, radius_m);
    at.par_iter()
        .map(|point| {
            let neighbours: Vec<Point3<f64>> = index
                .within(cloud, point, radius_m)
                .map(|i| cloud[i])
                .collect();
            surface_normal(&neighbours)
        })
        .collect()
}

/// The unit normal of the surface `points` lie on (see [`FLAT_ENOUGH`]), if they lie on one.
fn surface_normal(points: &[Point3<f64>]) -> Option<Vector3<f64>> {
    if points.len() < NORMAL_MIN_POINTS {
        return None;
    }
    let spread = PrincipalSpread::of(points.iter().copied())?;
    let [_, middle, least] = spread.sigma_m.map(|sigma| sigma * sigma);
    let normal = spread.axes[2];
    (middle > 0.0 && least <= FLAT_ENOUGH * middle && normal.iter().all(|c| c.is_finite()))
        .then_some(normal)
}

/// Voxels within this many of a point's voxel (each axis) are its neighbourhood in
/// [`without_isolated`].
const NEIGHBOURHOOD_VOXELS: i64 = 2;

/// The points of `cloud` whose voxel (edge `voxel_m`) has at least `min_neighbours` other
/// occupied voxels within [`NEIGHBOURHOOD_VOXELS`] of it on every axis; the others are isolated
/// returns: a scanner's spurious returns along its rays, and the mixed pixels it leaves streaked
/// across the depth gap behind a silhouette. A surface scanned at any spacing up to twice the
/// voxel fills ten or more of the 124 neighbouring voxels (its edge half as many); a spurious
/// return among a cell's tens of thousands lands near fewer than one other
/// (crates/cad-scans: the ray-cast robot scans). Order is kept. `voxel_m <= 0` or
/// `min_neighbours == 0` returns the cloud.
pub fn without_isolated(
    cloud: &[Point3<f64>],
    voxel_m: f64,
    min_neighbours: usize,
) -> Vec<Point3<f64>> {
    if !(voxel_m > 0.0 && voxel_m.is_finite()) || min_neighbours == 0 {
        return cloud.to_vec();
    }
    let keys: Vec<VoxelKey> = cloud.iter().map(|p| voxel_of(p, voxel_m)).collect();
    // Nearest offsets first: a voxel on a surface has its neighbours next to it, so the count
    // stops after a few lookups; only the isolated ones look at all 124.
    let reach = NEIGHBOURHOOD_VOXELS;
    let mut offsets: Vec<VoxelKey> = (-reach..=reach)
        .flat_map(|x| (-reach..=reach).flat_map(move |y| (-reach..=reach).map(move |z| (x, y, z))))
        .filter(|&offset| offset != (0, 0, 0))
        .collect();
    offsets.sort_by_key(|(x, y, z)| x * x + y * y + z * z);
    if let Some(grid) = OccupancyGrid::new(&keys, reach) {
        // A bit per voxel of the cloud's box: a lookup is a load, where a hash lookup was most
        // of the filter's 7 ms on a 20k-point robot scan (docs/BENCHMARKS.md).
        let steps: Vec<usize> = offsets.iter().map(|o| grid.step(o)).collect();
        let crowded = |key: &VoxelKey| {
            let at = grid.index(key);
            steps
                .iter()
                .filter(|&&step| grid.occupied(at.wrapping_add(step)))
                .take(min_neighbours)
                .count()
                >= min_neighbours
        };
        // On both cores for a robot's scan (20k points: the lookups took about 1.5 ms of a
        // 2.4 ms filter on one); a cloud below `PARALLEL_SORT_POINTS` stays one piece. The
        // order is kept.
        use rayon::prelude::*;
        return cloud
            .par_iter()
            .zip(&keys)
            .with_min_len(PARALLEL_SORT_POINTS / 2)
            .filter(|(_, key)| crowded(key))
            .map(|(point, _)| *point)
            .collect();
    }
    crowded_by_hash(cloud, &keys, &offsets, min_neighbours)
}

/// [`without_isolated`] with the occupied voxels in a hash, for a cloud whose box is too large
/// for an [`OccupancyGrid`].
fn crowded_by_hash(
    cloud: &[Point3<f64>],
    keys: &[VoxelKey],
    offsets: &[VoxelKey],
    min_neighbours: usize,
) -> Vec<Point3<f64>> {
    use rayon::prelude::*;
    use std::collections::HashSet;
    let occupied: HashSet<VoxelKey, KeyHashing> = keys.iter().copied().collect();
    let crowded = |key: &VoxelKey| {
        offsets
            .iter()
            .filter(|(x, y, z)| occupied.contains(&(key.0 + x, key.1 + y, key.2 + z)))
            .take(min_neighbours)
            .count()
            >= min_neighbours
    };
    let voxels: Vec<VoxelKey> = occupied.iter().copied().collect();
    let kept: HashSet<VoxelKey, KeyHashing> = voxels
        .par_iter()
        .filter(|key| crowded(key))
        .copied()
        .collect();
    cloud
        .iter()
        .zip(keys)
        .filter(|(_, key)| kept.contains(key))
        .map(|(point, _)| *point)
        .collect()
}

/// Voxels a [`OccupancyGrid`] holds at most: 32 MiB of bits. A robot's scan within its reach
/// at 100 mm (a box of about 3 m at 6 mm) needs 15 MiB; a larger box falls back to a hash.
const MAX_GRID_VOXELS: u64 = 1 << 28;

/// Which voxels of a box are occupied, a bit each, with a margin of `reach` voxels on every
/// side so that a neighbour's index never leaves the box.
struct OccupancyGrid {
    min: VoxelKey,
    size_y: usize,
    size_z: usize,
    bits: Vec<u64>,
}

impl OccupancyGrid {
    /// The grid of `keys`' box; `None` for an empty list or a box beyond [`MAX_GRID_VOXELS`].
    fn new(keys: &[VoxelKey], reach: i64) -> Option<Self> {
        let first = keys.first()?;
        let (mut min, mut max) = (*first, *first);
        for key in keys {
            min = (min.0.min(key.0), min.1.min(key.1), min.2.min(key.2));
            max = (max.0.max(key.0), max.1.max(key.1), max.2.max(key.2));
        }
        let size = |low: i64, high: i64| {
            u64::try_from(high.checked_sub(low)?.checked_add(1 + 2 * reach)?).ok()
        };
        let (x, y, z) = (
            size(min.0, max.0)?,
            size(min.1, max.1)?,
            size(min.2, max.2)?,
        );
        let voxels = x.checked_mul(y)?.checked_mul(z)?;
        if voxels > MAX_GRID_VOXELS {
            return None;
        }
        let mut grid = Self {
            min: (min.0 - reach, min.1 - reach, min.2 - reach),
            size_y: y as usize,
            size_z: z as usize,
            bits: vec![0; (voxels as usize).div_ceil(64)],
        };
        for key in keys {
            let at = grid.index(key);
            grid.bits[at / 64] |= 1 << (at % 64);
        }
        Some(grid)
    }

    /// The bit of `key`, which lies in the box.
    fn index(&self, key: &VoxelKey) -> usize {
        let x = (key.0 - self.min.0) as usize;
        let y = (key.1 - self.min.1) as usize;
        let z = (key.2 - self.min.2) as usize;
        (x * self.size_y + y) * self.size_z + z
    }

    /// How far the bit of the voxel `offset` away lies (wrapping: added with `wrapping_add`).
    fn step(&self, offset: &VoxelKey) -> usize {
        let linear = (offset.0 * self.size_y as i64 + offset.1) * self.size_z as i64 + offset.2;
        linear as usize
    }

    fn occupied(&self, at: usize) -> bool {
        self.bits[at / 64] & (1 << (at % 64)) != 0
    }
}

/// A hash of voxel keys: std's default (SipHash) guards against keys chosen to collide, which a
/// scan's voxels are not, at several times the cost of this multiply-and-fold.
#[derive(Debug, Clone, Copy, Default)]
struct KeyHashing;

impl std::hash::BuildHasher for KeyHashing {
    type Hasher = KeyHasher;

    fn build_hasher(&self) -> KeyHasher {
        KeyHasher(0)
    }
}

#[derive(Debug, Clone, Copy)]
struct KeyHasher(u64);

impl std::hash::Hasher for KeyHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &byte in bytes {
            self.write_u64(u64::from(byte));
        }
    }

    fn write_i64(&mut self, value: i64) {
        self.write_u64(value as u64);
    }

    fn write_u64(&mut self, value: u64) {
        self.0 = (self.0.rotate_left(21) ^ value).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }

    fn finish(&self) -> u64 {
        self.0 ^ (self.0 >> 32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on a grid of `step_m` over a square of `half_m` either side, lifted by `height`.
    fn grid(half_m: f64, step_m: f64, height: impl Fn(f64, f64) -> f64) -> Vec<Point3<f64>> {
        let steps = (half_m / step_m).round() as i32;
        (-steps..=steps)
            .flat_map(|i| (-steps..=steps).map(move |j| (i, j)))
            .map(|(i, j)| {
                let (x, y) = (f64::from(i) * step_m, f64::from(j) * step_m);
                Point3::new(x, y, height(x, y))
            })
            .collect()
    }

    #[test]
    fn a_tilted_planes_points_carry_its_normal_and_a_ridges_carry_none() {
        let at = |cloud: &[Point3<f64>]| voxel_representatives(cloud, 0.015);
        // A plane rising 1 in 2 along x: its normal is (-1, 0, 2) / sqrt(5).
        let slope = grid(0.1, 0.003, |x, _| 0.5 * x + 0.3);
        let normals = surface_normals_at(&slope, &at(&slope), 0.015);
        let expected = Vector3::new(-1.0, 0.0, 2.0).normalize();
        assert!(
            normals
                .iter()
                .all(|n| n.is_some_and(|n| n.dot(&expected).abs() > 0.999))
        );
        // A ridge: two faces meeting at a right angle along x = 0. On the ridge the points do
        // not lie on one surface; a ball's width away from it they do.
        let ridge = grid(0.1, 0.003, |x, _| -x.abs());
        let points = at(&ridge);
        let normals = surface_normals_at(&ridge, &points, 0.015);
        for (point, normal) in points.iter().zip(&normals) {
            if point.x.abs() < 0.002 {
                assert!(normal.is_none(), "a normal on the ridge at {point}");
            }
            if point.x.abs() > 0.02 && point.y.abs() < 0.085 {
                let face = Vector3::new(point.x.signum(), 0.0, 1.0).normalize();
                assert!(
                    normal.is_some_and(|n| n.dot(&face).abs() > 0.999),
                    "at {point}"
                );
            }
        }
        // Too few points for a surface, and no cloud at all.
        let sparse = [Point3::origin(), Point3::new(0.001, 0.0, 0.0)];
        assert_eq!(surface_normals_at(&sparse, &sparse[..1], 0.015), vec![None]);
        assert_eq!(surface_normals_at(&[], &sparse[..1], 0.015), vec![None]);
    }

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
        // Above the parallel sort's size; at 1e-7 m the spans (1e7, 3e6 and 1e6 voxels) need 66
        // bits, do not pack, and the tuples are sorted instead.
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
        let keys = [
            (-1 << 20, 0, 0),
            (-1, (1 << 20) - 1, -(1 << 20)),
            (-1, (1 << 20) - 1, 5),
            (0, -3, 7),
            (0, -2, -(1 << 20)),
            ((1 << 20) - 1, (1 << 20) - 1, (1 << 20) - 1),
        ];
        let packing = Packing::of(&keys).expect("three 21-bit spans fit");
        assert_eq!(packing.total_bits, 63);
        let packed_keys: Vec<u64> = keys.iter().map(|&k| packing.pack(k)).collect();
        assert!(packed_keys.windows(2).all(|pair| pair[0] < pair[1]));
        // One axis over its whole range takes every bit; the others must then be flat.
        let wide = [(i64::MIN / 2, 4, 9), (i64::MAX / 2, 4, 9), (0, 4, 9)];
        let packing = Packing::of(&wide).expect("a 63-bit span");
        let packed_keys: Vec<u64> = wide.iter().map(|&k| packing.pack(k)).collect();
        assert!(packed_keys[0] < packed_keys[2] && packed_keys[2] < packed_keys[1]);
        for keys in [
            vec![(i64::MIN / 2, 0, 0), (i64::MAX / 2, 3, 0)],
            vec![(i64::MIN, 0, 0), (i64::MAX, 0, 0)],
            vec![(0, -(1 << 30), 0), (1 << 30, 1 << 30, 1 << 30)],
        ] {
            assert_eq!(Packing::of(&keys), None, "{keys:?}");
        }
        assert_eq!(Packing::of(&[]), None);
        assert_eq!(Packing::of(&[(5, -5, 2)]).map(|p| p.total_bits), Some(0));
    }

    #[test]
    fn the_floor_index_is_the_floor_converted() {
        for value in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.999,
            -2.999,
            1e15 + 0.5,
            -1e15 - 0.5,
            9.3e18,
            -9.3e18,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
        ] {
            assert_eq!(floor_index(value), value.floor() as i64, "{value}");
        }
    }

    #[test]
    fn the_radix_sort_orders_by_key_and_keeps_the_order_of_equal_keys() {
        let mut rng = crate::rng::SplitMix64::new(7);
        // 34-bit keys, so that the narrower masks leave many equal.
        let mut next = || rng.next_u64() >> 30;
        for key_bits in [0, 5, 11, 12, 33, 64] {
            let mask = if key_bits == 64 {
                u64::MAX
            } else {
                (1u64 << key_bits) - 1
            };
            let keyed: Vec<(u64, usize)> = (0..5000).map(|i| (next() & mask, i)).collect();
            let mut expected = keyed.clone();
            expected.sort_unstable();
            assert_eq!(radix_sorted(keyed, key_bits), expected, "{key_bits} bits");
        }
    }

    #[test]
    fn isolated_returns_go_and_a_surface_with_its_edges_stays() {
        // A 10 cm square sampled every 8 mm (coarser than the 6 mm voxel), and returns scattered
        // far apart around it.
        let mut cloud: Vec<Point3<f64>> = (0..13)
            .flat_map(|i| {
                (0..13).map(move |j| Point3::new(0.008 * i as f64, 0.008 * j as f64, 0.0))
            })
            .collect();
        let surface = cloud.len();
        let strays: Vec<Point3<f64>> = (0..20)
            .map(|k| Point3::new(0.3 + 0.05 * k as f64, -0.2, 0.1 + 0.04 * (k % 3) as f64))
            .collect();
        cloud.extend(&strays);
        let kept = without_isolated(&cloud, 0.006, 3);
        assert_eq!(
            kept.len(),
            surface,
            "every surface point (corners too) and no stray"
        );
        assert!(kept.iter().all(|p| !strays.contains(p)));
        // Two returns side by side are still isolated; off, the cloud comes back whole.
        let pair = [Point3::new(1.0, 1.0, 1.0), Point3::new(1.004, 1.0, 1.0)];
        assert!(without_isolated(&pair, 0.006, 3).is_empty());
        assert_eq!(without_isolated(&pair, 0.006, 0).len(), 2);
    }

    #[test]
    fn a_cloud_too_wide_for_the_bit_grid_keeps_the_same_points() {
        // Surface patches and strays in a 1 m box (the bit grid), then the same with one
        // return 10 km away, which makes the box too large for the grid (the hash): the far
        // return is isolated and goes; every other point is judged the same way.
        let mut rng = crate::rng::SplitMix64::new(7);
        let mut cloud: Vec<Point3<f64>> = (0..4000)
            .map(|i| {
                let (u, v) = (rng.uniform(), rng.uniform());
                match i % 4 {
                    0 => Point3::new(u * 0.3, v * 0.3, 0.0),
                    1 => Point3::new(0.5, u * 0.2, v * 0.2),
                    _ => Point3::new(u, v, rng.uniform()),
                }
            })
            .collect();
        let in_grid = without_isolated(&cloud, 0.006, 3);
        assert!(in_grid.len() > 1000 && in_grid.len() < cloud.len());
        cloud.push(Point3::new(1e4, 0.0, 0.0));
        let keys: Vec<VoxelKey> = cloud.iter().map(|p| voxel_of(p, 0.006)).collect();
        assert!(OccupancyGrid::new(&keys, NEIGHBOURHOOD_VOXELS).is_none());
        assert_eq!(without_isolated(&cloud, 0.006, 3), in_grid);
    }
}
