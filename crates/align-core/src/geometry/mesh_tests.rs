//! Tests of [`Mesh`](super::Mesh) (its own file: mesh.rs is near the size limit).
use super::*;

#[test]
fn cube_distances_are_signed_with_pseudo_normals_at_edges_and_corners() {
    let mesh = Mesh::cuboid([0.2, 0.2, 0.2]).unwrap();
    assert!(mesh.is_watertight(), "{:?}", mesh.notes());
    let outside = mesh.closest_point(&Point3::new(0.0, 0.0, 0.15));
    assert!((outside.signed_distance - 0.05).abs() < 1e-12);
    assert!((outside.normal - Vector3::z()).norm() < 1e-12);
    assert!(outside.on_face);
    let inside = mesh.closest_point(&Point3::new(0.0, 0.0, 0.08));
    assert!((inside.signed_distance + 0.02).abs() < 1e-12);
    // Beyond a corner the closest point is the corner, with the diagonal pseudo-normal.
    let corner = mesh.closest_point(&Point3::new(0.2, 0.2, 0.2));
    assert!((corner.point - Point3::new(0.1, 0.1, 0.1)).norm() < 1e-12);
    assert!((corner.normal - Vector3::new(1.0, 1.0, 1.0).normalize()).norm() < 1e-9);
    assert!(corner.signed_distance > 0.0);
    assert!((mesh.radius_m() - 0.1 * 3f64.sqrt()).abs() < 1e-12);
}

#[test]
fn slack_queries_stay_within_their_factor_with_or_without_a_hint() {
    let mesh = Mesh::cuboid([0.3, 0.1, 0.05]).unwrap();
    let mut rng = crate::rng::SplitMix64::new(5);
    for _ in 0..500 {
        let query = Point3::from(Vector3::from_fn(|_, _| 1.6 * rng.uniform() - 0.8));
        let exact = mesh.closest_point(&query).signed_distance.abs();
        // A hint from another query, as a run's previous step gives.
        let hint = mesh
            .closest_point(&(query + Vector3::new(0.05, 0.0, 0.0)))
            .triangle;
        for hint in [None, Some(hint)] {
            let found = mesh
                .closest_point_within_slack(&query, 2.0, 1.5, hint)
                .unwrap();
            let distance = (found.point - query).norm();
            assert!(
                distance <= 1.5 * exact + 1e-12,
                "{distance} against {exact}"
            );
            assert!((found.signed_distance.abs() - distance).abs() < 1e-12);
        }
        // Beyond the limit there is nothing to find.
        assert!(
            mesh.closest_point_within_slack(&query, 0.5 * exact, 1.5, None)
                .is_none()
        );
    }
}

#[test]
fn a_hinted_query_gives_the_exact_answer_whatever_the_hint() {
    // A capsule: hundreds of triangles, round and flat, so that a stale hint is often far
    // from the best and a bound from it must not cut the true answer off.
    let soup = crate::geometry::shapes::capsule_soup(0.05, 0.2);
    let mesh = Mesh::new(&soup.vertices, &soup.triangles).unwrap();
    let count = mesh.triangles().len() as u32;
    let mut rng = crate::rng::SplitMix64::new(11);
    for _ in 0..2000 {
        let query = Point3::from(Vector3::from_fn(|_, _| 0.4 * rng.uniform() - 0.2));
        let limit = 0.1 * rng.uniform();
        let expected = mesh.closest_point_within(&query, limit);
        let near = mesh
            .closest_point(&(query + Vector3::new(0.01, -0.02, 0.005)))
            .triangle;
        let random = (rng.uniform() * f64::from(count)) as u32;
        for hint in [None, Some(near), Some(random), Some(count + 7)] {
            let found = mesh.closest_point_within_hinted(&query, limit, hint);
            match (&expected, &found) {
                (None, None) => {}
                (Some(e), Some(f)) => {
                    assert!(
                        (e.signed_distance - f.signed_distance).abs() < 1e-12,
                        "{query} hint {hint:?}: {} against {}",
                        f.signed_distance,
                        e.signed_distance
                    );
                    assert!((e.point - f.point).norm() < 1e-9);
                    assert_eq!(e.on_face, f.on_face, "{query} hint {hint:?}");
                }
                _ => panic!("{query} within {limit} hint {hint:?}: {found:?} against {expected:?}"),
            }
        }
    }
}

