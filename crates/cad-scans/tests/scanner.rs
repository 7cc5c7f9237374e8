//! The scanner sees what a real one sees: only the first surface along each ray, mixed pixels
//! where the depth jumps, and the outliers it is set up for.
#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use align_core::geometry::shapes::box_soup;
use align_core::rng::SplitMix64;
use cad_scans::scanner::{
    Origin, ScanNoise, ScanPoint, Scanner, SceneMesh, SceneObject, Surface, scan,
};
use nalgebra::{Point3, Vector3};

fn cube(surface: Surface, centre: Vector3<f64>, side_m: f64) -> SceneObject {
    let soup = box_soup([side_m; 3]);
    SceneObject {
        surface,
        vertices: soup.vertices.iter().map(|v| v + centre).collect(),
        triangles: soup.triangles,
    }
}

fn floor() -> SceneObject {
    let h = 3.0;
    SceneObject {
        surface: Surface::Floor,
        vertices: [(-h, -h), (h, -h), (h, h), (-h, h)]
            .map(|(x, y)| Point3::new(x, y, 0.0))
            .to_vec(),
        triangles: vec![[0, 1, 2], [0, 2, 3]],
    }
}

/// Pure geometry: no noise, no mixed pixels, no outliers.
fn exact() -> ScanNoise {
    ScanNoise {
        range_sigma_m: 0.0,
        mixed_pixel_chance: 0.0,
        outlier_fraction: 0.0,
        ..ScanNoise::default()
    }
}

fn scanner_at(origin: Point3<f64>, target: Point3<f64>) -> Scanner {
    // 5 mm spacing at 1.5 m.
    Scanner::aimed(origin, target, 0.25, 0.005 / 1.5, 10.0)
}

fn count(points: &[ScanPoint], origin: Origin) -> usize {
    points.iter().filter(|p| p.origin == origin).count()
}

#[test]
fn a_part_behind_an_occluder_returns_no_points_and_returns_them_once_the_occluder_goes() {
    let part = cube(Surface::Part, Vector3::new(0.0, 0.0, 0.1), 0.2);
    let wall = cube(Surface::Clutter, Vector3::new(0.6, 0.0, 0.1), 0.5);
    let scanner = scanner_at(Point3::new(1.5, 0.0, 0.1), Point3::new(0.0, 0.0, 0.1));
    let hidden = SceneMesh::new(&[part.clone(), wall, floor()]).unwrap();
    let points = scan(&hidden, &scanner, &exact(), &mut SplitMix64::new(1));
    assert!(count(&points, Origin::Surface(Surface::Clutter)) > 1000);
    assert_eq!(count(&points, Origin::Surface(Surface::Part)), 0);

    let open = SceneMesh::new(&[part, floor()]).unwrap();
    let points = scan(&open, &scanner, &exact(), &mut SplitMix64::new(1));
    // The 0.2 m face at 5 mm spacing: about 40 x 40 rays.
    assert!(count(&points, Origin::Surface(Surface::Part)) > 1000);
}

#[test]
fn only_the_faces_turned_to_the_scanner_are_seen() {
    let part = cube(Surface::Part, Vector3::new(0.0, 0.0, 0.1), 0.2);
    // From +x, above: the +x face and the top are seen, the -x, +y, -y faces are not.
    let scanner = scanner_at(Point3::new(1.2, 0.0, 0.9), Point3::new(0.0, 0.0, 0.1));
    let scene = SceneMesh::new(&[part, floor()]).unwrap();
    let points = scan(&scene, &scanner, &exact(), &mut SplitMix64::new(2));
    let on_part: Vec<_> = points
        .iter()
        .filter(|p| p.origin == Origin::Surface(Surface::Part))
        .map(|p| p.point)
        .collect();
    let near = |a: f64, b: f64| (a - b).abs() < 1e-6;
    let front = on_part.iter().filter(|p| near(p.x, 0.1)).count();
    let top = on_part.iter().filter(|p| near(p.z, 0.2)).count();
    assert!(front > 300 && top > 300, "front {front}, top {top}");
    assert_eq!(front + top, on_part.len(), "a point on a hidden face");
    // The floor behind the cube, as seen from the scanner, is in its shadow.
    let shadowed = points
        .iter()
        .filter(|p| p.origin == Origin::Surface(Surface::Floor))
        .filter(|p| p.point.x < -0.1 && p.point.x > -0.3 && p.point.y.abs() < 0.05)
        .count();
    assert_eq!(shadowed, 0);
}

