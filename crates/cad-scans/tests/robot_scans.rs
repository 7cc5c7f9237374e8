//! The hierarchical robot fit on whole robots in ray-cast scans (`robot-scans`): the shipped
//! UR10 always, the ABB IRB 1600 where its support package is (the repository does not ship
//! it: `$ABB_IRB1600_SUPPORT_DIR`, else the workspace's sibling `shared/data` folder), the UR10
//! with CAD links where `scripts/robot-descriptions.sh` wrote it (`$EXAMPLE_ROBOT_DATA_DIR`).

use align_core::registration::articulated::ArticulatedBody;
use align_core::robots::ShippedRobot;
use cad_scans::robot::{scene_trials, seeded_scene};
use cad_scans::scanner::ScanNoise;

// The ABB's loader and trial joints, shared with align-core's articulated tests.
#[path = "../../align-core/tests/common/abb.rs"]
mod abb;
#[path = "../../align-core/tests/common/robot_package.rs"]
mod robot_package;
#[path = "../../align-core/tests/common/ur10_cad.rs"]
mod ur10_cad;
use abb::{ABB_TRIAL_HOME, abb_irb1600};
use ur10_cad::ur10_cad;

/// `robot-scans`'s defaults: seed 20, joints drawn up to 0.5 rad about home.
const SEED: u64 = 20;
const SPREAD_RAD: f64 = 0.5;

/// Runs `trials` of scene `scene` at `delta_m` and asserts that no link failed (a joint the fit
/// reports unseen where the scan does not show it is counted apart, as `reported`).
fn no_link_fails(
    body: &ArticulatedBody,
    home: &[f64],
    scene: usize,
    delta_m: f64,
    trials: &[usize],
) {
    no_link_fails_with_seed(body, home, SEED, scene, delta_m, trials);
}

/// [`no_link_fails`] in the scenes of another seed (`robot-scans --seed`).
fn no_link_fails_with_seed(
    body: &ArticulatedBody,
    home: &[f64],
    seed: u64,
    scene: usize,
    delta_m: f64,
    trials: &[usize],
) {
    let scanned = seeded_scene(body, home, SPREAD_RAD, seed, scene, &ScanNoise::default())
        .expect("the scene scans");
    for &trial in trials {
        let rows = scene_trials(
            body,
            &scanned,
            &[delta_m],
            trial..trial + 1,
            seed,
            scene,
            |_, _| {},
        );
        for row in &rows {
            let tally = row.hierarchical.as_ref().expect("ran");
            assert_eq!(
                tally.failed,
                0,
                "seed {seed}, scene {scene}, trial {trial} at {} mm, {}: {tally:?}",
                delta_m * 1e3,
                row.object
            );
        }
    }
}

#[test]
fn the_ur10_in_a_ray_cast_scan_is_fitted_within_a_millimetre_on_every_link() {
    let robot = ShippedRobot::Ur10;
    let body = ArticulatedBody::from_model(&robot.model().expect("shipped")).expect("surfaces");
    no_link_fails(&body, &robot.home(), 1, 0.05, &[0, 1, 2]);
}

/// In scene 0 at 50 mm, trials 0 and 4 left joint 5 0.2-1.1 rad off (link_5 11-12 mm) before
/// the sweep of the wrist in a narrow band and the isolated returns' removal: the searches and
/// refinements kept the flange's 15-40 keypoints inside their centimetre bands.
#[test]
fn the_abb_wrists_left_off_in_ray_cast_scans_are_found() {
    let Some(body) = abb_irb1600() else {
        return;
    };
    no_link_fails(&body, &ABB_TRIAL_HOME, 0, 0.05, &[0, 4]);
}

/// In scene 2 at 200 mm, trial 1 put the base 0.44 m off, on the floor and the spurious
/// returns, before the isolated returns were left out and the base stage's rigid run left out
/// the floor.
#[test]
fn the_abb_base_lost_in_a_ray_cast_scan_at_200_mm_is_found() {
    let Some(body) = abb_irb1600() else {
        return;
    };
    no_link_fails(&body, &ABB_TRIAL_HOME, 2, 0.2, &[1]);
}

