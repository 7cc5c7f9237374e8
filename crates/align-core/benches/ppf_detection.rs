//! Point-pair-feature detection ([`ppf_poses`]) of a shipped robot's proximal links (the base
//! and what only the first joint moves, as the robot fit detects them when the start is not
//! local) and of the whole robot at home, in the cluttered 20k-point scene of the `articulated`
//! benches, anywhere within 2 m of the true root. Prints, per case, the model's triangles, the
//! poses found, how far the best one puts the model's centroid from the truth, and the time of
//! each of `--runs` detections (min / median / max).
//! Run: cargo bench -p align-core --bench ppf_detection [-- --runs N]

use std::time::Instant;

use align_core::registration::ppf::{PpfOptions, ppf_poses};
use align_core::robots::ShippedRobot;
use nalgebra::Point3;

#[path = "common/robot_scene.rs"]
mod robot_scene;
use robot_scene::{RobotScene, robot_scene};

fn runs_argument() -> usize {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == "--runs")
        .and_then(|i| args.get(i + 1))
        .map_or(5, |v| {
            v.parse()
                .unwrap_or_else(|_| panic!("--runs takes a count, got {v}"))
        })
        .max(1)
}

fn main() {
    let runs = runs_argument();
    let options = PpfOptions::default();
    println!("{runs} detections per case, 4 poses asked, search ball 2 m about the true root");
    println!(
        "| case | triangles | poses | best pose's centroid error mm | min ms | median ms | max ms |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|");
    for robot in [ShippedRobot::Ur10, ShippedRobot::Iiwa14] {
        let RobotScene {
            body,
            world_from_root,
            cloud,
        } = robot_scene(robot);
        let home = robot.home();
        // The links no joint moves or only the first one does (the fit's proximal links).
        let first_movers: Vec<usize> = (0..body.links().len())
            .filter(|&link| body.movers(link).len() <= 1)
            .collect();
        let all: Vec<usize> = (0..body.links().len()).collect();
        for (what, links) in [("proximal links", first_movers), ("whole robot", all)] {
            let Some(mesh) = body.rigid_mesh_of(&home, &links) else {
                continue;
            };
            let centre = world_from_root * Point3::origin();
            let truth = world_from_root * mesh.centroid();
            let mut times_ms = Vec::new();
            let mut poses = Vec::new();
            for _ in 0..runs {
                let clock = Instant::now();
                poses = ppf_poses(&mesh, &cloud, &centre, 2.0, &options, 4, 0.3);
                times_ms.push(clock.elapsed().as_secs_f64() * 1e3);
            }
            times_ms.sort_by(f64::total_cmp);
            let error_mm = poses.first().map_or(f64::NAN, |best| {
                (best.world_from_model * mesh.centroid() - truth).norm() * 1e3
            });
            println!(
                "| {} {what} | {} | {} | {error_mm:.1} | {:.0} | {:.0} | {:.0} |",
                robot.name(),
                mesh.triangles().len(),
                poses.len(),
                times_ms[0],
                times_ms[times_ms.len() / 2],
                times_ms[times_ms.len() - 1],
            );
        }
    }
}
