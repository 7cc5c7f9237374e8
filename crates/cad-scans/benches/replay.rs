//! Replays the scenes a `cad-scans` run wrote (scene.json, cloud.ply, part.stl and truth.json
//! per trial folder) through ips's Point Cloud Alignment, without scanning them again: the same
//! scans timed again and again, for speed work and profiling.
//!
//! ```text
//! target/release/cad-scans --scans 40 --ips local --no-peers --out /tmp/cs40
//! cargo bench -p cad-scans --bench replay -- --scenes /tmp/cs40 --runs 3 [--full] [--json]
//! ```
//!
//! Prints, per delta, the successes (pose distance under 1 mm, as cad-scans scores), the
//! median over the scenes of each scene's fastest run, how many successes' truths lie in the
//! pose's reported 95 % region, how many misses are flagged (ambiguous, or loose: reported
//! uncertain by 1 mm or more at 95 %, or without an uncertainty) and how many successes are
//! loose. The mesh and the cloud are read before the clock starts, as `cad-scans` and the peers
//! time them.

use std::path::{Path, PathBuf};
use std::time::Instant;

use align_core::geometry::Mesh;
use align_core::io::{read_cloud, read_mesh};
use align_core::registration::convergence::pose_distance;
use align_core::registration::pca::{align_cloud, scan_consensus};
use align_core::registration::uncertainty::{CHI2_95_6DOF, pose_deviation};
use align_core::trials::SUCCESS_THRESHOLD_M;
use align_service::jobs::cloud::cloud_options;
use cad_scans::files::{SceneFile, isometry_from_rows};
use cad_scans::table::median;
use nalgebra::{Isometry3, Point3};

struct Args {
    scenes: PathBuf,
    runs: usize,
    full: bool,
    json: bool,
}

const USAGE: &str = "replay --scenes DIR [--runs N (3)] [--full] [--json]
  DIR: a cad-scans --out folder (trial-NNNN/ each with scene.json, cloud.ply, part.stl, truth.json)
  --full: the whole alignment (exploration and uniqueness) instead of the local stage";

fn parse_args() -> Result<Args, String> {
    let mut args = Args {
        scenes: PathBuf::from("target/cad-scans"),
        runs: 3,
        full: false,
        json: false,
    };
    let mut given = std::env::args().skip(1);
    while let Some(flag) = given.next() {
        match flag.as_str() {
            "--scenes" => args.scenes = given.next().ok_or("--scenes needs a folder")?.into(),
            "--runs" => {
                args.runs = given
                    .next()
                    .and_then(|n| n.parse().ok())
                    .filter(|&n| n > 0)
                    .ok_or("--runs needs a count of at least 1")?
            }
            "--full" => args.full = true,
            "--json" => args.json = true,
            // cargo bench passes --bench.
            "--bench" => {}
            "--help" | "-h" => return Err(USAGE.into()),
            other => return Err(format!("unknown argument '{other}'\n{USAGE}")),
        }
    }
    Ok(args)
}

struct Replayed {
    scene: SceneFile,
    mesh: Mesh,
    cloud: Vec<Point3<f64>>,
    truth: Isometry3<f64>,
}

fn load(dir: &Path) -> Result<Replayed, String> {
    let read = |name: &str| {
        std::fs::read_to_string(dir.join(name))
            .map_err(|e| format!("{}: {e}", dir.join(name).display()))
    };
    let scene: SceneFile = serde_json::from_str(&read("scene.json")?)
        .map_err(|e| format!("{}/scene.json: {e}", dir.display()))?;
    let truth: [[f64; 4]; 4] = serde_json::from_str(&read("truth.json")?)
        .map_err(|e| format!("{}/truth.json: {e}", dir.display()))?;
    let soup = read_mesh(&dir.join(&scene.mesh), 1.0).map_err(|e| e.to_string())?;
    let mesh = Mesh::new(&soup.vertices, &soup.triangles).map_err(|e| e.to_string())?;
    let cloud = read_cloud(&dir.join(&scene.cloud), 1.0).map_err(|e| e.to_string())?;
    Ok(Replayed {
        scene,
        mesh,
        cloud,
        truth: isometry_from_rows(&truth),
    })
}

