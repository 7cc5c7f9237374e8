//! The `articulated` bench's fit (whole robot, cluttered 20k-point scan, delta 100 mm) from 20
//! starts rather than one: how long a fit takes depends on the start (a final refinement that
//! settles in three iterations or cycles to its limit), so one start's time says little about
//! the median over starts. Prints a table per robot: each start's median time over `--runs`
//! fits, the worst link's surface deviation from the truth, the links more than 1 mm off and the
//! joints the fit reports the scan does not show, then the median and mean over starts.
//! Where the ABB IRB 1600's support package is (`$ABB_IRB1600_SUPPORT_DIR`, else
//! `../shared/data` beside the workspace; the repository does not ship it), the ABB too, in a
//! scan of about 20k points of it at its trials' joint values (issue 20's 100 ms is for 20k
//! points at 100 mm, and its robots include the ABB). Where `scripts/robot-descriptions.sh` has
//! written it (`$EXAMPLE_ROBOT_DATA_DIR`), the UR10 with its CAD collision meshes too
//! (`ur10_cad`), at the shipped UR10's home: the shipped robots' links are primitives of
//! 256-512 triangles, the CAD UR10's 366-1224 and the ABB's 1096-6345.
//! Run: cargo bench -p align-core --bench articulated_starts [-- --runs N --starts N --only NAME]
//! (`--only ur10`, `iiwa14`, `abb_irb1600` or `ur10_cad`: that robot alone, as for a profile of
//! one).

use std::time::Instant;

use align_core::registration::articulated::{RobotFitOptions, align_robot};
use align_core::robots::ShippedRobot;
use align_core::trials::TrialRng;
use align_core::trials::robot_scan::{RobotScanOptions, scan_robot_of_about};
use align_core::trials::robot_trials::{perturb_robot, surface_deviation_m};

#[path = "common/robot_scene.rs"]
mod robot_scene;
use robot_scene::{RobotScene, robot_scene, trial_root_pose};
#[path = "../tests/common/abb.rs"]
mod abb;
#[path = "../tests/common/robot_package.rs"]
mod robot_package;
use abb::{ABB_TRIAL_HOME, abb_irb1600};
#[path = "../tests/common/ur10_cad.rs"]
mod ur10_cad;
use ur10_cad::ur10_cad;

fn argument(name: &str, default: usize) -> usize {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .map_or(default, |v| {
            v.parse()
                .unwrap_or_else(|_| panic!("{name} takes a count, got {v}"))
        })
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let middle = values.len() / 2;
    if values.len().is_multiple_of(2) {
        (values[middle - 1] + values[middle]) / 2.0
    } else {
        values[middle]
    }
}

fn main() {
    let runs = argument("--runs", 3).max(1);
    let starts = argument("--starts", 20).max(1);
    let options = RobotFitOptions::default();
    let only = std::env::args().skip_while(|a| a != "--only").nth(1);
    let scenes = scenes();
    if let Some(only) = &only
        && scenes.iter().all(|(name, ..)| name != only)
    {
        let names: Vec<&str> = scenes.iter().map(|(name, ..)| name.as_str()).collect();
        eprintln!(
            "--only {only}: no such robot here (these are: {})",
            names.join(", ")
        );
        std::process::exit(2);
    }
    for (name, home, scene) in scenes {
        if only.as_ref().is_some_and(|only| *only != name) {
            continue;
        }
        let RobotScene {
            body,
            world_from_root: truth,
            cloud,
        } = scene;
        let true_poses = body.link_poses(&truth, &home);
        println!(
            "{name}: {} cloud points, {starts} starts at delta 100 mm, {runs} fits each",
            cloud.len()
        );
        println!(
            "| start | median ms | iterations | worst link mm | links over 1 mm | joints not observed |"
        );
        println!("|---|---|---|---|---|---|");
        let mut per_start = Vec::new();
        for start_seed in 1..=starts as u64 {
            let mut rng = TrialRng::new(start_seed);
            let (start, q0) = perturb_robot(&body, &truth, &home, 0.1, &mut rng);
            let mut times_ms = Vec::new();
            let mut last = None;
            for _ in 0..runs {
                let clock = Instant::now();
                let fit = align_robot(&body, &cloud, &start, &q0, 0.1, &options).expect("aligns");
                times_ms.push(clock.elapsed().as_secs_f64() * 1e3);
                last = Some(fit);
            }
            let fit = last.expect("at least one run");
            let fitted = body.link_poses(&fit.world_from_root, &fit.q);
            let deviations_mm: Vec<(&str, f64)> = body
                .links()
                .iter()
                .enumerate()
                .filter_map(|(index, link)| {
                    let mesh = link.surface.as_ref()?;
                    let deviation_m = surface_deviation_m(mesh, &fitted[index], &true_poses[index]);
                    Some((link.name.as_str(), deviation_m * 1e3))
                })
                .collect();
            let worst_mm = deviations_mm.iter().map(|&(_, mm)| mm).fold(0.0, f64::max);
            let off = names_or_none(
                deviations_mm
                    .iter()
                    .filter(|&&(_, mm)| mm > 1.0)
                    .map(|&(name, _)| name),
            );
            // A joint the scan does not show is reported, not guessed (issue 20): the links it
            // moves may be off, and the fit says so.
            let unobserved = names_or_none(
                fit.joints
                    .iter()
                    .filter(|joint| !joint.observed)
                    .map(|joint| joint.name.as_str()),
            );
            let start_median = median(&mut times_ms);
            per_start.push(start_median);
            println!(
                "| {start_seed} | {start_median:.1} | {} | {worst_mm:.2} | {off} | {unobserved} |",
                fit.iterations
            );
        }
        let mean = per_start.iter().sum::<f64>() / per_start.len() as f64;
        println!(
            "{name}: median over starts {:.1} ms, mean {mean:.1} ms\n",
            median(&mut per_start)
        );
    }
}

/// `names` joined by commas, or "-".
fn names_or_none<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let joined: Vec<&str> = names.collect();
    if joined.is_empty() {
        "-".to_owned()
    } else {
        joined.join(", ")
    }
}

/// The robots fitted, each with the joint values it is scanned at: the shipped UR10 and iiwa14
/// at home, the ABB IRB 1600 at its trials' joint values where its package is, and the CAD
/// UR10 at the shipped UR10's home where its description is.
fn scenes() -> Vec<(String, Vec<f64>, RobotScene)> {
    let mut scenes: Vec<(String, Vec<f64>, RobotScene)> =
        [ShippedRobot::Ur10, ShippedRobot::Iiwa14]
            .into_iter()
            .map(|robot| (robot.name().to_owned(), robot.home(), robot_scene(robot)))
            .collect();
    let third_party = [
        (abb_irb1600(), "abb_irb1600", ABB_TRIAL_HOME.to_vec()),
        (ur10_cad(), "ur10_cad", ShippedRobot::Ur10.home()),
    ];
    for (body, name, home) in third_party {
        let Some(body) = body else {
            continue;
        };
        let world_from_root = trial_root_pose();
        // The shipped robots' scene (see `robot_scene`), at these joint values.
        let cloud = scan_robot_of_about(
            &body,
            &world_from_root,
            &home,
            &RobotScanOptions::default(),
            20_000,
        );
        scenes.push((
            name.to_owned(),
            home,
            RobotScene {
                body,
                world_from_root,
                cloud,
            },
        ));
    }
    scenes
}
