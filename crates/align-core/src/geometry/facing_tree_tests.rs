use super::*;
use crate::rng::SplitMix64;

fn unit_normals(corners: &[[Vector3<f64>; 3]]) -> Vec<Vector3<f64>> {
    corners
        .iter()
        .map(|[a, b, c]| (b - a).cross(&(c - a)).normalize())
        .collect()
}

fn between(rng: &mut SplitMix64, low: f64, high: f64) -> f64 {
    low + (high - low) * rng.uniform()
}

fn random_triangles(count: usize, rng: &mut SplitMix64) -> Vec<[Vector3<f64>; 3]> {
    (0..count)
        .map(|_| {
            let centre = Vector3::new(between(rng, -1.0, 1.0), between(rng, -1.0, 1.0), 0.0)
                + Vector3::z() * between(rng, -0.2, 0.2);
            [0, 1, 2].map(|_| {
                centre
                    + Vector3::new(
                        between(rng, -0.1, 0.1),
                        between(rng, -0.1, 0.1),
                        between(rng, -0.1, 0.1),
                    )
            })
        })
        .collect()
}

/// The serial depth-first build the tree had until 2026-11-29: (nodes, triangle order).
fn serial_build(
    corners: &[[Vector3<f64>; 3]],
    normals: &[Vector3<f64>],
    size_m: f64,
) -> (Vec<Node>, Vec<u32>) {
    fn bound_of(corners: &[[Vector3<f64>; 3]], normals: &[Vector3<f64>], members: &[u32]) -> Node {
        let c: Vec<_> = members.iter().map(|&t| corners[t as usize]).collect();
        let n: Vec<_> = members.iter().map(|&t| normals[t as usize]).collect();
        FacingTree::bound(&c, &n)
    }
    fn split(
        index: usize,
        members: &mut [u32],
        keys: &[[f64; 6]],
        corners: &[[Vector3<f64>; 3]],
        normals: &[Vector3<f64>],
        nodes: &mut Vec<Node>,
        order: &mut Vec<u32>,
    ) {
        if members.len() <= LEAF_SIZE {
            nodes[index].first = order.len() as u32;
            nodes[index].count = members.len() as u32;
            order.extend_from_slice(members);
            return;
        }
        let spread = |d: usize| {
            let (low, high) = members.iter().fold((f64::MAX, f64::MIN), |(lo, hi), &t| {
                (lo.min(keys[t as usize][d]), hi.max(keys[t as usize][d]))
            });
            high - low
        };
        let dimension = (0..6)
            .max_by(|&a, &b| spread(a).total_cmp(&spread(b)))
            .unwrap_or(0);
        let middle = members.len() / 2;
        members.select_nth_unstable_by(middle, |&a, &b| {
            keys[a as usize][dimension].total_cmp(&keys[b as usize][dimension])
        });
        let (left, right) = members.split_at_mut(middle);
        let first_child = nodes.len();
        nodes.push(bound_of(corners, normals, left));
        nodes.push(bound_of(corners, normals, right));
        nodes[index].first = first_child as u32;
        nodes[index].count = 0;
        split(first_child, left, keys, corners, normals, nodes, order);
        split(first_child + 1, right, keys, corners, normals, nodes, order);
    }
    let keys = split_keys(corners, normals, size_m);
    let mut members: Vec<u32> = (0..corners.len() as u32).collect();
    let mut nodes = vec![bound_of(corners, normals, &members)];
    let mut order = Vec::new();
    split(
        0,
        &mut members,
        &keys,
        corners,
        normals,
        &mut nodes,
        &mut order,
    );
    (nodes, order)
}

/// The build, on one core and on rayon's pool, lays out the very tree the serial depth-first
/// one did, on random triangles and on a grid whose centroids tie along every axis (where a
/// median split could go either way), from one triangle to enough for the parallel halving.
#[test]
fn the_build_lays_out_the_serial_depth_first_builds_tree() {
    let mut rng = SplitMix64::new(5);
    let mut grid = Vec::new();
    for i in 0..60 {
        for j in 0..50 {
            let corner = Vector3::new(i as f64, j as f64, 0.0) * 0.01;
            grid.push([
                corner,
                corner + Vector3::x() * 0.01,
                corner + Vector3::y() * 0.01,
            ]);
            grid.push([
                corner + Vector3::x() * 0.01,
                corner + Vector3::new(0.01, 0.01, 0.0),
                corner + Vector3::y() * 0.01,
            ]);
        }
    }
    for corners in [
        random_triangles(1, &mut rng),
        random_triangles(7, &mut rng),
        random_triangles(5000, &mut rng),
        grid,
    ] {
        let normals = unit_normals(&corners);
        let (nodes, order) = serial_build(&corners, &normals, 2.0);
        let count = corners.len();
        for parallel in [false, true] {
            let tree = FacingTree::new(&corners, &normals, 2.0, parallel);
            assert_eq!(tree.original, order, "{count} triangles");
            assert_eq!(tree.nodes.len(), nodes.len(), "{count} triangles");
            for (built, serial) in tree.nodes.iter().zip(&nodes) {
                assert_eq!(
                    (built.lower, built.upper, built.first, built.count),
                    (serial.lower, serial.upper, serial.first, serial.count),
                    "{count} triangles"
                );
                // The serial build summed a node's normals before its children were ordered:
                // the same sum in another order, equal to rounding. A cone only ever skips
                // triangles that no query accepts, so the answers are the same.
                assert!(
                    (built.axis - serial.axis).norm() < 1e-12,
                    "{count} triangles"
                );
                assert!((built.half_angle_rad - serial.half_angle_rad).abs() < 1e-12);
            }
            for (slot, &t) in order.iter().enumerate() {
                assert_eq!(tree.corners[slot], corners[t as usize]);
                assert_eq!(tree.slot_of[t as usize] as usize, slot);
            }
        }
    }
}

