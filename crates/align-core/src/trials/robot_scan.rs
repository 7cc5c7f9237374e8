//! Scanner-like clouds of a robot in a cell (seeded): link surfaces sampled at a scanner's
//! spacing and kept only where a scanner position sees them (facing it, and no link, neighbour
//! or floor in the line of sight), range noise along the line of sight, the floor the robot
//! stands on, a box beside it, and stray outliers.

use nalgebra::{Isometry3, Point3, Vector3};

use super::TrialRng;
use crate::geometry::Mesh;
use crate::registration::articulated::ArticulatedBody;

#[derive(Debug, Clone, PartialEq)]
pub struct RobotScanOptions {
    /// Mean distance between neighbouring samples, m.
    pub spacing_m: f64,
    /// Range noise (along the line of sight), m.
    pub noise_sigma_m: f64,
    /// Outliers added, as a fraction of the points of the scene.
    pub outlier_fraction: f64,
    /// Scanner positions in the world; empty: every surface is seen.
    pub scanners: Vec<Point3<f64>>,
    /// Half the edge of the square of floor scanned around the robot's root, m (0: no floor).
    pub floor_half_m: f64,
    /// Add a box standing beside the robot.
    pub neighbour: bool,
    /// Links left out of the scan (by name): hidden from every scanner.
    pub hidden_links: Vec<String>,
    pub seed: u64,
}

impl Default for RobotScanOptions {
    /// A cell as the trials scan it: three scanners around and above the robot, 6 mm spacing,
    /// 0.3 mm noise, floor, a neighbour and 10% outliers.
    fn default() -> Self {
        Self {
            spacing_m: 0.006,
            noise_sigma_m: 0.0003,
            outlier_fraction: 0.1,
            scanners: vec![
                Point3::new(2.0, 0.0, 1.6),
                Point3::new(-1.0, 1.8, 1.4),
                Point3::new(-1.0, -1.8, 1.8),
            ],
            floor_half_m: 0.4,
            neighbour: true,
            hidden_links: Vec::new(),
            seed: 1,
        }
    }
}

/// An occluder: a surface in the world.
struct Placed<'a> {
    mesh: &'a Mesh,
    world_from_mesh: Isometry3<f64>,
}

/// The scanner that sees `point` (on a surface with outward `normal`), if any.
fn seen_from(
    point: &Point3<f64>,
    normal: &Vector3<f64>,
    scanners: &[Point3<f64>],
    occluders: &[Placed],
) -> Option<Point3<f64>> {
    scanners.iter().copied().find(|scanner| {
        let to_scanner = scanner - point;
        if normal.dot(&to_scanner) <= 0.0 {
            return false;
        }
        let distance = to_scanner.norm();
        let direction = -to_scanner / distance;
        // Stop a millimetre short so the surface the point lies on does not hide it.
        let clear = distance - 1e-3;
        occluders.iter().all(|o| {
            let mesh_from_world = o.world_from_mesh.inverse();
            o.mesh
                .ray_hit_m(
                    &(mesh_from_world * scanner),
                    &(mesh_from_world * direction),
                    clear,
                )
                .is_none()
        })
    })
}

fn sample_mesh(
    placed: &Placed,
    spacing_m: f64,
    rng: &mut TrialRng,
    out: &mut Vec<(Point3<f64>, Vector3<f64>)>,
) {
    let vertices: Vec<Point3<f64>> = placed
        .mesh
        .vertices()
        .map(|v| placed.world_from_mesh * v)
        .collect();
    let per_area = 1.0 / (spacing_m * spacing_m);
    for (index, triangle) in placed.mesh.triangles().iter().enumerate() {
        let [a, b, c] = triangle.map(|i| vertices[i as usize]);
        let normal = placed.world_from_mesh.rotation * placed.mesh.triangle_normal(index as u32);
        let expected = placed.mesh.triangle_area(index as u32) * per_area;
        let count = expected.floor() as usize + usize::from(rng.uniform() < expected.fract());
        for _ in 0..count {
            let (mut u, mut v) = (rng.uniform(), rng.uniform());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            out.push((a + (b - a) * u + (c - a) * v, normal));
        }
    }
}

