//! Point-pair-feature detection ([`ppf_poses`]) of a shipped robot's proximal links (the base
//! and what only the first joint moves, as the robot fit detects them when the start is not
//! local) and of the whole robot at home, in the cluttered 20k-point scene of the `articulated`
//! benches, anywhere within 2 m of the true root. Prints, per case, the model's triangles, the
//! poses found, how far the best one puts the model's centroid from the truth, and the time of
//! each of `--runs` detections (min / median / max). Where the ABB IRB 1600's support package is
//! (`$ABB_IRB1600_SUPPORT_DIR`, else `../shared/data` beside the workspace; the repository does
//! not ship it), its proximal links too, in the full scan of its trials (`ips trials --urdf`,
//! about 90k points at its trial pose): the case the fit meets at 1000 mm; and, in that scan
//! without the planes larger than the proximal links (as the fit detects since the eighteenth
//! session), the proximal links and the base alone, which the fit detects instead (the ABB's
//! base is not round), and the base alone in that scan without the floor under it too (as the
//! fit detects it since the nineteenth session), and that with every reference's vote merged
//! (`min_vote_fraction` 0, as the fit detects since the twenty-ninth session).
//! Run: cargo bench -p align-core --bench ppf_detection [-- --runs N]

use std::time::Instant;

use align_core::registration::pca::{without_floor_under, without_planes_larger_than};
use align_core::registration::ppf::{PpfOptions, ppf_poses};
use align_core::registration::sampling::voxel_representatives;
use align_core::robots::ShippedRobot;
use align_core::trials::robot_scan::{RobotScanOptions, scan_robot};
use nalgebra::Point3;

#[path = "common/robot_scene.rs"]
mod robot_scene;
use robot_scene::{RobotScene, robot_scene, trial_root_pose};
#[path = "../tests/common/abb.rs"]
mod abb;
#[path = "../tests/common/robot_package.rs"]
mod robot_package;
use abb::{ABB_TRIAL_HOME, abb_irb1600};

/// Points below this height (m) are the floor's in the ABB's scene (the floor lies at z = 0,
/// with 0.3 mm noise).
const FLOOR_CUT_M: f64 = 0.004;

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
    let every_vote = PpfOptions {
        min_vote_fraction: 0.0,
        ..options.clone()
    };
    println!("{runs} detections per case, 4 poses asked, search ball 2 m about the true root");
    println!(
        "| case | triangles | poses | best pose's centroid error mm | min ms | median ms | max ms |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|");
    let mut cases: Vec<(String, RobotScene, Vec<f64>, bool)> =
        [ShippedRobot::Ur10, ShippedRobot::Iiwa14]
            .into_iter()
            .map(|robot| {
                (
                    robot.name().to_owned(),
                    robot_scene(robot),
                    robot.home(),
                    true,
                )
            })
            .collect();
    if let Some((scene, home)) = abb_scene() {
        cases.push(("abb_irb1600".to_owned(), scene, home, false));
    }
    for (name, scene, home, with_whole) in cases {
        let RobotScene {
            body,
            world_from_root,
            cloud,
        } = scene;
        // The links no joint moves or only the first one does (the fit's proximal links).
        let first_movers: Vec<usize> = (0..body.links().len())
            .filter(|&link| body.movers(link).len() <= 1)
            .collect();
        let all: Vec<usize> = (0..body.links().len()).collect();
        let proximal = body.rigid_mesh_of(&home, &first_movers);
        let (without_planes, without_floor, above_floor);
        let mut objects = vec![("proximal links", proximal.clone(), &cloud, &options)];
        if with_whole {
            objects.push((
                "whole robot",
                body.rigid_mesh_of(&home, &all),
                &cloud,
                &options,
            ));
        } else {
            // The scene as the fit detects in it since the eighteenth session: without the
            // planes larger than the proximal links, at the detection's step. Against it, the
            // floor cut where the scene put it (z = 0), which the fit does not know: what the
            // planes test leaves of the floor shows in the difference.
            without_planes = proximal.as_ref().map_or_else(Vec::new, |mesh| {
                without_planes_larger_than(
                    voxel_representatives(&cloud, options.step_m),
                    mesh,
                    options.step_m,
                )
            });
            // And as it detects a base that is not round (alone: the links no joint moves)
            // since the nineteenth session: without the floor under it too, however small.
            let base_alone = body.fixed_mesh(&home);
            without_floor = base_alone.as_ref().map_or_else(Vec::new, |base| {
                without_floor_under(without_planes.clone(), base, options.step_m)
            });
            above_floor = cloud
                .iter()
                .filter(|p| p.z > FLOOR_CUT_M)
                .copied()
                .collect::<Vec<Point3<f64>>>();
            objects.extend([
                (
                    "proximal links, no plane larger than them",
                    proximal,
                    &without_planes,
                    &options,
                ),
                (
                    "base alone, no plane larger than the proximal links",
                    base_alone.clone(),
                    &without_planes,
                    &options,
                ),
                (
                    "base alone, no plane larger than the proximal links nor the floor under it",
                    base_alone.clone(),
                    &without_floor,
                    &options,
                ),
                (
                    "base alone, as above, every reference's vote merged",
                    base_alone.clone(),
                    &without_floor,
                    &every_vote,
                ),
                (
                    "base alone, floor cut at its known height",
                    base_alone,
                    &above_floor,
                    &options,
                ),
            ]);
        }
        for (what, mesh, cloud, options) in objects {
            let Some(mesh) = mesh else {
                continue;
            };
            let centre = world_from_root * Point3::origin();
            let truth = world_from_root * mesh.centroid();
            let mut times_ms = Vec::new();
            let mut poses = Vec::new();
            for _ in 0..runs {
                let clock = Instant::now();
                poses = ppf_poses(&mesh, cloud, &centre, 2.0, options, 4, 0.3);
                times_ms.push(clock.elapsed().as_secs_f64() * 1e3);
            }
            times_ms.sort_by(f64::total_cmp);
            let error_mm = poses.first().map_or(f64::NAN, |best| {
                (best.world_from_model * mesh.centroid() - truth).norm() * 1e3
            });
            println!(
                "| {name} {what} | {} | {} | {error_mm:.1} | {:.0} | {:.0} | {:.0} |",
                mesh.triangles().len(),
                poses.len(),
                times_ms[0],
                times_ms[times_ms.len() / 2],
                times_ms[times_ms.len() - 1],
            );
        }
    }
}

/// The ABB IRB 1600 in the scene of its trials (`ips trials --urdf ... --home
/// 0,0.3,-0.2,0,0.6,0`): the trials' root pose and full scan, where its package is.
fn abb_scene() -> Option<(RobotScene, Vec<f64>)> {
    let body = abb_irb1600()?;
    let world_from_root = trial_root_pose();
    let home = ABB_TRIAL_HOME.to_vec();
    let cloud = scan_robot(&body, &world_from_root, &home, &RobotScanOptions::default());
    Some((
        RobotScene {
            body,
            world_from_root,
            cloud,
        },
        home,
    ))
}