#[test]
fn the_tree_finds_what_a_scan_of_every_triangle_finds() {
    let mut rng = SplitMix64::new(7);
    let corners = random_triangles(500, &mut rng);
    let normals = unit_normals(&corners);
    let tree = FacingTree::new(&corners, &normals, 2.0, false);
    for _ in 0..300 {
        let query = Point3::new(
            between(&mut rng, -1.5, 1.5),
            between(&mut rng, -1.5, 1.5),
            between(&mut rng, -1.0, 1.0),
        );
        let facing = Vector3::new(
            between(&mut rng, -1.0, 1.0),
            between(&mut rng, -1.0, 1.0),
            between(&mut rng, -1.0, 1.0),
        )
        .normalize();
        let cone = between(&mut rng, 0.2, 2.0);
        for filter in [None, Some((&facing, cone))] {
            let expected = corners
                .iter()
                .zip(&normals)
                .filter(|(_, n)| filter.is_none_or(|(f, cone)| n.dot(f) >= cone.cos()))
                .map(|([a, b, c], _)| {
                    (closest_on_triangle(&query.coords, a, b, c).0 - query.coords).norm()
                })
                .fold(f64::INFINITY, f64::min);
            let found = tree.closest(&query, filter, f64::INFINITY, None);
            let hinted = tree.closest(&query, filter, f64::INFINITY, Some(17));
            assert_eq!(
                found.map(|f| f.distance_m),
                hinted.map(|f| f.distance_m),
                "a hint changes the speed, never the distance"
            );
            match found {
                Some(found) => {
                    assert!((found.distance_m - expected).abs() < 1e-12);
                    let n = normals[found.triangle as usize];
                    assert!(filter.is_none_or(|(f, cone)| n.dot(f) >= cone.cos()));
                }
                None => assert!(expected.is_infinite()),
            }
        }
    }
}

#[test]
fn a_search_with_slack_stays_within_its_factor_and_facing() {
    let mut rng = SplitMix64::new(5);
    let corners = random_triangles(500, &mut rng);
    let normals = unit_normals(&corners);
    let tree = FacingTree::new(&corners, &normals, 2.0, false);
    let mut inexact = 0;
    for _ in 0..500 {
        // Queries near and far (up to a few part sizes off).
        let query = Point3::from(rng.unit_vector() * 10f64.powf(between(&mut rng, -1.0, 0.8)));
        let facing = rng.unit_vector();
        let filter = Some((&facing, std::f64::consts::FRAC_PI_4));
        let exact = tree.closest(&query, filter, f64::INFINITY, None);
        let loose = tree.closest_within_slack(&query, filter, f64::INFINITY, None, 1.5);
        let (Some(exact), Some(loose)) = (exact, loose) else {
            assert!(exact.is_none() && loose.is_none());
            continue;
        };
        assert!(loose.distance_m <= 1.5 * exact.distance_m + 1e-12);
        assert!(loose.distance_m >= exact.distance_m - 1e-12);
        assert!(normals[loose.triangle as usize].dot(&facing) >= FRAC_PI_4_COS);
        inexact += usize::from(loose.distance_m > exact.distance_m + 1e-12);
    }
    // The slack is used (else the test proves nothing about the bound).
    assert!(inexact > 0, "every answer was exact");
}

const FRAC_PI_4_COS: f64 = std::f64::consts::FRAC_1_SQRT_2 - 1e-12;

#[test]
fn cached_queries_find_what_a_descent_finds() {
    let mut rng = SplitMix64::new(11);
    let corners = random_triangles(400, &mut rng);
    let normals = unit_normals(&corners);
    let tree = FacingTree::new(&corners, &normals, 2.0, false);
    let mut cache = NearbyTriangles::default();
    let mut query = Point3::new(0.3, -0.2, 0.4);
    let mut reused = 0;
    for _ in 0..2000 {
        // A random walk with steps from far below to far above the cache's reach.
        let step = 10f64.powf(between(&mut rng, -4.0, -0.5));
        query += rng.unit_vector() * step;
        let expected = tree
            .closest(&query, None, f64::INFINITY, None)
            .expect("found");
        let found = tree.closest_cached(&query, &mut cache, 2.0).expect("found");
        reused += usize::from(cache.filled);
        assert!((found.distance_m - expected.distance_m).abs() < 1e-12);
    }
    assert!(reused > 200, "the cache answered only {reused} of 2000");
}

#[test]
fn points_on_each_feature_of_a_triangle_are_classified() {
    let (a, b, c) = (Vector3::zeros(), Vector3::x(), Vector3::y());
    let cases = [
        (Vector3::new(-1.0, -1.0, 0.5), Feature::Vertex(0)),
        (Vector3::new(2.0, -0.5, 0.0), Feature::Vertex(1)),
        (Vector3::new(-0.5, 2.0, 0.0), Feature::Vertex(2)),
        (Vector3::new(0.5, -1.0, 0.0), Feature::Edge(0)),
        (Vector3::new(1.0, 1.0, 0.3), Feature::Edge(1)),
        (Vector3::new(-1.0, 0.5, 0.0), Feature::Edge(2)),
        (Vector3::new(0.2, 0.2, 1.0), Feature::Face),
    ];
    for (query, feature) in cases {
        assert_eq!(
            closest_on_triangle(&query, &a, &b, &c).1,
            feature,
            "{query:?}"
        );
    }
}
