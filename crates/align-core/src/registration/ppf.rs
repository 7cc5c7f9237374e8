//! Global rigid detection by point pair features (Drost, Ulrich, Navab and Ilic, "Model
//! globally, match locally", CVPR 2010): where a small rigid part lies in a cluttered scan when
//! no start is near it.
//!
//! Every pair of oriented model samples is described by its distance and three angles (normal
//! to connecting line, twice, and normal to normal) and stored in a table. A scene point taken
//! as reference is paired with the scene points around it; each pair looks up the model pairs
//! with the same description, and each of those votes for a model reference point and a turn
//! about the reference normal. The winning votes of each scene reference are poses; poses
//! that agree are merged, their votes summed.
//!
//! A scan's normals have no reliable sign (no scanner position is known here), so the angles
//! are folded to [0, pi/2] and each scene reference votes with both signs of its normal.

use std::collections::HashMap;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::sampling::{CellIndex, cell_of, voxel_representatives};
use crate::geometry::{Mesh, plane_through};

#[derive(Debug, Clone, PartialEq)]
pub struct PpfOptions {
    /// Sample spacing on the model and the scene, and the distance bin of the features, m
    /// (at least a twentieth of the model's radius: the table grows with the square of the
    /// model's samples).
    pub step_m: f64,
    /// Bins of a folded feature angle over [0, pi/2].
    pub angle_bins: usize,
    /// Bins of the turn about the reference normal over a full turn.
    pub turn_bins: usize,
    /// Scene points used as references, at most (a stride sample).
    pub max_references: usize,
    /// A scene reference's vote below this fraction of the best reference's is dropped before
    /// the votes are merged into poses (0 merges every vote). A pose that many references agree
    /// on, each with few votes, goes with them.
    pub min_vote_fraction: f64,
}

impl Default for PpfOptions {
    fn default() -> Self {
        Self {
            step_m: 0.015,
            angle_bins: 6,
            turn_bins: 30,
            max_references: 500,
            min_vote_fraction: 0.2,
        }
    }
}

/// A surface point with its unit normal.
#[derive(Debug, Clone, Copy)]
struct Oriented {
    point: Point3<f64>,
    normal: Vector3<f64>,
}

/// Points on the mesh's triangles, one per `step_m` voxel, with their triangle's normal.
fn mesh_samples(mesh: &Mesh, step_m: f64) -> Vec<Oriented> {
    let vertices: Vec<Point3<f64>> = mesh.vertices().collect();
    let spacing = step_m / 3.0;
    let mut cells: HashMap<[i64; 3], Oriented> = HashMap::new();
    for (index, triangle) in mesh.triangles().iter().enumerate() {
        let [a, b, c] = triangle.map(|i| vertices[i as usize]);
        let normal = mesh.triangle_normal(index as u32);
        let longest = (b - a).norm().max((c - a).norm()).max((c - b).norm());
        let steps = ((longest / spacing).ceil() as usize).max(1);
        for i in 0..=steps {
            for j in 0..=steps - i {
                let point =
                    a + (b - a) * (i as f64 / steps as f64) + (c - a) * (j as f64 / steps as f64);
                cells
                    .entry(cell_of(&point, step_m))
                    .or_insert(Oriented { point, normal });
            }
        }
    }
    let mut samples: Vec<([i64; 3], Oriented)> = cells.into_iter().collect();
    samples.sort_by_key(|(cell, _)| *cell);
    samples.into_iter().map(|(_, sample)| sample).collect()
}

/// One point per `step_m` voxel of the scan with the normal of its neighbourhood's plane;
/// points with too few neighbours for a plane are left out.
fn scene_samples(cloud: &[Point3<f64>], step_m: f64) -> Vec<Oriented> {
    let points = voxel_representatives(cloud, step_m);
    let radius = 2.0 * step_m;
    let index = CellIndex::new(&points, radius);
    points
        .par_iter()
        .filter_map(|point| {
            let neighbours: Vec<Point3<f64>> = index
                .within(&points, point, radius)
                .map(|i| points[i])
                .collect();
            if neighbours.len() < 5 {
                return None;
            }
            let (_, normal) = plane_through(&neighbours)?;
            Some(Oriented {
                point: *point,
                normal,
            })
        })
        .collect()
}