fn main() {
    let args = match parse_args() {
        Ok(args) => args,
        Err(message) => {
            eprintln!("{message}");
            std::process::exit(2);
        }
    };
    let mut dirs: Vec<PathBuf> = match std::fs::read_dir(&args.scenes) {
        Ok(entries) => entries
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| p.join("scene.json").is_file())
            .collect(),
        Err(error) => {
            eprintln!("{}: {error}", args.scenes.display());
            std::process::exit(2);
        }
    };
    dirs.sort();
    if dirs.is_empty() {
        eprintln!(
            "no trial folders in {} (write some with cad-scans --out)",
            args.scenes.display()
        );
        std::process::exit(2);
    }
    let options = cloud_options(false, None, !args.full);
    // Each scene's outcome, and its record for --json.
    let mut results: Vec<Outcome> = Vec::new();
    let mut scenes = Vec::new();
    for (index, dir) in dirs.iter().enumerate() {
        let replayed = match load(dir) {
            Ok(replayed) => replayed,
            Err(message) => {
                eprintln!("skipped: {message}");
                continue;
            }
        };
        let start = isometry_from_rows(&replayed.scene.start);
        let mut fastest_s = f64::INFINITY;
        let mut error_mm = f64::NAN;
        let mut last = None;
        for _ in 0..args.runs {
            let clock = Instant::now();
            let result = align_cloud(
                &replayed.mesh,
                &replayed.cloud,
                &start,
                replayed.scene.delta_m,
                &options,
            );
            fastest_s = fastest_s.min(clock.elapsed().as_secs_f64());
            error_mm = result.as_ref().map_or(f64::NAN, |r| {
                1e3 * pose_distance(
                    &r.alignment.base_from_part,
                    &replayed.truth,
                    replayed.mesh.radius_m(),
                )
            });
            last = result.ok();
        }
        let succeeded = error_mm < SUCCESS_THRESHOLD_M * 1e3;
        // A miss's scores (after the clock): a truth that outscores the pose found is a pose
        // the search never reached; one that scores alike is a scan the score cannot read.
        let miss_scores = match (&last, succeeded) {
            (Some(r), false) => Some(serde_json::json!({
                "found": scan_consensus(&replayed.mesh, &replayed.cloud, &r.alignment.base_from_part, &options),
                "truth": scan_consensus(&replayed.mesh, &replayed.cloud, &replayed.truth, &options),
            })),
            _ => None,
        };
        let uniqueness = last.as_ref().and_then(|r| r.uniqueness.as_ref());
        // Where the truth lies in the reported 95 % region (the squared Mahalanobis distance of
        // the pose's error), and how far the report says such fits end from the truth.
        let uncertainty = last.as_ref().and_then(|r| r.uncertainty.as_ref().ok());
        let mahalanobis_squared = uncertainty.zip(last.as_ref()).and_then(|(u, r)| {
            u.mahalanobis_squared(&pose_deviation(
                &replayed.truth,
                &r.alignment.base_from_part,
            ))
        });
        let within_95_mm = uncertainty.map(|u| u.pose_distance_95_m * 1e3);
        let outcome = Outcome {
            delta_mm: replayed.scene.delta_m * 1e3,
            succeeded,
            fastest_s,
            truth_in_region: mahalanobis_squared.is_some_and(|m| m <= CHI2_95_6DOF),
            ambiguous: uniqueness.is_some_and(|u| u.ambiguous),
            loose: within_95_mm.is_none_or(|mm| mm >= SUCCESS_THRESHOLD_M * 1e3),
        };
        results.push(outcome);
        scenes.push(serde_json::json!({
            "id": replayed.scene.id,
            "part": replayed.scene.part,
            "delta_mm": replayed.scene.delta_m * 1e3,
            "error_mm": error_mm,
            "succeeded": succeeded,
            "time_s": fastest_s,
            "refused": last.is_none(),
            "ambiguous": uniqueness.is_some_and(|u| u.ambiguous),
            "margin": uniqueness.map(|u| u.margin),
            "miss_scores": miss_scores,
            "mahalanobis_squared": mahalanobis_squared,
            "within_95_mm": within_95_mm,
            "weak_direction": uncertainty.map(|u| u.weak_direction.describe()),
            "uncertainty_error": last.as_ref().and_then(|r| r.uncertainty.as_ref().err()).map(ToString::to_string),
            "loose": outcome.loose,
            "kept": last.as_ref().map(|r| r.kept),
        }));
        if index % 10 == 9 || index + 1 == dirs.len() {
            eprint!("\rreplay: {}/{}", index + 1, dirs.len());
        }
    }
    eprintln!();
    let mut deltas: Vec<f64> = results.iter().map(|r| r.delta_mm).collect();
    deltas.sort_by(f64::total_cmp);
    deltas.dedup();
    let rows: Vec<Row> = deltas
        .iter()
        .map(|&delta_mm| {
            let at: Vec<&Outcome> = results.iter().filter(|r| r.delta_mm == delta_mm).collect();
            let mut times: Vec<f64> = at.iter().map(|r| r.fastest_s).collect();
            let count = |keep: &dyn Fn(&Outcome) -> bool| at.iter().filter(|r| keep(r)).count();
            Row {
                delta_mm,
                succeeded: count(&|r| r.succeeded),
                scans: at.len(),
                median_s: median(&mut times),
                truth_in_region: count(&|r| r.succeeded && r.truth_in_region),
                misses_flagged: count(&|r| !r.succeeded && (r.ambiguous || r.loose)),
                successes_loose: count(&|r| r.succeeded && r.loose),
            }
        })
        .collect();
    if args.json {
        let rows: Vec<_> = rows
            .iter()
            .map(|row| {
                serde_json::json!({"delta_mm": row.delta_mm, "succeeded": row.succeeded, "scans": row.scans,
                    "median_time_s": row.median_s, "truth_in_region": row.truth_in_region,
                    "misses_flagged": row.misses_flagged, "successes_loose": row.successes_loose})
            })
            .collect();
        println!(
            "{}",
            serde_json::json!({ "full": args.full, "runs": args.runs, "rows": rows, "scenes": scenes })
        );
        return;
    }
    println!(
        "ips {} (fastest of {} runs per scene)",
        if args.full { "full" } else { "local" },
        args.runs
    );
    println!(
        "| delta (mm) | succeeded | median time (s) | truth in the 95 % region (of successes) | misses ambiguous or loose | successes loose |"
    );
    println!("| ---: | ---: | ---: | ---: | ---: | ---: |");
    for row in rows {
        println!(
            "| {:.0} | {}/{} | {:.4} | {}/{} | {}/{} | {}/{} |",
            row.delta_mm,
            row.succeeded,
            row.scans,
            row.median_s,
            row.truth_in_region,
            row.succeeded,
            row.misses_flagged,
            row.scans - row.succeeded,
            row.successes_loose,
            row.succeeded
        );
    }
}

/// One scene's replay, as the table counts it.
#[derive(Debug, Clone, Copy)]
struct Outcome {
    delta_mm: f64,
    succeeded: bool,
    fastest_s: f64,
    /// The truth lies in the reported 95 % region of the pose.
    truth_in_region: bool,
    ambiguous: bool,
    /// Reported uncertain by 1 mm or more (95 %, pose distance), or without an uncertainty
    /// (refused, or too few matches to measure one).
    loose: bool,
}

/// The scenes at one delta.
struct Row {
    delta_mm: f64,
    succeeded: usize,
    scans: usize,
    median_s: f64,
    truth_in_region: usize,
    misses_flagged: usize,
    successes_loose: usize,
}
