//! Hops out of a near miss. The narrow bands and the polish settle a pose where the residuals'
//! pulls balance, and on real CAD that can be millimetres from the truth: on the held-out set C
//! (`scripts/unseen-parts.sh`), the TALOS arm's second link at 50 mm ended 3 mm off at 0.72 mm
//! rms, where the truth fits the same scan at 0.33 mm. The link's visual mesh is a shell with
//! walls about 3 mm thick; along the straight path to the truth, the count of points within
//! half a millimetre falls from 375 to 229 half way and rises to 593 (a ridge between two
//! basins), so no step from there goes back. Both peers ended 1.6-1.7 mm off the same scan.
//!
//! Such an end leaves the scan in the part's material: of the polish's last matches more than a
//! robust standard deviation off their surface, 165 lay behind it and 53 in front, where the
//! scanner's noise alone puts about as many on each side. Then (see `Sides::mostly_behind`) the
//! found pose is shifted and turned a few millimetres each way and each start is polished.
//!
//! Not every near miss is inside the material. On the held-out set D, a Centauro arm link
//! (non-manifold CAD) ended 2.9 mm off at 0.60 mm rms with as many matches on each side of the
//! surface, where the truth fits at 0.34 mm; a start 3 mm off along one axis slides back to
//! the truth. A full alignment therefore also hops from its final pose, along the axes only
//! (half the starts: the turns fitted nothing more there). Counted keypoints within the
//! narrowest band could not tell the two (a temporary trace, not kept: 424 against 403, within
//! the count's noise of 41):
//! the near miss's band had widened to hold its own offset points. Each end is now compared
//! with the found pose point by point, by Tukey's biweight loss at the narrowest band (the
//! polish's own objective), and it must win by three standard deviations of the paired
//! differences (docs/cad-scan-trials.md, thirty-seventh session).

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::PcaOptions;
use super::consensus::{Coarse, narrowest_band};
use super::polish::{Polished, polish, polish_in_steps};
use super::schedule::ScheduleRun;
use crate::geometry::Mesh;

/// The starts are this fraction of the last band off the found pose, shifted along each of the
/// base frame's axes or turned about them by as much at the part's radius.
const HOP_FRACTION_OF_BAND: f64 = 0.3;

/// At most this many hops in a row: each from the pose the last one reached.
const MAX_HOPS: usize = 2;

/// A start's steps match about this many keypoints at most (one in every n): they only find the
/// basin the start lies in, and the comparison and the last polish use every keypoint. The
/// links of the 50 mm CAD scans had 700-2400 keypoints near them, and the six starts' two steps
/// on all of them were about two thirds of the hop's time (a temporary probe); every scene of
/// the four unseen sets ends as before (docs/BENCHMARKS.md, fortieth session).
const SETTLE_MATCHES_PER_STEP: f64 = 600.0;

/// Which starts a hop polishes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum HopStarts {
    /// Shifted along each of the base frame's axes and turned about them.
    ShiftsAndTurns,
    /// Shifted only: half the cost, for the hop every full alignment makes.
    Shifts,
}

impl HopStarts {
    /// The polish's steps each start takes before the comparison: enough to slide into the
    /// basin it starts in, and only the best start is polished to the end. The shifts of every
    /// full alignment take two: on all four sets' 800 scenes they fitted exactly the scans six
    /// did, for 2-12 ms less at 50 mm (docs/BENCHMARKS.md, thirty-eighth session).
    fn steps_per_start(self) -> usize {
        match self {
            HopStarts::ShiftsAndTurns => 6,
            HopStarts::Shifts => 2,
        }
    }
}

