//! The local stage's precision on scans of real CAD: from the true pose itself, with the search
//! band of the schedule's end (1 cm), where does ips settle? On the shipped xArm7 and SO-ARM100
//! links, scanned with the floor and a box beside them, the schedule alone ended over 1 mm off in
//! about a fifth of the scans (the floor and the mixed pixels at the silhouettes pull it); the
//! polishing run in a band fitted to the residuals' spread is what brings them under.
#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use align_core::registration::convergence::pose_distance;
use align_core::registration::pca::{PcaOptions, align_cloud};
use cad_scans::scanner::ScanNoise;
use cad_scans::scenes::{make_scene, shipped_parts};

/// Scenes per shipped part.
const SEEDS: std::ops::Range<u64> = 1..4;

/// The pose error (the thesis's distance, r = the part's radius) of a local alignment from the
/// truth of each scene, mm.
fn errors_from_truth(polish: bool) -> Vec<(String, f64)> {
    let options = PcaOptions {
        starts: 0,
        polish,
        ..PcaOptions::default()
    };
    let mut errors = Vec::new();
    for part in shipped_parts().unwrap() {
        for seed in SEEDS {
            let scene = make_scene(&part, seed, &ScanNoise::default()).unwrap();
            let truth = scene.world_from_part;
            let result = align_cloud(&part.mesh, &scene.cloud(), &truth, 0.01, &options).unwrap();
            let error_m = pose_distance(
                &result.alignment.base_from_part,
                &truth,
                part.mesh.radius_m(),
            );
            errors.push((format!("{} seed {seed}", part.name), error_m * 1e3));
        }
    }
    errors
}

fn within_1_mm(errors: &[(String, f64)]) -> usize {
    errors.iter().filter(|(_, e)| *e < 1.0).count()
}

#[test]
fn from_the_truth_the_polished_local_stage_stays_within_a_millimetre() {
    let polished = errors_from_truth(true);
    let schedule_only = errors_from_truth(false);
    let report = format!("polished {polished:.2?}\nschedule only {schedule_only:.2?}");
    // Measured when written: every scene under 1 mm polished.
    assert_eq!(within_1_mm(&polished), polished.len(), "{report}");
    // What the test guards: the schedule alone does not get there on these scans.
    assert!(
        within_1_mm(&schedule_only) < polished.len(),
        "the schedule alone is within 1 mm everywhere: this test no longer shows the polish's effect\n{report}"
    );
    let mean =
        |errors: &[(String, f64)]| errors.iter().map(|(_, e)| e).sum::<f64>() / errors.len() as f64;
    assert!(mean(&polished) < 0.5 * mean(&schedule_only), "{report}");
}
