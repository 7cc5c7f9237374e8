//! A second look at a pose the exploration's score could not tell from its runner-up. That score
//! counts coarse keypoints (15 mm voxels) within a centimetre of the part, the right scale for
//! ranking the ends of short runs, but on a small part two poses a few centimetres apart fill it
//! alike: on the held-out CAD set C (`scripts/unseen-parts.sh`), the Go2's calf at 100 mm was
//! fitted 0.2 mm off by the local stage, at 0.3 mm rms, and the full alignment then chose its
//! half-turn twin, 316 mm off at 0.9 mm rms, on a score of 34 against 34. The contenders are run
//! down to the scanner's scale as the found pose was (the fine run and the polish), and the fine
//! keypoints are counted in the narrowest of their polishes' bands, a few of the residuals'
//! robust deviations. The one that explains clearly more is the pose. The result stays
//! ambiguous: a pose the search never reached cannot be compared, and when the fine count
//! was also made to decide the flag, set C's confident misses went from 4 to 14
//! (docs/cad-scan-trials.md).

use nalgebra::{Isometry3, Point3};

use super::PcaOptions;
use super::consensus::{Coarse, clearly_ahead, score_noise};
use super::exploration::same_pose;
use super::polish::polish;
use super::schedule::{RunSlack, ScheduleRun, run_schedule_on_levels};
use crate::geometry::Mesh;

/// At most this many of the exploration's ends besides the found pose are run down and counted
/// again: those within [`CONTENDER_NOISES`] of the coarse score's noise of the best, best
/// first, one per pose.
///
/// The coarse score ranks the true pose below a wrong one by more than its noise on small parts
/// in clutter: of the 96 misses the unseen sets A-D reported ambiguous at 200-1000 mm, 24 had
/// the truth among the exploration's ends (a probe, not kept), scoring up to 44 below the pose
/// chosen (335 against 291 on a UR5 shoulder) and ranked up to 35th among ends that are often
/// the same few poses. With three contenders within one noise (before the forty-second session)
/// they stayed misses; six within two fit 7 more of the 800 scenes of sets A-D and 8 more of
/// the 200 of set E (scanned after this was chosen), losing none (docs/cad-scan-trials.md).
const CONTENDERS: usize = 6;

/// How many of the coarse score's noises (see [`score_noise`]) below the best an end may score
/// and still be a contender.
const CONTENDER_NOISES: f64 = 2.0;

/// What the coarse score left undecided: the found pose's run (polished), the coarse score it is
/// measured against (the higher of its own and its runner-up's), and the exploration's ends
/// (coarse score, pose).
pub(super) struct Undecided<'a> {
    pub(super) run: &'a ScheduleRun,
    pub(super) score: f64,
    pub(super) ends: &'a [(f64, Isometry3<f64>)],
}

/// The found pose against the exploration's ends that score within [`CONTENDER_NOISES`] of the
/// coarse noise of it (at most [`CONTENDERS`], one per pose), each run down from `band0_m` on the
/// fine `keypoints` and polished (when the options polish, as the found pose was), all counted
/// on the fine keypoints off the large planes in the narrowest of their polishes' bands: the
/// contender's run when it explains more than the found pose by more than the count's noise;
/// `None` when the found pose stays.
pub(super) fn decide_finely(
    mesh: &Mesh,
    coarse: &Coarse,
    keypoints: &[Point3<f64>],
    undecided: Undecided,
    band0_m: f64,
    options: &PcaOptions,
) -> Option<ScheduleRun> {
    let Undecided {
        run: found_run,
        score: found_score,
        ends,
    } = undecided;
    let same = |a: &Isometry3<f64>, b: &Isometry3<f64>| same_pose(mesh, a, b);
    let bar = found_score - CONTENDER_NOISES * score_noise(found_score);
    let mut ranked = ends.to_vec();
    ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut starts: Vec<Isometry3<f64>> = Vec::new();
    for (score, end) in &ranked {
        if starts.len() == CONTENDERS || *score < bar {
            break;
        }
        if !same(end, &found_run.pose) && !starts.iter().any(|s| same(s, end)) {
            starts.push(*end);
        }
    }
    let refine = |start: &Isometry3<f64>| {
        let run = run_schedule_on_levels(
            mesh,
            &[(0.0, keypoints)],
            start,
            band0_m,
            options,
            RunSlack::EXACT,
            &[],
        );
        let polished = options
            .polish
            .then(|| polish(mesh, keypoints, &run.pose, run.delta, options))
            .flatten();
        match polished {
            Some(polished) => ScheduleRun {
                pose: polished.pose,
                iterations: run.iterations + polished.iterations,
                converged: run.converged && polished.converged,
                delta: polished.band_m,
            },
            None => run,
        }
    };
    let mut runs = vec![*found_run];
    for start in &starts {
        let run = refine(start);
        if !runs.iter().any(|r| same(&r.pose, &run.pose)) {
            runs.push(run);
        }
    }
    if runs.len() < 2 {
        return None;
    }
    // Counted off the large planes, as the coarse score is: a flat face laid on a box's side
    // explains its points to the micron.
    let counted = coarse.off_the_planes(keypoints);
    let contenders: Vec<(Isometry3<f64>, f64)> =
        runs[1..].iter().map(|r| (r.pose, r.delta)).collect();
    clearly_ahead(mesh, &counted, (&runs[0].pose, runs[0].delta), &contenders)
        .map(|best| runs[best + 1])
}