/// In scene 0 at 1000 mm (the global search) the base was lost in both trials: in trial 0 the
/// floor's points, most of the detection's references, outvoted the robot's (no detected
/// pose within 0.1 m of the truth); in trial 1 the first joint's link, in the model at the
/// start's value, pulled the best-voted pose 0.19 m off, and the fit ended 0.6 m off (a probe
/// of the detection, not kept; docs/articulated-trials.md). The detection now leaves out the
/// planes larger than the proximal links and detects a base that is not round alone.
#[test]
fn the_abb_base_lost_in_ray_cast_scans_at_1000_mm_is_found() {
    let Some(body) = abb_irb1600() else {
        return;
    };
    no_link_fails(&body, &ABB_TRIAL_HOME, 0, 1.0, &[0, 1]);
}

/// In scene 0 at 1000 mm, trial 5 ended with the base turned 2.94 rad and joint 1 making up for
/// it: every link above within a few millimetres, the base's own points at 2.5 mm rms. The base
/// turn check took the best turn in its coarse band, a broad wrong one; the truth's narrow peak
/// scored 64 keypoints lower there and 405 higher in the fine band (a probe, not kept). The
/// check now looks finely at the best few coarse turns.
#[test]
fn the_abb_base_turned_in_a_ray_cast_scan_at_1000_mm_is_found() {
    let Some(body) = abb_irb1600() else {
        return;
    };
    no_link_fails(&body, &ABB_TRIAL_HOME, 0, 1.0, &[5]);
}

/// In scene 1 the wrist shows on some 65 keypoints, its joint 5 on about ten of them (link_5 is
/// round about that joint; the flange's side carries it). At 50 mm link_5 failed in 9 trials of
/// 10 (a probe, not kept): in seven, trial 1 among them, the fit had joint 5 within 0.006 rad
/// and the observability test, which wanted the motion spread over 12 points, reset it to the
/// start's; in three, trial 5 among them, the wrist's sweep counted 57 keypoints in its band at
/// the truth against 52 where it was (1.6 mm rms against 0.4 mm), short of its gain of 8, and
/// left joint 5 0.12 rad off. The sweep now grades each point by its distance, and the test
/// asks that the evidence survive losing its three strongest points.
#[test]
fn the_abb_wrist_seen_on_a_few_points_in_a_ray_cast_scan_is_fitted() {
    let Some(body) = abb_irb1600() else {
        return;
    };
    no_link_fails(&body, &ABB_TRIAL_HOME, 1, 0.05, &[1, 5]);
}

/// In scene 1 at 500 mm, trial 0 ended with the wrist folded the other way: joint 5 at -1.7 rad
/// against 0.78, beyond the reach of a sweep in a window about the state (0.46 rad each way), and
/// reported unobserved; 7 trials of 10 there and 8 at 1000 mm did the same. The wrist's joints
/// are now swept over their whole turn.
#[test]
fn the_abb_wrist_folded_the_other_way_in_a_ray_cast_scan_at_500_mm_is_found() {
    let Some(body) = abb_irb1600() else {
        return;
    };
    no_link_fails(&body, &ABB_TRIAL_HOME, 1, 0.5, &[0]);
}

/// In scene 1 at 1000 mm, trial 2 comes to the wrist's sweep with joint 5 at -1.53 rad against
/// 0.78. The sweep's coarse pass (a band four times the fine one, on the distance grids) scores
/// within 1 of its best from 0.27 to 0.81 rad, and a fine pass only about the best coarse peak
/// (0.38) missed the truth there, in 4 trials of 10 (a probe, not kept). The fine pass now
/// covers every coarse value within the scores' noise of the best.
#[test]
fn the_abb_wrist_on_the_coarse_sweeps_plateau_at_1000_mm_is_found() {
    let Some(body) = abb_irb1600() else {
        return;
    };
    no_link_fails(&body, &ABB_TRIAL_HOME, 1, 1.0, &[2]);
}

