//! Degenerate geometry and unit mistakes get clear errors or warnings, never a panic or a
//! confident wrong answer: meshes without a surface are refused at `Mesh::new`, flat meshes and
//! implausible sizes are noted, and Point Cloud Alignment refuses clouds that cannot fix a pose.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use align_core::geometry::shapes::extrude;
use align_core::geometry::{Mesh, MeshError};
use align_core::registration::pca::{PcaError, PcaOptions, align_cloud};
use align_core::registration::psa::{PsaOptions, PsaTarget, Touch, align_touches};
use align_core::trials::clouds::{ScanOptions, scan_part};
use nalgebra::{Isometry3, Point3, Vector3};

/// A mesh from triangles given by their corners, as an STL stores them (every corner repeated).
fn soup(triangles: &[[[f64; 3]; 3]]) -> Result<Mesh, MeshError> {
    let vertices: Vec<Point3<f64>> = triangles
        .iter()
        .flatten()
        .map(|&[x, y, z]| Point3::new(x, y, z))
        .collect();
    let indices: Vec<[u32; 3]> = (0..triangles.len() as u32)
        .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
        .collect();
    Mesh::new(&vertices, &indices)
}

fn step_block() -> Mesh {
    let outline = [
        [0.0, 0.0],
        [0.2, 0.0],
        [0.2, 0.06],
        [0.14, 0.06],
        [0.14, 0.1],
        [0.0, 0.1],
    ];
    extrude(&outline, 0.15).unwrap()
}

#[test]
fn twelve_collinear_triangles_are_refused_naming_the_free_motion() {
    // The fault test's part: it used to panic in the PSA code.
    let error = soup(&[[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]]; 12]).unwrap_err();
    assert!(matches!(error, MeshError::Collinear { .. }), "{error:?}");
    let message = error.to_string();
    assert!(
        message.contains("zero area") && message.contains("rotation about that line"),
        "{message}"
    );
    // Scaled to mm, as the session reads it: still refused.
    let error = soup(
        &[[
            [0.0, 0.0, 0.0],
            [0.001, 0.001, 0.001],
            [0.002, 0.002, 0.002],
        ]; 12],
    )
    .unwrap_err();
    assert!(matches!(error, MeshError::Collinear { .. }), "{error:?}");
}

#[test]
fn a_single_point_repeated_is_refused() {
    let point = [5.0, 5.0, 5.0];
    let error = soup(&[[point, point, point]; 12]).unwrap_err();
    assert_eq!(error, MeshError::AllDegenerate);
}

#[test]
fn a_single_triangle_and_a_flat_plate_are_noted_with_the_free_motion() {
    let triangle = soup(&[[[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]]]).unwrap();
    let plate = soup(&[
        [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.1, 0.05, 0.0]],
        [[0.0, 0.0, 0.0], [0.1, 0.05, 0.0], [0.0, 0.05, 0.0]],
    ])
    .unwrap();
    for mesh in [triangle, plate] {
        let flat = mesh
            .notes()
            .iter()
            .find(|note| note.contains("flat"))
            .unwrap_or_else(|| panic!("{:?}", mesh.notes()));
        assert!(
            flat.contains("normal (0.000, 0.000, 1.000)")
                && flat.contains("translation within the plane")
                && flat.contains("rotation about its normal"),
            "{flat}"
        );
    }
    // A solid part is not flat.
    assert!(!step_block().notes().iter().any(|n| n.contains("flat")));
}

#[test]
fn psa_on_a_flat_plate_returns_without_panicking() {
    let plate = soup(&[
        [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.1, 0.05, 0.0]],
        [[0.0, 0.0, 0.0], [0.1, 0.05, 0.0], [0.0, 0.05, 0.0]],
    ])
    .unwrap();
    let target = PsaTarget::new(&plate);
    let touches: Vec<Touch> = [[0.02, 0.01], [0.08, 0.01], [0.05, 0.04]]
        .iter()
        .enumerate()
        .map(|(i, &[x, y])| Touch {
            id: format!("t{i}"),
            point: Point3::new(x, y, 0.0),
            approach: Some(-Vector3::z()),
            face: None,
        })
        .collect();
    let options = PsaOptions {
        tip_radius_m: 0.0,
        ..PsaOptions::default()
    };
    // Either an alignment or an error naming the free motion: no panic.
    if let Err(error) = align_touches(&target, &touches, &Isometry3::identity(), &options) {
        assert!(!error.to_string().is_empty());
    }
}