/// The found pose's `run` (polished), or a start that ends where `counted` fits clearly better
/// (see [`fits_clearly_better`]), hopped again from there up to [`MAX_HOPS`] times; `None` when
/// the found pose stays. `keypoints` are the fine keypoints the polish steps on, `band_m` the
/// schedule's last band, `kinds` the starts tried.
pub(super) fn hop(
    mesh: &Mesh,
    keypoints: &[Point3<f64>],
    counted: &[Point3<f64>],
    run: &ScheduleRun,
    band_m: f64,
    options: &PcaOptions,
    kinds: HopStarts,
) -> Option<ScheduleRun> {
    let mut current = *run;
    let mut hopped = false;
    for _ in 0..MAX_HOPS {
        let starts = starts_around(mesh, &current.pose, band_m, kinds);
        let settle = |start: &Isometry3<f64>| {
            polish_in_steps(
                mesh,
                keypoints,
                start,
                band_m,
                options,
                (kinds.steps_per_start(), SETTLE_MATCHES_PER_STEP),
            )
        };
        let ends: Vec<Polished> = if options.parallel {
            starts.par_iter().filter_map(settle).collect()
        } else {
            starts.iter().filter_map(settle).collect()
        };
        let counted_ends: Vec<(Isometry3<f64>, f64)> =
            ends.iter().map(|end| (end.pose, end.band_m)).collect();
        let Some(best) = fits_clearly_better(
            mesh,
            counted,
            (&current.pose, current.delta),
            &counted_ends,
            options.parallel,
        )
        .map(|index| ends[index]) else {
            break;
        };
        // The start's few steps found the better basin; the polish settles in it.
        let settled = polish(mesh, keypoints, &best.pose, band_m, options).unwrap_or(best);
        current = ScheduleRun {
            pose: settled.pose,
            iterations: current.iterations + best.iterations + settled.iterations,
            converged: settled.converged,
            delta: settled.band_m,
        };
        hopped = true;
    }
    hopped.then_some(current)
}

/// A full alignment's hop from its final `run`, along the axes only, `counted` the fine
/// keypoints off the large planes (as the coarse score counts) and the band the schedule's
/// last (`delta_min_m`, or `delta0_m` when smaller).
pub(super) fn hop_from_the_end(
    mesh: &Mesh,
    keypoints: &[Point3<f64>],
    coarse: &Coarse,
    run: &ScheduleRun,
    delta0_m: f64,
    options: &PcaOptions,
) -> Option<ScheduleRun> {
    let counted = coarse.off_the_planes(keypoints);
    let band_m = options.delta_min_m.min(delta0_m);
    hop(
        mesh,
        keypoints,
        &counted,
        run,
        band_m,
        options,
        HopStarts::Shifts,
    )
}

/// Tukey's biweight loss of each of `points` at `pose`, the band its cutoff (1 beyond it). The
/// search for a point's surface stops at the band: beyond it the loss is 1 whatever the
/// distance (the floor's and a neighbour's points near the part's box, the scan's far side).
fn biweight_losses(
    mesh: &Mesh,
    points: &[Point3<f64>],
    pose: &Isometry3<f64>,
    band_m: f64,
) -> Vec<f64> {
    let part_from_base = pose.inverse();
    points
        .iter()
        .map(|p| {
            let Some(found) = mesh.closest_point_within(&(part_from_base * p), band_m) else {
                return 1.0;
            };
            let u = found.signed_distance.abs() / band_m;
            if u >= 1.0 {
                1.0
            } else {
                1.0 - (1.0 - u * u).powi(3)
            }
        })
        .collect()
}

