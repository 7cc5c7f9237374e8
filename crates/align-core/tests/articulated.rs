//! Hierarchical alignment of the shipped robots in scanner-like clouds.

use align_core::registration::articulated::{
    ArticulatedBody, RobotFitOptions, align_robot, observed_joints_at, searches_globally,
};
use align_core::robots::ShippedRobot;
use align_core::trials::TrialRng;
use align_core::trials::robot_scan::{RobotScanOptions, scan_robot};
use align_core::trials::robot_trials::{
    Methods, RobotScene, RobotTrialRow, joint_start_bounds, perturb_robot, run_robot_trials,
    surface_deviation_m,
};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};

#[path = "common/abb.rs"]
mod abb;
#[path = "common/robot_package.rs"]
mod robot_package;
use abb::{ABB_TRIAL_HOME, abb_irb1600};

fn cell_pose() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.2, -0.1, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, 0.4),
    )
}

/// The scene of `ips trials --robot`: the robot at home, its root at the cell pose.
fn trial_scene(robot: ShippedRobot) -> RobotScene {
    RobotScene {
        world_from_root: cell_pose(),
        q: robot.home(),
        scan: RobotScanOptions::default(),
    }
}

/// Fits from a perturbed start and returns the largest surface deviation over the visible links.
fn recover(
    robot: ShippedRobot,
    q_true: &[f64],
    scan: &RobotScanOptions,
    delta_m: f64,
    seed: u64,
) -> (f64, Vec<String>) {
    let body = ArticulatedBody::from_model(&robot.model().expect("shipped URDF loads"))
        .expect("shipped robot has surfaces");
    let truth = cell_pose();
    let cloud = scan_robot(&body, &truth, q_true, scan);
    let mut rng = TrialRng::new(seed);
    let (base, q0) = perturb_robot(&body, &truth, q_true, delta_m, &mut rng);
    let label = format!("{} seed {seed}", robot.name());
    fit_from(&body, &cloud, q_true, &base, &q0, delta_m, &label)
}

/// Fits `cloud` (the robot at `q_true` in the cell) from `base` and `q0` and returns the
/// largest surface deviation over the visible links, and each link's.
fn fit_from(
    body: &ArticulatedBody,
    cloud: &[nalgebra::Point3<f64>],
    q_true: &[f64],
    base: &Isometry3<f64>,
    q0: &[f64],
    delta_m: f64,
    label: &str,
) -> (f64, Vec<String>) {
    let truth = cell_pose();
    let fit = align_robot(body, cloud, base, q0, delta_m, &RobotFitOptions::default())
        .expect("the fit runs");
    let fitted = body.link_poses(&fit.world_from_root, &fit.q);
    let true_poses = body.link_poses(&truth, q_true);
    let mut worst: f64 = 0.0;
    let mut report = Vec::new();
    for (index, link) in body.links().iter().enumerate() {
        let Some(mesh) = &link.surface else { continue };
        let error = surface_deviation_m(mesh, &fitted[index], &true_poses[index]);
        report.push(format!(
            "{} {:.3} mm ({} pts)",
            link.name,
            error * 1e3,
            fit.links[index].points
        ));
        if fit.links[index].visible {
            worst = worst.max(error);
        }
    }
    // Both shipped robots stand on round bases: the first joint, and only it, is flagged as
    // observed only together with the base's yaw.
    let flagged: Vec<bool> = fit.joints.iter().map(|j| j.turns_with_base).collect();
    assert_eq!(flagged[0], fit.joints[0].observed, "{:?}", fit.joints);
    assert!(!flagged[1..].iter().any(|f| *f), "{:?}", fit.joints);
    eprintln!(
        "{label} delta {delta_m}: {:.3} s, {report:?}, joints {:?}",
        fit.time_s, fit.joints
    );
    (worst, report)
}

#[test]
fn ur10_recovers_from_a_small_perturbation_in_a_cluttered_scan() {
    let (worst, report) = recover(
        ShippedRobot::Ur10,
        &ShippedRobot::Ur10.home(),
        &RobotScanOptions::default(),
        0.05,
        3,
    );
    assert!(worst < 1e-3, "{report:?}");
}

