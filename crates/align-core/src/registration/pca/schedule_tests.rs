//! Tests of the halving schedule, the kept keypoints and the run's stops.

use super::*;

#[test]
fn both_cosine_schedules_run_from_delta0_to_delta_min_in_100_iterations() {
    for schedule in [DeltaSchedule::Cosine, DeltaSchedule::CosineSquared] {
        let options = PcaOptions {
            schedule,
            ..PcaOptions::default()
        };
        assert!((delta_at(0, 0.5, &options) - 0.5).abs() < 1e-15);
        assert!((delta_at(100, 0.5, &options) - 0.01).abs() < 1e-15);
        assert!((delta_at(250, 0.5, &options) - 0.01).abs() < 1e-15);
    }
    let cos = PcaOptions {
        schedule: DeltaSchedule::Cosine,
        ..PcaOptions::default()
    };
    let squared = PcaOptions {
        schedule: DeltaSchedule::CosineSquared,
        ..PcaOptions::default()
    };
    assert!(delta_at(50, 0.5, &squared) < delta_at(50, 0.5, &cos));
}

#[test]
fn a_halving_band_halves_when_the_pose_settles_or_after_its_steps_and_ends_at_delta_min() {
    let options = PcaOptions {
        schedule: DeltaSchedule::Halving,
        ..PcaOptions::default()
    };
    let mut band = Band::new(0.08, &options);
    // Still moving by more than a hundredth of the band: the band holds...
    for _ in 0..STEPS_PER_BAND - 1 {
        let delta = band.next(&options);
        assert_eq!(delta, 0.08);
        band.stepped(0.01, delta);
    }
    // ...until its steps are spent.
    band.stepped(0.01, 0.08);
    assert_eq!(band.next(&options), 0.04);
    // Settled: halves at once, and never below delta_min.
    band.stepped(1e-5, 0.04);
    assert_eq!(band.next(&options), 0.02);
    band.stepped(1e-5, 0.02);
    assert_eq!(band.next(&options), 0.01);
    assert!(!band.at_end());
    band.stepped(1e-5, 0.01);
    assert_eq!(band.next(&options), 0.01);
    assert!(band.at_end());
}

/// Points on the five faces of a 200 x 100 x 150 mm box a scanner above it sees, 5 mm apart.
fn box_scan() -> (Mesh, Vec<Point3<f64>>) {
    let size = [0.2, 0.1, 0.15];
    let mesh = Mesh::cuboid(size).expect("a box");
    let half = size.map(|s| s / 2.0);
    let mut points = Vec::new();
    let steps = |extent: f64| (0..=(extent / 0.005) as i32).map(move |i| f64::from(i) * 0.005);
    for x in steps(size[0]) {
        for y in steps(size[1]) {
            points.push(Point3::new(x - half[0], y - half[1], half[2]));
        }
        for z in steps(size[2]) {
            points.push(Point3::new(x - half[0], -half[1], z - half[2]));
            points.push(Point3::new(x - half[0], half[1], z - half[2]));
        }
    }
    for y in steps(size[1]) {
        for z in steps(size[2]) {
            points.push(Point3::new(-half[0], y - half[1], z - half[2]));
            points.push(Point3::new(half[0], y - half[1], z - half[2]));
        }
    }
    (mesh, points)
}

#[test]
fn a_halving_run_that_never_stands_still_ends_after_its_last_band_steps() {
    let (mesh, points) = box_scan();
    let start = Isometry3::translation(0.02, -0.01, 0.005);
    let restless = PcaOptions {
        schedule: DeltaSchedule::Halving,
        max_iterations: 1000,
        // No step is ever below it: the pose never stands still.
        tolerance_m: -1.0,
        ..PcaOptions::default()
    };
    let run = run_schedule(&mesh, &points, &start, 0.05, &restless, 1.0);
    // Bands of 50, 25, 12.5 and 10 mm, which settle in two steps or fewer each from 2 cm
    // off, then LAST_BAND_STEPS in the last, when its progress is looked at (with 30 the run
    // took 35 steps).
    assert!(!run.converged);
    assert!(
        run.iterations < restless.max_iterations && run.iterations <= 4 * 2 + LAST_BAND_STEPS,
        "{} iterations",
        run.iterations
    );
    assert!(pose_distance(&run.pose, &Isometry3::identity(), mesh.radius_m()) < 1e-6);
    // A run that stands still ends well before.
    let settled = run_schedule(&mesh, &points, &start, 0.05, &PcaOptions::default(), 1.0);
    assert!(settled.converged && settled.iterations < run.iterations);
}