/// The refinements stopped when the step's motion over all points fell below the tolerance: a
/// wrist's hundred points among 30 000 moved by a millimetre count a twentieth of that. In
/// scene 4, trial 0 at 50 mm ended with joint 5 0.015 rad short (link_6 1.01 mm off), and in the
/// scenes of seed 77 the same scene's joints failed link_5 in trials 2, 4, 7 and 8 at 50 mm
/// (0.25 mm mean error on link_5 over the ten, 0.04 mm and 0.22 mm now). The exact refinements
/// now stop on the motion of the link they move most.
#[test]
fn the_abb_wrist_the_refinement_stopped_short_of_in_ray_cast_scans_is_fitted() {
    let Some(body) = abb_irb1600() else {
        return;
    };
    no_link_fails(&body, &ABB_TRIAL_HOME, 4, 0.05, &[0]);
    no_link_fails_with_seed(&body, &ABB_TRIAL_HOME, 77, 4, 0.05, &[2, 4]);
}

/// At 200 mm the whole robot's rigid alignment, pulled by the links still at the start's
/// joints, left the base 88 mm above the floor in seed 77's scene 2, trial 5: the only base
/// hypothesis there, and out of reach of the settling after each joint (a probe, not kept). The
/// proximal links are now also aligned on their own from 200 mm (a third of their 0.56 m
/// radius, where it was three quarters).
#[test]
fn the_abb_base_the_whole_robot_lifted_off_the_floor_at_200_mm_is_found() {
    let Some(body) = abb_irb1600() else {
        return;
    };
    no_link_fails_with_seed(&body, &ABB_TRIAL_HOME, 77, 2, 0.2, &[5]);
}

/// In scene 0 of seed 91 (the robot at home) at 500 mm, trials 2, 3, 4 and 7 lost the base:
/// the beam kept the base hypotheses set down on the floor beside the robot, whose undersides
/// explained 87 floor keypoints of its 3000 (and 27 others) against the truth's 97 others, and
/// dropped the true place after the first joint (a probe, not kept). At 200 mm trial 5 lost it
/// the same way. The floor's points now never count for the base in the beam's scores.
#[test]
fn the_abb_base_set_down_on_the_floor_beside_its_place_is_not_taken_for_it() {
    let Some(body) = abb_irb1600() else {
        return;
    };
    no_link_fails_with_seed(&body, &ABB_TRIAL_HOME, 91, 0, 0.5, &[2]);
    no_link_fails_with_seed(&body, &ABB_TRIAL_HOME, 91, 0, 0.2, &[5]);
}

/// In scene 0 of seed 91 at 1000 mm, 8 of 10 trials lost the base, trials 0 and 1 among them.
/// The detection dropped every reference's vote under a fifth of the best one's before merging
/// them: the true base, a pose many references agree on with few votes each, was among none of
/// the 117 poses left. With every vote merged it ranks 6th; and the beam dropped it all the same
/// at the wrist, whose pair search found no point to score from the true base (a probe, not
/// kept). Both fixed, the fit finds the robot in 10 of 10 trials there.
#[test]
fn the_abb_base_many_references_agree_on_with_few_votes_each_is_found_at_1000_mm() {
    let Some(body) = abb_irb1600() else {
        return;
    };
    no_link_fails_with_seed(&body, &ABB_TRIAL_HOME, 91, 0, 1.0, &[0, 1]);
}