/// Near starts (100 mm, under a fifth of both robots' radii) at corners of the box the trials
/// draw joint starts from: every joint off by the most the start allows, the base where it is.
/// From a near start a joint that spins its own links in place (the UR10's first joint and its
/// first two wrist joints among them) keeps its value: the refinements after the next joint's
/// search settle it, from as far as a start puts it.
#[test]
fn near_starts_at_the_corners_of_the_joint_box_recover_every_visible_link() {
    let delta_m = 0.1;
    for robot in [ShippedRobot::Ur10, ShippedRobot::Iiwa14] {
        let body = ArticulatedBody::from_model(&robot.model().expect("shipped URDF loads"))
            .expect("shipped robot has surfaces");
        let truth = robot.home();
        let cloud = scan_robot(&body, &cell_pose(), &truth, &RobotScanOptions::default());
        let bounds = joint_start_bounds(&body, &cell_pose(), &truth, delta_m);
        for (corner, signs) in [[1.0, 1.0], [1.0, -1.0]].iter().enumerate() {
            let q0: Vec<f64> = truth
                .iter()
                .zip(&bounds)
                .enumerate()
                .map(|(parameter, (value, bound))| {
                    let info = &body.parameters()[parameter];
                    (value + signs[parameter % 2] * bound).clamp(info.lower, info.upper)
                })
                .collect();
            let label = format!("{} corner {corner}", robot.name());
            let (worst, report) =
                fit_from(&body, &cloud, &truth, &cell_pose(), &q0, delta_m, &label);
            assert!(worst < 1e-3, "{} corner {corner}: {report:?}", robot.name());
        }
    }
}

/// Joint values drawn around the robot's home (within 0.6 rad, inside the limits).
fn random_configuration(robot: ShippedRobot, rng: &mut TrialRng) -> Vec<f64> {
    robot
        .home()
        .iter()
        .map(|q| q + (2.0 * rng.uniform() - 1.0) * 0.6)
        .collect()
}

#[test]
fn random_configurations_of_both_robots_recover_every_visible_link_to_a_millimetre() {
    let mut rng = TrialRng::new(11);
    for robot in [ShippedRobot::Ur10, ShippedRobot::Iiwa14] {
        for case in 0..3u64 {
            let q_true = random_configuration(robot, &mut rng);
            let scan = RobotScanOptions {
                seed: 100 + case,
                ..RobotScanOptions::default()
            };
            let delta_m = [0.05, 0.1, 0.2][case as usize];
            let (worst, report) = recover(robot, &q_true, &scan, delta_m, case);
            assert!(worst < 1e-3, "{} case {case}: {report:?}", robot.name());
        }
    }
}

/// Each joint's 95 % interval holds its true value in most fits, and is reported only for
/// joints the scan fixes on their own. The robot's own scans (the scanner sees the meshes the
/// fit uses), so this checks the sums, not the noise calibration (see `fit::uncertainty`).
#[test]
fn each_joints_95_percent_interval_holds_its_truth_in_most_fits() {
    let mut rng = TrialRng::new(29);
    let (mut counted, mut inside) = (0, 0);
    let mut misses = Vec::new();
    for robot in [ShippedRobot::Ur10, ShippedRobot::Iiwa14] {
        let body = ArticulatedBody::from_model(&robot.model().expect("shipped URDF loads"))
            .expect("shipped robot has surfaces");
        for case in 0..4u64 {
            let q_true = random_configuration(robot, &mut rng);
            let scan = RobotScanOptions {
                seed: 200 + case,
                ..RobotScanOptions::default()
            };
            let truth = cell_pose();
            let cloud = scan_robot(&body, &truth, &q_true, &scan);
            let (base, q0) = perturb_robot(&body, &truth, &q_true, 0.05, &mut rng);
            let fit = align_robot(&body, &cloud, &base, &q0, 0.05, &RobotFitOptions::default())
                .expect("the fit runs");
            for (joint, truth) in fit.joints.iter().zip(&q_true) {
                let Some(within) = joint.within_95 else {
                    // Only a joint the scan does not fix alone goes without.
                    assert!(
                        !joint.observed || joint.turns_with_base,
                        "{} case {case}: {joint:?}",
                        robot.name()
                    );
                    continue;
                };
                assert!(joint.observed && !joint.turns_with_base, "{joint:?}");
                // The links are fitted to well under a millimetre: a joint to a few mrad.
                assert!(within > 0.0 && within < 0.01, "{joint:?}");
                counted += 1;
                if (joint.value - truth).abs() <= within {
                    inside += 1;
                } else {
                    misses.push(format!(
                        "{} case {case} {}: off {:.3} mrad, interval {:.3} mrad",
                        robot.name(),
                        joint.name,
                        (joint.value - truth).abs() * 1e3,
                        within * 1e3
                    ));
                }
            }
        }
    }
    eprintln!("{inside} of {counted} inside; outside: {misses:?}");
    assert!(counted >= 30, "{counted} intervals");
    assert!(
        10 * inside >= 9 * counted,
        "{inside} of {counted}: {misses:?}"
    );
}

