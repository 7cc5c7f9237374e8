//! Base hypotheses standing on the floor: where the base's own shape, stood on the floor the
//! scan shows, is voted for by the scan points at its height.
//!
//! The rigid alignments of the proximal links (the base with the first joint's link) settle on
//! whatever shape resembles them: the UR10 with CAD links has its upper arm standing beside the
//! base, a tube of the shoulder's girth, and from 500 mm every such alignment of base and
//! shoulder set the base on the floor under it, 0.18 m beside its place, or lying on its side
//! (`robot-scans --urdf` with scripts/robot-descriptions.sh, seed 20 scene 0; a probe, not
//! kept). Stood on the floor, the base alone reaches up only to the first joint, below the
//! arm: only the base itself has its shape at that height.

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::context::FitContext;
use super::tree::{axis_of, search_order};
use crate::geometry::{Mesh, tangents};
use crate::registration::articulated::body::{ArticulatedBody, JointAxis};
use crate::registration::pca::{ModelSamples, on_a_plane};

/// Root positions closer than this are one hypothesis, m.
const DISTINCT_STANDING_M: f64 = 0.05;

/// A hypothesis needs at least this many keypoints on the stood base: fewer say nothing.
const MIN_VOTES: u32 = 8;

/// Turns of a base that shows its turn voted for, at most (one per 4 degrees).
const MAX_TURNS: usize = 90;

/// Keypoints that vote, at most (a stride sample of those at the base's height). The ABB IRB
/// 1600's base (a 0.44 m rim, 0.17 m tall) drew 1 464 with a cap of 1 500 in a ray-cast scan at
/// 200 mm (`robot-scans` seed 20 scene 1), and its 77 turns took 200-300 ms of a 1.3 s fit (a
/// probe, not kept); the CAD UR10's flat base draws some 70, at 2 ms.
const MAX_VOTERS: usize = 800;

/// Cells from the start's root to the edge of the voted square, at most: a turn's grid holds at
/// most 1001 by 1001 cells (8 MB), half-band cells out to a 4.5 m bound.
const MAX_CELLS_ACROSS_HALF: usize = 500;

/// The best cells of each turn kept for the ranking.
const CELLS_PER_TURN: usize = 64;

