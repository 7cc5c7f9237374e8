//! Point Set Alignment: a whole alignment with 6 and 9 touches, local (the thesis's scope: from
//! a start within delta) and global (multi-start with ambiguity detection); and point-to-mesh
//! closest-point queries.
//! Run: cargo bench -p align-core --bench psa

use std::hint::black_box;
use std::time::Duration;

use align_core::registration::psa::{PsaOptions, PsaTarget, Search, align_touches};
use align_core::trials::parts::step_block;
use align_core::trials::{
    TouchSetup, TrialRng, displace_about_centroid, plan_touches, random_displacement,
};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Isometry3, Point3};

fn psa(c: &mut Criterion) {
    let part = step_block().expect("part");
    let truth = Isometry3::translation(0.6, 0.1, 0.05);
    let target = PsaTarget::new(&part.mesh);
    for count in [6, 9] {
        let setup = TouchSetup {
            count,
            tip_radius_m: 0.003,
            face_hints: false,
            approach: true,
        };
        let touches = plan_touches(&part, &truth, &setup);
        let mut rng = TrialRng::new(7);
        let start = displace_about_centroid(
            &truth,
            &part.mesh,
            &random_displacement(&mut rng, 0.05, part.mesh.radius_m()),
        );
        for (label, search) in [
            ("local", Search::Local),
            ("global", PsaOptions::default().search),
        ] {
            let options = PsaOptions {
                tip_radius_m: 0.003,
                search,
                ..PsaOptions::default()
            };
            c.bench_function(&format!("psa {label} {count} touches (delta 50 mm)"), |b| {
                b.iter(|| align_touches(&target, black_box(&touches), black_box(&start), &options))
            });
        }
        let thesis = PsaOptions {
            method: align_core::registration::psa::PsaMethod::PointToPoint,
            search: Search::Local,
            coherence: false,
            tolerance_m: 1e-6,
            tip_radius_m: 0.003,
            ..PsaOptions::default()
        };
        c.bench_function(
            &format!("psa thesis method {count} touches (delta 50 mm)"),
            |b| b.iter(|| align_touches(&target, black_box(&touches), black_box(&start), &thesis)),
        );
    }
    let queries: Vec<Point3<f64>> = {
        let mut rng = TrialRng::new(3);
        (0..1000)
            .map(|_| {
                Point3::new(
                    rng.uniform() * 0.5 - 0.1,
                    rng.uniform() * 0.4 - 0.1,
                    rng.uniform() * 0.35 - 0.1,
                )
            })
            .collect()
    };
    c.bench_function("closest point x1000 (step block, 1 thread)", |b| {
        b.iter(|| {
            queries
                .iter()
                .map(|q| part.mesh.closest_point(black_box(q)).signed_distance)
                .sum::<f64>()
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30).measurement_time(Duration::from_secs(3)).warm_up_time(Duration::from_millis(500));
    targets = psa
}
criterion_main!(benches);
