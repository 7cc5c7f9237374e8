//! The inside grid of meshes that are not closed (`geometry::InsideGrid`, which the coarse
//! score of a cloud alignment builds on its first inside test of such a mesh): its build time
//! per mesh, the share of the box it calls inside, and how often it agrees with the signed
//! distance (closed meshes) and with the exact winding number (every mesh), on random points of
//! the box farther than a cell's half diagonal from the surface. The exact winding number (the
//! solid angles of all triangles summed, over 4 pi; inside above one half) is the reference for
//! both: it is right for closed bodies that overlap, where the side of the closest feature is
//! not, and it is defined for open meshes. Best of `--runs` builds each; a table for people.
//!
//! The last column is the share of the surface with the solid on both sides (faces inside the
//! part; see `buried_area_share`).
//! Run: cargo bench -p align-core --bench inside_grid -- [--runs N] [--points N]
//! [--winding-points N] [MESH ...]
//! Without meshes it reads the xArm7 and SO-ARM100 links in crates/cad-scans/meshes; the links of
//! docs/cad-scan-trials.md come from `scripts/unseen-parts.sh OUT`, the ABB IRB 1600's from
//! ../shared/data (abb_irb1600_support/meshes/irb1600/visual).

use std::path::{Path, PathBuf};
use std::time::Instant;

use align_core::geometry::{InsideGrid, Mesh};
use align_core::io::read_mesh;
use align_core::rng::SplitMix64;
use nalgebra::{Point3, Vector3};

#[path = "common/shipped_meshes.rs"]
mod shipped_meshes;
use shipped_meshes::shipped_meshes;

struct Args {
    runs: usize,
    points: usize,
    /// How many of the points are also tested against the exact winding number (it visits
    /// every triangle for every point).
    winding_points: usize,
    paths: Vec<PathBuf>,
}

fn parse_args() -> Result<Option<Args>, String> {
    let mut parsed = Args {
        runs: 5,
        points: 20_000,
        winding_points: 2_000,
        paths: Vec::new(),
    };
    let mut args = std::env::args().skip(1);
    let count = |value: Option<String>, flag: &str| {
        value
            .and_then(|v| v.parse().ok())
            .filter(|&n: &usize| n > 0)
            .ok_or(format!("{flag} needs a positive whole number"))
    };
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--runs" => parsed.runs = count(args.next(), "--runs")?,
            "--points" => parsed.points = count(args.next(), "--points")?,
            "--winding-points" => parsed.winding_points = count(args.next(), "--winding-points")?,
            "--help" | "-h" => {
                println!(
                    "inside_grid [--runs N (5)] [--points N (20000)] [--winding-points N \
                     (2000)] [MESH ...]: the inside grid's build time per mesh, its agreement \
                     with closed meshes' signed distances, and the agreement of both with the \
                     exact winding number"
                );
                return Ok(None);
            }
            // cargo bench passes --bench to every bench binary.
            "--bench" => {}
            _ => parsed.paths.push(PathBuf::from(arg)),
        }
    }
    if parsed.paths.is_empty() {
        parsed.paths = shipped_meshes()?;
    }
    Ok(Some(parsed))
}

