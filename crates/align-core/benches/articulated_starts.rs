//! The `articulated` bench's fit (whole robot, cluttered 20k-point scan, delta 100 mm) from 20
//! starts rather than one: how long a fit takes depends on the start (a final refinement that
//! settles in three iterations or cycles to its limit), so one start's time says little about
//! the median over starts. Prints a table per robot: each start's median time over `--runs`
//! fits and the worst link's surface deviation from the truth, then the median and mean over
//! starts.
//! Run: cargo bench -p align-core --bench articulated_starts [-- --runs N --starts N]

use std::time::Instant;

use align_core::registration::articulated::{RobotFitOptions, align_robot};
use align_core::robots::ShippedRobot;
use align_core::trials::TrialRng;
use align_core::trials::robot_trials::{perturb_robot, surface_deviation_m};

#[path = "common/robot_scene.rs"]
mod robot_scene;
use robot_scene::{RobotScene, robot_scene};

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
    for robot in [ShippedRobot::Ur10, ShippedRobot::Iiwa14] {
        let RobotScene {
            body,
            world_from_root: truth,
            cloud,
        } = robot_scene(robot);
        let true_poses = body.link_poses(&truth, &robot.home());
        println!(
            "{}: {} cloud points, {starts} starts at delta 100 mm, {runs} fits each",
            robot.name(),
            cloud.len()
        );
        println!("| start | median ms | iterations | worst link mm |");
        println!("|---|---|---|---|");
        let mut per_start = Vec::new();
        for start_seed in 1..=starts as u64 {
            let mut rng = TrialRng::new(start_seed);
            let (start, q0) = perturb_robot(&body, &truth, &robot.home(), 0.1, &mut rng);
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
            let worst_mm = body
                .links()
                .iter()
                .enumerate()
                .filter_map(|(index, link)| {
                    let mesh = link.surface.as_ref()?;
                    Some(surface_deviation_m(mesh, &fitted[index], &true_poses[index]) * 1e3)
                })
                .fold(0.0, f64::max);
            let start_median = median(&mut times_ms);
            per_start.push(start_median);
            println!(
                "| {start_seed} | {start_median:.1} | {} | {worst_mm:.2} |",
                fit.iterations
            );
        }
        let mean = per_start.iter().sum::<f64>() / per_start.len() as f64;
        println!(
            "{}: median over starts {:.1} ms, mean {mean:.1} ms\n",
            robot.name(),
            median(&mut per_start)
        );
    }
}