#[test]
fn implausible_part_sizes_are_noted_with_the_likely_unit() {
    // A 300 mm block read with a scale of 1000 instead of 0.001: 300 km.
    let km = Mesh::cuboid([300e3, 200e3, 100e3]).unwrap();
    let generic = km.notes().iter().find(|n| n.contains("km across")).unwrap();
    assert!(generic.contains("over 10 m"), "{generic}");
    let notes = km.notes_with_unit_scale(1000.0);
    let named = notes.iter().find(|n| n.contains("km across")).unwrap();
    assert!(
        named.contains("in mm, its scale is 0.001, not 1000"),
        "{named}"
    );
    // A 300 mm block in m read as mm: 0.3 mm.
    let tiny = Mesh::cuboid([0.3e-3, 0.2e-3, 0.1e-3]).unwrap();
    let notes = tiny.notes_with_unit_scale(0.001);
    let named = notes.iter().find(|n| n.contains("under 1 mm")).unwrap();
    assert!(named.contains("in m, its scale is 1, not 0.001"), "{named}");
    // A plausible part has no size note.
    assert!(step_block().notes_with_unit_scale(0.001).is_empty());
}

#[test]
fn a_collinear_cloud_is_refused_naming_the_free_motion() {
    let mesh = step_block();
    let line: Vec<Point3<f64>> = (0..2000)
        .map(|i| Point3::new(-0.05 + 0.0001 * i as f64, 0.05, 0.15))
        .collect();
    let error = align_cloud(
        &mesh,
        &line,
        &Isometry3::identity(),
        0.1,
        &PcaOptions::default(),
    )
    .unwrap_err();
    assert!(matches!(error, PcaError::Collinear { .. }), "{error:?}");
    let message = error.to_string();
    assert!(
        message.contains("along (1.000, 0.000, 0.000)")
            && message.contains("rotation about that line and the translation along it"),
        "{message}"
    );
}

#[test]
fn a_planar_cloud_with_scanner_noise_is_refused_naming_the_free_motion() {
    let mesh = step_block();
    // The top face seen alone, with +-0.5 mm of deterministic noise off the plane.
    let top: Vec<Point3<f64>> = (0..40)
        .flat_map(|i| (0..20).map(move |j| (i, j)))
        .map(|(i, j)| {
            let noise_m = 0.0005 * (((i * 7 + j * 13) % 11) as f64 / 5.0 - 1.0);
            Point3::new(0.005 * i as f64, 0.005 * j as f64, 0.15 + noise_m)
        })
        .collect();
    let error = align_cloud(
        &mesh,
        &top,
        &Isometry3::identity(),
        0.1,
        &PcaOptions::default(),
    )
    .unwrap_err();
    let PcaError::Planar { nz, .. } = error else {
        panic!("{error:?}");
    };
    assert!(
        nz.abs() > 0.999,
        "the plane's normal is the top face's: {error}"
    );
    let message = error.to_string();
    assert!(
        message.contains("translation within that plane and the rotation about its normal"),
        "{message}"
    );
}

#[test]
fn a_scan_of_several_faces_is_not_refused() {
    let mesh = step_block();
    let truth = Isometry3::new(Vector3::new(0.7, -0.1, 0.0), Vector3::new(0.0, 0.0, 0.5));
    let scan = ScanOptions {
        scanners: vec![Point3::new(1.5, -1.0, 1.0)],
        ..ScanOptions::default()
    };
    let cloud = scan_part(&mesh, &truth, &scan);
    let result = align_cloud(&mesh, &cloud, &truth, 0.05, &PcaOptions::default()).unwrap();
    assert!(result.alignment.rms_m < 1e-6);
}
