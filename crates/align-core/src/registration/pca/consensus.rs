//! How much of a scan a pose of the part explains: the score the exploration ranks its ends by,
//! the uniqueness test compares poses with, and the checks of a run against its start use.

use nalgebra::{Isometry3, Point3, Vector3};

use super::PcaOptions;
use super::planes::{large_planes, off_the_planes};
use crate::geometry::Mesh;
use crate::registration::sampling::{surface_normals_at, voxel_representatives};

/// The score the exploration ranks poses by (coarse keypoints of `cloud` within a band of the
/// part's surface at `pose`, less those inside it), for telling why a pose is wrong against a
/// known truth: a truth that scores higher is a pose the search never reached; one that scores
/// lower is a scan the score cannot read (crates/cad-scans).
pub fn scan_consensus(
    mesh: &Mesh,
    cloud: &[Point3<f64>],
    pose: &Isometry3<f64>,
    options: &PcaOptions,
) -> f64 {
    Coarse::new(mesh, cloud, options).score(mesh, pose)
}

/// The coarse keypoints the exploration runs on and scores its runs with, and the band it
/// scores in, built once per alignment (a voxel grid of the whole cloud and the plane search;
/// rebuilt for every stage that scored, they were a fifth to a third of a 50 mm alignment's
/// time on the CAD scans).
pub(super) struct Coarse {
    /// One keypoint per voxel of three times the options' voxel.
    pub(super) all: Vec<Point3<f64>>,
    /// `all` without the planes too large to be the part's (see [`super::planes`]); `None`
    /// when the options keep them.
    without_planes: Option<Vec<Point3<f64>>>,
    /// The scan's normal at each of the scored keypoints (see [`oriented_consensus`]); empty
    /// when the options score without them.
    scored_normals: Vec<Option<Vector3<f64>>>,
    /// The planes left out of `without_planes` (a point on each and its unit normal; empty when
    /// the options keep them).
    planes: Vec<(Point3<f64>, Vector3<f64>)>,
    /// The cloud's points off `planes`; `None` when there are none, and when neither the
    /// oriented score nor the wide exploration asks for them.
    cloud_off_planes: Option<Vec<Point3<f64>>>,
    band_m: f64,
}

impl Coarse {
    pub(super) fn new(mesh: &Mesh, cloud: &[Point3<f64>], options: &PcaOptions) -> Self {
        let voxel_m = options.voxel_m * 3.0;
        let all = voxel_representatives(cloud, voxel_m);
        let planes = if options.without_large_planes {
            large_planes(&all, mesh, voxel_m)
        } else {
            Vec::new()
        };
        let without_planes = options
            .without_large_planes
            .then(|| off_the_planes(&all, &planes));
        // Only the keypoints the score counts, from the points off the planes: the floor is
        // most of a cell's scan, and its normals were 30-130 ms of 20-115k-point scans (a
        // probe, not kept).
        // For the normals and the wide exploration's second detection only: the robot fit's
        // base stage, which needs neither, would copy its whole scan for nothing.
        let cloud_off_planes = (!planes.is_empty()
            && (options.oriented_score || options.wide_exploration))
            .then(|| off_the_planes(cloud, &planes));
        let scored_normals = if options.oriented_score {
            let scored = without_planes.as_deref().unwrap_or(&all);
            let surface = cloud_off_planes.as_deref().unwrap_or(cloud);
            surface_normals_at(surface, scored, voxel_m)
        } else {
            Vec::new()
        };
        Self {
            all,
            without_planes,
            scored_normals,
            planes,
            cloud_off_planes,
            band_m: (options.voxel_m * 2.0).max(options.delta_min_m * 0.3),
        }
    }

    /// The keypoints every score counts (and the runs from a far start follow).
    pub(super) fn scored(&self) -> &[Point3<f64>] {
        self.without_planes.as_deref().unwrap_or(&self.all)
    }

    /// Whether `pose` explains less of the scan than `than` by more than the scores' sampling
    /// noise (see [`score_noise`]).
    pub(super) fn explains_less(
        &self,
        mesh: &Mesh,
        pose: &Isometry3<f64>,
        than: &Isometry3<f64>,
    ) -> bool {
        let than_score = self.score(mesh, than);
        self.score(mesh, pose) < than_score - score_noise(than_score)
    }

    /// The cloud without the planes the scores leave out; `None` when they leave none out (or
    /// the options neither score oriented nor explore wide).
    pub(super) fn cloud_off_planes(&self) -> Option<&[Point3<f64>]> {
        self.cloud_off_planes.as_deref()
    }

    /// `points` without those on the planes the scores leave out.
    pub(super) fn off_the_planes(&self, points: &[Point3<f64>]) -> Vec<Point3<f64>> {
        off_the_planes(points, &self.planes)
    }

    /// The score of `pose` (see [`oriented_consensus`]).
    pub(super) fn score(&self, mesh: &Mesh, pose: &Isometry3<f64>) -> f64 {
        self.score_in_band(mesh, pose, self.band_m)
    }

