//! Scanner-like point clouds of a part in a cell, generated from its mesh (seeded): surfaces
//! sampled at a scanner's spacing, only those facing at least one scanner position, Gaussian
//! range noise, the floor the part stands on, a neighbouring object, and stray outliers.

use nalgebra::{Isometry3, Point3, Vector3};

use super::TrialRng;
use crate::geometry::Mesh;

#[derive(Debug, Clone, PartialEq)]
pub struct ScanOptions {
    /// Mean distance between neighbouring samples, m.
    pub spacing_m: f64,
    pub noise_sigma_m: f64,
    /// Outliers added, as a fraction of the points of the scene.
    pub outlier_fraction: f64,
    /// Scanner positions in the base frame; a surface is seen when it faces one of them.
    /// Empty: every surface is seen.
    pub scanners: Vec<Point3<f64>>,
    /// Add the floor plane under the part.
    pub floor: bool,
    /// Add a box standing next to the part.
    pub neighbour: bool,
    pub seed: u64,
}

impl Default for ScanOptions {
    fn default() -> Self {
        Self {
            spacing_m: 0.004,
            noise_sigma_m: 0.0,
            outlier_fraction: 0.0,
            scanners: Vec::new(),
            floor: false,
            neighbour: false,
            seed: 1,
        }
    }
}

/// Area-weighted samples of the mesh surfaces facing a scanner, in the base frame.
fn sample_surface(
    mesh: &Mesh,
    base_from_part: &Isometry3<f64>,
    options: &ScanOptions,
    rng: &mut TrialRng,
) -> Vec<Point3<f64>> {
    let vertices: Vec<Point3<f64>> = mesh.vertices().map(|v| base_from_part * v).collect();
    let per_area = 1.0 / (options.spacing_m * options.spacing_m);
    let mut points = Vec::new();
    for (index, triangle) in mesh.triangles().iter().enumerate() {
        let [a, b, c] = triangle.map(|i| vertices[i as usize]);
        let normal = base_from_part.rotation * mesh.triangle_normal(index as u32);
        let centre = Point3::from((a.coords + b.coords + c.coords) / 3.0);
        let seen = options.scanners.is_empty()
            || options
                .scanners
                .iter()
                .any(|s| normal.dot(&(s - centre)) > 0.0);
        if !seen {
            continue;
        }
        let expected = mesh.triangle_area(index as u32) * per_area;
        let count = expected.floor() as usize + usize::from(rng.uniform() < expected.fract());
        for _ in 0..count {
            let (mut u, mut v) = (rng.uniform(), rng.uniform());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            points.push(a + (b - a) * u + (c - a) * v);
        }
    }
    points
}

/// The scan `ips trials --pca` aligns to (docs/pca-trials.md): the cell as a scanner sees it,
/// from three positions, with the floor, a neighbouring box, 10% outliers and 0.3 mm noise.
pub fn pca_trial_scan() -> ScanOptions {
    ScanOptions {
        spacing_m: 0.006,
        noise_sigma_m: 0.0003,
        outlier_fraction: 0.1,
        floor: true,
        neighbour: true,
        scanners: vec![
            Point3::new(0.0, 0.0, 1.6),
            Point3::new(1.6, -1.2, 1.0),
            Point3::new(1.4, 0.9, 0.9),
        ],
        seed: 7,
    }
}

/// A scan of `mesh` placed at `base_from_part`, with the clutter the options ask for.
pub fn scan_part(
    mesh: &Mesh,
    base_from_part: &Isometry3<f64>,
    options: &ScanOptions,
) -> Vec<Point3<f64>> {
    let mut rng = TrialRng::new(options.seed);
    let mut points = sample_surface(mesh, base_from_part, options, &mut rng);
    let radius = mesh.radius_m();
    let centre = base_from_part * mesh.centroid();
    let lowest = mesh
        .vertices()
        .map(|v| (base_from_part * v).z)
        .fold(f64::INFINITY, f64::min);
    if options.neighbour {
        let size = [radius, 0.6 * radius, 0.8 * radius];
        if let Ok(neighbour) = Mesh::cuboid(size) {
            let beside = Isometry3::translation(
                centre.x + 1.8 * radius,
                centre.y + 0.3 * radius,
                lowest + size[2] / 2.0,
            );
            points.extend(sample_surface(&neighbour, &beside, options, &mut rng));
        }
    }
    if options.floor {
        let half = 2.5 * radius;
        let steps = (2.0 * half / options.spacing_m).ceil() as usize;
        let part_from_base = base_from_part.inverse();
        for i in 0..steps {
            for j in 0..steps {
                let jitter = |rng: &mut TrialRng| (rng.uniform() - 0.5) * options.spacing_m;
                let p = Point3::new(
                    centre.x - half + i as f64 * options.spacing_m + jitter(&mut rng),
                    centre.y - half + j as f64 * options.spacing_m + jitter(&mut rng),
                    lowest,
                );
                // The floor under the part is hidden by it.
                let under = mesh.closest_point(&(part_from_base * (p + Vector3::z() * 1e-4)));
                if under.signed_distance > 0.0 || !mesh.is_watertight() {
                    points.push(p);
                }
            }
        }
    }
    if options.noise_sigma_m > 0.0 {
        for p in &mut points {
            *p += Vector3::new(rng.gaussian(), rng.gaussian(), rng.gaussian())
                * options.noise_sigma_m;
        }
    }
    let outliers = (points.len() as f64 * options.outlier_fraction).round() as usize;
    for _ in 0..outliers {
        let offset = Vector3::new(
            rng.uniform() - 0.5,
            rng.uniform() - 0.5,
            rng.uniform() - 0.5,
        ) * (4.0 * radius);
        points.push(centre + offset);
    }
    points
}
