//! Touch guidance on parts made another way than the planner's (`align_core::corpus::parts`:
//! CAD-like meshes with fillets, holes and thin walls): starting from one touch and following
//! `next_touch`, six touches fix the part's pose on every part that has no symmetry, which six
//! touches drawn by area (what a person touching "somewhere on it" does) often do not.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use align_core::corpus::parts::{fixture_plate, open_shell, thin_wall_bracket};
use align_core::corpus::touches::on_table;
use align_core::geometry::Mesh;
use align_core::guidance::{Candidate, TakenTouch, candidates, next_touch};
use align_core::rng::SplitMix64;
use nalgebra::{Isometry3, Matrix6, SymmetricEigen, Vector6};

const RADIUS_M: f64 = 0.003;

fn taken(pose: &Isometry3<f64>, candidate: &Candidate) -> TakenTouch {
    TakenTouch {
        ball_centre: pose * (candidate.point_in_part + candidate.normal_in_part * RADIUS_M),
        approach: Some(pose.rotation * -candidate.normal_in_part),
    }
}

/// Smallest eigenvalue of the touches' pose information over the largest (0: a direction free).
fn conditioning(mesh: &Mesh, touches: &[Candidate]) -> f64 {
    let centre = mesh.centroid();
    let length = mesh.radius_m();
    let mut information = Matrix6::zeros();
    for touch in touches {
        let moment = (touch.point_in_part - centre).cross(&touch.normal_in_part) / length;
        let n = touch.normal_in_part;
        let a = Vector6::new(moment.x, moment.y, moment.z, n.x, n.y, n.z);
        information += a * a.transpose();
    }
    let eigen = SymmetricEigen::new(information).eigenvalues;
    let (low, high) = eigen
        .iter()
        .fold((f64::MAX, 0.0f64), |(lo, hi), v| (lo.min(*v), hi.max(*v)));
    low / high
}

#[test]
fn following_the_suggestions_fixes_the_pose_in_six_touches_where_random_touches_often_do_not() {
    let parts = [
        ("fixture plate", fixture_plate().unwrap()),
        ("thin-wall bracket", thin_wall_bracket().unwrap()),
        ("open shell", open_shell().unwrap()),
    ];
    let mut rng = SplitMix64::new(21);
    for (name, mesh) in parts {
        let pose = on_table(&mesh, 0.4, [0.6, -0.1], 0.0);
        let found = candidates(&mesh, &pose, RADIUS_M);
        assert!(found.len() > 50, "{name}: {} candidates", found.len());
        let mut random_full_rank = 0;
        for trial in 0..10 {
            let first = found[(rng.next_u64() % found.len() as u64) as usize];
            let mut guided = vec![first];
            while guided.len() < 6 {
                let taken: Vec<TakenTouch> = guided.iter().map(|c| taken(&pose, c)).collect();
                let next = next_touch(&mesh, &pose, &found, &taken).unwrap();
                let in_part = pose.inverse() * next.point;
                let chosen = found
                    .iter()
                    .min_by(|a, b| {
                        (a.point_in_part - in_part)
                            .norm()
                            .total_cmp(&(b.point_in_part - in_part).norm())
                    })
                    .unwrap();
                guided.push(*chosen);
            }
            let guided_conditioning = conditioning(&mesh, &guided);
            assert!(
                guided_conditioning > 1e-3,
                "{name}, trial {trial}: six guided touches leave the pose nearly free ({guided_conditioning:.2e})"
            );
            let random: Vec<Candidate> = (0..6)
                .map(|_| found[(rng.next_u64() % found.len() as u64) as usize])
                .collect();
            if conditioning(&mesh, &random) > 1e-3 {
                random_full_rank += 1;
            }
        }
        println!(
            "{name}: six random touches fix the pose in {random_full_rank} of 10 trials, guided in 10 of 10"
        );
        assert!(random_full_rank < 10, "{name}: random touches did as well");
    }
}