/// In scene 1 of robot-scans' default seed at 1000 mm, trial 4 left joint 5 0.43 rad off, where
/// the scan does not pin it (the report set it unseen); the true value, which the scan pins,
/// explained 6.8 graded keypoints more of 65, short of the 8 the distal sweep asks between two
/// values. A value the scan pins is now taken over one it does not, for a gain of 4.
#[test]
fn the_abb_wrist_the_scan_pins_is_taken_over_one_it_does_not_at_1000_mm() {
    let Some(body) = abb_irb1600() else {
        return;
    };
    no_link_fails(&body, &ABB_TRIAL_HOME, 1, 1.0, &[4]);
}

/// In scene 1 of seed 91 at 200 mm, trial 0 lost link_4 and the wrist in every build: the 8
/// refinement steps that rank the beam's survivors turned one state's forearm roll 1.9 rad,
/// where the start allows 0.8, and that state won. A survivor whose refinement leaves a joint's
/// window is now ranked as it was before.
#[test]
fn the_abb_forearm_roll_the_ranking_refinement_turned_past_its_window_is_found_at_200_mm() {
    let Some(body) = abb_irb1600() else {
        return;
    };
    no_link_fails_with_seed(&body, &ABB_TRIAL_HOME, 91, 1, 0.2, &[0]);
}

/// In scene 4 of seed 77 at 500 mm, trial 0 left joint 5 0.05 rad off (link_5 1.9 mm, the
/// flange 3.1 mm), where the scan does not pin it. The true value, which the scan pins, graded
/// 3.75 more on 100 free keypoints, short of the pinning rule's 4; but 15 keypoints made that
/// gain and 1 gave some back. A gain most free points agree on (a paired test, z >= 3) now
/// counts as well.
#[test]
fn the_abb_wrist_a_gain_most_keypoints_agree_on_is_taken_at_500_mm() {
    let Some(body) = abb_irb1600() else {
        return;
    };
    no_link_fails_with_seed(&body, &ABB_TRIAL_HOME, 77, 4, 0.5, &[0]);
}

/// The fit's 95 % joint intervals against the truth, on ray-cast scans (mixed pixels, a floor and
/// a box, 0.5 mm noise): `(inside, counted)` over `scenes` fitted from 50 mm starts, and the
/// joints outside.
fn joints_within_their_intervals(
    body: &ArticulatedBody,
    home: &[f64],
    scenes: std::ops::Range<usize>,
) -> (usize, usize, Vec<String>) {
    use align_core::registration::articulated::{RobotFitOptions, align_robot};
    use align_core::trials::TrialRng;
    use align_core::trials::robot_trials::perturb_robot;
    let (mut inside, mut counted, mut outside) = (0, 0, Vec::new());
    for scene in scenes {
        let scanned = seeded_scene(body, home, SPREAD_RAD, SEED, scene, &ScanNoise::default())
            .expect("the scene scans");
        let mut rng = TrialRng::new(SEED ^ scene as u64);
        let (base, q0) = perturb_robot(body, &scanned.world_from_root, &scanned.q, 0.05, &mut rng);
        let fit = align_robot(
            body,
            &scanned.cloud(),
            &base,
            &q0,
            0.05,
            &RobotFitOptions::default(),
        )
        .expect("the fit runs");
        for (joint, truth) in fit.joints.iter().zip(&scanned.q) {
            let Some(within) = joint.within_95 else {
                continue;
            };
            counted += 1;
            let off = (joint.value - truth).abs();
            if off <= within {
                inside += 1;
            } else {
                outside.push(format!(
                    "scene {scene} {}: off {:.3} mrad, interval {:.3} mrad",
                    joint.name,
                    off * 1e3,
                    within * 1e3
                ));
            }
        }
    }
    (inside, counted, outside)
}