#[test]
fn inward_winding_is_flipped_and_open_meshes_are_unsigned() {
    let cube = Mesh::cuboid([1.0, 1.0, 1.0]).unwrap();
    let vertices: Vec<_> = cube.vertices().collect();
    let flipped: Vec<[u32; 3]> = cube
        .triangles()
        .iter()
        .map(|t| [t[0], t[2], t[1]])
        .collect();
    let mesh = Mesh::new(&vertices, &flipped).unwrap();
    let sample = mesh.closest_point(&Point3::new(0.0, 0.0, 0.4));
    assert!(sample.signed_distance < 0.0);
    assert!((sample.normal - Vector3::z()).norm() < 1e-12);

    let open = Mesh::new(&vertices, &cube.triangles()[..10]).unwrap();
    assert!(!open.is_watertight());
    assert!(open.notes()[0].contains("unsigned"));
    assert!(
        open.closest_point(&Point3::new(0.0, 0.0, 0.4))
            .signed_distance
            > 0.0
    );
}

#[test]
fn bad_meshes_are_rejected_with_the_reason() {
    let p = Point3::new(0.0, 0.0, 0.0);
    assert_eq!(Mesh::new(&[p], &[]).unwrap_err(), MeshError::Empty);
    let error = Mesh::new(&[p, p, Point3::new(f64::NAN, 0.0, 0.0)], &[[0, 1, 2]]).unwrap_err();
    assert_eq!(error.to_string(), "vertex 2 is not finite (NaN, 0, 0)");
    let error = Mesh::new(&[p, p, p], &[[0, 1, 3]]).unwrap_err();
    assert_eq!(
        error.to_string(),
        "triangle 0 uses vertex 3, but the mesh has 3 vertices"
    );
    let q = Point3::new(1.0, 0.0, 0.0);
    assert_eq!(
        Mesh::new(&[p, q, q], &[[0, 1, 2]]).unwrap_err(),
        MeshError::AllDegenerate
    );
}

#[test]
fn has_surface_within_answers_as_the_closest_distance_does() {
    // A watertight box: a point deep inside a solid is far from its surface, not near it.
    let block = Mesh::cuboid([0.3, 0.12, 0.05]).unwrap();
    let mut rng = crate::rng::SplitMix64::new(11);
    let (mut near, mut far) = (0, 0);
    for _ in 0..3000 {
        let query = Point3::from(rng.unit_vector() * (0.4 * rng.uniform()));
        let closest = block.closest_point(&query).signed_distance.abs();
        for max_distance_m in [0.001, 0.01, 0.05, 0.2] {
            let expected = closest <= max_distance_m;
            assert_eq!(
                block.has_surface_within(&query, max_distance_m),
                expected,
                "{query:?} within {max_distance_m} m: the closest is {closest} m off"
            );
            if expected {
                near += 1;
            } else {
                far += 1;
            }
        }
    }
    // Both answers are exercised often.
    assert!(near > 2000 && far > 2000, "{near} near, {far} far");
    assert!(
        !block.has_surface_within(&Point3::origin(), 0.02),
        "the box's centre"
    );
    assert!(block.has_surface_within(&Point3::origin(), 0.025));
    assert!(!block.has_surface_within(&Point3::origin(), f64::NAN));
}

