//! The facing tree's build time (the tree the approximate and facing mesh queries descend), per
//! mesh: prepared on rayon's pool (`Mesh::prepare_approximate_queries`, as a local alignment
//! from 100 mm on does while the scan is binned) and built lazily on one core by a first
//! approximate query. Best of `--runs` fresh meshes each; a table for people.
//!
//! Run: cargo bench -p align-core --bench facing_tree -- [--runs N] [MESH ...]
//! Without meshes it times the xArm7 and SO-ARM100 links in crates/cad-scans/meshes; the larger
//! links of docs/cad-scan-trials.md come from `scripts/unseen-parts.sh OUT` (OUT/z1/*.stl).

use std::path::PathBuf;
use std::time::Instant;

use align_core::geometry::Mesh;
use align_core::io::read_mesh;
use nalgebra::Point3;

#[path = "common/shipped_meshes.rs"]
mod shipped_meshes;
use shipped_meshes::shipped_meshes;

fn main() {
    let mut runs = 5usize;
    let mut paths: Vec<PathBuf> = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--runs" => match args.next().and_then(|v| v.parse().ok()) {
                Some(n) if n > 0 => runs = n,
                _ => {
                    eprintln!("--runs needs a positive whole number");
                    std::process::exit(2);
                }
            },
            "--help" | "-h" => {
                println!(
                    "facing_tree [--runs N (5)] [MESH ...]: the facing tree's build time per mesh"
                );
                return;
            }
            // cargo bench passes --bench to every bench binary.
            "--bench" => {}
            _ => paths.push(PathBuf::from(arg)),
        }
    }
    if paths.is_empty() {
        paths = match shipped_meshes() {
            Ok(paths) => paths,
            Err(message) => {
                eprintln!("facing_tree: {message}");
                std::process::exit(2);
            }
        };
    }
    println!("| mesh | triangles | prepared, on the pool (ms) | lazy, one core (ms) |");
    println!("| --- | ---: | ---: | ---: |");
    let far_off = Point3::new(0.01, 0.02, 0.03);
    for path in &paths {
        let soup = match read_mesh(path, 1.0) {
            Ok(soup) => soup,
            Err(error) => {
                eprintln!("skipped: {error}");
                continue;
            }
        };
        let fresh = || Mesh::new(&soup.vertices, &soup.triangles);
        let (mut prepared_s, mut lazy_s) = (f64::INFINITY, f64::INFINITY);
        for _ in 0..runs {
            let Ok(mesh) = fresh() else { break };
            let clock = Instant::now();
            mesh.prepare_approximate_queries();
            prepared_s = prepared_s.min(clock.elapsed().as_secs_f64());
            let Ok(mesh) = fresh() else { break };
            let clock = Instant::now();
            // The first approximate query builds the tree; the query itself is one descent.
            std::hint::black_box(mesh.closest_point_within_slack(&far_off, 1.0, 1.5, None));
            lazy_s = lazy_s.min(clock.elapsed().as_secs_f64());
        }
        println!(
            "| {} | {} | {:.2} | {:.2} |",
            path.file_name().map_or_else(
                || path.display().to_string(),
                |n| n.to_string_lossy().into_owned()
            ),
            soup.triangles.len(),
            prepared_s * 1e3,
            lazy_s * 1e3
        );
    }
}