/// Each joint's 95 % interval holds its truth in at least nine fits of ten, on scans the fit's
/// model did not make: ray-cast, with mixed pixels at depth edges. Measured when written: the
/// UR10 23 of 24 (one shoulder lift 1.2 mrad off, its interval 0.5), the ABB 30 of 30.
#[test]
fn each_joints_95_percent_interval_holds_its_truth_in_ray_cast_scans() {
    let robot = ShippedRobot::Ur10;
    let body = ArticulatedBody::from_model(&robot.model().expect("shipped")).expect("surfaces");
    let mut robots = vec![("UR10", body, robot.home())];
    if let Some(abb) = abb_irb1600() {
        robots.push(("ABB IRB 1600", abb, ABB_TRIAL_HOME.to_vec()));
    }
    for (name, body, home) in &robots {
        let (inside, counted, outside) = joints_within_their_intervals(body, home, 0..6);
        eprintln!("{name}: {inside} of {counted} inside; {outside:?}");
        assert!(counted >= 20, "{name}: {counted} intervals");
        assert!(
            10 * inside >= 9 * counted,
            "{name}: {inside} of {counted}: {outside:?}"
        );
    }
}

/// The UR10 with CAD links at home (scene 0), in a scan that is mostly floor (2 658 of the
/// beam's 2 802 keypoints), lost its base in every trial at 200 mm: the beam ranked only states
/// lying on their side, whose links' undersides explained more of the floor than the robot's
/// own points (a probe, not kept). The floor's points now count for a link above the base only
/// where its surface faces up, as a scanner above sees it.
#[test]
fn the_cad_ur10_lying_on_the_floor_is_not_taken_for_it() {
    let Some(body) = ur10_cad() else {
        return;
    };
    no_link_fails(&body, &ShippedRobot::Ur10.home(), 0, 0.2, &[0, 5]);
}

/// At 500 mm, the same scene's base hypotheses (the whole robot's and the base and shoulder's
/// rigid alignments) all lay on their side or stood 0.18 m beside the base, under the upper
/// arm, a tube of the shoulder's girth: the base was lost in 6 of 10 trials, trials 0 and 1
/// among them (a probe, not kept). The base alone, stood on the floor the scan shows, is now
/// voted for by the keypoints at its height (`fit/standing.rs` in align-core).
#[test]
fn the_cad_ur10_base_stood_on_the_floor_is_found_at_500_mm() {
    let Some(body) = ur10_cad() else {
        return;
    };
    no_link_fails(&body, &ShippedRobot::Ur10.home(), 0, 0.5, &[0, 1]);
}

/// In scene 3 at 500 mm the base stood on the floor at its place was among the hypotheses, but
/// after the first joint the beam ranks states on the base and shoulder alone, and the places
/// the folded arm offers them explained more (16 keypoints for the truth against 18-28): the
/// base was lost in trials 2, 6, 10 and 11 (a probe, not kept). Each hypothesis's best state
/// now goes on to the second joint, where the arm decides; trials 6 and 10 are fitted (trial
/// 11 loses the arm after the second joint; trial 2's base turn, below).
#[test]
fn the_cad_ur10_base_ranked_low_on_its_first_link_is_kept_for_its_arm_at_500_mm() {
    let Some(body) = ur10_cad() else {
        return;
    };
    no_link_fails(&body, &ShippedRobot::Ur10.home(), 3, 0.5, &[6, 10]);
}

/// The CAD base is a disc with four lugs and a cable outlet, about 20 mm proud: in the base-turn
/// check's coarse band (three keypoint voxels) every turn of it scored alike (586-615 keypoints
/// in scene 1 trial 6 at 500 mm), and the base stayed 0.54 rad turned, joint 1 making up for
/// it; in scene 3 trial 2, 1.12 rad. In the fine band its true turn stood out (359 against the
/// fit's 229; a probe, not kept). The coarse turns are now scored in the fine band too.
#[test]
fn the_cad_ur10_base_turned_with_joint_1_making_up_for_it_is_found_at_500_mm() {
    let Some(body) = ur10_cad() else {
        return;
    };
    no_link_fails(&body, &ShippedRobot::Ur10.home(), 1, 0.5, &[6]);
    no_link_fails(&body, &ShippedRobot::Ur10.home(), 3, 0.5, &[2]);
}
