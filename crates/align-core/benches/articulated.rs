//! Hierarchical alignment of a whole robot (UR10, iiwa14) in a cluttered 20k-point scan from a
//! start 100 mm off; and preparing the robot for it (`ArticulatedBody::from_model`: link
//! surfaces and their distance grids), which a service does once per robot model; and the fit's
//! first step alone, the isolated returns' removal, on the same scan.
//! Run: cargo bench -p align-core --bench articulated

use std::hint::black_box;
use std::time::Duration;

use align_core::registration::articulated::{ArticulatedBody, RobotFitOptions, align_robot};
use align_core::registration::sampling::without_isolated;
use align_core::robots::ShippedRobot;
use align_core::trials::TrialRng;
use align_core::trials::robot_trials::perturb_robot;
use criterion::{Criterion, criterion_group, criterion_main};

#[path = "common/robot_scene.rs"]
mod robot_scene;
use robot_scene::{RobotScene, robot_scene};

fn articulated(c: &mut Criterion) {
    let mut group = c.benchmark_group("align_robot");
    group
        .sample_size(20)
        .measurement_time(Duration::from_secs(20));
    for robot in [ShippedRobot::Ur10, ShippedRobot::Iiwa14] {
        let model = robot.model().expect("shipped");
        group.bench_function(format!("{}_prepare_body", robot.name()), |b| {
            b.iter(|| black_box(ArticulatedBody::from_model(&model).expect("surfaces")))
        });
        let RobotScene {
            body,
            world_from_root: truth,
            cloud,
        } = robot_scene(robot);
        let mut rng = TrialRng::new(9);
        let (start, q0) = perturb_robot(&body, &truth, &robot.home(), 0.1, &mut rng);
        let options = RobotFitOptions::default();
        let probe = align_robot(&body, &cloud, &start, &q0, 0.1, &options).expect("aligns");
        println!(
            "{}: {} cloud points, rms {:.3} mm, {} iterations",
            robot.name(),
            cloud.len(),
            probe.rms_m * 1e3,
            probe.iterations
        );
        // The fit's first step, alone: its cost was measured only inside the fit before.
        group.bench_function(
            format!("{}_20k_points_isolated_returns", robot.name()),
            |b| {
                b.iter(|| {
                    black_box(without_isolated(
                        &cloud,
                        options.voxel_m,
                        options.isolated_min_neighbours,
                    ))
                })
            },
        );
        group.bench_function(format!("{}_20k_points_delta_100mm", robot.name()), |b| {
            b.iter(|| {
                black_box(align_robot(&body, &cloud, &start, &q0, 0.1, &options).expect("aligns"))
            })
        });
    }
    group.finish();
}

criterion_group!(benches, articulated);
criterion_main!(benches);
