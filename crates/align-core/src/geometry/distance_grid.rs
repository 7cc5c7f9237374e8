//! A mesh's signed distance sampled on a regular grid around it: a few tens of nanoseconds per
//! query instead of a BVH descent, for searches that ask "is this point near the surface, or
//! inside it?" millions of times and can live with a millimetre of blur.

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::Mesh;

/// More than the rounding of a distance of a few metres stored as f32 (2^-24 of it).
const F32_ROUNDING_M: f64 = 1e-6;

/// Signed distance (negative inside a watertight mesh, unsigned otherwise) at the corners of
/// cubic cells covering the mesh's bounds plus a margin, interpolated trilinearly between them.
/// Corners farther than the margin from the surface hold +-margin: the grid answers distances
/// up to [`DistanceGrid::reliable_m`] and only the side beyond.
#[derive(Debug, Clone)]
pub struct DistanceGrid {
    /// The sample of index (0, 0, 0), mesh frame.
    lower: Point3<f64>,
    cell_m: f64,
    dims: [usize; 3],
    values: Vec<f32>,
    margin_m: f64,
}

impl DistanceGrid {
    /// How many samples [`DistanceGrid::new`] would take (and store, 4 bytes each).
    /// `usize::MAX` when that does not fit in one (a mesh in the wrong unit, kilometres long).
    pub fn sample_count(mesh: &Mesh, cell_m: f64, margin_m: f64) -> usize {
        Self::dims(mesh, cell_m, margin_m)
            .iter()
            .try_fold(1usize, |count, &d| count.checked_mul(d))
            .unwrap_or(usize::MAX)
    }

    fn dims(mesh: &Mesh, cell_m: f64, margin_m: f64) -> [usize; 3] {
        let (low, high) = mesh.bounds();
        [0, 1, 2].map(|a| ((high[a] - low[a] + 2.0 * margin_m) / cell_m).ceil() as usize + 1)
    }

    /// Samples `mesh` every `cell_m` over its bounds grown by `margin_m` (both > 0).
    pub fn new(mesh: &Mesh, cell_m: f64, margin_m: f64) -> Self {
        assert!(
            cell_m > 0.0 && margin_m > 0.0,
            "cell and margin must be > 0"
        );
        let (low, _) = mesh.bounds();
        let lower = low - Vector3::repeat(margin_m);
        let dims = Self::dims(mesh, cell_m, margin_m);
        let slab = dims[1] * dims[2];
        let mut values = vec![0f32; dims[0] * slab];
        let watertight = mesh.is_watertight();
        values
            .par_chunks_mut(slab)
            .enumerate()
            .for_each(|(i, slab_values)| {
                for j in 0..dims[1] {
                    // Along a line of samples the distance changes by at most a cell per
                    // sample, so it cannot change sign between two samples farther than the
                    // margin without samples nearer than it in between: a far sample is on the
                    // side of the last near one before it (the line starts outside the bounds,
                    // outside any solid).
                    let mut side = 1.0;
                    for k in 0..dims[2] {
                        let sample = lower + Vector3::new(i as f64, j as f64, k as f64) * cell_m;
                        let distance = match mesh.closest_point_within(&sample, margin_m) {
                            Some(closest) => {
                                if watertight {
                                    side = closest.signed_distance.signum();
                                }
                                closest.signed_distance
                            }
                            None => side * margin_m,
                        };
                        slab_values[j * dims[2] + k] = distance as f32;
                    }
                }
            });
        Self {
            lower,
            cell_m,
            dims,
            values,
            margin_m,
        }
    }

    /// Distances the grid answers: below this in magnitude a value is the interpolated true
    /// distance; beyond it, only its sign is meaningful (corners further than the margin are
    /// clamped, and a cell's diagonal away from them the interpolation still feels it).
    pub fn reliable_m(&self) -> f64 {
        self.margin_m - self.cell_m * 3f64.sqrt()
    }

    pub fn cell_m(&self) -> f64 {
        self.cell_m
    }

    /// The interpolated signed distance at `local` (mesh frame); `None` outside the grid, where
    /// the surface is farther than the margin and the point is outside any solid.
    pub fn signed_distance_m(&self, local: &Point3<f64>) -> Option<f64> {
        let (corners, [fx, fy, fz]) = self.cell_of(local)?;
        let along_z = |c: usize| corners[c] * (1.0 - fz) + corners[c + 1] * fz;
        let along_y = |c: usize| along_z(c) * (1.0 - fy) + along_z(c + 2) * fy;
        Some(along_y(0) * (1.0 - fx) + along_y(4) * fx)
    }

    /// [`DistanceGrid::signed_distance_m`] and the interpolant's gradient (per m): a unit-ish
    /// vector pointing away from the surface, outward on a watertight mesh.
    pub fn distance_and_gradient(&self, local: &Point3<f64>) -> Option<(f64, Vector3<f64>)> {
        let (c, [fx, fy, fz]) = self.cell_of(local)?;
        let along_z = |i: usize| c[i] * (1.0 - fz) + c[i + 1] * fz;
        let dz = |i: usize| c[i + 1] - c[i];
        let along_y = |i: usize| along_z(i) * (1.0 - fy) + along_z(i + 2) * fy;
        let value = along_y(0) * (1.0 - fx) + along_y(4) * fx;
        let gradient = Vector3::new(
            along_y(4) - along_y(0),
            (along_z(2) - along_z(0)) * (1.0 - fx) + (along_z(6) - along_z(4)) * fx,
            (dz(0) * (1.0 - fy) + dz(2) * fy) * (1.0 - fx) + (dz(4) * (1.0 - fy) + dz(6) * fy) * fx,
        ) / self.cell_m;
        Some((value, gradient))
    }

