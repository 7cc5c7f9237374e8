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
//! scanner's noise alone puts about as many on each side. Only then (see
//! `Sides::mostly_behind`), the found pose is shifted and turned a few millimetres each way,
//! each start is polished, and the fine keypoints are counted in the narrowest of the polishes'
//! bands: a start that ends where clearly more of them fit is the pose. Hopping from every end
//! fitted no more scans of the three unseen sets at 50-200 mm and made that scan's alignment
//! 48 -> 147 ms (docs/cad-scan-trials.md).

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::PcaOptions;
use super::consensus::clearly_ahead;
use super::polish::{Polished, polish, polish_in_steps};
use super::schedule::ScheduleRun;
use crate::geometry::Mesh;

/// The starts are this fraction of the last band off the found pose, shifted along each of the
/// base frame's axes or turned about them by as much at the part's radius.
const HOP_FRACTION_OF_BAND: f64 = 0.3;

/// At most this many hops in a row: each from the pose the last one reached.
const MAX_HOPS: usize = 2;

/// Each start takes at most this many of the polish's steps before the count: enough to slide
/// into the basin it starts in, and only the best start is polished to the end.
const STEPS_PER_START: usize = 6;

/// The found pose's `run` (polished), or a start that ends where clearly more of `counted` fit
/// (by more than the count's noise, in the narrowest of the polishes' bands), hopped again from
/// there up to [`MAX_HOPS`] times; `None` when the found pose stays. `keypoints` are the fine
/// keypoints the polish steps on, `band_m` the schedule's last band.
pub(super) fn hop(
    mesh: &Mesh,
    keypoints: &[Point3<f64>],
    counted: &[Point3<f64>],
    run: &ScheduleRun,
    band_m: f64,
    options: &PcaOptions,
) -> Option<ScheduleRun> {
    let mut current = *run;
    let mut hopped = false;
    for _ in 0..MAX_HOPS {
        let starts = starts_around(mesh, &current.pose, band_m);
        let settle = |start: &Isometry3<f64>| {
            polish_in_steps(mesh, keypoints, start, band_m, options, STEPS_PER_START)
        };
        let ends: Vec<Polished> = if options.parallel {
            starts.par_iter().filter_map(settle).collect()
        } else {
            starts.iter().filter_map(settle).collect()
        };
        let counted_ends: Vec<(Isometry3<f64>, f64)> =
            ends.iter().map(|end| (end.pose, end.band_m)).collect();
        let Some(best) =
            clearly_ahead(mesh, counted, (&current.pose, current.delta), &counted_ends)
                .map(|index| ends[index])
        else {
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

/// The found pose shifted by [`HOP_FRACTION_OF_BAND`] of `band_m` each way along the base
/// frame's axes, and turned each way about axes through the part's centre parallel to them by
/// as much at its radius.
fn starts_around(mesh: &Mesh, pose: &Isometry3<f64>, band_m: f64) -> Vec<Isometry3<f64>> {
    let hop_m = HOP_FRACTION_OF_BAND * band_m;
    let turn_rad = hop_m / mesh.radius_m().max(hop_m);
    let centre = pose * mesh.centroid();
    let mut starts = Vec::with_capacity(12);
    for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
        for sign in [-1.0, 1.0] {
            starts.push(Translation3::from(axis * (sign * hop_m)) * pose);
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

    use nalgebra::{Isometry3, Point3};

    use super::hop;
    use crate::geometry::Mesh;
    use crate::registration::pca::PcaOptions;
    use crate::registration::pca::polish::polish;
    use crate::registration::pca::schedule::ScheduleRun;
    use crate::registration::sampling::voxel_representatives;
    use crate::trials::clouds::{ScanOptions, scan_part};

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
        let hopped = hop(&shell, &keypoints, &keypoints, &settled, band_m, &options).unwrap();
        let off_m = forward_of_truth_m(&hopped.pose);
        assert!(
            off_m.abs() < 2e-4,
            "hopped to {off_m} m forward of the truth"
        );
        // From the truth nothing fits better, and the residuals are the noise's, on both sides.
        let (at_truth, truth_inside) = polished_from(&truth);
        assert!(!truth_inside);
        assert!(hop(&shell, &keypoints, &keypoints, &at_truth, band_m, &options).is_none());
    }
}
