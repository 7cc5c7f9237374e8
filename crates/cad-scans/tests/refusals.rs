//! What ips says about scans it cannot align uniquely: a symmetric part, and clouds that cannot
//! fix a pose (all in a plane, on a line, or too few points near the part). The alignment is
//! the one `ips align-cloud` runs (`align_service::jobs::cloud::align`).
#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::path::PathBuf;

use align_core::geometry::shapes::{box_soup, cylinder_soup};
use align_core::io::write_stl_binary;
use align_core::rng::SplitMix64;
use align_service::jobs::cloud::{CloudAlignment, align, cloud_options};
use cad_scans::files::write_ply;
use cad_scans::scanner::ScanNoise;
use cad_scans::scenes::Part;
use cad_scans::trials::{CorpusOptions, Outcome, prepare_trial, run_ips};
use nalgebra::{Isometry3, Point3, Vector3};

fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("cad-scans-{name}"));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn options(name: &str) -> CorpusOptions {
    CorpusOptions {
        deltas_m: vec![0.05],
        scans_per_delta: 1,
        seed: 20,
        noise: ScanNoise::default(),
        out_dir: scratch(name),
    }
}

#[test]
fn a_cylinder_spun_about_its_axis_fits_the_scan_as_well_and_ips_says_ambiguous() {
    // A plain cylinder, 80 mm across and 250 mm long: every turn about its axis is the same
    // surface, so no scan can fix that angle.
    let part = Part::from_soup("cylinder", cylinder_soup(0.04, 0.25)).unwrap();
    let options = options("cylinder");
    let mut ambiguous = 0;
    for seed in [1, 2, 3] {
        let trial = prepare_trial(seed as usize, &part, seed, 0.05, &options).unwrap();
        let outcome: Outcome = run_ips(&trial, false);
        assert!(outcome.refused.is_none(), "{:?}", outcome.refused);
        ambiguous += usize::from(outcome.ambiguous);
    }
    assert_eq!(ambiguous, 3, "a symmetric part reported unique");
}

/// The mesh of a 100 mm cube at the origin, written for the alignment job.
fn cube_job(name: &str, cloud: &[Point3<f64>]) -> CloudAlignment {
    let dir = scratch(name);
    let mesh = dir.join("cube.stl");
    write_stl_binary(&mesh, &box_soup([0.1; 3])).unwrap();
    let cloud_path = dir.join("cloud.ply");
    write_ply(&cloud_path, cloud).unwrap();
    CloudAlignment {
        cloud: cloud_path,
        cloud_scale: 1.0,
        mesh,
        mesh_scale: 1.0,
        base_from_part_start: Isometry3::translation(0.003, -0.002, 0.001),
        delta_m: 0.05,
        options: cloud_options(false, None, false),
    }
}

fn refusal(job: &CloudAlignment) -> String {
    match align(job) {
        Ok(report) => panic!("aligned: {:?}", report.alignment.pose),
        Err(error) => error.0,
    }
}

#[test]
fn a_scan_of_one_face_is_refused_naming_the_plane_and_the_free_motions() {
    // The cube's top face only (z = 0.05), 2 mm grid with 0.3 mm noise.
    let mut rng = SplitMix64::new(7);
    let cloud: Vec<Point3<f64>> = (0..50)
        .flat_map(|i| (0..50).map(move |j| (i, j)))
        .map(|(i, j)| {
            Point3::new(
                -0.049 + 0.002 * f64::from(i),
                -0.049 + 0.002 * f64::from(j),
                0.05,
            )
        })
        .map(|p| p + Vector3::z() * 3e-4 * rng.gaussian())
        .collect();
    let reason = refusal(&cube_job("plane", &cloud));
    assert!(reason.contains("lie in one plane"), "{reason}");
    assert!(reason.contains("unconstrained"), "{reason}");
}

#[test]
fn a_scan_of_one_edge_is_refused_naming_the_line() {
    let cloud: Vec<Point3<f64>> = (0..100)
        .map(|i| Point3::new(-0.05 + 0.001 * f64::from(i), 0.05, 0.05))
        .collect();
    let reason = refusal(&cube_job("line", &cloud));
    assert!(reason.contains("lie on a line"), "{reason}");
}

#[test]
fn a_scan_with_too_few_points_near_the_part_is_refused_with_the_count() {
    let cloud = vec![
        Point3::new(0.05, 0.0, 0.0),
        Point3::new(0.0, 0.05, 0.0),
        Point3::new(0.0, 0.0, 0.05),
        // Far from the part: outside the cut-off box.
        Point3::new(2.0, 2.0, 2.0),
    ];
    let reason = refusal(&cube_job("few", &cloud));
    assert!(reason.contains("only 3 cloud points"), "{reason}");
}