    /// A lower bound on the distance from `local` (mesh frame) to the surface, with no blur:
    /// the distance is 1-Lipschitz, so it is at least each corner's stored distance less the
    /// way to that corner (a corner clamped at the margin stores less than its distance, which
    /// keeps the bound), less the f32 rounding of the stored values. `None` outside the grid,
    /// where the surface is farther than the margin. The interpolated value less a cell
    /// diagonal (8.7 mm at 5 mm cells) is a bound too; this one is a few millimetres tighter.
    pub fn distance_lower_bound_m(&self, local: &Point3<f64>) -> Option<f64> {
        let (corners, [fx, fy, fz]) = self.cell_of(local)?;
        let mut bound = f64::NEG_INFINITY;
        for (corner, value) in corners.iter().enumerate() {
            // x slowest, z fastest, as `cell_of` orders them.
            let offset = Vector3::new(
                fx - (corner >> 2) as f64,
                fy - ((corner >> 1) & 1) as f64,
                fz - (corner & 1) as f64,
            );
            bound = bound.max(value.abs() - offset.norm() * self.cell_m);
        }
        Some(bound - F32_ROUNDING_M)
    }

    /// The eight corner values of the cell holding `local` (x slowest, z fastest) and the
    /// position inside it, each in [0, 1].
    fn cell_of(&self, local: &Point3<f64>) -> Option<([f64; 8], [f64; 3])> {
        let mut index = [0usize; 3];
        let mut fraction = [0f64; 3];
        for a in 0..3 {
            let f = (local[a] - self.lower[a]) / self.cell_m;
            let last = (self.dims[a] - 1) as f64;
            if !(0.0..=last).contains(&f) {
                return None;
            }
            // f >= 0: truncation is the floor.
            let i = (f as usize).min(self.dims[a] - 2);
            index[a] = i;
            fraction[a] = f - i as f64;
        }
        let [i, j, k] = index;
        let at = |di: usize, dj: usize| {
            let start = ((i + di) * self.dims[1] + j + dj) * self.dims[2] + k;
            [
                f64::from(self.values[start]),
                f64::from(self.values[start + 1]),
            ]
        };
        let [a, b] = at(0, 0);
        let [c, d] = at(0, 1);
        let [e, f] = at(1, 0);
        let [g, h] = at(1, 1);
        Some(([a, b, c, d, e, f, g, h], fraction))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cube_grid_matches_the_exact_distance_where_it_claims_to() {
        let cube = Mesh::cuboid([0.2, 0.1, 0.3]).unwrap();
        let grid = DistanceGrid::new(&cube, 0.005, 0.03);
        let mut worst: f64 = 0.0;
        let mut state = 12345u64;
        let mut uniform = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..20_000 {
            let p = Point3::new(
                (uniform() - 0.5) * 0.35,
                (uniform() - 0.5) * 0.25,
                (uniform() - 0.5) * 0.45,
            );
            let exact = cube.closest_point(&p).signed_distance;
            match grid.signed_distance_m(&p) {
                Some(d) if exact.abs() < grid.reliable_m() => worst = worst.max((d - exact).abs()),
                Some(d) => assert_eq!(d.signum(), exact.signum(), "{p}: {d} vs {exact}"),
                None => assert!(exact > 0.03, "{p}: outside the grid at {exact}"),
            }
        }
        // Beside a face the gradient is the face's normal.
        let (distance, gradient) = grid
            .distance_and_gradient(&Point3::new(0.01, 0.013, 0.16))
            .unwrap();
        assert!((distance - 0.01).abs() < 1e-6, "{distance}");
        assert!((gradient - Vector3::z()).norm() < 1e-6, "{gradient}");
        // Flat faces are exact; the blur is where the field bends, near edges and corners.
        assert!(worst < 0.0025, "worst {worst}");
        assert!(grid.reliable_m() > 0.02);
    }

    #[test]
    fn the_lower_bound_never_exceeds_the_distance_and_is_tighter_than_a_cell_diagonal() {
        let cube = Mesh::cuboid([0.2, 0.1, 0.3]).unwrap();
        let grid = DistanceGrid::new(&cube, 0.005, 0.03);
        let mut rng = crate::trials::TrialRng::new(17);
        let (mut gap_sum, mut counted) = (0.0, 0);
        for _ in 0..20_000 {
            let p = Point3::new(
                (rng.uniform() - 0.5) * 0.3,
                (rng.uniform() - 0.5) * 0.2,
                (rng.uniform() - 0.5) * 0.4,
            );
            let exact = cube.closest_point(&p).signed_distance.abs();
            match grid.distance_lower_bound_m(&p) {
                Some(lower) => {
                    assert!(lower <= exact, "{p}: bound {lower} over {exact}");
                    if exact < grid.reliable_m() {
                        gap_sum += exact - lower;
                        counted += 1;
                    }
                }
                None => assert!(exact > 0.03, "{p}: outside the grid at {exact}"),
            }
        }
        // The interpolated value's guarantee is a cell diagonal (8.7 mm); the bound is
        // within a few millimetres on average.
        let mean_gap = gap_sum / counted as f64;
        assert!(counted > 5000 && mean_gap < 0.004, "{counted} {mean_gap}");
    }

    #[test]
    fn a_mesh_kilometres_long_counts_as_too_many_samples_not_an_overflow() {
        let huge = Mesh::cuboid([4e6, 4e6, 4e6]).unwrap();
        assert_eq!(DistanceGrid::sample_count(&huge, 0.005, 0.03), usize::MAX);
        let cube = Mesh::cuboid([0.1, 0.1, 0.1]).unwrap();
        assert_eq!(DistanceGrid::sample_count(&cube, 0.005, 0.03), 33 * 33 * 33);
    }
}
