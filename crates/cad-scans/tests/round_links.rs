//! A round link lying on the floor, a few millimetres off its truth at the start: the local
//! stage's wide bands must not pull it into the floor or spin it about its axis. On the TIAGo
//! Pro's arm links (the unseen set A of docs/cad-scan-trials.md) a start 3 mm off ended 228 mm
//! off before the wide bands' scan-to-model half left the floor out and their steps left the
//! directions their matches barely constrain alone. The part here is made, not fetched: a
//! capsule, finely tessellated (so that no floor point's nearest feature is an edge the edge
//! rejection drops), with a boss on its side that fixes its spin.
#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use align_core::geometry::shapes::{box_soup, capsule_soup};
use align_core::registration::convergence::pose_distance;
use align_core::registration::pca::{PcaOptions, align_cloud};
use align_core::trials::{TrialRng, random_displacement};
use cad_scans::scanner::ScanNoise;
use cad_scans::scenes::{Part, Posture, make_scene};
use nalgebra::Vector3;

/// A capsule 70 mm across and 300 mm long (a 230 mm cylinder between its caps) along z, a 30 x 20 x 40 mm boss on its side.
fn round_link() -> Part {
    let mut soup = capsule_soup(0.035, 0.23);
    let boss = box_soup([0.03, 0.02, 0.04]);
    let offset = soup.vertices.len() as u32;
    soup.vertices.extend(
        boss.vertices
            .iter()
            .map(|v| v + Vector3::new(0.04, 0.0, 0.05)),
    );
    soup.triangles
        .extend(boss.triangles.iter().map(|t| t.map(|i| i + offset)));
    Part::from_soup("round link", soup).unwrap()
}

/// The pose errors (mm) of local alignments from starts up to `delta_m` off, on the scenes
/// that lay the link down.
fn errors(options: &PcaOptions, delta_m: f64) -> Vec<f64> {
    let part = round_link();
    let radius_m = part.mesh.radius_m();
    let mut errors = Vec::new();
    for seed in 1..=16 {
        let scene = make_scene(&part, seed, &ScanNoise::default()).unwrap();
        if scene.posture != Posture::Lying {
            continue;
        }
        let mut rng = TrialRng::new(seed);
        let start = scene.world_from_part * random_displacement(&mut rng, delta_m, radius_m);
        let result = align_cloud(&part.mesh, &scene.cloud(), &start, delta_m, options);
        let error_m = result.map_or(f64::INFINITY, |r| {
            pose_distance(
                &r.alignment.base_from_part,
                &scene.world_from_part,
                radius_m,
            )
        });
        errors.push(error_m * 1e3);
    }
    errors
}

#[test]
fn a_round_link_lying_on_the_floor_is_not_pulled_into_it_by_the_wide_bands() {
    let local = PcaOptions {
        starts: 0,
        ..PcaOptions::default()
    };
    let every_keypoint_every_direction = PcaOptions {
        wide_band_without_planes: false,
        wide_band_skips_weak_directions: false,
        ..local.clone()
    };
    let within_1_mm = |errors: &[f64]| errors.iter().filter(|e| **e < 1.0).count();
    let mut report = String::new();
    let (mut now_total, mut before_total) = (0, 0);
    // Measured when written, of the 8 scenes that lay it down: 7 and 5 now (the miss at 50 mm
    // ends 10 mm off, as it does from 10 mm: its boss is hidden, so nothing fixes the spin),
    // 6 and 3 with every keypoint and every direction (48-184 mm off).
    for (delta_m, floor) in [(0.05, 7), (0.1, 5)] {
        let now = errors(&local, delta_m);
        let before = errors(&every_keypoint_every_direction, delta_m);
        report += &format!("delta {delta_m} m: now {now:.2?}, before {before:.2?}\n");
        assert!(within_1_mm(&now) >= floor, "{report}");
        now_total += within_1_mm(&now);
        before_total += within_1_mm(&before);
    }
    assert!(
        before_total < now_total,
        "the wide bands' settings no longer make a difference here\n{report}"
    );
}
