//! Point Cloud Alignment: exact recovery on noiseless scans, error consistent with the noise,
//! robustness to clutter and outliers, and clear refusals.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use align_core::geometry::Mesh;
use align_core::geometry::shapes::extrude;
use align_core::registration::articulated::RobotFitOptions;
use align_core::registration::pca::{
    DeltaSchedule, PcaOptions, PcaStep, WideBandMatching, align_cloud, pose_candidates_spread,
};
use align_core::trials::clouds::{ScanOptions, pca_trial_scan, scan_part};
use align_core::trials::{TrialRng, displace_about_centroid, random_displacement};
use nalgebra::{Isometry3, Point3};

/// A 200 x 100 x 150 mm block with a step cut from one corner: no symmetry.
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

fn truth() -> Isometry3<f64> {
    Isometry3::new(
        nalgebra::Vector3::new(0.7, -0.1, 0.0),
        nalgebra::Vector3::new(0.0, 0.0, 0.5),
    )
}

/// A scan with 0.3 mm noise, 10% outliers, the floor and a neighbouring box, from three
/// scanners.
fn cluttered_scan(mesh: &Mesh, truth: &Isometry3<f64>) -> Vec<Point3<f64>> {
    let scan = ScanOptions {
        noise_sigma_m: 0.0003,
        outlier_fraction: 0.1,
        floor: true,
        neighbour: true,
        scanners: vec![
            Point3::new(0.0, 0.0, 1.5),
            Point3::new(1.5, -1.0, 1.0),
            Point3::new(1.5, 1.0, 0.8),
        ],
        ..ScanOptions::default()
    };
    scan_part(mesh, truth, &scan)
}

/// `truth` displaced by the thesis's scheme within `delta_m` (seeded), about the part's centroid.
fn displaced_start(mesh: &Mesh, truth: &Isometry3<f64>, seed: u64, delta_m: f64) -> Isometry3<f64> {
    let mut rng = TrialRng::new(seed);
    let displacement = random_displacement(&mut rng, delta_m, mesh.radius_m());
    displace_about_centroid(truth, mesh, &displacement)
}

fn errors(result: &Isometry3<f64>, truth: &Isometry3<f64>) -> (f64, f64) {
    (
        (result.translation.vector - truth.translation.vector).norm(),
        result.rotation.angle_to(&truth.rotation),
    )
}

#[test]
fn noiseless_scans_recover_random_poses_within_200_mm_to_a_micrometre() {
    let mesh = step_block();
    let truth = truth();
    let cloud = scan_part(&mesh, &truth, &ScanOptions::default());
    let mut rng = TrialRng::new(11);
    for trial in 0..24 {
        let delta = [0.05, 0.1, 0.2][trial % 3];
        let start = displace_about_centroid(
            &truth,
            &mesh,
            &random_displacement(&mut rng, delta, mesh.radius_m()),
        );
        let result = align_cloud(&mesh, &cloud, &start, delta, &PcaOptions::default()).unwrap();
        let (position, rotation) = errors(&result.alignment.base_from_part, &truth);
        assert!(
            position < 1e-6 && rotation < 1e-6,
            "trial {trial}, delta {delta}: {position:e} m, {rotation:e} rad after {} iterations",
            result.alignment.iterations
        );
    }
}

/// With isotropic noise sigma on N kept points, a point-to-plane fit has pose errors of order
/// sigma / sqrt(N) scaled by the geometry; with N ~ 5000 and sigma = 0.5 mm that is ~10 um. The
/// bound below, 0.1 mm, is ten times that and still two orders under the 1 mm success threshold.
#[test]
fn pose_error_with_noise_is_of_the_order_the_noise_allows() {
    let mesh = step_block();
    let truth = truth();
    let scan = ScanOptions {
        noise_sigma_m: 0.0005,
        ..ScanOptions::default()
    };
    let cloud = scan_part(&mesh, &truth, &scan);
    let mut rng = TrialRng::new(12);
    for _ in 0..6 {
        let start = displace_about_centroid(
            &truth,
            &mesh,
            &random_displacement(&mut rng, 0.05, mesh.radius_m()),
        );
        let result = align_cloud(&mesh, &cloud, &start, 0.05, &PcaOptions::default()).unwrap();
        let (position, rotation) = errors(&result.alignment.base_from_part, &truth);
        assert!(
            position < 1e-4 && rotation * mesh.radius_m() < 1e-4,
            "{position:e} m, {rotation:e} rad"
        );
        assert!(result.kept > 1000);
    }
}