impl FitContext<'_> {
    /// Up to `count` poses of the root with the base standing on the floor the scan shows,
    /// within `bound_m` of the start's root along the floor, the best voted first. The base is
    /// stood as [`standing_on`] stands it and turned about the floor's normal in steps that
    /// move its rim by two bands (one turn for a base that looks the same at every angle about
    /// its first joint, `round_base`: the joint's value shows its turn); at each turn every scan
    /// keypoint at the height of some of the base's surface samples (a floor's keypoints left
    /// out) votes for the root positions that put one of those samples on it, once per cell,
    /// and a cell's score is the keypoints voting in it and the eight round it.
    pub(super) fn standing_candidates(
        &self,
        world_from_root_start: &Isometry3<f64>,
        q0: &[f64],
        bound_m: f64,
        round_base: Option<&JointAxis>,
        count: usize,
    ) -> Vec<Isometry3<f64>> {
        let Some(floor) = self.stand_on else {
            return Vec::new();
        };
        let Some(fixed) = self.body.fixed_mesh(q0) else {
            return Vec::new();
        };
        let Some(stood) = standing_on(self.body, &fixed, world_from_root_start, q0, &floor) else {
            return Vec::new();
        };
        let (_, up) = floor;
        let (across, along) = tangents(&up);
        let band = 3.0 * self.options.voxel_m;
        // Votes land within a cell of where a sample a band apart puts them: the 3 by 3 window
        // of cells half a band wide holds them. A start off by metres (delta is the caller's)
        // gets coarser cells instead of a grid of hundreds of megabytes.
        let cell_m = (band / 2.0).max(bound_m / MAX_CELLS_ACROSS_HALF as f64);
        // The base's samples stood: height above the floor, and offset from the root along it.
        let root = stood.translation.vector;
        let samples = ModelSamples::new(&fixed, band);
        let mut stood_samples: Vec<(f64, f64, f64)> = samples
            .points
            .iter()
            .map(|s| {
                let offset = stood.rotation * s.coords;
                let height = (stood * s - floor.0).dot(&up);
                (height, offset.dot(&across), offset.dot(&along))
            })
            // The bottom lies in the floor's band: the floor's points would vote for it anywhere.
            .filter(|(height, _, _)| *height > band)
            .collect();
        stood_samples.sort_by(|a, b| a.0.total_cmp(&b.0));
        let Some(&(top_m, _, _)) = stood_samples.last() else {
            return Vec::new();
        };
        let rim_m = stood_samples
            .iter()
            .map(|(_, x, y)| x.hypot(*y))
            .fold(0.0, f64::max);
        let turns = if round_base.is_some() {
            1
        } else {
            // A step moves the rim by two bands: votes from samples a band apart still meet.
            ((std::f64::consts::TAU * rim_m / (2.0 * band)).ceil() as usize).clamp(1, MAX_TURNS)
        };
        let plane = [floor];
        let voters: Vec<(f64, f64, f64)> = self
            .scan
            .coarse
            .iter()
            .filter(|p| !on_a_plane(p, &plane))
            .map(|p| {
                let relative = p.coords - root;
                (
                    (p - floor.0).dot(&up),
                    relative.dot(&across),
                    relative.dot(&along),
                )
            })
            .filter(|(height, x, y)| {
                *height >= band && *height <= top_m + band && x.hypot(*y) <= bound_m + rim_m
            })
            .collect();
        let voters: Vec<(f64, f64, f64)> = voters
            .iter()
            .step_by(voters.len().div_ceil(MAX_VOTERS).max(1))
            .copied()
            .collect();
        let cells = (bound_m / cell_m).ceil() as i64;
        let side = (2 * cells + 1) as usize;
        // (score, turn, x, y) of a turn's best cells.
        let vote_at_turn = |turn: usize| -> Vec<(u32, f64, f64, f64)> {
            let angle = std::f64::consts::TAU * turn as f64 / turns as f64;
            let (sin, cos) = angle.sin_cos();
            let mut votes = vec![0_u32; side * side];
            let mut last_voter = vec![u32::MAX; side * side];
            for (voter, &(height, x, y)) in voters.iter().enumerate() {
                let first = stood_samples.partition_point(|s| s.0 < height - band);
                for &(_, sx, sy) in stood_samples[first..]
                    .iter()
                    .take_while(|s| s.0 <= height + band)
                {
                    let (cx, cy) = (x - (sx * cos - sy * sin), y - (sx * sin + sy * cos));
                    if cx * cx + cy * cy > bound_m * bound_m {
                        continue;
                    }
                    let i = (cx / cell_m).round() as i64 + cells;
                    let j = (cy / cell_m).round() as i64 + cells;
                    let cell = i as usize * side + j as usize;
                    if last_voter[cell] != voter as u32 {
                        last_voter[cell] = voter as u32;
                        votes[cell] += 1;
                    }
                }
            }
            let window = |i: usize, j: usize| -> u32 {
                let mut sum = 0;
                for a in i.saturating_sub(1)..(i + 2).min(side) {
                    for b in j.saturating_sub(1)..(j + 2).min(side) {
                        sum += votes[a * side + b];
                    }
                }
                sum
            };
            let offset = |k: usize| (k as f64 - cells as f64) * cell_m;
            let mut best: Vec<(u32, f64, f64, f64)> = (0..side * side)
                .filter(|&cell| votes[cell] > 0)
                .map(|cell| (window(cell / side, cell % side), cell))
                .filter(|(score, _)| *score >= MIN_VOTES)
                .map(|(score, cell)| (score, angle, offset(cell / side), offset(cell % side)))
                .collect();
            best.sort_by_key(|b| std::cmp::Reverse(b.0));
            best.truncate(CELLS_PER_TURN);
            best
        };
        let mut scored: Vec<(u32, f64, f64, f64)> = if self.options.parallel {
            (0..turns).into_par_iter().flat_map(vote_at_turn).collect()
        } else {
            (0..turns).flat_map(vote_at_turn).collect()
        };
        scored.sort_by(|a, b| {
            b.0.cmp(&a.0)
                .then(a.1.total_cmp(&b.1))
                .then(a.2.total_cmp(&b.2))
                .then(a.3.total_cmp(&b.3))
        });
        // A base nearly the same at every turn scores its turns alike: of those within a tenth
        // of the best at a place, the one nearest the start's (turn 0) is kept, as a round
        // base is turned to the start's angle. Turned by the votes' noise, the first joint's
        // window from a 500 mm start does not reach back.
        let nearest_start = |angle: f64| angle.min(std::f64::consts::TAU - angle);
        let mut kept: Vec<(f64, f64, f64)> = Vec::new();
        for &(best, _, x, y) in &scored {
            if kept.len() == count {
                break;
            }
            if kept
                .iter()
                .all(|(_, kx, ky)| (kx - x).hypot(ky - y) > DISTINCT_STANDING_M)
            {
                let angle = scored
                    .iter()
                    .filter(|s| s.2 == x && s.3 == y && 10 * s.0 >= 9 * best)
                    .map(|s| s.1)
                    .min_by(|a, b| nearest_start(*a).total_cmp(&nearest_start(*b)))
                    .expect("the best turn is there");
                kept.push((angle, x, y));
            }
        }
        kept.into_iter()
            .map(|(angle, x, y)| {
                let turn = UnitQuaternion::from_axis_angle(&Unit::new_normalize(up), angle);
                Isometry3::from_parts(
                    Translation3::from(root + across * x + along * y),
                    turn * stood.rotation,
                )
            })
            .collect()
    }
}