#[test]
fn a_zero_area_triangle_closing_a_t_junction_gets_a_finite_normal() {
    // A cube whose bottom diagonal is split on one side (triangle [0, 2, 1] into two at the
    // diagonal's midpoint), the T-junction closed by a triangle with its three corners on the
    // diagonal, as a third-party pelvis's mesh has them.
    let soup = crate::geometry::shapes::box_soup([0.2, 0.2, 0.2]);
    let mut vertices = soup.vertices.clone();
    let middle = vertices.len() as u32;
    vertices.push(Point3::from(
        (vertices[1].coords + vertices[2].coords) / 2.0,
    ));
    let mut triangles: Vec<[u32; 3]> = soup
        .triangles
        .iter()
        .copied()
        .filter(|t| *t != [0, 2, 1])
        .collect();
    triangles.extend([[0, 2, middle], [0, middle, 1], [2, 1, middle]]);
    let mesh = Mesh::new(&vertices, &triangles).unwrap();
    assert!(mesh.is_watertight(), "{:?}", mesh.notes());
    for triangle in 0..mesh.num_triangles() as u32 {
        let normal = mesh.triangle_normal(triangle);
        assert!(
            normal.iter().all(|c| c.is_finite()) && (normal.norm() - 1.0).abs() < 1e-12,
            "triangle {triangle}: {normal}"
        );
    }
    // Below and above the split diagonal: the bottom face's normal, the distance signed.
    for (z, signed) in [(-0.15, 0.05), (-0.08, -0.02)] {
        let found = mesh.closest_point(&Point3::new(0.01, 0.01, z));
        assert!(found.normal.iter().all(|c| c.is_finite()), "{found:?}");
        assert!((found.signed_distance - signed).abs() < 1e-9, "{found:?}");
    }
}

/// The corners and triangles of an axis-aligned box `size_m` wide centred on `centre`.
fn box_at(centre: Vector3<f64>, size_m: f64) -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
    let cube = Mesh::cuboid([size_m; 3]).unwrap();
    let vertices = cube.vertices().map(|v| v + centre).collect();
    (vertices, cube.triangles().to_vec())
}

/// Two 0.2 m boxes overlapping by half along x, the second without its first
/// `second_triangles_left_out` triangles (0: both closed).
fn overlapping_boxes(second_triangles_left_out: usize) -> Mesh {
    let (mut vertices, mut triangles) = box_at(Vector3::zeros(), 0.2);
    let (second, second_triangles) = box_at(Vector3::new(0.1, 0.0, 0.0), 0.2);
    let offset = vertices.len() as u32;
    vertices.extend(second);
    triangles.extend(
        second_triangles[second_triangles_left_out..]
            .iter()
            .map(|t| t.map(|i| i + offset)),
    );
    Mesh::new(&vertices, &triangles).unwrap()
}

/// Asserts `mesh`'s inside test (deeper than 1 cm) at each query.
fn assert_inside_1cm(mesh: &Mesh, cases: &[(Point3<f64>, bool)]) {
    for (query, inside) in cases {
        let closest = mesh.closest_point(query);
        assert_eq!(
            mesh.is_inside_deeper_than(query, &closest, 0.01),
            *inside,
            "{query}"
        );
    }
}

#[test]
fn an_open_mesh_is_inside_where_most_of_its_rays_leave_it() {
    let (vertices, triangles) = box_at(Vector3::zeros(), 0.2);
    let closed = Mesh::new(&vertices, &triangles).unwrap();
    // Half of the top face gone: the rays up from under the opening leave through nothing.
    let open = Mesh::new(&vertices, &[&triangles[..2], &triangles[3..]].concat()).unwrap();
    assert!(!open.is_watertight());
    let depth_m = 0.01;
    for (query, inside) in [
        (Point3::new(0.0, 0.0, 0.0), true),
        (Point3::new(0.05, 0.05, 0.05), true),
        (Point3::new(-0.05, 0.05, 0.05), true),
        (Point3::new(0.0, 0.0, 0.095), false), // inside, but nearer than `depth_m`
        (Point3::new(0.0, 0.0, 0.15), false),
        (Point3::new(0.3, -0.2, 0.0), false),
    ] {
        for mesh in [&closed, &open] {
            let closest = mesh.closest_point(&query);
            assert_eq!(
                mesh.is_inside_deeper_than(&query, &closest, depth_m),
                inside,
                "{query} in the {} box",
                if mesh.is_watertight() {
                    "closed"
                } else {
                    "open"
                }
            );
        }
    }
}