#[test]
fn clutter_and_ten_percent_outliers_still_align_below_a_millimetre() {
    let mesh = step_block();
    let truth = truth();
    let cloud = cluttered_scan(&mesh, &truth);
    let mut rng = TrialRng::new(13);
    // Ours; the thesis's SVD step is compared on the same kind of scene in docs/pca-trials.md.
    for step in [PcaStep::PointToPlane] {
        for _ in 0..4 {
            let start = displace_about_centroid(
                &truth,
                &mesh,
                &random_displacement(&mut rng, 0.1, mesh.radius_m()),
            );
            let options = PcaOptions {
                step,
                ..PcaOptions::default()
            };
            let result = align_cloud(&mesh, &cloud, &start, 0.1, &options).unwrap();
            let (position, rotation) = errors(&result.alignment.base_from_part, &truth);
            let d = position.hypot(rotation * mesh.radius_m());
            assert!(
                d < 1e-3,
                "{step:?}: pose distance {d:e} m after {} iterations",
                result.alignment.iterations
            );
        }
    }
}

#[test]
fn spread_candidates_find_a_part_three_times_its_radius_from_the_start_among_clutter() {
    let mesh = step_block();
    let truth = truth();
    let cloud = cluttered_scan(&mesh, &truth);
    let mut rng = TrialRng::new(21);
    let bound_m = 0.5;
    for _ in 0..3 {
        // Off by 0.35-0.4 m (the block's radius is about 0.13 m) and turned by up to 0.3 rad.
        let offset = loop {
            let v = nalgebra::Vector3::new(
                rng.uniform() - 0.5,
                rng.uniform() - 0.5,
                rng.uniform() - 0.5,
            );
            if v.norm() > 0.1 {
                break v.normalize() * (0.35 + 0.05 * rng.uniform());
            }
        };
        let turn = nalgebra::Vector3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 0.17;
        let start = Isometry3::new(truth.translation.vector + offset, turn) * truth.rotation;
        // The robot fit's options for its proximal links: the band reaches its floor within the
        // candidates' 40 iterations. (`pose_candidates`, runs from the start in a band this
        // wide, ended 0.2 m off at best on the first of these starts when this was written.)
        let options = PcaOptions {
            voxel_m: 0.015,
            schedule_iterations: 40,
            schedule: DeltaSchedule::Cosine,
            ..PcaOptions::default()
        };
        let candidates = pose_candidates_spread(&mesh, &cloud, &start, bound_m, &options, 4, 0.05);
        assert!(candidates.len() <= 4);
        let best = candidates
            .iter()
            .map(|c| {
                let (position, rotation) = errors(c, &truth);
                position.hypot(rotation * mesh.radius_m())
            })
            .fold(f64::INFINITY, f64::min);
        assert!(
            best < 5e-3,
            "start {:.3} m off: nearest of {} candidates {best:e} m",
            offset.norm(),
            candidates.len()
        );
    }
}

#[test]
fn bad_inputs_are_refused_with_the_reason() {
    let mesh = step_block();
    let truth = truth();
    let options = PcaOptions::default();
    assert_eq!(
        align_cloud(&mesh, &[], &truth, 0.1, &options)
            .unwrap_err()
            .to_string(),
        "the cloud is empty"
    );
    let cloud = vec![Point3::new(0.0, 0.0, 0.0), Point3::new(f64::NAN, 0.0, 0.0)];
    assert_eq!(
        align_cloud(&mesh, &cloud, &truth, 0.1, &options)
            .unwrap_err()
            .to_string(),
        "cloud point 1 is not finite"
    );
    let cloud = scan_part(&mesh, &truth, &ScanOptions::default());
    assert_eq!(
        align_cloud(&mesh, &cloud, &truth, 0.0, &options)
            .unwrap_err()
            .to_string(),
        "delta must be finite and > 0, got 0"
    );
    let far = Isometry3::translation(5.0, 0.0, 0.0) * truth;
    let message = align_cloud(&mesh, &cloud, &far, 0.1, &options)
        .unwrap_err()
        .to_string();
    assert!(
        message.starts_with(
            "only 0 cloud points lie within delta = 0.1 m of the part at the start pose"
        ),
        "{message}"
    );
}