/// The rotation taking `normal` to +x, and the transform taking `point` to the origin with it.
fn reference_frame(reference: &Oriented) -> Isometry3<f64> {
    let rotation = UnitQuaternion::rotation_between(&reference.normal, &Vector3::x())
        .unwrap_or_else(|| {
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::PI)
        });
    Isometry3::from_parts(Translation3::identity(), rotation)
        * Isometry3::translation(-reference.point.x, -reference.point.y, -reference.point.z)
}

/// A turn in (-pi, pi] (or any angle) as a fraction of a full turn in 32-bit fixed point: the
/// difference of two such turns, wrapped to a full turn, is one `wrapping_sub`, and its bin one
/// multiply and shift (the voting's inner loop spent most of its time on the float version's
/// wrap and division). The resolution, 1.5e-9 rad, is far below any bin.
fn fixed_turn(turn: f64) -> u32 {
    let fraction = turn.rem_euclid(std::f64::consts::TAU) / std::f64::consts::TAU;
    // A tiny negative angle's `rem_euclid` rounds to a full turn: it stays just below one,
    // where the angle is (`as` would saturate there anyway; the bound says so).
    (fraction * FULL_TURN as f64).min(FULL_TURN as f64 - 1.0) as u32
}

/// A full turn in [`fixed_turn`]'s units.
const FULL_TURN: u64 = 1 << 32;

/// The bin of `turn_bins` over a full turn that a wrapped fixed-point turn falls in.
fn turn_bin(turn: u32, turn_bins: usize) -> usize {
    ((u64::from(turn) * turn_bins as u64) >> 32) as usize
}

/// Angle of `point` about +x once `frame` has moved it (in (-pi, pi]).
fn turn_of(frame: &Isometry3<f64>, point: &Point3<f64>) -> f64 {
    let moved = frame * point;
    moved.z.atan2(moved.y)
}

/// A folded angle's bins (`bins` over [0, pi/2]) by the cosines of their edges: the pair
/// features' three angles were three `acos` a pair, and the model's table and the voting make
/// millions of pairs (a probe, not kept: the model's table alone took 5-95 ms of a 100 mm
/// CAD-scan alignment, on one core; 39 -> 22 ms mean on set C, docs/BENCHMARKS.md). The bin is
/// the same as the angle's except within rounding of an edge.
#[derive(Debug, Clone)]
struct FoldedAngleBins {
    /// cos(k pi / (2 bins)) for k = 1 .. bins - 1: falling.
    cos_edges: Vec<f64>,
}

impl FoldedAngleBins {
    fn new(bins: usize) -> Self {
        let step = std::f64::consts::FRAC_PI_2 / bins.max(1) as f64;
        Self {
            cos_edges: (1..bins.max(1)).map(|k| (k as f64 * step).cos()).collect(),
        }
    }

    fn count(&self) -> usize {
        self.cos_edges.len() + 1
    }

    /// The bin of the angle whose cosine is `cos` up to sign: the edges it is at or past.
    fn bin(&self, cos: f64) -> usize {
        let folded = cos.abs();
        self.cos_edges
            .iter()
            .filter(|&&edge| folded <= edge)
            .count()
    }
}

/// What a pair's description needs besides the pair: the table's distance bins, its step (m)
/// and its angle bins.
#[derive(Debug, Clone)]
struct Describing {
    distance_bins: usize,
    step_m: f64,
    angles: FoldedAngleBins,
}