/// [`scan_robot`] with the spacing scaled (from `options.spacing_m`, a few tries) until the scan
/// holds about `target_points` points (within 3%, else the last try): a benchmark's cloud size
/// stays put when the robot or the clutter changes.
pub fn scan_robot_of_about(
    body: &ArticulatedBody,
    world_from_root: &Isometry3<f64>,
    q: &[f64],
    options: &RobotScanOptions,
    target_points: usize,
) -> Vec<Point3<f64>> {
    let mut options = options.clone();
    for _ in 0..4 {
        let cloud = scan_robot(body, world_from_root, q, &options);
        // Points scale with the inverse square of the spacing on surfaces.
        let ratio = cloud.len() as f64 / target_points.max(1) as f64;
        if (ratio - 1.0).abs() < 0.03 || cloud.is_empty() {
            return cloud;
        }
        options.spacing_m *= ratio.sqrt();
    }
    scan_robot(body, world_from_root, q, &options)
}

/// A scan of the robot at `world_from_root` and joints `q`, with the clutter the options ask for.
pub fn scan_robot(
    body: &ArticulatedBody,
    world_from_root: &Isometry3<f64>,
    q: &[f64],
    options: &RobotScanOptions,
) -> Vec<Point3<f64>> {
    let mut rng = TrialRng::new(options.seed);
    let poses = body.link_poses(world_from_root, q);
    let mut occluders: Vec<Placed> = Vec::new();
    let mut sampled: Vec<Placed> = Vec::new();
    for (link, pose) in body.links().iter().zip(&poses) {
        if let Some(mesh) = &link.surface {
            let placed = || Placed {
                mesh,
                world_from_mesh: *pose,
            };
            occluders.push(placed());
            if !options.hidden_links.contains(&link.name) {
                sampled.push(placed());
            }
        }
    }
    let root = world_from_root * Point3::origin();
    let lowest = occluders
        .iter()
        .flat_map(|o| o.mesh.vertices().map(|v| (o.world_from_mesh * v).z))
        .fold(f64::INFINITY, f64::min);
    let neighbour_mesh = Mesh::cuboid([0.4, 0.3, 0.5]).ok();
    if let (true, Some(mesh)) = (options.neighbour, &neighbour_mesh) {
        let beside = Isometry3::translation(root.x + 0.25, root.y - 0.75, lowest + 0.25);
        let placed = || Placed {
            mesh,
            world_from_mesh: beside,
        };
        occluders.push(placed());
        sampled.push(placed());
    }
    let mut candidates = Vec::new();
    for placed in &sampled {
        sample_mesh(placed, options.spacing_m, &mut rng, &mut candidates);
    }
    if options.floor_half_m > 0.0 {
        let steps = (2.0 * options.floor_half_m / options.spacing_m).ceil() as usize;
        for i in 0..steps {
            for j in 0..steps {
                let jitter = |rng: &mut TrialRng| (rng.uniform() - 0.5) * options.spacing_m;
                let x = root.x - options.floor_half_m + i as f64 * options.spacing_m;
                let y = root.y - options.floor_half_m + j as f64 * options.spacing_m;
                candidates.push((
                    Point3::new(x + jitter(&mut rng), y + jitter(&mut rng), lowest),
                    Vector3::z(),
                ));
            }
        }
    }
    let mut points = Vec::with_capacity(candidates.len());
    for (point, normal) in candidates {
        let seen = if options.scanners.is_empty() {
            Some(point + normal)
        } else {
            seen_from(&point, &normal, &options.scanners, &occluders)
        };
        let Some(scanner) = seen else {
            continue;
        };
        let line_of_sight = (point - scanner).normalize();
        points.push(point + line_of_sight * (rng.gaussian() * options.noise_sigma_m));
    }
    let (lower, upper) = points.iter().fold(
        (
            Vector3::repeat(f64::INFINITY),
            Vector3::repeat(f64::NEG_INFINITY),
        ),
        |(lo, hi), p| (lo.inf(&p.coords), hi.sup(&p.coords)),
    );
    let outliers = (points.len() as f64 * options.outlier_fraction).round() as usize;
    for _ in 0..outliers {
        let mix = Vector3::new(rng.uniform(), rng.uniform(), rng.uniform());
        points.push(Point3::from(lower + (upper - lower).component_mul(&mix)));
    }
    points
}