#[test]
fn a_point_inside_two_overlapping_bodies_is_inside_and_a_sheet_has_no_inside() {
    // Two boxes overlapping by half, one of them open: a ray from their common part leaves
    // both (parity along it would call the point outside).
    let overlapping = overlapping_boxes(1);
    assert!(!overlapping.is_watertight());
    assert_inside_1cm(
        &overlapping,
        &[
            (Point3::new(0.05, 0.0, 0.0), true),
            (Point3::new(-0.05, 0.0, 0.0), true),
            (Point3::new(0.15, 0.02, -0.03), true),
            (Point3::new(0.05, 0.0, 0.2), false),
        ],
    );
    let sheet = Mesh::new(
        &[
            Point3::new(-0.1, -0.1, 0.0),
            Point3::new(0.1, -0.1, 0.01),
            Point3::new(0.1, 0.1, 0.0),
            Point3::new(-0.1, 0.1, 0.02),
        ],
        &[[0, 1, 2], [0, 2, 3]],
    )
    .unwrap();
    for z in [-0.05, 0.05] {
        let query = Point3::new(0.01, -0.02, z);
        let closest = sheet.closest_point(&query);
        assert!(!sheet.is_inside_deeper_than(&query, &closest, 0.01), "{z}");
    }
}

#[test]
fn a_box_missing_two_faces_is_inside_and_a_channel_is_not() {
    // From the centre of a box each face subtends a sixth of the sphere: with two faces gone
    // the exact winding number there is 2/3 (inside), with three gone 1/2 (a channel, no
    // inside). Four of the six rays from the centre cross the first, three the second.
    let (vertices, triangles) = box_at(Vector3::zeros(), 0.2);
    let without = |faces: &[usize]| {
        let kept: Vec<[u32; 3]> = triangles
            .iter()
            .enumerate()
            .filter(|(index, _)| !faces.contains(&(index / 2)))
            .map(|(_, triangle)| *triangle)
            .collect();
        Mesh::new(&vertices, &kept).unwrap()
    };
    // Faces of `Mesh::cuboid`: z-, z+, y-, y+, x-, x+.
    let two_gone = without(&[1, 5]);
    let channel = without(&[1, 2, 3]);
    let centre = Point3::origin();
    for (mesh, inside) in [(&two_gone, true), (&channel, false)] {
        assert!(!mesh.is_watertight());
        assert_inside_1cm(mesh, &[(centre, inside)]);
    }
}

#[test]
fn a_point_where_two_closed_bodies_overlap_is_inside_though_its_closest_face_says_outside() {
    let two_bodies = overlapping_boxes(0);
    assert!(two_bodies.is_watertight());
    assert_eq!(two_bodies.bodies(), 2);
    assert_eq!(Mesh::cuboid([0.2; 3]).unwrap().bodies(), 1);
    // In the first box, 3 cm in front of the second box's face at x = 0: that face is the
    // closest feature and says outside.
    let query = Point3::new(-0.03, 0.0, 0.0);
    let closest = two_bodies.closest_point(&query);
    assert!(closest.signed_distance > 0.0);
    assert_inside_1cm(
        &two_bodies,
        &[
            (query, true),
            (Point3::new(0.05, 0.0, 0.0), true),
            (Point3::new(0.17, 0.0, 0.0), true),
            (Point3::new(0.05, 0.0, 0.15), false),
            (Point3::new(-0.2, 0.0, 0.0), false),
        ],
    );
}