/// Starts half a metre off: the base by up to 0.5 m and about 0.5 rad, every joint moving its
/// farthest point by up to 0.5 m (the wrists by up to half a turn). The beam search, the
/// proximal base candidates and the half-turn check are what recover these.
#[test]
fn starts_half_a_metre_off_recover_every_visible_link_to_a_millimetre() {
    for robot in [ShippedRobot::Ur10, ShippedRobot::Iiwa14] {
        for seed in [21, 22] {
            let (worst, report) = recover(
                robot,
                &robot.home(),
                &RobotScanOptions::default(),
                0.5,
                seed,
            );
            assert!(worst < 1e-3, "{} seed {seed}: {report:?}", robot.name());
        }
    }
}

/// docs/articulated-trials.md says which rows of the trials ran the global search: every
/// 1000 mm trial, some 500 mm ones (start joints that fold the arm) and none below. The starts
/// are the trials' (`ips trials`, seed 2024, 50 per delta).
#[test]
fn the_trials_search_globally_at_1000_mm_some_at_500_and_never_below() {
    let truth = cell_pose();
    for robot in [ShippedRobot::Ur10, ShippedRobot::Iiwa14] {
        let body = ArticulatedBody::from_model(&robot.model().expect("shipped URDF loads"))
            .expect("shipped robot has surfaces");
        let global_starts = |delta_m: f64| {
            let mut rng = TrialRng::new(2024 ^ delta_m.to_bits());
            (0..50)
                .filter(|_| {
                    let (_, q0) = perturb_robot(&body, &truth, &robot.home(), delta_m, &mut rng);
                    searches_globally(&body, &q0, delta_m)
                })
                .count()
        };
        for delta_m in [0.05, 0.1, 0.2] {
            assert_eq!(global_starts(delta_m), 0, "{} {delta_m}", robot.name());
        }
        let at_500 = global_starts(0.5);
        assert!((1..=10).contains(&at_500), "{}: {at_500}", robot.name());
        assert_eq!(global_starts(1.0), 50, "{}", robot.name());
    }
}