fn main() {
    let args = match parse_args() {
        Ok(Some(args)) => args,
        Ok(None) => return,
        Err(message) => {
            eprintln!("inside_grid: {message}");
            std::process::exit(2);
        }
    };
    println!(
        "| mesh | triangles | closed | bodies | grid build (ms) | inside (share of the box) | grid = signed distance | grid = winding number | signed distance = winding number | buried faces (share of the area) |"
    );
    println!("| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
    for path in &args.paths {
        let mesh = match read_mesh(path, 1.0)
            .map_err(|e| e.to_string())
            .and_then(|soup| Mesh::new(&soup.vertices, &soup.triangles).map_err(|e| e.to_string()))
        {
            Ok(mesh) => mesh,
            Err(error) => {
                eprintln!("skipped {}: {error}", path.display());
                continue;
            }
        };
        let vertices: Vec<Point3<f64>> = mesh.vertices().collect();
        let corners: Vec<[Vector3<f64>; 3]> = mesh
            .triangles()
            .iter()
            .map(|t| t.map(|i| vertices[i as usize].coords))
            .collect();
        let (lower, upper) = mesh.bounds();
        let mut build_s = f64::INFINITY;
        let mut grid = None;
        for _ in 0..args.runs {
            let clock = Instant::now();
            let built = InsideGrid::new(&corners, &lower, &upper);
            build_s = build_s.min(clock.elapsed().as_secs_f64());
            grid = Some(built);
        }
        let Some(grid) = grid else { continue };
        let mut rng = SplitMix64::new(7);
        let (mut counted, mut inside, mut agreeing) = (0usize, 0usize, 0usize);
        let (mut wound, mut grid_wound, mut signed_wound) = (0usize, 0usize, 0usize);
        for _ in 0..args.points {
            let query = Point3::from(Vector3::from_fn(|axis, _| {
                lower[axis] + rng.uniform() * (upper[axis] - lower[axis])
            }));
            let signed_m = mesh.closest_point(&query).signed_distance;
            if signed_m.abs() <= grid.cell_half_diagonal_m() {
                continue;
            }
            counted += 1;
            let in_grid = grid.contains(&query);
            inside += usize::from(in_grid);
            agreeing += usize::from(in_grid == (signed_m < 0.0));
            if wound < args.winding_points {
                let in_winding = winding_number(&corners, &query).abs() > 0.5;
                wound += 1;
                grid_wound += usize::from(in_grid == in_winding);
                signed_wound += usize::from((signed_m < 0.0) == in_winding);
            }
        }
        let share = |n: usize| n as f64 / counted.max(1) as f64;
        let percent = |n: usize, of: usize| format!("{:.1} %", 100.0 * n as f64 / of.max(1) as f64);
        let closed_only = |figure: String| {
            if mesh.is_watertight() {
                figure
            } else {
                "-".to_owned()
            }
        };
        let buried = buried_area_share(&mesh, &corners, BURIED_FACE_SAMPLES, &mut rng);
        println!(
            "| {} | {} | {} | {} | {:.2} | {:.3} | {} | {} | {} | {:.2} |",
            shown_name(path),
            mesh.num_triangles(),
            if mesh.is_watertight() { "yes" } else { "no" },
            mesh.bodies(),
            build_s * 1e3,
            share(inside),
            closed_only(percent(agreeing, counted)),
            percent(grid_wound, wound),
            closed_only(percent(signed_wound, wound)),
            buried,
        );
    }
}

/// Faces sampled (by area) for the buried faces' share.
const BURIED_FACE_SAMPLES: usize = 500;

/// How far off a face its two sides are looked at, m: well under the parts' wall thicknesses,
/// well over the winding number's rounding near the face.
const BURIED_FACE_OFFSET_M: f64 = 5e-4;

/// The share of the surface's area with the solid on both sides (winding number over one half
/// just in front of and just behind the face, at its centroid): faces inside the part, such as
/// a wall's inner shell or a motor modelled inside a housing. No scanner sees them, and a
/// method that samples its model over every face samples them too. `samples` faces drawn by
/// area.
fn buried_area_share(
    mesh: &Mesh,
    corners: &[[Vector3<f64>; 3]],
    samples: usize,
    rng: &mut SplitMix64,
) -> f64 {
    let areas: Vec<f64> = (0..corners.len() as u32)
        .map(|t| mesh.triangle_area(t))
        .collect();
    let total: f64 = areas.iter().sum();
    if total <= 0.0 || samples == 0 {
        return 0.0;
    }
    let cumulative: Vec<f64> = areas
        .iter()
        .scan(0.0, |sum, area| {
            *sum += area;
            Some(*sum)
        })
        .collect();
    let buried = (0..samples)
        .filter(|_| {
            let at = rng.uniform() * total;
            let face = cumulative
                .partition_point(|&sum| sum < at)
                .min(corners.len() - 1);
            let [a, b, c] = corners[face];
            let centre = Point3::from((a + b + c) / 3.0);
            let normal = mesh.triangle_normal(face as u32) * BURIED_FACE_OFFSET_M;
            winding_number(corners, &(centre + normal)).abs() > 0.5
                && winding_number(corners, &(centre - normal)).abs() > 0.5
        })
        .count();
    buried as f64 / samples as f64
}

/// The generalised winding number of `triangles` about `point`: the solid angles they subtend,
/// signed by the side they face, over 4 pi (van Oosterom and Strackee's formula). 1 inside a
/// closed outward-facing body, 0 outside, the count of bodies where closed bodies overlap.
fn winding_number(triangles: &[[Vector3<f64>; 3]], point: &Point3<f64>) -> f64 {
    let solid_angle_sum: f64 = triangles
        .iter()
        .map(|corners| {
            let [a, b, c] = corners.map(|corner| corner - point.coords);
            let (la, lb, lc) = (a.norm(), b.norm(), c.norm());
            let numerator = a.dot(&b.cross(&c));
            let denominator = la * lb * lc + a.dot(&b) * lc + a.dot(&c) * lb + b.dot(&c) * la;
            2.0 * numerator.atan2(denominator)
        })
        .sum();
    solid_angle_sum / (4.0 * std::f64::consts::PI)
}

/// The file's name and its folder's (robots name their links alike: `arm_1.stl`).
fn shown_name(path: &Path) -> String {
    let name = |p: Option<&Path>| {
        p.and_then(Path::file_name)
            .map(|n| n.to_string_lossy().into_owned())
    };
    match (name(path.parent()), name(Some(path))) {
        (Some(folder), Some(file)) => format!("{folder}/{file}"),
        _ => path.display().to_string(),
    }
}