/// The exploration's ends also say how clearly the pose wins: a plain box (half a turn about an
/// axis through its centre gives the same box) is reported ambiguous with a twin as the
/// runner-up and its centre where the truth has it, while the step block, whose step tells every
/// turn apart, is found with a clear margin.
#[test]
fn a_symmetric_part_is_ambiguous_and_an_asymmetric_one_unique() {
    let box_mesh = extrude(&[[0.0, 0.0], [0.2, 0.0], [0.2, 0.1], [0.0, 0.1]], 0.15).unwrap();
    for (name, mesh, expect_ambiguous) in
        [("box", box_mesh, true), ("step block", step_block(), false)]
    {
        let truth = truth();
        let cloud = cluttered_scan(&mesh, &truth);
        // A start off by 200 mm (the thesis's scheme).
        let start = displaced_start(&mesh, &truth, 5, 0.2);
        let result = align_cloud(&mesh, &cloud, &start, 0.2, &PcaOptions::default()).unwrap();
        let found = result.uniqueness.clone().expect("the exploration ran");
        println!(
            "{name}: score {:.0}, runner-up {:.0}, margin {:.3}, ambiguous {}; pose off the truth by {:?}, runner-up by {:?}",
            found.score,
            found.runner_up_score,
            found.margin,
            found.ambiguous,
            errors(&result.alignment.base_from_part, &truth),
            errors(&found.runner_up, &truth)
        );
        assert_eq!(found.ambiguous, expect_ambiguous, "{name}: {found:?}");
        if expect_ambiguous {
            // A twin: the box turned half a turn about an axis through its centre, the same
            // surface to within the scan's noise.
            let (_, turn) = errors(&found.runner_up, &result.alignment.base_from_part);
            assert!(turn > 1.0, "{name}: runner-up only {turn} rad away");
            let (shift, _) = errors(&result.alignment.base_from_part, &truth);
            let twin_shift = (result.alignment.base_from_part * mesh.centroid()
                - truth * mesh.centroid())
            .norm();
            assert!(
                twin_shift < 2e-3,
                "{name}: {shift} m, centre {twin_shift} m off"
            );
        } else {
            let (shift, turn) = errors(&result.alignment.base_from_part, &truth);
            assert!(shift < 1e-3 && turn < 1e-2, "{name}: {shift} m, {turn} rad");
            assert!(found.margin > 0.05, "{name}: margin {}", found.margin);
        }
    }
}

/// The 500 mm PCA trial of `ips trials --pca` (seed 2024, trial 3) that nine trials in fifty
/// failed like: the point-pair-feature detection put a start 9.5 mm from the truth, and its run,
/// made in the band of the far start (half a metre), was pulled 283 mm off into the floor and
/// the box; no other start got there, and the pose returned was 826 mm off (docs/pca-trials.md).
#[test]
fn a_detected_start_near_the_truth_is_not_pulled_into_the_clutter() {
    use align_core::registration::convergence::pose_distance;
    use align_core::trials::{parts, trial_pose};
    let part = parts::step_block().unwrap();
    let truth = trial_pose();
    let cloud = scan_part(&part.mesh, &truth, &pca_trial_scan());
    let delta_m: f64 = 0.5;
    let radius_m = part.mesh.radius_m();
    let mut rng = TrialRng::new(2024 ^ delta_m.to_bits());
    let displacements: Vec<Isometry3<f64>> = (0..4)
        .map(|_| random_displacement(&mut rng, delta_m, radius_m))
        .collect();
    let start = displace_about_centroid(&truth, &part.mesh, &displacements[3]);
    let result = align_cloud(&part.mesh, &cloud, &start, delta_m, &PcaOptions::default()).unwrap();
    let error_m = pose_distance(&result.alignment.base_from_part, &truth, radius_m);
    assert!(error_m < 1e-3, "{:.1} mm off", error_m * 1e3);
    assert!(
        !result.uniqueness.as_ref().is_some_and(|u| u.ambiguous),
        "{:?}",
        result.uniqueness
    );
}