/// A trial run can start part-way through its seeded sequence: the skipped starts are drawn,
/// so trials 0 and 1 run apart give what the run of both gives, for both methods, on every
/// object, and the failed trials are named by their index in the whole sequence.
#[test]
fn trials_run_in_parts_give_the_figures_of_the_whole_run() {
    let robot = ShippedRobot::Ur10;
    let body = ArticulatedBody::from_model(&robot.model().expect("shipped URDF loads"))
        .expect("shipped robot has surfaces");
    let scene = trial_scene(robot);
    let both = Methods {
        independent: true,
        hierarchical: true,
    };
    // 200 mm: the independent method fails some objects there, so failures are numbered too.
    let run = |trials| run_robot_trials(&body, &scene, &[0.2], trials, 2024, both, |_, _| {});
    let whole = run(0..2);
    let first = run(0..1);
    let second = run(1..2);
    for ((whole, first), second) in whole.iter().zip(&first).zip(&second) {
        let object = &whole.object;
        for (all, a, b) in [
            (&whole.independent, &first.independent, &second.independent),
            (
                &whole.hierarchical,
                &first.hierarchical,
                &second.hierarchical,
            ),
        ] {
            let (all, a, b) = (all.as_ref(), a.as_ref(), b.as_ref());
            let (all, a, b) = (all.expect("ran"), a.expect("ran"), b.expect("ran"));
            assert!(
                (all.mean_error_m * 2.0 - a.mean_error_m - b.mean_error_m).abs() < 1e-9,
                "{object}: {all:?} vs {a:?} + {b:?}"
            );
            assert_eq!(all.succeeded, a.succeeded + b.succeeded, "{object}");
            let named: Vec<usize> = a
                .failed_trials
                .iter()
                .chain(&b.failed_trials)
                .copied()
                .collect();
            assert_eq!(all.failed_trials, named, "{object}");
            assert!(b.failed_trials.iter().all(|&t| t == 1), "{object}: {b:?}");
        }
    }
}

/// Runs trial `trial` of the seeded hierarchical sequence (seed 2024, the trials' default) at
/// `delta_m` and asserts that the whole robot and every link are within 1 mm.
fn assert_trial_succeeds(robot: ShippedRobot, delta_m: f64, trial: usize) {
    let body = ArticulatedBody::from_model(&robot.model().expect("shipped URDF loads"))
        .expect("shipped robot has surfaces");
    for row in &hierarchical_trial(&body, &trial_scene(robot), delta_m, trial) {
        let tally = row.hierarchical.as_ref().expect("ran");
        assert_eq!(tally.succeeded, 1, "{}: {tally:?}", row.object);
    }
}

/// The rows of trial `trial` of the seeded hierarchical sequence (seed 2024, the trials'
/// default) at `delta_m`.
fn hierarchical_trial(
    body: &ArticulatedBody,
    scene: &RobotScene,
    delta_m: f64,
    trial: usize,
) -> Vec<RobotTrialRow> {
    let hierarchical = Methods {
        independent: false,
        hierarchical: true,
    };
    run_robot_trials(
        body,
        scene,
        &[delta_m],
        trial..trial + 1,
        2024,
        hierarchical,
        |_, _| {},
    )
}

/// Trial 31 of the UR10 at 500 mm (seed 2024) folds the arm so far that the global search
/// runs; wrist 2, round about its own joint, settled on an angle 1.27 rad off and left wrist 3
/// 89 mm from its points until the fit took a second look at such joints from its final state.
#[test]
fn the_ur10_wrist_lost_in_trial_31_at_500_mm_is_found() {
    assert_trial_succeeds(ShippedRobot::Ur10, 0.5, 31);
}

/// Trial 33 of the UR10 at 500 mm (seed 2024) left wrist 2 at -6.28 rad against -1.57 and
/// wrist 3 61 mm from its points. The wrist's sweep over a whole turn, centred on -6.28 and
/// clamped at the joint's limit of -2 pi, never reached -1.57; the turn is now slid inside the
/// limits.
#[test]
fn the_ur10_wrist_left_at_its_limit_in_trial_33_at_500_mm_is_found() {
    assert_trial_succeeds(ShippedRobot::Ur10, 0.5, 33);
}

/// Trial 13 of the iiwa14 at 1000 mm settled on a copy of the arm with joints 1, 3 and 5 a
/// half turn off, pinned at their 170 degree limits (so not an exact copy: link 7 was 0.2 m
/// off); no single joint turned back explained the scan better, two together do.
#[test]
fn the_iiwa_half_turn_copy_of_trial_13_at_1000_mm_is_turned_back() {
    assert_trial_succeeds(ShippedRobot::Iiwa14, 1.0, 13);
}

