//! Point Cloud Alignment on a finely tessellated part, and closest-point query throughput on one
//! and two threads.
//! Run: cargo bench -p align-core --bench pca

use std::hint::black_box;
use std::time::Duration;

use align_core::geometry::Mesh;
use align_core::registration::pca::{PcaOptions, align_cloud};
use align_core::trials::clouds::{ScanOptions, scan_part};
use align_core::trials::parts::step_block;
use align_core::trials::{TrialRng, displace_about_centroid, random_displacement, trial_pose};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Point3;
use rayon::prelude::*;

/// Splits every triangle into four, `levels` times (CAD exports are this dense).
fn subdivided(mesh: &Mesh, levels: usize) -> Mesh {
    let mut vertices: Vec<Point3<f64>> = mesh.vertices().collect();
    let mut triangles = mesh.triangles().to_vec();
    for _ in 0..levels {
        let mut next = Vec::with_capacity(triangles.len() * 4);
        for [a, b, c] in triangles {
            let mut mid = |i: u32, j: u32| {
                vertices.push(Point3::from(
                    (vertices[i as usize].coords + vertices[j as usize].coords) / 2.0,
                ));
                vertices.len() as u32 - 1
            };
            let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
            next.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
        }
        triangles = next;
    }
    Mesh::new(&vertices, &triangles).expect("subdivided mesh")
}

fn pca(c: &mut Criterion) {
    let part = step_block().expect("part");
    let mesh = subdivided(&part.mesh, 4);
    let truth = trial_pose();
    let scan = ScanOptions {
        spacing_m: 0.0065,
        noise_sigma_m: 0.0003,
        scanners: vec![
            Point3::new(0.0, 0.0, 1.6),
            Point3::new(1.6, -1.2, 1.0),
            Point3::new(1.4, 0.9, 0.9),
        ],
        ..ScanOptions::default()
    };
    let cloud = scan_part(&mesh, &truth, &scan);
    let mut rng = TrialRng::new(5);
    let start = displace_about_centroid(
        &truth,
        &mesh,
        &random_displacement(&mut rng, 0.05, mesh.radius_m()),
    );
    let probe = align_cloud(&mesh, &cloud, &start, 0.05, &PcaOptions::default()).expect("aligns");
    println!(
        "PCA bench scene: {} triangles, {} cloud points, {} keypoints, {} kept, {} iterations",
        mesh.num_triangles(),
        cloud.len(),
        probe.keypoints,
        probe.kept,
        probe.alignment.iterations
    );
    for (label, parallel, starts) in [
        ("1 thread, local", false, 0),
        ("2 threads, local", true, 0),
        (
            "2 threads, default (exploration)",
            true,
            PcaOptions::default().starts,
        ),
    ] {
        let options = PcaOptions {
            parallel,
            starts,
            ..PcaOptions::default()
        };
        c.bench_function(&format!("pca delta 50 mm, {label}"), |b| {
            b.iter(|| align_cloud(&mesh, black_box(&cloud), black_box(&start), 0.05, &options))
        });
    }
    let queries: Vec<Point3<f64>> = cloud
        .iter()
        .take(4000)
        .map(|p| truth.inverse() * p)
        .collect();
    c.bench_function("closest point x4000, 1 thread", |b| {
        b.iter(|| {
            queries
                .iter()
                .map(|q| mesh.closest_point(black_box(q)).signed_distance)
                .sum::<f64>()
        })
    });
    c.bench_function("closest point x4000, 2 threads (rayon)", |b| {
        b.iter(|| {
            queries
                .par_iter()
                .map(|q| mesh.closest_point(black_box(q)).signed_distance)
                .sum::<f64>()
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10).measurement_time(Duration::from_secs(5)).warm_up_time(Duration::from_millis(500));
    targets = pca
}
criterion_main!(benches);