/// The local stage's end (`local`, run down and polished) in place of the pose `found` when it
/// explains clearly more of the scan (by more than [`score_noise`]), both counted on the fine
/// `keypoints` off the large planes in the narrower of their polishes' bands, as
/// [`decide_finely`] compares. The coarse score, which chose between them before the fine run,
/// counts 15 mm keypoints within a centimetre: on a small part it cannot tell a pose from one
/// 5 mm off, and the fine run and the polish may then end below the local end it beat (on the
/// held-out set F, the double pendulum's 59 mm base at 50 mm: the local end 0.25 mm off scored
/// 36, an exploration's end 5 mm off 37, and the pose found from it ended 9 mm off at 34, not
/// flagged, for the two are the same pose to the uniqueness test).
pub(super) fn local_end_ahead(
    mesh: &Mesh,
    coarse: &Coarse,
    keypoints: &[Point3<f64>],
    found: &ScheduleRun,
    local: &ScheduleRun,
) -> Option<ScheduleRun> {
    if local.pose == found.pose {
        return None;
    }
    let counted = coarse.off_the_planes(keypoints);
    clearly_ahead(
        mesh,
        &counted,
        (&found.pose, found.delta),
        &[(local.pose, local.delta)],
    )
    .map(|_| *local)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

    use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

    use super::{Undecided, decide_finely, local_end_ahead};
    use crate::geometry::Mesh;
    use crate::registration::convergence::pose_distance;
    use crate::registration::pca::PcaOptions;
    use crate::registration::pca::consensus::Coarse;
    use crate::registration::pca::schedule::ScheduleRun;
    use crate::registration::sampling::voxel_representatives;
    use crate::trials::clouds::{ScanOptions, scan_part};
    use crate::trials::parts::step_block;

    /// A found pose's run, fitted 3 mm loosely.
    fn found_at(pose: Isometry3<f64>) -> ScheduleRun {
        ScheduleRun {
            pose,
            iterations: 10,
            converged: true,
            delta: 0.003,
        }
    }

    /// The part scanned at `truth` beside a box on the floor: the fine keypoints and the coarse
    /// score.
    fn scene(mesh: &Mesh, truth: &Isometry3<f64>) -> (Vec<Point3<f64>>, Coarse) {
        let options = PcaOptions::default();
        let scan = ScanOptions {
            floor: true,
            neighbour: true,
            ..ScanOptions::default()
        };
        let cloud = scan_part(mesh, truth, &scan);
        let coarse = Coarse::new(mesh, &cloud, &options);
        (voxel_representatives(&cloud, options.voxel_m), coarse)
    }

    fn decide(
        mesh: &Mesh,
        truth: &Isometry3<f64>,
        found: Isometry3<f64>,
        contender: Isometry3<f64>,
    ) -> Option<ScheduleRun> {
        decide_scored(mesh, truth, found, (100.0, contender))
    }

    /// As [`decide`], the found pose's coarse score 100 and the contender's given.
    fn decide_scored(
        mesh: &Mesh,
        truth: &Isometry3<f64>,
        found: Isometry3<f64>,
        contender: (f64, Isometry3<f64>),
    ) -> Option<ScheduleRun> {
        let (keypoints, coarse) = scene(mesh, truth);
        decide_finely(
            mesh,
            &coarse,
            &keypoints,
            Undecided {
                run: &found_at(found),
                score: 100.0,
                ends: &[contender, (10.0, *truth)],
            },
            0.03,
            &PcaOptions::default(),
        )
    }

    /// The step block on the floor (mesh, truth), the block slid 80 mm along the floor (a found
    /// pose) and the truth 2 mm and 0.01 rad off, as a short run on coarse keypoints ends (a
    /// contender).
    fn slid_block() -> (Mesh, Isometry3<f64>, Isometry3<f64>, Isometry3<f64>) {
        let mesh = step_block().unwrap().mesh;
        let truth = Isometry3::new(Vector3::new(0.7, -0.1, 0.0), Vector3::new(0.0, 0.0, 0.5));
        let slid = Isometry3::translation(0.08, 0.0, 0.0) * truth;
        let near_truth = Isometry3::from_parts(
            Translation3::new(0.002, -0.001, 0.001),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.01),
        ) * truth;
        (mesh, truth, slid, near_truth)
    }

    #[test]
    fn a_pose_slid_off_the_part_gives_way_to_the_contender_that_fits_it() {
        // The truth itself scores too low to be a contender: only what the search reached is
        // compared.
        let (mesh, truth, slid, near_truth) = slid_block();
        let decided = decide(&mesh, &truth, slid, near_truth).unwrap();
        let off_m = pose_distance(&decided.pose, &truth, mesh.radius_m());
        assert!(off_m < 5e-4, "{off_m} m off the truth");
        // The other way round the found pose stays.
        assert!(decide(&mesh, &truth, truth, slid).is_none());
    }

    #[test]
    fn a_contender_beyond_the_coarse_noise_but_within_twice_it_is_run_down_too() {
        let (mesh, truth, slid, near_truth) = slid_block();
        // The found pose scores 100, whose noise is 20: a contender at 70 is within twice it
        // (the coarse score ranked the true pose of the unseen sets' misses up to 44 below a
        // wrong one, docs/cad-scan-trials.md), one at 55 is not.
        let decided = decide_scored(&mesh, &truth, slid, (70.0, near_truth)).unwrap();
        let off_m = pose_distance(&decided.pose, &truth, mesh.radius_m());
        assert!(off_m < 5e-4, "{off_m} m off the truth");
        assert!(decide_scored(&mesh, &truth, slid, (55.0, near_truth)).is_none());
    }

    #[test]
    fn a_box_and_its_half_turn_explain_the_scan_alike_and_the_found_pose_stays() {
        let mesh = Mesh::cuboid([0.2, 0.1, 0.06]).unwrap();
        let truth = Isometry3::new(Vector3::new(0.7, -0.1, 0.03), Vector3::new(0.0, 0.0, 0.5));
        let centre = mesh.centroid();
        let half_turn = truth
            * Isometry3::translation(centre.x, centre.y, centre.z)
            * Isometry3::rotation(Vector3::z() * std::f64::consts::PI)
            * Isometry3::translation(-centre.x, -centre.y, -centre.z);
        assert!(decide(&mesh, &truth, half_turn, truth).is_none());
    }

    #[test]
    fn a_local_end_on_the_part_replaces_a_pose_found_a_few_millimetres_off_and_not_the_reverse() {
        // The pose found 6 mm and 0.02 rad off (what the coarse score cannot tell from the
        // truth on a small part), the local stage's end on the truth; both polished to 1 mm.
        let mesh = step_block().unwrap().mesh;
        let truth = Isometry3::new(Vector3::new(0.7, -0.1, 0.0), Vector3::new(0.0, 0.0, 0.5));
        let off = Isometry3::from_parts(
            Translation3::new(0.006, -0.002, 0.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.02),
        ) * truth;
        let (keypoints, coarse) = scene(&mesh, &truth);
        let polished = |pose| ScheduleRun {
            delta: 0.001,
            ..found_at(pose)
        };
        let replaced =
            local_end_ahead(&mesh, &coarse, &keypoints, &polished(off), &polished(truth));
        assert_eq!(replaced.map(|run| run.pose), Some(truth));
        assert!(
            local_end_ahead(&mesh, &coarse, &keypoints, &polished(truth), &polished(off)).is_none()
        );
        assert!(
            local_end_ahead(
                &mesh,
                &coarse,
                &keypoints,
                &polished(truth),
                &polished(truth)
            )
            .is_none()
        );
    }
}