/// Without the twin search (as the robot fit's rigid stage of the whole robot runs) the runs
/// from the start still bring the step block home, and no uniqueness is claimed: the runs that
/// would find a twin did not happen, so a margin would be a guess.
#[test]
fn without_the_twin_search_the_pose_is_found_and_no_uniqueness_claimed() {
    let mesh = step_block();
    let truth = truth();
    let cloud = cluttered_scan(&mesh, &truth);
    let start = displaced_start(&mesh, &truth, 5, 0.2);
    let options = PcaOptions {
        twin_search: false,
        ..PcaOptions::default()
    };
    let result = align_cloud(&mesh, &cloud, &start, 0.2, &options).unwrap();
    assert!(result.uniqueness.is_none(), "{:?}", result.uniqueness);
    let (shift, turn) = errors(&result.alignment.base_from_part, &truth);
    assert!(shift < 1e-3 && turn < 1e-2, "{shift} m, {turn} rad");
}

/// Without the fine run (as the robot fit's rigid stage runs from a near start) the pose is the
/// exploration's best end: brought within a few millimetres by runs on coarse keypoints, and no
/// iteration of a run on the fine ones counted. Without an exploration the run is made anyway.
#[test]
fn without_the_fine_run_the_exploration_brings_the_part_near() {
    let mesh = step_block();
    let truth = truth();
    let cloud = cluttered_scan(&mesh, &truth);
    let start = displaced_start(&mesh, &truth, 7, 0.05);
    let rigid_stage = PcaOptions {
        fine_run: false,
        ..RobotFitOptions::default().base
    };
    let result = align_cloud(&mesh, &cloud, &start, 0.05, &rigid_stage).unwrap();
    assert_eq!(result.alignment.iterations, 0);
    let (shift, turn) = errors(&result.alignment.base_from_part, &truth);
    assert!(shift < 5e-3 && turn < 3e-2, "{shift} m, {turn} rad");
    let unexplored = PcaOptions {
        starts: 0,
        ..rigid_stage
    };
    let result = align_cloud(&mesh, &cloud, &start, 0.05, &unexplored).unwrap();
    assert!(result.alignment.iterations > 0);
    let (shift, turn) = errors(&result.alignment.base_from_part, &truth);
    assert!(shift < 5e-3 && turn < 3e-2, "{shift} m, {turn} rad");
}

#[test]
fn a_local_run_is_the_same_whatever_lies_beyond_its_reach() {
    // The local stage bins only the points a run from the start can reach (the box's half
    // diagonal and three delta0 from its centre): clutter a few metres off changes nothing, not
    // even the last bit of the pose.
    let mesh = step_block();
    let truth = truth();
    let cloud = cluttered_scan(&mesh, &truth);
    let far_clutter: Vec<Point3<f64>> = (0..20_000)
        .map(|i| {
            let t = i as f64 * 0.37;
            Point3::new(
                4.0 + (t * 0.11).sin(),
                -3.0 + (t * 0.07).cos(),
                (t * 0.05).sin(),
            )
        })
        .collect();
    let with_far: Vec<Point3<f64>> = cloud.iter().chain(&far_clutter).copied().collect();
    let local = PcaOptions {
        starts: 0,
        ..PcaOptions::default()
    };
    for (seed, delta_m) in [(3, 0.05), (4, 0.3)] {
        let start = displaced_start(&mesh, &truth, seed, delta_m);
        let alone = align_cloud(&mesh, &cloud, &start, delta_m, &local).unwrap();
        let among = align_cloud(&mesh, &with_far, &start, delta_m, &local).unwrap();
        assert_eq!(
            alone.alignment.base_from_part, among.alignment.base_from_part,
            "delta {delta_m} m"
        );
        assert_eq!(alone.alignment.iterations, among.alignment.iterations);
        // The keypoints count what was binned: the far clutter was not.
        assert_eq!(alone.keypoints, among.keypoints, "delta {delta_m} m");
    }
}