#[test]
fn mixed_pixels_appear_at_depth_edges_between_the_surfaces_and_nowhere_else() {
    let noise = ScanNoise {
        range_sigma_m: 0.0,
        outlier_fraction: 0.0,
        ..ScanNoise::default()
    };
    let scanner = scanner_at(Point3::new(1.2, 0.3, 0.9), Point3::new(0.0, 0.0, 0.1));
    let flat = SceneMesh::new(&[floor()]).unwrap();
    let points = scan(&flat, &scanner, &noise, &mut SplitMix64::new(3));
    assert_eq!(
        count(&points, Origin::MixedPixel),
        0,
        "a floor has no depth edge"
    );

    let part = cube(Surface::Part, Vector3::new(0.0, 0.0, 0.1), 0.2);
    let scene = SceneMesh::new(&[part.clone(), floor()]).unwrap();
    let points = scan(&scene, &scanner, &noise, &mut SplitMix64::new(3));
    let mixed: Vec<Point3<f64>> = points
        .iter()
        .filter(|p| p.origin == Origin::MixedPixel)
        .map(|p| p.point)
        .collect();
    // The cube's silhouette is about 4 x 40 edge pixels long, half of them mixed.
    assert!(mixed.len() > 40, "{} mixed pixels", mixed.len());
    let origin = scanner.origin();
    for point in &mixed {
        // Behind the first surface on its own ray (the foreground), short of the floor behind
        // it (the background): between the two, as the sensor's averaged range puts it.
        let along = point - origin;
        let first = scene
            .first_hit(&origin, &along.normalize(), 10.0)
            .unwrap()
            .0;
        assert!(
            along.norm() > first + 2e-3,
            "{point}: {} vs {first}",
            along.norm()
        );
        assert!(point.z > 1e-3, "{point}");
        // Near the cube's silhouette, not anywhere in the view.
        assert!(
            (point.coords - Vector3::new(0.0, 0.0, 0.1)).norm() < 0.5,
            "{point}"
        );
    }
}

#[test]
fn outliers_mixed_pixels_included_make_up_the_fraction_asked_for() {
    let part = cube(Surface::Part, Vector3::new(0.0, 0.0, 0.1), 0.2);
    let scene = SceneMesh::new(&[part, floor()]).unwrap();
    let scanner = scanner_at(Point3::new(1.2, 0.3, 0.9), Point3::new(0.0, 0.0, 0.1));
    let points = scan(
        &scene,
        &scanner,
        &ScanNoise::default(),
        &mut SplitMix64::new(4),
    );
    let bad = count(&points, Origin::MixedPixel) + count(&points, Origin::Outlier);
    let fraction = bad as f64 / points.len() as f64;
    assert!((fraction - 0.1).abs() < 0.005, "{fraction}");
}

#[test]
fn range_noise_lies_along_the_ray() {
    let noise = ScanNoise {
        mixed_pixel_chance: 0.0,
        outlier_fraction: 0.0,
        ..ScanNoise::default()
    };
    let scanner = scanner_at(Point3::new(1.2, 0.3, 0.9), Point3::new(0.0, 0.0, 0.0));
    let scene = SceneMesh::new(&[floor()]).unwrap();
    let points = scan(&scene, &scanner, &noise, &mut SplitMix64::new(5));
    // Off a floor along a ray that meets it at elevation e, a range error r moves the point
    // r sin(e) off the plane: the spread off the plane is below 0.5 mm but well above zero.
    let rms =
        (points.iter().map(|p| p.point.z * p.point.z).sum::<f64>() / points.len() as f64).sqrt();
    assert!(rms > 1e-4 && rms < 5e-4, "{rms}");
}