#[test]
fn a_run_in_its_last_band_ends_at_the_first_step_that_does_not_move() {
    let (mesh, points) = box_scan();
    // From the truth in the last band (1 cm): the first step moves by nothing, and the
    // stopping window would have waited for `window` more.
    let options = PcaOptions::default();
    let run = run_schedule(&mesh, &points, &Isometry3::identity(), 0.01, &options, 1.0);
    assert!(run.converged);
    assert_eq!(run.iterations, 1);
    // A band that still halves does not end on a still step: 2 and 1 cm bands.
    let run = run_schedule(&mesh, &points, &Isometry3::identity(), 0.02, &options, 1.0);
    assert!(run.converged);
    assert_eq!(run.iterations, 2);
}

#[test]
fn narrowed_keypoints_keep_every_one_a_narrow_band_can_match() {
    let (mesh, _) = box_scan();
    let (lower, upper) = mesh.bounds();
    let mut rng = SplitMix64::new(3);
    let keypoints: Vec<Point3<f64>> = (0..5000)
        .map(|_| Point3::from(rng.unit_vector() * (0.8 * rng.uniform())))
        .collect();
    let pose = Isometry3::new(Vector3::new(0.02, -0.01, 0.0), Vector3::new(0.0, 0.0, 0.3));
    let mut reachable = Reachable::new(&lower, &upper, 0.5);
    let mut hints = vec![NO_HINT; keypoints.len()];
    reachable.update(&keypoints, &pose, &mut hints);
    let kept_wide = reachable.points.len();
    for band_m in [0.5, 0.2, 0.05, 0.01] {
        reachable.narrow_to(band_m);
        reachable.update(&keypoints, &pose, &mut hints);
        // Every keypoint inside the part's box grown by the band is still there.
        let in_band_box = keypoints.iter().filter(|p| {
            let in_part = pose.inverse() * *p;
            (0..3).all(|axis| {
                in_part[axis] >= lower[axis] - band_m && in_part[axis] <= upper[axis] + band_m
            })
        });
        for point in in_band_box {
            assert!(reachable.points.contains(point), "band {band_m}");
        }
    }
    // And the 1 cm band keeps far fewer than the first band did.
    assert!(
        2 * reachable.points.len() < kept_wide,
        "{} of {kept_wide}",
        reachable.points.len()
    );
}

#[test]
fn a_thinned_level_keeps_one_keypoint_in_stride_spread_over_the_cloud_and_the_same_ones() {
    // No thinning up to the cap, then one in every whole multiple of it.
    assert_eq!(thinning_for(MATCHES_PER_STEP), 1);
    assert_eq!(thinning_for(2.9 * MATCHES_PER_STEP), 2);
    assert_eq!(thinning_for(f64::NAN), 1);
    // A smaller cap (a hop's settling steps), and none below one match a step.
    assert_eq!(thinning_to(2000.0, 600.0), 3);
    assert_eq!(thinning_to(600.0, 600.0), 1);
    assert_eq!(thinning_to(2000.0, 0.0), 1);
    let (mesh, _) = box_scan();
    let (lower, upper) = mesh.bounds();
    let mut rng = SplitMix64::new(5);
    let keypoints: Vec<Point3<f64>> = (0..30_000)
        .map(|_| Point3::from(rng.unit_vector() * (0.4 * rng.uniform())))
        .collect();
    let pose = Isometry3::identity();
    let mut hints = vec![NO_HINT; keypoints.len()];
    let mut whole = Reachable::new(&lower, &upper, 0.05);
    whole.update(&keypoints, &pose, &mut hints);
    let mut thinned = Reachable::new(&lower, &upper, 0.05);
    thinned.thin_to(3);
    thinned.update(&keypoints, &pose, &mut hints);
    let ratio = whole.points.len() as f64 / thinned.points.len() as f64;
    assert!((2.7..3.3).contains(&ratio), "kept one in {ratio}");
    // Spread: each eighth of the space around the part keeps about a third of its share.
    let octant = |p: &Point3<f64>| {
        usize::from(p.x > 0.0) + 2 * usize::from(p.y > 0.0) + 4 * usize::from(p.z > 0.0)
    };
    for which in 0..8 {
        let all = whole.points.iter().filter(|p| octant(p) == which).count() as f64;
        let kept = thinned.points.iter().filter(|p| octant(p) == which).count() as f64;
        assert!(
            (2.5..3.5).contains(&(all / kept)),
            "octant {which}: {kept} of {all}"
        );
    }
    // Filtered again from elsewhere, the keypoints kept in both places are the same ones.
    let before = thinned.points.clone();
    let moved = Isometry3::translation(0.05, 0.0, 0.0);
    thinned.update(&keypoints, &moved, &mut hints);
    let after: std::collections::HashSet<_> = thinned
        .points
        .iter()
        .map(|p| p.coords.map(f64::to_bits))
        .collect();
    let in_both: Vec<&Point3<f64>> = keypoints
        .iter()
        .filter(|p| {
            (**p - moved * Point3::origin()).norm() < 0.1 && (**p - Point3::origin()).norm() < 0.1
        })
        .collect();
    assert!(in_both.len() > 500, "{} in both", in_both.len());
    for point in in_both {
        let key = point.coords.map(f64::to_bits);
        assert_eq!(before.contains(point), after.contains(&key));
    }
    // Back to one in one: every keypoint again.
    thinned.thin_to(1);
    thinned.update(&keypoints, &pose, &mut hints);
    assert_eq!(thinned.points, whole.points);
}