/// The local stage (no exploration) as it runs by default, and with every band matched exactly.
fn local_with_and_without_slack() -> (PcaOptions, PcaOptions) {
    let with_slack = PcaOptions {
        starts: 0,
        ..PcaOptions::default()
    };
    let exact = PcaOptions {
        wide_band_slack: false,
        ..with_slack.clone()
    };
    (with_slack, exact)
}

#[test]
fn a_local_run_matches_approximately_only_in_bands_wider_than_5_cm() {
    let mesh = step_block();
    let truth = truth();
    let cloud = cluttered_scan(&mesh, &truth);
    let (with_slack, exact) = local_with_and_without_slack();
    // From 50 mm every band is exact either way: the same pose to the last bit.
    let start = displaced_start(&mesh, &truth, 5, 0.05);
    let a = align_cloud(&mesh, &cloud, &start, 0.05, &with_slack).unwrap();
    let b = align_cloud(&mesh, &cloud, &start, 0.05, &exact).unwrap();
    assert_eq!(a.alignment.base_from_part, b.alignment.base_from_part);
    // From 150 mm the first bands differ, and both reach the truth.
    let start = displaced_start(&mesh, &truth, 6, 0.15);
    let a = align_cloud(&mesh, &cloud, &start, 0.15, &with_slack).unwrap();
    let b = align_cloud(&mesh, &cloud, &start, 0.15, &exact).unwrap();
    assert_ne!(a.alignment.base_from_part, b.alignment.base_from_part);
    for (name, result) in [("with the slack", &a), ("exact", &b)] {
        let (position, rotation) = errors(&result.alignment.base_from_part, &truth);
        let d = position.hypot(rotation * mesh.radius_m());
        assert!(d < 1e-3, "{name}: pose distance {d:e} m");
    }
}

/// How many of 30 starts (seeds `seed_of(0..30)`, displaced within `delta_m`) `options` brings
/// within 1 mm (pose distance) of the truth.
fn successes_of_30(
    mesh: &Mesh,
    truth: &Isometry3<f64>,
    cloud: &[Point3<f64>],
    delta_m: f64,
    seed_of: impl Fn(u64) -> u64,
    options: &PcaOptions,
) -> usize {
    (0..30u64)
        .filter(|&seed| {
            let start = displaced_start(mesh, truth, seed_of(seed), delta_m);
            let result = align_cloud(mesh, cloud, &start, delta_m, options).unwrap();
            let (position, rotation) = errors(&result.alignment.base_from_part, truth);
            position.hypot(rotation * mesh.radius_m()) < 1e-3
        })
        .count()
}

#[test]
fn on_the_step_block_the_wide_band_slack_loses_no_delta() {
    // The 20-triangle block, whose faces are two triangles each: an approximate answer beyond the
    // band's inner half is often another face. With the exploration's rule (approximate beyond
    // 2 cm) 150 mm fell from 17 to 6 of 30 (a probe before the rule was chosen); matching the
    // outer half only keeps every delta within a start or two of the exact runs.
    //
    // Scan to model in every band, as the slack was measured: it approximates the answers of the
    // scan's keypoints only. With the default (the wide bands matched both ways, the model's
    // samples matched exactly) 0.2 m gave 9 of 30 with the slack and 12 exact on this block,
    // while on the CAD corpora the slack found 488 of 1200 and exact 482
    // (docs/cad-scan-trials.md, fourteenth session).
    let mesh = step_block();
    let truth = truth();
    let cloud = cluttered_scan(&mesh, &truth);
    let [with_slack, exact] =
        <[PcaOptions; 2]>::from(local_with_and_without_slack()).map(|o| PcaOptions {
            wide_band_matching: WideBandMatching::ScanToModel,
            ..o
        });
    for delta_m in [0.1, 0.15, 0.2] {
        let successes = |options: &PcaOptions| {
            successes_of_30(&mesh, &truth, &cloud, delta_m, |seed| seed * 7 + 1, options)
        };
        let (slack_found, exact_found) = (successes(&with_slack), successes(&exact));
        eprintln!("{delta_m} m: with the slack {slack_found}/30, exact {exact_found}/30");
        assert!(
            slack_found + 2 >= exact_found,
            "{delta_m} m: with the slack {slack_found}/30, exact {exact_found}/30"
        );
    }
}