/// `world_from_root` stood on `floor` (a point on it and its unit normal, up): turned the least
/// that puts the first joint's axis along the floor's normal, pointing away from it, and moved
/// along the normal until the lowest point of `mesh` (root frame) lies on the floor. `None`
/// for a robot whose first joint has no axis.
pub(super) fn standing_on(
    body: &ArticulatedBody,
    mesh: &Mesh,
    world_from_root: &Isometry3<f64>,
    q0: &[f64],
    floor: &(Point3<f64>, Vector3<f64>),
) -> Option<Isometry3<f64>> {
    let first = *search_order(body).first()?;
    let axis = axis_of(body, &body.link_poses(&Isometry3::identity(), q0), first)?;
    let (floor_point, up) = floor;
    let axis_world = world_from_root.rotation * axis.axis.normalize();
    // Upside down, any half turn about a line along the floor stands it up.
    let turn = UnitQuaternion::rotation_between(&axis_world, up).unwrap_or_else(|| {
        UnitQuaternion::from_axis_angle(&Unit::new_normalize(tangents(up).0), std::f64::consts::PI)
    });
    let rotation = turn * world_from_root.rotation;
    let lowest_m = mesh
        .vertices()
        .map(|v| {
            (rotation * v.coords + world_from_root.translation.vector - floor_point.coords).dot(up)
        })
        .fold(f64::INFINITY, f64::min);
    lowest_m.is_finite().then(|| {
        Isometry3::from_parts(
            Translation3::from(world_from_root.translation.vector - up * lowest_m),
            rotation,
        )
    })
}

#[cfg(test)]
mod tests {
    use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

    use super::super::RobotFitOptions;
    use super::super::context::{FitContext, Keypoints};
    use super::super::placed::Placed;
    use super::super::tests::forked_wrist_and_its_base;
    use super::standing_on;

    /// A 3 m floor at z = 0 on a 15 mm grid, without what `hidden` covers.
    fn floor_without(hidden: impl Fn(&Point3<f64>) -> bool) -> Vec<Point3<f64>> {
        let step_m = 0.015;
        (0..200)
            .flat_map(|i| (0..200).map(move |j| (i, j)))
            .map(|(i, j)| Point3::new(-1.5 + i as f64 * step_m, -1.5 + j as f64 * step_m, 0.0))
            .filter(|p| !hidden(p))
            .collect()
    }

    /// The two faces of an upright box (half widths `hx`, `hy`, height `h`) that look at -x
    /// and -y, on a 12 mm grid, at `world_from_box` (the box's bottom centre).
    fn box_sides(hx: f64, hy: f64, h: f64, world_from_box: &Isometry3<f64>) -> Vec<Point3<f64>> {
        let step_m = 0.012;
        let mut points = Vec::new();
        for k in 1..(h / step_m) as usize {
            let z = k as f64 * step_m;
            for i in 0..=(2.0 * hy / step_m) as usize {
                points.push(Point3::new(-hx, -hy + i as f64 * step_m, z));
            }
            for i in 0..=(2.0 * hx / step_m) as usize {
                points.push(Point3::new(-hx + i as f64 * step_m, -hy, z));
            }
        }
        points.into_iter().map(|p| world_from_box * p).collect()
    }