/// The folded, binned description of the pair (reference, other) as an index into the table
/// (`distance_bins` x `angle_bins`^3 slots); none for a pair farther apart than the table
/// holds and for a pair lying in one plane (both normals across the line joining them and
/// parallel): a floor or a box face is full of those, and they say nothing of where a part is.
fn feature(reference: &Oriented, other: &Oriented, describing: &Describing) -> Option<usize> {
    let d = other.point - reference.point;
    let distance = d.norm();
    let distance_bin = (distance / describing.step_m) as usize;
    if distance < 1e-9 || distance_bin >= describing.distance_bins {
        return None;
    }
    let direction = d / distance;
    let angles = &describing.angles;
    let bins = angles.count();
    let across_reference = angles.bin(reference.normal.dot(&direction));
    let across_other = angles.bin(other.normal.dot(&direction));
    let between = angles.bin(reference.normal.dot(&other.normal));
    if across_reference == bins - 1 && across_other == bins - 1 && between == 0 {
        return None;
    }
    Some(((distance_bin * bins + across_reference) * bins + across_other) * bins + between)
}

/// The model is sampled no finer than its radius over this.
const MODEL_SAMPLES_PER_RADIUS: f64 = 20.0;

/// A rigid pose of the model in the scene, with the votes of the references that agree on it.
#[derive(Debug, Clone, PartialEq)]
pub struct PpfPose {
    pub world_from_model: Isometry3<f64>,
    pub votes: usize,
}

/// Poses of `mesh` whose model frame origin lies within `radius_m` of `centre` in `cloud`,
/// most votes first, at most `count`; two poses are one when they put the mesh's centroid
/// within two steps of each other and differ by less than `distinct_rad` in rotation.
pub fn ppf_poses(
    mesh: &Mesh,
    cloud: &[Point3<f64>],
    centre: &Point3<f64>,
    radius_m: f64,
    options: &PpfOptions,
    count: usize,
    distinct_rad: f64,
) -> Vec<PpfPose> {
    ppf_poses_where(
        mesh,
        cloud,
        (centre, radius_m),
        options,
        count,
        distinct_rad,
        &|_| true,
    )
}

/// [`ppf_poses`] among the poses `allowed` keeps (and within `radius_m` of `centre`): a caller
/// that knows more of the pose, as a bound on its turn, says so before the votes are ranked.
/// Filtering the `count` best afterwards loses the true pose whenever `count` better-voted
/// poses lie outside the bound: on thin robot links (xArm7, cad-scans) the 16 best of the
/// whole scan were all turned further than the user's delta allows, and none was near the
/// truth.
pub fn ppf_poses_where(
    mesh: &Mesh,
    cloud: &[Point3<f64>],
    (centre, radius_m): (&Point3<f64>, f64),
    options: &PpfOptions,
    count: usize,
    distinct_rad: f64,
    allowed: &(dyn Fn(&Isometry3<f64>) -> bool + Sync),
) -> Vec<PpfPose> {
    PpfModel::new(mesh, options).map_or_else(Vec::new, |model| {
        model.poses_where(cloud, (centre, radius_m), count, distinct_rad, allowed)
    })
}

/// Whether two poses of a model are one for the detection: they put its `centroid` within two
/// steps (`step_m`) of each other and differ by less than `distinct_rad` in rotation.
pub(crate) fn detected_alike(
    a: &Isometry3<f64>,
    b: &Isometry3<f64>,
    centroid: &Point3<f64>,
    step_m: f64,
    distinct_rad: f64,
) -> bool {
    (a * centroid - b * centroid).norm() < 2.0 * step_m
        && a.rotation.angle_to(&b.rotation) < distinct_rad
}

/// The model's side of the detection: its samples, their frames and the table of their pairs'
/// descriptions, built once for as many scenes as are searched (the table alone took 5-95 ms
/// of a 100 mm CAD-scan alignment, see [`FoldedAngleBins`]).
#[derive(Debug)]
pub struct PpfModel {
    /// The options, with the step raised to what the model's size allows.
    options: PpfOptions,
    samples: Vec<Oriented>,
    frames: Vec<Isometry3<f64>>,
    describing: Describing,
    /// Description -> (model reference sample, its turn).
    table: Vec<Vec<(u32, u32)>>,
    radius_m: f64,
    centroid: Point3<f64>,
}