/// Of `ends`, the one whose fit to `counted` is clearly better than `found`'s: the lowest sum
/// of Tukey's biweight loss in the narrowest of the bands, lower than found's by more than
/// three times the paired differences' spread (a paired z-test). With `parallel`, the poses'
/// losses are computed on all threads: at 50 mm the comparison was about half of the hop's
/// time (a temporary probe, not kept; docs/BENCHMARKS.md, thirty-ninth session). The sums are
/// taken in the same order either way, so the answer does not depend on it.
fn fits_clearly_better(
    mesh: &Mesh,
    counted: &[Point3<f64>],
    found: (&Isometry3<f64>, f64),
    ends: &[(Isometry3<f64>, f64)],
    parallel: bool,
) -> Option<usize> {
    let (found_pose, found_band_m) = found;
    let band_m = narrowest_band(found_band_m, ends);
    // Only points near the part at either pose matter; the others lose 1 at both.
    let (lower, upper) = mesh.bounds();
    let reach = 3.0 * found_band_m;
    let part_from_base = found_pose.inverse();
    let near: Vec<Point3<f64>> = counted
        .iter()
        .filter(|p| {
            let q = part_from_base * *p;
            (0..3).all(|a| q[a] >= lower[a] - reach && q[a] <= upper[a] + reach)
        })
        .copied()
        .collect();
    // The found pose first, then every end.
    let poses: Vec<&Isometry3<f64>> = std::iter::once(found_pose)
        .chain(ends.iter().map(|(pose, _)| pose))
        .collect();
    let losses_at = |pose: &&Isometry3<f64>| biweight_losses(mesh, &near, pose, band_m);
    let losses: Vec<Vec<f64>> = if parallel {
        poses.par_iter().map(losses_at).collect()
    } else {
        poses.iter().map(losses_at).collect()
    };
    let (found_losses, end_losses) = losses.split_first()?;
    let mut best: Option<(usize, f64)> = None;
    for (index, losses) in end_losses.iter().enumerate() {
        let (mut gain, mut spread) = (0.0, 0.0);
        for (a, b) in found_losses.iter().zip(losses) {
            gain += a - b;
            spread += (a - b) * (a - b);
        }
        if gain > 3.0 * spread.sqrt() && best.is_none_or(|(_, g)| gain > g) {
            best = Some((index, gain));
        }
    }
    best.map(|(index, _)| index)
}

