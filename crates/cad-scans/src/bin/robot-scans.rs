//! `robot-scans`: a whole robot in ray-cast scans, fitted by ips's hierarchical alignment (base
//! pose and joints) from perturbed starts, scored per link.

use std::path::PathBuf;
use std::process::ExitCode;

use align_core::kinematics::{PackageMap, RobotModel};
use align_core::registration::articulated::ArticulatedBody;
use align_core::robots::ShippedRobot;
use cad_scans::files::write_ply;
use cad_scans::robot::{RobotCell, add_scene_rows, robot_markdown, scene_trials, seeded_scene};
use cad_scans::scanner::{Origin, ScanNoise};
use clap::Parser;

/// The ABB IRB 1600's URDF when neither --robot nor --urdf is given (relative to the working
/// directory: a checkout's root, beside the workplace's shared data).
const DEFAULT_ABB_URDF: &str =
    "../shared/data/abb_irb1600/abb_irb1600_support/urdf/irb1600_6_12.urdf";
/// Its joints as the project's ABB trials scan it (docs/articulated-trials.md).
const ABB_HOME: [f64; 6] = [0.0, 0.3, -0.2, 0.0, 0.6, 0.0];

/// Scans a whole robot with the ray-casting scanner of the CAD corpus (2-3 positions, a floor
/// and a box, occlusion, 0.5 mm range noise, mixed pixels at depth edges, 10 % outliers), in
/// several seeded scenes (the robot turned and its joints moved from home), and fits it with
/// ips's hierarchical alignment (base pose and every joint) from starts displaced by the
/// thesis's scheme, every joint moved too. Success per link: surface deviation under 1 mm.
/// "Reported": within 1 mm only through what the fit said it could not tell (joints it
/// reported unseen, set to the truth's values, where the scan does not pin them at the true
/// pose either: a flange's spin, a wrist shown on a few points; or an ambiguous twin). Progress
/// goes to stderr, the table (or --json) to stdout.
///
/// Default robot: the ABB IRB 1600 from ../shared/data ($CAD_SCANS_ABB_URDF), never in the
/// repository. Example: `robot-scans --deltas-mm 50,200 --scenes 5 --trials 10`.
#[derive(Debug, Parser)]
#[command(name = "robot-scans", version)]
struct Args {
    /// A shipped robot (ur10, ur10e, iiwa14) instead of the ABB.
    #[arg(long, conflicts_with = "urdf")]
    robot: Option<String>,
    /// A URDF of your own instead of the ABB (mesh or primitive link geometry).
    #[arg(long, value_name = "FILE")]
    urdf: Option<PathBuf>,
    /// Where a ROS package named in package:// URIs lives; repeatable. Packages not given are
    /// looked for among the URDF's parent folders.
    #[arg(long = "package-dir", value_name = "NAME=DIR")]
    package_dirs: Vec<String>,
    /// Home joint values (rad or m, one per moving joint) the scenes' poses are drawn about
    /// [default: the ABB's 0,0.3,-0.2,0,0.6,0; a shipped robot's home; else 0 or the limit
    /// nearest it].
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    home: Vec<f64>,
    /// Each scene's joints are home moved by up to this much each (scene 0 is home itself).
    #[arg(long, default_value_t = 0.5)]
    spread_rad: f64,
    /// Deltas in mm: the bound on the start's displacement (the robot's base and each joint's
    /// farthest point).
    #[arg(long, value_delimiter = ',', default_value = "50,100,200,500")]
    deltas_mm: Vec<f64>,
    /// Seeded scenes (scan and pose).
    #[arg(long, default_value_t = 5)]
    scenes: usize,
    /// Run only this scene (0-based), to reproduce a failure.
    #[arg(long, value_name = "S")]
    scene: Option<usize>,
    /// Trials per scene and delta.
    #[arg(long, default_value_t = 10)]
    trials: usize,
    /// The first trial of each scene's seeded sequence (`--first-trial T --trials 1` reruns T).
    #[arg(long, default_value_t = 0)]
    first_trial: usize,
    #[arg(long, default_value_t = 20)]
    seed: u64,
    /// Write each scene's cloud (binary PLY, m) and truth (root pose, joints) here.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// No mixed pixels and no spurious returns (range noise stays): tells what the scanner's
    /// artefacts cost from what the geometry does.
    #[arg(long)]
    clean: bool,
    /// One JSON document instead of the table.
    #[arg(long)]
    json: bool,
}

fn main() -> ExitCode {
    cad_scans::finish("robot-scans", run(&Args::parse()))
}

