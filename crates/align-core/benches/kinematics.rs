//! Forward kinematics, Jacobian and inverse kinematics of the shipped robots.
//! Run: cargo bench -p align-core --bench kinematics

use std::hint::black_box;
use std::time::Duration;

use align_core::kinematics::IkOptions;
use align_core::robots::ShippedRobot;
use criterion::{Criterion, criterion_group, criterion_main};

fn configuration(dof: usize) -> Vec<f64> {
    (0..dof)
        .map(|i| 0.3 + 0.17 * i as f64 * if i % 2 == 0 { 1.0 } else { -1.0 })
        .collect()
}

fn kinematics(c: &mut Criterion) {
    for robot in [ShippedRobot::Ur10, ShippedRobot::Iiwa14] {
        let chain = robot.chain().expect("shipped chain");
        let q = configuration(chain.dof());
        let name = format!("{} ({} DoF)", robot.name(), chain.dof());
        c.bench_function(&format!("fk_unchecked {name}"), |b| {
            b.iter(|| chain.forward_unchecked(black_box(&q)))
        });
        c.bench_function(&format!("fk {name}"), |b| {
            b.iter(|| chain.forward(black_box(&q)))
        });
        c.bench_function(&format!("jacobian {name}"), |b| {
            b.iter(|| chain.jacobian(black_box(&q)))
        });
        let target = chain.forward(&q).expect("fk");
        let near: Vec<f64> = q
            .iter()
            .enumerate()
            .map(|(i, v)| v + if i % 2 == 0 { 0.1 } else { -0.1 })
            .collect();
        let options = IkOptions::default();
        c.bench_function(&format!("ik from a seed 0.1 rad away {name}"), |b| {
            b.iter(|| chain.inverse(black_box(&target), black_box(&near), &options))
        });
        let zero = vec![0.0; chain.dof()];
        c.bench_function(&format!("ik from zero {name}"), |b| {
            b.iter(|| chain.inverse(black_box(&target), black_box(&zero), &options))
        });
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(50).measurement_time(Duration::from_secs(2)).warm_up_time(Duration::from_millis(500));
    targets = kinematics
}
criterion_main!(benches);
