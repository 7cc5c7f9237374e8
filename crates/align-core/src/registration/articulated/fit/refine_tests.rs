//! Unit tests of the refinement: its normal equations and the measure its stop uses.

use nalgebra::{DMatrix, DVector, Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use super::placed::{Match, Placed, placed_radius};
use super::refine::{JacobianRows, normal_equations};
use crate::registration::articulated::body::ArticulatedBody;
use crate::robots::ShippedRobot;
use crate::trials::TrialRng;

/// The shipped UR10 at its home joints, its root at (0.2, -0.1, 0) m.
fn ur10_at_home() -> (ArticulatedBody, Isometry3<f64>, Vec<f64>) {
    let body = ArticulatedBody::from_model(&ShippedRobot::Ur10.model().unwrap()).unwrap();
    (
        body,
        Isometry3::translation(0.2, -0.1, 0.0),
        ShippedRobot::Ur10.home(),
    )
}

/// At least `count` matches of points 2 mm off random surface points of random links, placed.
fn matches_near_surfaces(
    body: &ArticulatedBody,
    placed: &Placed,
    seed: u64,
    count: usize,
) -> Vec<Match> {
    let all: Vec<usize> = (0..body.links().len()).collect();
    let mut rng = TrialRng::new(seed);
    let mut matches = Vec::new();
    while matches.len() < count {
        let link = (rng.uniform() * body.links().len() as f64) as usize;
        let Some(surface) = &body.links()[link].surface else {
            continue;
        };
        let around = surface.centroid().coords
            + Vector3::new(
                rng.uniform() - 0.5,
                rng.uniform() - 0.5,
                rng.uniform() - 0.5,
            ) * surface.radius_m()
                * 2.0;
        let on = surface.closest_point(&Point3::from(around));
        let point = placed.poses[link] * (on.point + on.normal * 0.002);
        matches.extend(placed.nearest(&point, 0.01, &all));
    }
    matches
}

#[test]
fn the_normal_matrix_measures_a_step_as_the_points_normal_motions_do() {
    // step . (J^T W J) step is the weighted sum of (J step)^2 over the points: what the
    // refinement compares with its tolerance. The rank-one updates fill one triangle; a
    // product with that triangle alone miscounts every coupling (the base's yaw against
    // the first joint's), and the refinement then ran to its limit on most starts.
    let (body, base, q) = ur10_at_home();
    let placed = Placed::new(&body, &base, &q);
    let matches = matches_near_surfaces(&body, &placed, 11, 400);
    let scale = placed_radius(&placed);
    let normal = normal_equations(&body, &placed, &matches, scale, false, false).normal;
    // Summed over the links' own matrices (the exact refinements' way) it is the same.
    let summed = normal_equations(&body, &placed, &matches, scale, true, false).normal;
    assert!((&summed - &normal).amax() <= 1e-12 * normal.amax());
    let n = normal.nrows();
    let step = DVector::from_fn(n, |i, _| ((i * 7 + 3) % 5) as f64 - 2.0);
    // The step taken a millionth of the way, as the refinement applies it, and each
    // matched surface point carried along with its link.
    let epsilon = 1e-6;
    let small = &step * epsilon;
    let omega = Vector3::new(small[0], small[1], small[2]) / scale;
    let rotation = UnitQuaternion::from_scaled_axis(omega);
    let centre = base.translation.vector;
    let shift = centre + Vector3::new(small[3], small[4], small[5]) - rotation * centre;
    let moved_base = Isometry3::from_parts(Translation3::from(shift), rotation) * base;
    let moved_q: Vec<f64> = q
        .iter()
        .enumerate()
        .map(|(parameter, value)| value + small[6 + parameter] / scale)
        .collect();
    let moved = body.link_poses(&moved_base, &moved_q);
    let direct: f64 = matches
        .iter()
        .map(|m| {
            let carried = moved[m.link] * (placed.inverse[m.link] * m.surface);
            let along_normal = m.normal.dot(&(carried - m.surface)) / epsilon;
            m.weight * along_normal * along_normal
        })
        .sum();
    let measured = step.dot(&(&normal * &step));
    assert!(
        (measured - direct).abs() <= 1e-4 * direct,
        "{measured} vs {direct}"
    );
}

#[test]
fn the_normal_equations_are_the_sums_nalgebra_s_rank_one_updates_make_to_the_last_bit() {
    // The refinement's sums are written out by hand for speed; every trial row was measured
    // with nalgebra's `syger` and `axpy`, so the hand-written sums must be those, bit for bit.
    let (body, base, q) = ur10_at_home();
    let placed = Placed::new(&body, &base, &q);
    let matches = matches_near_surfaces(&body, &placed, 13, 500);
    let scale = placed_radius(&placed);
    let n = 6 + q.len();
    let rows = JacobianRows::new(&body, &placed, scale);
    let links = body.links().len();
    let mut normal = DMatrix::zeros(n, n);
    let mut link_normals = vec![DMatrix::zeros(n, n); links];
    let mut rhs = DVector::zeros(n);
    let mut row = DVector::zeros(n);
    for m in &matches {
        rows.fill(m, row.as_mut_slice());
        let residual = m.normal.dot(&(m.point - m.surface));
        normal.syger(m.weight, &row, &row, 1.0);
        link_normals[m.link].syger(m.weight, &row, &row, 1.0);
        rhs.axpy(residual * m.weight, &row, 1.0);
    }
    normal.fill_upper_triangle_with_lower_triangle();
    let mut summed = DMatrix::zeros(n, n);
    for link_normal in &mut link_normals {
        link_normal.fill_upper_triangle_with_lower_triangle();
        summed += &*link_normal;
    }
    let whole = normal_equations(&body, &placed, &matches, scale, false, true);
    assert_eq!(whole.normal, normal);
    assert_eq!(whole.rhs, rhs);
    let per_link = normal_equations(&body, &placed, &matches, scale, true, true);
    assert_eq!(per_link.normal, summed);
    assert_eq!(per_link.rhs, rhs);
    assert_eq!(per_link.link_normals, link_normals);
    // More matches than a block: the blocks' sums are the same with and without threads, and
    // on any number of them.
    let many = matches_near_surfaces(&body, &placed, 14, 9000);
    let serial = normal_equations(&body, &placed, &many, scale, true, false);
    let blocks = normal_equations(&body, &placed, &many, scale, true, true);
    assert_eq!(serial.normal, blocks.normal);
    assert_eq!(serial.rhs, blocks.rhs);
    let on_one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| normal_equations(&body, &placed, &many, scale, true, true));
    assert_eq!(on_one_thread.normal, blocks.normal);
    assert_eq!(on_one_thread.rhs, blocks.rhs);
}