fn load_robot(args: &Args) -> Result<(ArticulatedBody, Vec<f64>), String> {
    let (model, default_home) = if let Some(name) = &args.robot {
        let robot = ShippedRobot::from_name(name).ok_or_else(|| {
            format!(
                "--robot {name}: the shipped robots are {}",
                ShippedRobot::ALL.map(|r| r.name()).join(", ")
            )
        })?;
        (
            robot.model().map_err(|e| e.to_string())?,
            Some(robot.home()),
        )
    } else {
        let (urdf, abb) = match &args.urdf {
            Some(urdf) => (urdf.clone(), false),
            None => (
                std::env::var_os("CAD_SCANS_ABB_URDF")
                    .map_or_else(|| PathBuf::from(DEFAULT_ABB_URDF), PathBuf::from),
                true,
            ),
        };
        if !urdf.is_file() {
            return Err(format!(
                "no URDF at '{}' (give --robot NAME, --urdf FILE or $CAD_SCANS_ABB_URDF)",
                urdf.display()
            ));
        }
        let mut packages = PackageMap::new();
        for entry in &args.package_dirs {
            let (name, dir) = PackageMap::parse_entry(entry)?;
            packages.insert(name, dir);
        }
        let model = RobotModel::from_urdf_file(&urdf, &packages).map_err(|e| e.to_string())?;
        (model, abb.then(|| ABB_HOME.to_vec()))
    };
    let body = ArticulatedBody::from_model(&model).map_err(|e| e.to_string())?;
    let home = if !args.home.is_empty() {
        args.home.clone()
    } else {
        default_home.unwrap_or_else(|| body.values_nearest_zero())
    };
    body.check_values(&home)
        .map_err(|message| format!("--home: {message}"))?;
    Ok((body, home))
}

fn run(args: &Args) -> Result<String, String> {
    if args.trials == 0 || args.scenes == 0 {
        return Err("--trials and --scenes must be at least 1".to_owned());
    }
    if let Some(bad) = args
        .deltas_mm
        .iter()
        .find(|d| !(d.is_finite() && **d > 0.0))
    {
        return Err(format!("--deltas-mm: {bad} is not a positive distance"));
    }
    if !(args.spread_rad.is_finite() && args.spread_rad >= 0.0) {
        return Err(format!(
            "--spread-rad: {} is not a non-negative angle",
            args.spread_rad
        ));
    }
    let (body, home) = load_robot(args)?;
    let deltas_m: Vec<f64> = args.deltas_mm.iter().map(|d| d * 1e-3).collect();
    let scenes: Vec<usize> = match args.scene {
        Some(scene) => vec![scene],
        None => (0..args.scenes).collect(),
    };
    let noise = if args.clean {
        ScanNoise {
            mixed_pixel_chance: 0.0,
            outlier_fraction: 0.0,
            ..ScanNoise::default()
        }
    } else {
        ScanNoise::default()
    };
    let mut cells: Vec<RobotCell> = Vec::new();
    let mut scene_records = Vec::new();
    for &scene in &scenes {
        let scanned = seeded_scene(&body, &home, args.spread_rad, args.seed, scene, &noise)
            .map_err(|e| e.to_string())?;
        let (world_from_root, q) = (scanned.world_from_root, scanned.q.clone());
        let cloud = scanned.cloud();
        eprintln!(
            "robot-scans: {} scene {scene}: joints {:?}, {} points ({} on the robot, {} mixed pixels, {} outliers), spacing {:?} mm",
            body.robot,
            q.iter()
                .map(|v| (v * 1e3).round() / 1e3)
                .collect::<Vec<_>>(),
            cloud.len(),
            scanned.count(Origin::Surface(cad_scans::scanner::Surface::Part)),
            scanned.count(Origin::MixedPixel),
            scanned.count(Origin::Outlier),
            scanned
                .spacing_m
                .iter()
                .map(|s| (s * 1e4).round() / 10.0)
                .collect::<Vec<_>>()
        );
        if let Some(out) = &args.out {
            let dir = out.join(format!("scene-{scene:02}"));
            std::fs::create_dir_all(&dir).map_err(|e| format!("'{}': {e}", dir.display()))?;
            let ply = dir.join("cloud.ply");
            write_ply(&ply, &cloud).map_err(|e| format!("'{}': {e}", ply.display()))?;
            let truth = serde_json::json!({
                "robot": body.robot,
                "world_from_root": align_core::pose::matrix_rows(&world_from_root),
                "q": q,
            });
            let path = dir.join("truth.json");
            std::fs::write(&path, truth.to_string())
                .map_err(|e| format!("'{}': {e}", path.display()))?;
        }
        let rows = scene_trials(
            &body,
            &scanned,
            &deltas_m,
            args.first_trial..args.first_trial + args.trials,
            args.seed,
            scene,
            |delta_m, trial| {
                eprintln!(
                    "robot-scans: scene {scene}, delta {:.0} mm, trial {trial}",
                    delta_m * 1e3
                );
            },
        );
        add_scene_rows(&mut cells, scene, &rows);
        scene_records.push(serde_json::json!({
            "scene": scene, "q": q, "points": cloud.len(), "spacing_m": scanned.spacing_m,
        }));
    }
    if args.json {
        return Ok(serde_json::json!({
            "robot": body.robot, "home": home, "seed": args.seed,
            "trials_per_scene": args.trials, "first_trial": args.first_trial,
            "scenes": scene_records, "cells": cells,
        })
        .to_string());
    }
    Ok(format!(
        "Robot '{}' in ray-cast scans: {} scene(s), {} trials per scene and delta, seed {} (success: surface deviation < 1 mm)\n\n{}",
        body.robot,
        scenes.len(),
        args.trials,
        args.seed,
        robot_markdown(&cells)
    ))
}