#[test]
fn a_local_run_from_far_off_starts_in_a_band_of_the_parts_radius() {
    // From 0.3 and 0.5 m off, a band of delta0 around the 20-triangle block (radius 146 mm)
    // holds the floor, the box beside it and the outliers of the whole scene. Capped at the
    // part's radius the local run must find the part at least as often: measured when written,
    // 7 against 1 and 4 against 0 of 30 (1 against 0 from 1 m, not run here: slow and says
    // little); the CAD scans 72 -> 75 and 75 -> 80 of 200 (docs/cad-scan-trials.md). From 50 mm,
    // below the radius, nothing changes.
    //
    // Scan to model in every band, as the cap was measured: a wide band's keypoints then pull
    // by their number. With the default (the wide bands matched both ways, the part's samples
    // each counting once) this block from 0.5 m gave 2 of 30 capped and 5 from delta0, and
    // 7 and 6 from 0.3 m; on the CAD corpora the cap kept its lead, 488 of 1200 against 463
    // (docs/cad-scan-trials.md, fourteenth session), so it stays the default.
    let mesh = step_block();
    let truth = truth();
    let cloud = cluttered_scan(&mesh, &truth);
    let capped = PcaOptions {
        starts: 0,
        wide_band_matching: WideBandMatching::ScanToModel,
        ..PcaOptions::default()
    };
    let from_delta0 = PcaOptions {
        local_band_within_radius: false,
        ..capped.clone()
    };
    let start = displaced_start(&mesh, &truth, 5, 0.05);
    let a = align_cloud(&mesh, &cloud, &start, 0.05, &capped).unwrap();
    let b = align_cloud(&mesh, &cloud, &start, 0.05, &from_delta0).unwrap();
    assert_eq!(a.alignment.base_from_part, b.alignment.base_from_part);
    for delta_m in [0.3, 0.5] {
        let successes = |options: &PcaOptions| {
            successes_of_30(
                &mesh,
                &truth,
                &cloud,
                delta_m,
                |seed| seed * 11 + 3,
                options,
            )
        };
        let (capped_found, delta0_found) = (successes(&capped), successes(&from_delta0));
        eprintln!(
            "{delta_m} m: first band the radius {capped_found}/30, delta0 {delta0_found}/30 (radius {:.3} m)",
            mesh.radius_m()
        );
        assert!(
            capped_found >= delta0_found,
            "{delta_m} m: first band the radius {capped_found}/30, delta0 {delta0_found}/30"
        );
    }
}

/// At a delta too small for the exploration's turns, the full alignment's candidate is the local
/// stage's end, which has already run the schedule down to the narrowest band on the fine
/// keypoints and polished: it is taken as it is (pose and iterations), not refined a second
/// time. Before, the run on the fine keypoints and the polish ran again from it: a 50 mm
/// alignment of the unseen CAD set A took about a third longer (docs/BENCHMARKS.md).
#[test]
fn a_local_end_that_wins_is_the_alignment_without_a_second_run() {
    let mesh = step_block();
    let truth = truth();
    let cloud = cluttered_scan(&mesh, &truth);
    for seed in [21, 22] {
        let start = displaced_start(&mesh, &truth, seed, 0.02);
        let full = align_cloud(&mesh, &cloud, &start, 0.02, &PcaOptions::default()).unwrap();
        let local_options = PcaOptions {
            starts: 0,
            ..PcaOptions::default()
        };
        let local = align_cloud(&mesh, &cloud, &start, 0.02, &local_options).unwrap();
        let (position, rotation) = errors(
            &full.alignment.base_from_part,
            &local.alignment.base_from_part,
        );
        assert!(
            position < 1e-9 && rotation < 1e-9,
            "seed {seed}: the full alignment moved the local end {position:e} m, {rotation:e} rad"
        );
        assert_eq!(
            full.alignment.iterations, local.alignment.iterations,
            "seed {seed}: iterations after the local end"
        );
        let (position, rotation) = errors(&full.alignment.base_from_part, &truth);
        assert!(position.hypot(rotation * mesh.radius_m()) < 1e-3);
        // Unique: every run about the pose ended there (None) or short of it.
        assert!(
            !full.uniqueness.as_ref().is_some_and(|u| u.ambiguous),
            "seed {seed}: {:?}",
            full.uniqueness
        );
    }
}