/// Starts a metre off, beyond the robots' radius: the base by up to 1 m and about 1.6 rad,
/// every joint anywhere in a window of up to a half turn each way. Nothing is local any more:
/// the proximal links are detected by point pair features and each joint is searched with its
/// child on a fine grid. Configurations away from home, so that nothing here is the trials'
/// scene.
#[test]
fn starts_a_metre_off_recover_every_visible_link_to_a_millimetre() {
    let mut rng = TrialRng::new(41);
    for robot in [ShippedRobot::Ur10, ShippedRobot::Iiwa14] {
        let q_true = random_configuration(robot, &mut rng);
        let scan = RobotScanOptions {
            seed: 141,
            ..RobotScanOptions::default()
        };
        let (worst, report) = recover(robot, &q_true, &scan, 1.0, 31);
        assert!(worst < 1e-3, "{}: {report:?}", robot.name());
    }
}

#[test]
fn a_link_no_scanner_sees_is_reported_and_its_joint_kept_at_the_start() {
    let robot = ShippedRobot::Iiwa14;
    let body = ArticulatedBody::from_model(&robot.model().expect("shipped URDF loads"))
        .expect("shipped robot has surfaces");
    let hidden = "iiwa_link_7";
    let scan = RobotScanOptions {
        hidden_links: vec![hidden.to_owned()],
        ..RobotScanOptions::default()
    };
    let truth = cell_pose();
    let q_true = robot.home();
    let cloud = scan_robot(&body, &truth, &q_true, &scan);
    let mut rng = TrialRng::new(5);
    let (base, q0) = perturb_robot(&body, &truth, &q_true, 0.05, &mut rng);
    let fit = align_robot(&body, &cloud, &base, &q0, 0.05, &RobotFitOptions::default())
        .expect("the fit runs");
    let link = fit
        .links
        .iter()
        .find(|link| link.name == hidden)
        .expect("the link is reported");
    assert!(!link.visible, "{link:?}");
    let last = fit.joints.last().expect("iiwa has joints");
    assert!(!last.observed);
    assert_eq!(last.value, q0[q0.len() - 1]);
    // Judged at the true pose as the fit judges its own state (what the trials ask before they
    // forgive a joint reported unseen): the same joints are shown, the hidden one is not.
    let shown = observed_joints_at(
        &body,
        &cloud,
        &base,
        0.05,
        &truth,
        &q_true,
        &RobotFitOptions::default(),
    )
    .expect("judged");
    let claimed: Vec<bool> = fit.joints.iter().map(|joint| joint.observed).collect();
    assert_eq!(shown, claimed);
    // The links that are seen are still found.
    let fitted = body.link_poses(&fit.world_from_root, &fit.q);
    let true_poses = body.link_poses(&truth, &q_true);
    for (index, link) in body.links().iter().enumerate() {
        if let (Some(mesh), true) = (&link.surface, fit.links[index].visible) {
            let error = surface_deviation_m(mesh, &fitted[index], &true_poses[index]);
            assert!(error < 1e-3, "{}: {error}", link.name);
        }
    }
}

#[test]
fn bad_inputs_are_refused_with_the_reason() {
    let body =
        ArticulatedBody::from_model(&ShippedRobot::Ur10.model().expect("loads")).expect("surfaces");
    let cloud = scan_robot(
        &body,
        &cell_pose(),
        &ShippedRobot::Ur10.home(),
        &RobotScanOptions::default(),
    );
    let options = RobotFitOptions::default();
    let short = align_robot(&body, &cloud, &cell_pose(), &[0.0; 5], 0.05, &options)
        .expect_err("five values for six joints");
    assert!(short.to_string().contains("6 joints"), "{short}");
    assert!(short.to_string().contains("wrist_3_joint"), "{short}");
    let mut q = ShippedRobot::Ur10.home();
    q[2] = f64::NAN;
    let nan = align_robot(&body, &cloud, &cell_pose(), &q, 0.05, &options).expect_err("NaN");
    assert!(nan.to_string().contains("elbow_joint"), "{nan}");
    let far = Isometry3::translation(50.0, 0.0, 0.0);
    let nothing = align_robot(
        &body,
        &cloud,
        &far,
        &ShippedRobot::Ur10.home(),
        0.05,
        &options,
    )
    .expect_err("no points near the start");
    assert!(nothing.to_string().contains("base pose"), "{nothing}");
}