impl PpfModel {
    /// `None` for a step that is not a positive distance and for a mesh too small or degenerate
    /// to give two samples.
    pub fn new(mesh: &Mesh, options: &PpfOptions) -> Option<Self> {
        if !(options.step_m.is_finite() && options.step_m > 0.0) {
            return None;
        }
        let options = PpfOptions {
            step_m: options
                .step_m
                .max(mesh.radius_m() / MODEL_SAMPLES_PER_RADIUS),
            ..options.clone()
        };
        let samples = mesh_samples(mesh, options.step_m);
        let diameter = 2.0 * mesh.radius_m();
        if samples.len() < 2 || diameter.is_nan() || diameter <= 0.0 {
            return None;
        }
        let frames: Vec<Isometry3<f64>> = samples.iter().map(reference_frame).collect();
        let describing = Describing {
            distance_bins: (diameter / options.step_m) as usize + 1,
            step_m: options.step_m,
            angles: FoldedAngleBins::new(options.angle_bins),
        };
        let mut table: Vec<Vec<(u32, u32)>> =
            vec![Vec::new(); describing.distance_bins * describing.angles.count().pow(3)];
        for (r, reference) in samples.iter().enumerate() {
            for (i, other) in samples.iter().enumerate() {
                if r == i {
                    continue;
                }
                if let Some(key) = feature(reference, other, &describing) {
                    table[key].push((r as u32, fixed_turn(turn_of(&frames[r], &other.point))));
                }
            }
        }
        Some(Self {
            options,
            samples,
            frames,
            describing,
            table,
            radius_m: mesh.radius_m(),
            centroid: mesh.centroid(),
        })
    }