#[test]
fn a_run_that_comes_back_to_a_pose_of_two_or_three_steps_before_is_in_a_cycle() {
    let radius_m = 0.1;
    let at = |x_mm: f64| Isometry3::translation(x_mm * 1e-3, 0.0, 0.0);
    let fixed_m = FIXED_POINT_FRACTION * PcaOptions::default().tolerance_m;
    // Back and forth between two poses 0.3 mm apart: period 2.
    let two = [(at(0.0), 3e-4), (at(0.3), 3e-4), (at(0.0), 3e-4)];
    assert_eq!(cycle_period(&two, radius_m, fixed_m), Some(2));
    // Round three poses, back to within a micron of the first: period 3.
    let three = [
        (at(0.0), 2e-4),
        (at(0.2), 2e-4),
        (at(0.1), 1e-4),
        (at(0.001), 1e-4),
    ];
    assert_eq!(cycle_period(&three, radius_m, fixed_m), Some(3));
    // A slow slide, each step a little on: no cycle, however short the steps.
    let slide: Vec<_> = (0..4).map(|i| (at(0.01 * f64::from(i)), 1e-5)).collect();
    assert_eq!(cycle_period(&slide, radius_m, fixed_m), None);
    assert_eq!(cycle_period(&[], radius_m, fixed_m), None);
}

#[test]
fn only_a_halving_run_from_a_wide_band_gets_coarser_keypoints() {
    let keypoints: Vec<Point3<f64>> = (0..200)
        .map(|i| Point3::new(f64::from(i) * 0.001, 0.0, 0.0))
        .collect();
    let halving = PcaOptions {
        schedule: DeltaSchedule::Halving,
        ..PcaOptions::default()
    };
    let cosine = PcaOptions {
        schedule: DeltaSchedule::Cosine,
        ..PcaOptions::default()
    };
    let voxels = |levels: Vec<(f64, Vec<Point3<f64>>)>| -> Vec<f64> {
        levels.iter().map(|(voxel_m, _)| *voxel_m).collect()
    };
    assert!(coarser_levels(&keypoints, 0.5, &cosine).is_empty());
    // 5 mm keypoints: 10 and 20 mm levels, each for bands over 2.4 of its voxels.
    assert_eq!(
        voxels(coarser_levels(&keypoints, 0.5, &halving)),
        [0.01, 0.02]
    );
    assert_eq!(
        voxels(coarser_levels(&keypoints, 0.05, &halving)),
        [0.01, 0.02]
    );
    assert_eq!(voxels(coarser_levels(&keypoints, 0.03, &halving)), [0.01]);
    assert_eq!(voxels(coarser_levels(&keypoints, 0.025, &halving)), [0.01]);
    assert!(coarser_levels(&keypoints, 0.024, &halving).is_empty());
    let levels = coarser_levels(&keypoints, 0.5, &halving);
    assert!(levels[0].1.len() < keypoints.len() && levels[1].1.len() < levels[0].1.len());
}

fn a_match(weight: f64) -> Match {
    Match {
        point: Point3::origin(),
        surface: Point3::origin(),
        normal: Vector3::z(),
        distance: 0.0,
        weight,
    }
}

#[test]
fn matched_both_ways_the_scans_set_weighs_as_much_as_the_parts_and_keeps_its_proportions() {
    // The part's 3 samples against 6 keypoints, most of them clutter: both sets weigh 2.5.
    let from_model = [0.5, 1.0, 1.0].map(a_match);
    let mut from_scan = [1.0, 1.0, 0.5, 0.5, 1.0, 1.0].map(a_match);
    balance_weights(&from_model, &mut from_scan);
    let scan_total: f64 = from_scan.iter().map(|m| m.weight).sum();
    assert!((scan_total - 2.5).abs() < 1e-12, "{scan_total}");
    assert!((from_scan[0].weight - 2.0 * from_scan[2].weight).abs() < 1e-12);
    // Nothing matched one way: the other set is left as it is.
    let mut alone = [1.0, 0.5].map(a_match);
    balance_weights(&[], &mut alone);
    assert_eq!(alone.map(|m| m.weight), [1.0, 0.5]);
}
