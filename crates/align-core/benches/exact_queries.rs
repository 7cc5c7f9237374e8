//! The exact closest-point query the robot fit's refinements ask of each link (`Mesh::
//! closest_point_within`), bounded by the answer's own distance as a query hinted by the
//! keypoint's last triangle is: ns per query over 40 000 points within a millimetre of each
//! link's surface, with each link's triangles. The shipped robots' links are primitives; the
//! ABB IRB 1600's (`$ABB_IRB1600_SUPPORT_DIR`) and the CAD UR10's (`scripts/robot-descriptions.sh`,
//! `$EXAMPLE_ROBOT_DATA_DIR`) are CAD, where those are.
//! Run: cargo bench -p align-core --bench exact_queries

use std::time::Instant;

use align_core::registration::articulated::ArticulatedBody;
use align_core::robots::ShippedRobot;
use align_core::trials::TrialRng;
use nalgebra::Point3;

// Its trials' joint values are not needed here.
#[allow(dead_code)]
#[path = "../tests/common/abb.rs"]
mod abb;
#[path = "../tests/common/robot_package.rs"]
mod robot_package;
#[path = "../tests/common/ur10_cad.rs"]
mod ur10_cad;

const QUERIES: usize = 40_000;

fn main() {
    let mut robots: Vec<(&str, ArticulatedBody)> = [ShippedRobot::Ur10, ShippedRobot::Iiwa14]
        .into_iter()
        .map(|robot| {
            let model = robot.model().expect("shipped");
            (
                robot.name(),
                ArticulatedBody::from_model(&model).expect("surfaces"),
            )
        })
        .collect();
    robots.extend(abb::abb_irb1600().map(|body| ("abb_irb1600", body)));
    robots.extend(ur10_cad::ur10_cad().map(|body| ("ur10_cad", body)));
    println!("| robot | link | triangles | bounded query (ns) |");
    println!("| --- | --- | ---: | ---: |");
    for (name, body) in &robots {
        for link in body.links() {
            let Some(mesh) = &link.surface else {
                continue;
            };
            let triangles = mesh.triangles();
            let vertices: Vec<Point3<f64>> = mesh.vertices().collect();
            let mut rng = TrialRng::new(5);
            // A point on a random triangle, moved along its normal by up to a millimetre.
            let queries: Vec<Point3<f64>> = (0..QUERIES)
                .map(|_| {
                    let t = (rng.uniform() * triangles.len() as f64) as usize % triangles.len();
                    let [a, b, c] = triangles[t].map(|i| vertices[i as usize]);
                    let (mut u, mut v) = (rng.uniform(), rng.uniform());
                    if u + v > 1.0 {
                        (u, v) = (1.0 - u, 1.0 - v);
                    }
                    let on = a + (b - a) * u + (c - a) * v;
                    on + mesh.triangle_normal(t as u32) * (rng.uniform() - 0.5) * 0.002
                })
                .collect();
            let bounds: Vec<f64> = queries
                .iter()
                .map(|q| {
                    mesh.closest_point_within(q, 0.01).map_or(0.01, |found| {
                        found.signed_distance.abs() * (1.0 + 1e-9) + 1e-12
                    })
                })
                .collect();
            let clock = Instant::now();
            let mut found = 0usize;
            for (query, bound) in queries.iter().zip(&bounds) {
                found += usize::from(mesh.closest_point_within(query, *bound).is_some());
            }
            let ns = clock.elapsed().as_secs_f64() / QUERIES as f64 * 1e9;
            assert!(found > QUERIES / 2, "{name} {}: {found} found", link.name);
            println!(
                "| {name} | {} | {} | {ns:.0} |",
                link.name,
                mesh.num_triangles()
            );
        }
    }
}