    #[test]
    fn a_tilted_start_stands_with_its_first_axis_up_and_its_base_on_the_floor() {
        let (body, _) = forked_wrist_and_its_base();
        let q0 = [0.0; 6];
        let fixed = body.fixed_mesh(&q0).unwrap();
        let start = Isometry3::from_parts(
            Translation3::new(0.4, -0.3, 0.5),
            UnitQuaternion::from_euler_angles(1.0, -0.4, 2.0),
        );
        let floor = (Point3::new(0.0, 0.0, 0.02), Vector3::z());
        let stood = standing_on(&body, &fixed, &start, &q0, &floor).unwrap();
        // j1 turns about the base's z.
        assert!((stood.rotation * Vector3::z() - Vector3::z()).norm() < 1e-9);
        let lowest = fixed
            .vertices()
            .map(|v| (stood * v).z)
            .fold(f64::INFINITY, f64::min);
        assert!((lowest - 0.02).abs() < 1e-9, "{lowest}");
        // Upside down it stands too.
        let upside_down = Isometry3::from_parts(
            start.translation,
            UnitQuaternion::from_euler_angles(3.1, 0.0, 0.0),
        );
        let stood = standing_on(&body, &fixed, &upside_down, &q0, &floor).unwrap();
        assert!((stood.rotation * Vector3::z() - Vector3::z()).norm() < 1e-6);
    }

    /// The forked wrist's base (a 0.4 by 0.4 m box, 0.3 m tall) stands turned on a floor beside
    /// a smaller box of the same height; the start is 0.45 m off and tilted. The best voted
    /// standing pose puts the base's sides on the scan's; the smaller box is not taken for it.
    #[test]
    fn the_base_standing_on_the_floor_is_voted_for_beside_a_smaller_box() {
        let (body, base) = forked_wrist_and_its_base();
        let q0 = [0.0; 6];
        let truth = Isometry3::from_parts(
            Translation3::new(0.3, -0.2, 0.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.7),
        );
        let decoy = Isometry3::translation(-0.5, 0.4, 0.0);
        let mut scan = floor_without(|p| {
            let local = truth.inverse() * p;
            let decoy_local = decoy.inverse() * p;
            (local.x.abs() < 0.2 && local.y.abs() < 0.2)
                || (decoy_local.x.abs() < 0.14 && decoy_local.y.abs() < 0.14)
        });
        let sides = box_sides(0.2, 0.2, 0.3, &truth);
        scan.extend(&sides);
        scan.extend(box_sides(0.14, 0.14, 0.3, &decoy));
        let options = RobotFitOptions::default();
        let start = Isometry3::from_parts(
            Translation3::new(0.0, 0.1, 0.25),
            UnitQuaternion::from_euler_angles(0.3, 0.0, 0.2),
        );
        let mut context = FitContext {
            body: &body,
            scan: Keypoints {
                coarse: &scan,
                fine: &scan,
            },
            delta_m: 0.5,
            global: false,
            near: false,
            floor: None,
            stand_on: Some((Point3::origin(), Vector3::z())),
            options: &options,
        };
        let candidates = context.standing_candidates(&start, &q0, 1.0, None, 4);
        let best = candidates.first().expect("a standing candidate");
        let placed = Placed::new(&body, best, &q0);
        let on_base = sides
            .iter()
            .filter(|p| placed.evidence(p, 0.006, 0.006, &[base]) == 1)
            .count();
        assert!(
            10 * on_base >= 9 * sides.len(),
            "{on_base} of {} side points on the base at {best}",
            sides.len()
        );
        // A start off by tens of metres votes on coarser cells, not on a grid of gigabytes: the
        // base is still found, to within a few of those 0.1 m cells.
        let far = context.standing_candidates(&start, &q0, 50.0, None, 4);
        let off_m = far
            .first()
            .map(|c| (c.translation.vector - truth.translation.vector).norm());
        assert!(off_m.is_some_and(|off| off < 0.3), "{off_m:?}");
        // No floor, no standing.
        context.stand_on = None;
        assert!(
            context
                .standing_candidates(&start, &q0, 1.0, None, 4)
                .is_empty()
        );
    }
}