    /// The score of `pose` in a band of `band_m`.
    pub(super) fn score_in_band(&self, mesh: &Mesh, pose: &Isometry3<f64>, band_m: f64) -> f64 {
        oriented_consensus(mesh, self.scored(), &self.scored_normals, pose, band_m)
    }
}

/// How well a pose explains the scan: keypoints on the surface (within `band`) count for it,
/// keypoints deep inside the part count against it twice, since a scanner cannot see into a
/// solid. Clutter neither helps nor hurts a pose it does not touch.
pub(super) fn consensus(
    mesh: &Mesh,
    keypoints: &[Point3<f64>],
    pose: &Isometry3<f64>,
    band: f64,
) -> f64 {
    oriented_consensus(mesh, keypoints, &[], pose, band)
}

/// A keypoint on the surface counts only while the scan's normal there is within this angle
/// (its cosine) of the surface's, either sign.
const AGREEING_NORMALS_COS: f64 = 0.866;

/// [`consensus`], where a keypoint with a normal in `normals` (the scan's, by index; a shorter
/// list leaves the rest without) counts on the surface only when that normal agrees with the
/// surface's there (see [`AGREEING_NORMALS_COS`]). A wrong pose of a small part in clutter
/// explains many keypoints where the floor or a box merely crosses its surface, across it; the
/// true pose explains its own, along it. In the 79 scans of the unseen CAD sets A-D reported
/// ambiguous and missed where the part is not symmetric, the truth explained clearly more than
/// the pose found in 23 counted without normals and in 43 with them (an Open3D probe, not
/// kept). Replayed, sets A-D fitted 16 more scans of 800 (25 fitted, 9 lost) and the held-out
/// set E 18 more of 200, none lost (docs/cad-scan-trials.md, forty-third session).
pub(super) fn oriented_consensus(
    mesh: &Mesh,
    keypoints: &[Point3<f64>],
    normals: &[Option<Vector3<f64>>],
    pose: &Isometry3<f64>,
    band: f64,
) -> f64 {
    let part_from_base = pose.inverse();
    let (lower, upper) = mesh.bounds();
    keypoints
        .iter()
        .enumerate()
        .map(|(index, p)| (index, part_from_base * p))
        .filter(|(_, p)| {
            (0..3).all(|axis| p[axis] >= lower[axis] - band && p[axis] <= upper[axis] + band)
        })
        .map(|(index, p)| {
            let closest = mesh.closest_point(&p);
            if closest.signed_distance.abs() <= band {
                let across = normals.get(index).copied().flatten().is_some_and(|normal| {
                    let surface = mesh.triangle_normal(closest.triangle);
                    (part_from_base.rotation * normal).dot(&surface).abs() < AGREEING_NORMALS_COS
                });
                if across { 0.0 } else { 1.0 }
            } else if mesh.is_inside_deeper_than(&p, &closest, band) {
                -2.0
            } else {
                0.0
            }
        })
        .sum()
}

/// Of `ends` (pose, the band its polish ended in), the one that explains clearly more of
/// `counted` than `found` does (by more than [`score_noise`]), all counted in the narrowest of
/// the bands, `found`'s among them: the pose that fits best measures the scanner's noise best,
/// and in a wider band a worse fit's points would count as well. The last of equal bests.
pub(super) fn clearly_ahead(
    mesh: &Mesh,
    counted: &[Point3<f64>],
    found: (&Isometry3<f64>, f64),
    ends: &[(Isometry3<f64>, f64)],
) -> Option<usize> {
    let (found_pose, found_band_m) = found;
    let band_m = narrowest_band(found_band_m, ends);
    let found_score = consensus(mesh, counted, found_pose, band_m);
    let (best, best_score) = ends
        .iter()
        .map(|(pose, _)| consensus(mesh, counted, pose, band_m))
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    (best_score - found_score > score_noise(best_score)).then_some(best)
}

/// The narrowest of `found_band_m` and the bands `ends` (pose, band) ended in: the pose that
/// fits best measures the scanner's noise best, and every pose is compared in its band.
pub(super) fn narrowest_band(found_band_m: f64, ends: &[(Isometry3<f64>, f64)]) -> f64 {
    ends.iter()
        .map(|(_, band_m)| *band_m)
        .fold(found_band_m, f64::min)
}

/// How far apart two scores may lie by the sampling alone: a score counts keypoints, and a
/// count of n varies by about sqrt(n), so two poses within twice that explain the scan alike.
pub(super) fn score_noise(score: f64) -> f64 {
    2.0 * score.max(0.0).sqrt()
}

#[cfg(test)]
pub(super) mod tests {
    #![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

    use std::f64::consts::FRAC_PI_2;

    use nalgebra::{Isometry3, Point3, Vector3};

    use super::{Coarse, consensus, oriented_consensus};
    use crate::geometry::Mesh;
    use crate::registration::pca::PcaOptions;
    use crate::registration::sampling::{surface_normals_at, voxel_representatives};
    use crate::trials::clouds::{ScanOptions, scan_part};
    use crate::trials::parts::step_block;