/// Threads only share out the work: the beam's states, the spread's runs and every search over
/// points are merged in order, so a fit with threads and one without agree to the bit. (At
/// 200 mm the UR10's fit takes every local stage: the spread of base candidates as well.)
#[test]
fn a_fit_is_the_same_with_and_without_threads() {
    let robot = ShippedRobot::Ur10;
    let body = ArticulatedBody::from_model(&robot.model().expect("shipped URDF loads"))
        .expect("shipped robot has surfaces");
    let truth = cell_pose();
    let cloud = scan_robot(&body, &truth, &robot.home(), &RobotScanOptions::default());
    let mut rng = TrialRng::new(4);
    let (base, q0) = perturb_robot(&body, &truth, &robot.home(), 0.2, &mut rng);
    let threaded = RobotFitOptions::default();
    let mut single = threaded.clone();
    single.parallel = false;
    single.base.parallel = false;
    single.proximal.parallel = false;
    let with = align_robot(&body, &cloud, &base, &q0, 0.2, &threaded).expect("the fit runs");
    let without = align_robot(&body, &cloud, &base, &q0, 0.2, &single).expect("the fit runs");
    assert_eq!(with.q, without.q);
    assert_eq!(with.world_from_root, without.world_from_root);
    assert_eq!(with.iterations, without.iterations);
    assert_eq!(with.rms_m.to_bits(), without.rms_m.to_bits());
}

/// Runs `trials` of the ABB at `delta_m`: every link within 1 mm but the flange, whose spin
/// shows on a few rim points only (the fit reports it unobserved, which the tally counts apart
/// from failures).
fn abb_trials_succeed(delta_m: f64, trials: &[usize]) {
    let Some(body) = abb_irb1600() else {
        return;
    };
    let scene = RobotScene {
        world_from_root: cell_pose(),
        q: ABB_TRIAL_HOME.to_vec(),
        scan: RobotScanOptions::default(),
    };
    for &trial in trials {
        for row in &hierarchical_trial(&body, &scene, delta_m, trial) {
            let tally = row.hierarchical.as_ref().expect("ran");
            assert_eq!(tally.failed, 0, "trial {trial}, {}: {tally:?}", row.object);
        }
    }
}

/// Trials 25, 38 and 43 of the ABB IRB 1600 at 200 mm (seed 2024, `ips trials --urdf ...
/// --home 0,0.3,-0.2,0,0.6,0`) ended with joint 4 0.9 rad off and joint 5 making up for it
/// (link_4 24-33 mm off) until a local fit above 0.18 of the robot's radius took a second look
/// at every joint; trial 45 lost joint 5 the same way the 500 mm trials did. Runs only where the
/// third-party robot is (see `common/abb.rs`).
#[test]
fn the_abb_wrists_lost_at_200_mm_are_found() {
    abb_trials_succeed(0.2, &[25, 38, 43, 45]);
}

/// Trials 17 and 21 of the ABB at 1000 mm lost the base (in 21 the whole robot) while the fit
/// took the 12 best-voted detections of the proximal links: they are detected at the start's
/// value of joint 1, far off there, and the pose nearest the truth ranked 29th and 20th. With
/// 40 both are found.
#[test]
fn the_abb_bases_lost_at_1000_mm_are_found() {
    abb_trials_succeed(1.0, &[17, 21]);
}

/// Trial 15 of the ABB at 1000 mm lost every link once its base was detected alone: the scan's
/// floor, 0.6 m^2 around the base, is too small for the planes test (it holds fewer keypoints
/// than the base's whole surface could) and its votes put the base 0.4 m off (`ppf_detection`
/// bench). With the floor the base stands on left out, whatever its size, 50 of 50 are found.
#[test]
fn the_abb_base_lost_on_a_small_floor_at_1000_mm_is_found() {
    abb_trials_succeed(1.0, &[15]);
}