/// The found pose shifted by [`HOP_FRACTION_OF_BAND`] of `band_m` each way along the base
/// frame's axes, and turned each way about axes through the part's centre parallel to them by
/// as much at its radius.
fn starts_around(
    mesh: &Mesh,
    pose: &Isometry3<f64>,
    band_m: f64,
    kinds: HopStarts,
) -> Vec<Isometry3<f64>> {
    let hop_m = HOP_FRACTION_OF_BAND * band_m;
    let turn_rad = hop_m / mesh.radius_m().max(hop_m);
    let centre = pose * mesh.centroid();
    let mut starts = Vec::with_capacity(12);
    for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
        for sign in [-1.0, 1.0] {
            starts.push(Translation3::from(axis * (sign * hop_m)) * pose);
            if kinds == HopStarts::Shifts {
                continue;
            }
            let turn = UnitQuaternion::from_scaled_axis(axis * (sign * turn_rad));
            let about_centre =
                Translation3::from(centre.coords) * turn * Translation3::from(-centre.coords);
            starts.push(about_centre * pose);
        }
    }
    starts
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

    use nalgebra::{Isometry3, Point3, Vector3};

    use super::{HopStarts, fits_clearly_better, hop};
    use crate::geometry::Mesh;
    use crate::registration::pca::PcaOptions;
    use crate::registration::pca::polish::BAND_PER_SIGMA;
    use crate::registration::pca::polish::polish;
    use crate::registration::pca::schedule::ScheduleRun;
    use crate::registration::sampling::voxel_representatives;
    use crate::trials::clouds::{ScanOptions, scan_part};
    use crate::trials::parts::step_block;

    /// A hollow bar's outer box (what a scanner sees) and its shell: the box with 3 mm walls
    /// round a closed cavity, the cavity's faces turned in, as a cast or printed part's visual
    /// mesh is.
    fn hollow_bar(size_m: [f64; 3]) -> (Mesh, Mesh) {
        let outer = Mesh::cuboid(size_m).unwrap();
        let cavity = Mesh::cuboid(size_m.map(|s| s - 0.006)).unwrap();
        let mut vertices: Vec<Point3<f64>> = outer.vertices().collect();
        let mut triangles: Vec<[u32; 3]> = outer.triangles().to_vec();
        let offset = vertices.len() as u32;
        vertices.extend(cavity.vertices());
        triangles.extend(
            cavity
                .triangles()
                .iter()
                .map(|[a, b, c]| [a + offset, c + offset, b + offset]),
        );
        (outer, Mesh::new(&vertices, &triangles).unwrap())
    }

    #[test]
    fn a_fit_millimetres_off_is_clearly_worse_and_one_a_hair_off_is_not() {
        let mesh = step_block().unwrap().mesh;
        let truth = Isometry3::new(Vector3::new(0.7, -0.1, 0.0), Vector3::new(0.0, 0.0, 0.5));
        let noise_m = 0.0005;
        let scan = ScanOptions {
            noise_sigma_m: noise_m,
            floor: true,
            neighbour: true,
            ..ScanOptions::default()
        };
        let keypoints = voxel_representatives(&scan_part(&mesh, &truth, &scan), 0.005);
        let band_m = BAND_PER_SIGMA * noise_m;
        let near_miss = Isometry3::translation(0.002, -0.0015, 0.0) * truth;
        let hair_off = Isometry3::translation(0.00005, 0.0, 0.0) * truth;
        let far = Isometry3::translation(0.3, 0.0, 0.0) * truth;
        let ends = [(far, band_m), (truth, band_m), (hair_off, band_m)];
        // On all threads or one, the same answer.
        for parallel in [false, true] {
            // From the near miss the truth fits clearly better (the hair-off pose as well, less).
            assert_eq!(
                fits_clearly_better(&mesh, &keypoints, (&near_miss, band_m), &ends, parallel),
                Some(1)
            );
            // From the truth, nothing; a pose 50 um off fits as well, within the noise.
            let others = [(near_miss, band_m), (hair_off, band_m), (far, band_m)];
            assert_eq!(
                fits_clearly_better(&mesh, &keypoints, (&truth, band_m), &others, parallel),
                None
            );
            assert_eq!(
                fits_clearly_better(
                    &mesh,
                    &keypoints,
                    (&hair_off, band_m),
                    &[(truth, band_m)],
                    parallel,
                ),
                None
            );
        }
    }

    #[test]
    fn a_face_settled_on_the_inner_wall_of_a_shell_hops_back_to_the_outer_one() {
        let (outer, shell) = hollow_bar([0.009, 0.02, 0.6]);
        let truth = Isometry3::translation(0.5, 0.0, 0.3);
        // Seen from two sides and the front: the front face and both sides, not the back.
        let scan = ScanOptions {
            spacing_m: 0.003,
            noise_sigma_m: 0.0003,
            scanners: vec![Point3::new(1.5, 1.0, 0.3), Point3::new(1.5, -1.0, 0.3)],
            ..ScanOptions::default()
        };
        let options = PcaOptions::default();
        let keypoints = voxel_representatives(&scan_part(&outer, &truth, &scan), options.voxel_m);
        let band_m = 0.01;
        let polished_from = |pose: &Isometry3<f64>| {
            let polished = polish(&shell, &keypoints, pose, band_m, &options).unwrap();
            let run = ScheduleRun {
                pose: polished.pose,
                iterations: polished.iterations,
                converged: polished.converged,
                delta: polished.band_m,
            };
            (run, polished.off_the_surface.mostly_behind())
        };
        // How far the front face is from the scan's, along the bar's depth: the bar's length
        // and its spin about it are barely constrained by a scan of its long faces.
        let front = Point3::new(0.0045, 0.0, 0.0);
        let forward_of_truth_m = |pose: &Isometry3<f64>| (pose * front).x - (truth * front).x;
        // 3 mm forward the front face's points lie on the cavity's front wall, and only the
        // sides' back ends, 3 mm past the back edge, say it is wrong.
        let (settled, settled_inside) =
            polished_from(&(Isometry3::translation(0.003, 0.0, 0.0) * truth));
        let settled_off_m = forward_of_truth_m(&settled.pose);
        assert!(
            settled_off_m > 0.0025,
            "the polish alone settled {settled_off_m} m forward"
        );
        assert!(
            settled_inside,
            "the polish's end is not mostly behind the surface"
        );
        let hopped = hop(
            &shell,
            &keypoints,
            &keypoints,
            &settled,
            band_m,
            &options,
            HopStarts::ShiftsAndTurns,
        )
        .unwrap();
        let off_m = forward_of_truth_m(&hopped.pose);
        assert!(
            off_m.abs() < 2e-4,
            "hopped to {off_m} m forward of the truth"
        );
        // From the truth nothing fits better, and the residuals are the noise's, on both sides.
        let (at_truth, truth_inside) = polished_from(&truth);
        assert!(!truth_inside);
        assert!(
            hop(
                &shell,
                &keypoints,
                &keypoints,
                &at_truth,
                band_m,
                &options,
                HopStarts::ShiftsAndTurns
            )
            .is_none()
        );
    }
}