    /// The step block on the floor beside a neighbouring box, scanned: its mesh, its true pose
    /// and the cloud's coarse score with the default options.
    pub(in crate::registration::pca) fn step_block_beside_a_box() -> (Mesh, Isometry3<f64>, Coarse)
    {
        let mesh = step_block().unwrap().mesh;
        let truth = Isometry3::new(Vector3::new(0.7, -0.1, 0.0), Vector3::new(0.0, 0.0, 0.5));
        let scan = ScanOptions {
            floor: true,
            neighbour: true,
            ..ScanOptions::default()
        };
        let cloud = scan_part(&mesh, &truth, &scan);
        let coarse = Coarse::new(&mesh, &cloud, &PcaOptions::default());
        (mesh, truth, coarse)
    }

    #[test]
    fn a_plate_standing_through_the_floor_counts_the_floor_only_without_normals() {
        // The floor, scanned every 3 mm over 40 cm; a plate 100 x 4 x 100 mm.
        let floor: Vec<Point3<f64>> = (-66..=66)
            .flat_map(|i| (-66..=66).map(move |j| (i, j)))
            .map(|(i, j)| Point3::new(f64::from(i) * 0.003, f64::from(j) * 0.003, 0.0))
            .collect();
        let keypoints = voxel_representatives(&floor, 0.015);
        let normals = surface_normals_at(&floor, &keypoints, 0.015);
        let plate = Mesh::cuboid([0.1, 0.004, 0.1]).unwrap();
        let band_m = 0.01;
        // Standing, its faces cut the floor along a line: the floor's keypoints beside them are
        // within the band, across the faces.
        let standing = Isometry3::identity();
        let plain = consensus(&plate, &keypoints, &standing, band_m);
        let oriented = oriented_consensus(&plate, &keypoints, &normals, &standing, band_m);
        assert!(plain >= 10.0, "{plain}");
        assert_eq!(oriented, 0.0);
        // Lying on it, the floor runs along its face: both count the keypoints under it, and
        // only those beyond its rims nearest its thin sides are left out with normals.
        let lying = Isometry3::new(Vector3::new(0.0, 0.0, 0.002), Vector3::x() * FRAC_PI_2);
        let plain = consensus(&plate, &keypoints, &lying, band_m);
        let oriented = oriented_consensus(&plate, &keypoints, &normals, &lying, band_m);
        let over_the_face = keypoints
            .iter()
            .filter(|p| p.x.abs() <= 0.05 && p.y.abs() <= 0.05)
            .count();
        assert!(over_the_face >= 30, "{over_the_face}");
        assert!(
            oriented >= over_the_face as f64,
            "{oriented} of {over_the_face}"
        );
        assert!(oriented < plain, "{oriented} of {plain}");
    }

    #[test]
    fn keypoints_deep_inside_an_open_mesh_count_against_a_pose_as_in_a_closed_one() {
        let closed = Mesh::cuboid([0.2, 0.2, 0.2]).unwrap();
        let vertices: Vec<_> = closed.vertices().collect();
        let open = Mesh::new(&vertices, &closed.triangles()[1..]).unwrap();
        assert!(!open.is_watertight());
        // Keypoints every 20 mm through the box and 60 mm past it on every side, but for the
        // layer on its faces (where the opening is, a keypoint is on the surface of one mesh
        // and not of the other): 9 x 9 x 9 inside, 20 mm deep at least.
        let keypoints: Vec<Point3<f64>> = (-8..=8)
            .flat_map(|i| (-8..=8).flat_map(move |j| (-8..=8).map(move |k| [i, j, k])))
            .filter(|index| index.iter().all(|&i: &i32| i.abs() != 5))
            .map(|[i, j, k]| Point3::new(f64::from(i), f64::from(j), f64::from(k)) * 0.02)
            .collect();
        let pose = Isometry3::identity();
        let band_m = 0.01;
        let expected = -2.0 * (9 * 9 * 9) as f64;
        assert_eq!(consensus(&closed, &keypoints, &pose, band_m), expected);
        assert_eq!(consensus(&open, &keypoints, &pose, band_m), expected);
    }

    #[test]
    fn a_pose_carried_off_the_part_explains_less_and_one_a_hair_off_as_much() {
        let (mesh, truth, coarse) = step_block_beside_a_box();
        // Slid 300 mm along the floor, as the fine run carried the TIAGo Pro link.
        let carried_off = Isometry3::translation(0.3, 0.0, 0.0) * truth;
        let hair_off = Isometry3::translation(0.0002, 0.0, 0.0) * truth;
        assert!(coarse.score(&mesh, &truth) > 50.0);
        assert!(coarse.explains_less(&mesh, &carried_off, &truth));
        assert!(!coarse.explains_less(&mesh, &truth, &carried_off));
        assert!(!coarse.explains_less(&mesh, &hair_off, &truth));
        assert!(!coarse.explains_less(&mesh, &truth, &hair_off));
    }
}