    /// The model's poses in `cloud`, as [`ppf_poses_where`] gives them.
    pub fn poses_where(
        &self,
        cloud: &[Point3<f64>],
        (centre, radius_m): (&Point3<f64>, f64),
        count: usize,
        distinct_rad: f64,
        allowed: &(dyn Fn(&Isometry3<f64>) -> bool + Sync),
    ) -> Vec<PpfPose> {
        let Self {
            options,
            samples: model,
            frames,
            describing,
            table,
            ..
        } = self;
        let diameter = 2.0 * self.radius_m;
        let reach = radius_m + self.radius_m + self.centroid.coords.norm();
        let near: Vec<Point3<f64>> = cloud
            .iter()
            .filter(|p| (*p - centre).norm() <= reach)
            .copied()
            .collect();
        let scene = scene_samples(&near, options.step_m);
        if scene.len() < 2 {
            return Vec::new();
        }
        let scene_points: Vec<Point3<f64>> = scene.iter().map(|s| s.point).collect();
        let index = CellIndex::new(&scene_points, diameter);
        let stride = scene.len().div_ceil(options.max_references.max(1));
        let turn_bins = options.turn_bins.max(1);
        let turn_step = std::f64::consts::TAU / turn_bins as f64;
        let model_centroid = self.centroid;
        // Each reference (with either sign of its normal): its best model reference and turn.
        let mut votes: Vec<(usize, Isometry3<f64>)> = scene
            .par_iter()
            .step_by(stride)
            .flat_map_iter(|reference| {
                // The description does not depend on the normals' signs; the turn does.
                let pairs: Vec<(usize, Point3<f64>)> = index
                    .within(&scene_points, &reference.point, diameter)
                    .filter_map(|i| {
                        feature(reference, &scene[i], describing).map(|key| (key, scene[i].point))
                    })
                    .collect();
                // Both signs vote in one pass over the pairs' table entries (the entries are the
                // same; only the scene's turn differs): each accumulator gets the increments it got
                // in a pass of its own, in the same order.
                let frames_by_sign = [1.0, -1.0].map(|sign| {
                    reference_frame(&Oriented {
                        point: reference.point,
                        normal: reference.normal * sign,
                    })
                });
                let slots = model.len() * turn_bins;
                let mut accumulators = vec![0u32; 2 * slots];
                let (plus, minus) = accumulators.split_at_mut(slots);
                for (key, point) in &pairs {
                    let scene_turns =
                        frames_by_sign.map(|frame| fixed_turn(turn_of(&frame, point)));
                    for &(model_reference, model_turn) in &table[*key] {
                        let row = model_reference as usize * turn_bins;
                        for (accumulator, scene_turn) in
                            [&mut *plus, &mut *minus].into_iter().zip(scene_turns)
                        {
                            accumulator
                                [row + turn_bin(scene_turn.wrapping_sub(model_turn), turn_bins)] +=
                                1;
                        }
                    }
                }
                accumulators
                    .chunks_exact(slots)
                    .zip(frames_by_sign)
                    .filter_map(|(accumulator, frame)| {
                        let (best, &count) = accumulator
                            .iter()
                            .enumerate()
                            .max_by_key(|(slot, count)| (**count, std::cmp::Reverse(*slot)))?;
                        if count == 0 {
                            return None;
                        }
                        let (model_reference, bin) = (best / turn_bins, best % turn_bins);
                        let turn = (bin as f64 + 0.5) * turn_step;
                        let pose = frame.inverse()
                            * Isometry3::rotation(Vector3::x() * turn)
                            * frames[model_reference];
                        ((pose * Point3::origin() - centre).norm() <= radius_m && allowed(&pose))
                            .then_some((count as usize, pose))
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        votes.sort_by_key(|v| std::cmp::Reverse(v.0));
        let best = votes.first().map_or(0, |v| v.0);
        // Merge poses that agree, most votes first.
        let mut merged: Vec<PpfPose> = Vec::new();
        for (count, pose) in votes {
            if (count as f64) < options.min_vote_fraction * best as f64 {
                break;
            }
            let same = merged.iter_mut().find(|m| {
                detected_alike(
                    &m.world_from_model,
                    &pose,
                    &model_centroid,
                    options.step_m,
                    distinct_rad,
                )
            });
            match same {
                Some(m) => m.votes += count,
                None => merged.push(PpfPose {
                    world_from_model: pose,
                    votes: count,
                }),
            }
        }
        merged.sort_by_key(|m| std::cmp::Reverse(m.votes));
        merged.truncate(count);
        merged
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_point_turns_bin_their_wrapped_difference_as_the_float_angles_do() {
        use std::f64::consts::{PI, TAU};
        let turn_bins = 30;
        let step = TAU / turn_bins as f64;
        let mut angles = vec![0.0, -0.0, PI, -PI, TAU, -TAU, 1e-17, -1e-17, PI - 1e-12];
        angles.extend((0..400).map(|i| -PI + i as f64 * TAU / 399.0));
        angles.extend((0..turn_bins).map(|bin| bin as f64 * step - PI));
        for &scene in &angles {
            for &model in &angles {
                let difference = (scene - model).rem_euclid(TAU);
                let expected = ((difference / step) as usize).min(turn_bins - 1);
                let got = turn_bin(fixed_turn(scene).wrapping_sub(fixed_turn(model)), turn_bins);
                // Only a difference within the fixed point's resolution of a bin's edge (or
                // of a full turn) may land in the neighbouring bin.
                let from_edge = (difference / step - (difference / step).round()).abs() * step;
                let near_full_turn = (TAU - difference).min(difference) < 1e-8;
                assert!(
                    got == expected || from_edge < 1e-8 || near_full_turn,
                    "{scene} - {model}: bin {got} against {expected}"
                );
                assert!(got < turn_bins);
            }
        }
        // A fraction that rounds up to a full turn stays inside the range.
        assert_eq!(fixed_turn(-1e-300), u32::MAX);
        assert_eq!(turn_bin(u32::MAX, turn_bins), turn_bins - 1);
    }

    #[test]
    fn folded_angle_bins_by_cosine_edges_are_the_bins_of_the_angle() {
        use std::f64::consts::FRAC_PI_2;
        for bins in [1, 2, 6, 9] {
            let angles = FoldedAngleBins::new(bins);
            assert_eq!(angles.count(), bins);
            let step = FRAC_PI_2 / bins as f64;
            let of_angle = |cos: f64| {
                let angle = cos.abs().min(1.0).acos();
                ((angle / step) as usize).min(bins - 1)
            };
            for i in 0..=4000 {
                let cos = -1.0 + f64::from(i) / 2000.0;
                let angle = cos.abs().acos();
                // Within rounding of an edge either side may win.
                let from_edge = (angle / step - (angle / step).round()).abs() * step;
                if from_edge > 1e-12 {
                    assert_eq!(angles.bin(cos), of_angle(cos), "{bins} bins, cos {cos}");
                }
            }
            // A right angle (cos 0) is the last bin, parallel either way the first.
            assert_eq!(angles.bin(0.0), bins - 1);
            assert_eq!(angles.bin(1.0), 0);
            assert_eq!(angles.bin(-1.0), 0);
            assert_eq!(angles.bin(f64::NAN), of_angle(f64::NAN));
        }
    }

    /// A scan-like cloud of a mesh: points on its surface every few millimetres.
    fn surface_cloud(mesh: &Mesh, pose: &Isometry3<f64>, step_m: f64) -> Vec<Point3<f64>> {
        mesh_samples(mesh, step_m)
            .iter()
            .map(|s| pose * s.point)
            .collect()
    }

    /// A block with a smaller block standing on it, off centre: no symmetry, and locally
    /// like any box (faces, edges, corners).
    fn stepped_block() -> Mesh {
        let lower = Mesh::cuboid([0.2, 0.12, 0.06]).unwrap();
        let upper = Mesh::cuboid([0.06, 0.06, 0.08]).unwrap();
        let shift = Vector3::new(0.05, 0.02, 0.07);
        let mut vertices: Vec<Point3<f64>> = lower.vertices().collect();
        let offset = vertices.len() as u32;
        vertices.extend(upper.vertices().map(|v| v + shift));
        let mut triangles = lower.triangles().to_vec();
        triangles.extend(upper.triangles().iter().map(|t| t.map(|i| i + offset)));
        Mesh::new(&vertices, &triangles).unwrap()
    }

    #[test]
    fn finds_a_part_turned_and_moved_far_among_clutter() {
        let part = stepped_block();
        let truth = Isometry3::from_parts(
            Translation3::new(0.7, -0.4, 0.3),
            UnitQuaternion::from_euler_angles(0.9, -0.5, 2.0),
        );
        let mut cloud = surface_cloud(&part, &truth, 0.004);
        // A floor and a larger box beside the part.
        for i in 0..100 {
            for j in 0..100 {
                cloud.push(Point3::new(
                    -0.5 + i as f64 * 0.02,
                    -1.5 + j as f64 * 0.02,
                    0.0,
                ));
            }
        }
        let other = Mesh::cuboid([0.4, 0.3, 0.3]).unwrap();
        cloud.extend(surface_cloud(
            &other,
            &Isometry3::translation(0.0, -0.6, 0.15),
            0.004,
        ));
        let poses = ppf_poses(
            &part,
            &cloud,
            &Point3::new(0.2, -0.2, 0.2),
            1.0,
            &PpfOptions::default(),
            5,
            0.3,
        );
        assert!(!poses.is_empty());
        // Every vertex of the part where the best pose puts it, against where it is.
        let worst = part
            .vertices()
            .map(|v| (poses[0].world_from_model * v - truth * v).norm())
            .fold(0.0, f64::max);
        assert!(worst < 0.03, "a vertex {worst} m off; {poses:?}");
    }

    #[test]
    fn one_model_searched_in_two_scenes_finds_what_two_detections_find() {
        let part = stepped_block();
        let truth = Isometry3::from_parts(
            Translation3::new(0.3, 0.1, 0.2),
            UnitQuaternion::from_euler_angles(0.4, 0.2, -1.1),
        );
        let alone = surface_cloud(&part, &truth, 0.004);
        let mut beside_a_box = alone.clone();
        let other = Mesh::cuboid([0.2, 0.3, 0.25]).unwrap();
        beside_a_box.extend(surface_cloud(
            &other,
            &Isometry3::translation(0.1, 0.4, 0.125),
            0.004,
        ));
        let options = PpfOptions::default();
        let centre = Point3::new(0.2, 0.2, 0.2);
        let model = PpfModel::new(&part, &options).unwrap();
        // The cluttered scene first: nothing it leaves in the model may change the other's.
        for scene in [&beside_a_box, &alone] {
            let once = model.poses_where(scene, (&centre, 0.6), 8, 0.3, &|_| true);
            let afresh = ppf_poses(&part, scene, &centre, 0.6, &options, 8, 0.3);
            assert!(!once.is_empty());
            assert_eq!(once, afresh);
        }
    }

    #[test]
    fn a_bound_on_the_pose_is_applied_before_the_best_poses_are_kept() {
        let part = stepped_block();
        let first = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 0.1),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.2),
        );
        let second = Isometry3::from_parts(
            Translation3::new(0.5, 0.0, 0.1),
            UnitQuaternion::from_euler_angles(2.0, 0.5, -1.0),
        );
        let mut cloud = surface_cloud(&part, &first, 0.004);
        cloud.extend(surface_cloud(&part, &second, 0.004));
        let near = |found: &PpfPose, truth: &Isometry3<f64>| {
            (found.world_from_model.translation.vector - truth.translation.vector).norm() < 0.03
                && found.world_from_model.rotation.angle_to(&truth.rotation) < 0.2
        };
        let centre = Point3::new(0.25, 0.0, 0.1);
        let options = PpfOptions::default();
        let best = ppf_poses(&part, &cloud, &centre, 1.0, &options, 1, 0.3);
        assert_eq!(best.len(), 1);
        // Whichever copy wins unbounded, the bound that excludes it gives the other.
        let (winner, other) = if near(&best[0], &first) {
            (first, second)
        } else {
            assert!(near(&best[0], &second), "{best:?}");
            (second, first)
        };
        let excluding_winner =
            |pose: &Isometry3<f64>| pose.rotation.angle_to(&winner.rotation) > 1.0;
        let bounded = ppf_poses_where(
            &part,
            &cloud,
            (&centre, 1.0),
            &options,
            1,
            0.3,
            &excluding_winner,
        );
        assert_eq!(bounded.len(), 1);
        assert!(near(&bounded[0], &other), "{bounded:?}");
    }

    #[test]
    fn a_step_that_is_not_a_positive_distance_gives_no_pose() {
        let part = stepped_block();
        let cloud = surface_cloud(&part, &Isometry3::identity(), 0.004);
        for step_m in [0.0, -0.01, f64::NAN, f64::INFINITY] {
            let options = PpfOptions {
                step_m,
                ..PpfOptions::default()
            };
            let poses = ppf_poses(&part, &cloud, &Point3::origin(), 0.5, &options, 5, 0.3);
            assert!(poses.is_empty(), "{step_m}: {poses:?}");
        }
    }

    #[test]
    fn nothing_in_the_search_ball_gives_no_pose() {
        let part = stepped_block();
        let cloud = surface_cloud(&part, &Isometry3::translation(5.0, 0.0, 0.0), 0.004);
        let poses = ppf_poses(
            &part,
            &cloud,
            &Point3::origin(),
            0.5,
            &PpfOptions::default(),
            5,
            0.3,
        );
        assert!(poses.is_empty(), "{poses:?}");
    }
}
