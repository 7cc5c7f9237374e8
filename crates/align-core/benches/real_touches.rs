//! Issue 18's speed targets on data made by `align_core::corpus`, not by the simulator: a blind
//! global alignment of 65 touches (tilts to 60 degrees plus side contacts, 0.3-0.5 mm noise) on
//! the 9.3k-triangle sheet bracket (target: median 100 ms), and the diagnosis of a 65-touch UR5e
//! session on the 6.2k-triangle fixture plate (target: 300 ms).
//! Run: cargo bench -p align-core --bench real_touches

use std::hint::black_box;
use std::time::Duration;

use align_core::corpus::parts::{fixture_plate, thin_wall_bracket};
use align_core::corpus::robots::ur5e_dh_urdf;
use align_core::corpus::sessions::{HiddenEffects, ProbeTool, SessionRobot, generate_session};
use align_core::corpus::touches::{TouchOptions, blind_start, on_table, sample_touches};
use align_core::diagnosis::{TouchSample, diagnose};
use align_core::kinematics::{PackageMap, RobotModel};
use align_core::registration::psa::{PsaOptions, PsaTarget, Touch, align_touches};
use align_core::rng::SplitMix64;
use align_core::tool::Tool;
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Isometry3;

fn alignment(c: &mut Criterion) {
    let mesh = thin_wall_bracket().expect("part");
    let options = TouchOptions {
        floor_z_in_base: Some(0.0),
        ..TouchOptions::default()
    };
    let mut rng = SplitMix64::new(18);
    let truth = on_table(&mesh, 0.7, [0.5, 0.0], 0.0);
    let set = sample_touches(&mesh, &truth, 65, &options, &mut rng).expect("touches");
    let touches: Vec<Touch> = set
        .touches
        .iter()
        .map(|t| {
            let mut touch = Touch::new(t.id.clone(), t.ball_centre_in_base);
            touch.approach = Some(t.approach_in_base);
            touch
        })
        .collect();
    let start = blind_start(&set.touches, &mesh, &mut rng);
    let target = PsaTarget::new(&mesh);
    let psa = PsaOptions {
        tip_radius_m: options.ball_radius_m,
        ..PsaOptions::default()
    };
    c.bench_function(
        "blind global alignment, 65 touches, bracket 9.3k triangles",
        |b| b.iter(|| black_box(align_touches(&target, &touches, &start, &psa).expect("aligns"))),
    );
}

fn diagnosis(c: &mut Criterion) {
    let chain = RobotModel::from_urdf_str(&ur5e_dh_urdf(), &PackageMap::new())
        .expect("urdf")
        .chain("base_link", "flange")
        .expect("chain");
    let mesh = fixture_plate().expect("part");
    let probe = ProbeTool::straight(0.15, 0.003);
    let mut hidden = HiddenEffects::none(6);
    hidden.tcp_error_m = nalgebra::Vector3::new(0.002, 0.0, 0.0);
    let seeds = vec![
        vec![0.0, -1.3, 1.6, -1.9, -1.57, 0.0],
        vec![0.6, -1.0, 1.2, -1.7, -1.57, 0.5],
    ];
    let robot = SessionRobot {
        chain: &chain,
        tool: &probe,
        hidden: &hidden,
        seeds: &seeds,
    };
    let options = TouchOptions {
        sigma_range_m: (4e-4, 4e-4),
        ..TouchOptions::default()
    };
    let session =
        generate_session(&robot, &mesh, 65, &options, &mut SplitMix64::new(18)).expect("session");
    let samples: Vec<TouchSample> = session
        .touches
        .iter()
        .map(|t| TouchSample::from_joints(t.touch.id.clone(), t.q_reported.clone(), None))
        .collect();
    let tool = Tool::new(probe.flange_from_tcp, probe.ball_radius_m, 0.0).expect("tool");
    let start: Isometry3<f64> = session.base_from_part_truth;
    c.bench_function("diagnosis, 65 touches, UR5e, fixture 6.2k triangles", |b| {
        b.iter(|| {
            black_box(
                diagnose(Some(&chain), &tool, &mesh, &samples, &start, 4e-4).expect("diagnoses"),
            )
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10).measurement_time(Duration::from_secs(20));
    targets = alignment, diagnosis
}
criterion_main!(benches);
