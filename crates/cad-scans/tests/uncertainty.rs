//! The cloud alignment's reported uncertainty on scans of real CAD (the shipped xArm7 and
//! SO-ARM100 links, scanned with the floor, a box beside them, mixed pixels and clutter): from
//! the true pose, does the truth lie in the pose's 95 % region, and does the report say the
//! scan fixes the pose to under a millimetre? The noise factor was calibrated on the unseen set A
//! (docs/cad-scan-trials.md), not on these parts.
#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use align_core::registration::convergence::pose_distance;
use align_core::registration::pca::{PcaOptions, align_cloud};
use align_core::registration::uncertainty::{CHI2_95_6DOF, pose_deviation};
use cad_scans::scanner::ScanNoise;
use cad_scans::scenes::{make_scene, shipped_parts};

#[test]
fn from_the_truth_the_truth_lies_in_the_reported_region_and_the_arm_links_are_fixed_under_a_millimetre()
 {
    let options = PcaOptions {
        starts: 0,
        ..PcaOptions::default()
    };
    let (mut scenes, mut inside, mut within_bound) = (0, 0, 0);
    let mut report = String::new();
    for part in shipped_parts().unwrap() {
        for seed in 1..4 {
            let scene = make_scene(&part, seed, &ScanNoise::default()).unwrap();
            let truth = scene.world_from_part;
            let result = align_cloud(&part.mesh, &scene.cloud(), &truth, 0.01, &options).unwrap();
            let found = result.uncertainty.unwrap();
            let pose = result.alignment.base_from_part;
            let squared = found
                .mahalanobis_squared(&pose_deviation(&truth, &pose))
                .unwrap();
            let error_m = pose_distance(&pose, &truth, part.mesh.radius_m());
            report += &format!(
                "{} seed {seed}: squared distance {squared:.1}, error {:.3} mm, 95% within {:.3} mm, noise {:.3} mm; {}\n",
                part.name,
                error_m * 1e3,
                found.pose_distance_95_m * 1e3,
                found.sigma_m * 1e3,
                found.weak_direction.describe()
            );
            scenes += 1;
            inside += usize::from(squared <= CHI2_95_6DOF);
            within_bound += usize::from(error_m <= found.pose_distance_95_m);
            // The xArm7's base is round: lying on the floor its turn about its axis is held by
            // little (measured when written: 1.2-1.3 mm at two of three seeds). The links are
            // not.
            if !part.name.contains("base") {
                assert!(found.pose_distance_95_m < 1e-3, "{report}");
            }
        }
    }
    // Measured when written: all 15 inside and within the bound.
    assert!(
        inside + 2 >= scenes,
        "{inside} of {scenes} inside\n{report}"
    );
    assert!(
        within_bound + 2 >= scenes,
        "{within_bound} of {scenes} within the bound\n{report}"
    );
}