#[test]
fn the_refinements_stop_measures_a_step_on_the_link_it_moves_most() {
    // A step that turns only the last wrist joint moves a few hundredths of the points: over
    // all of them its motion is diluted below the tolerance, and the refinement stopped with
    // a wrist still moving. The measure is each link's own RMS motion along the normals.
    let (body, base, q) = ur10_at_home();
    let placed = Placed::new(&body, &base, &q);
    let mut matches = matches_near_surfaces(&body, &placed, 12, 2000);
    // Most points on the base and the arm, a few on the wrist joint's links, as in a scan.
    let wrist_parameter = body.parameters().len() - 2;
    let wrist_links = body.moved_by(wrist_parameter);
    let mut kept = 0;
    matches.retain(|m| {
        let on_wrist = wrist_links.contains(&m.link);
        kept += usize::from(on_wrist);
        !on_wrist || kept <= 40
    });
    let scale = placed_radius(&placed);
    let equations = normal_equations(&body, &placed, &matches, scale, true, false);
    let n = equations.normal.nrows();
    let mut step = DVector::zeros(n);
    step[6 + wrist_parameter] = 0.001;
    // Each link's RMS motion along the normals, from the points carried by the step.
    let epsilon = 1e-6;
    let moved_q: Vec<f64> = q
        .iter()
        .enumerate()
        .map(|(parameter, value)| value + epsilon * step[6 + parameter] / scale)
        .collect();
    let moved = body.link_poses(&base, &moved_q);
    let links = body.links().len();
    let (mut motion, mut weight) = (vec![0.0; links], vec![0.0; links]);
    for m in &matches {
        let carried = moved[m.link] * (placed.inverse[m.link] * m.surface);
        let along_normal = m.normal.dot(&(carried - m.surface)) / epsilon;
        motion[m.link] += m.weight * along_normal * along_normal;
        weight[m.link] += m.weight;
    }
    let min_weight = 5.0;
    let direct = (0..links)
        .filter(|&l| weight[l] >= min_weight)
        .map(|l| (motion[l] / weight[l]).sqrt())
        .fold(0.0, f64::max);
    let measured = equations.largest_link_motion_m(&step, min_weight);
    assert!(
        direct > 0.0 && (measured - direct).abs() <= 1e-4 * direct,
        "{measured} vs {direct}"
    );
    let all_points = (step.dot(&(&equations.normal * &step))
        / matches.iter().map(|m| m.weight).sum::<f64>())
    .sqrt();
    assert!(measured > 5.0 * all_points, "{measured} vs {all_points}");
    // A link with fewer matches than asked does not count.
    assert_eq!(equations.largest_link_motion_m(&step, 1e9), 0.0);
}
