//! The thesis's PCA trials (3.4) on a robot: the whole robot and each link, aligned
//! independently (each link as a rigid part, as the thesis did) and hierarchically (base pose
//! and joints, children constrained by parents).
//!
//! Errors are surface deviations: the largest distance between a link's surface where the
//! alignment puts it and where it truly is (both ways). Unlike a pose distance this is zero for
//! a cylinder turned about its own axis, which no scan can tell apart.

use std::ops::Range;
use std::time::Instant;

use nalgebra::{Isometry3, Point3, UnitQuaternion};

use super::robot_scan::{RobotScanOptions, scan_robot};
use super::{SUCCESS_THRESHOLD_M, TrialRng, random_displacement};
use crate::geometry::Mesh;
use crate::registration::articulated::{ArticulatedBody, RobotFitOptions, align_robot};
use crate::registration::pca::{PcaOptions, align_cloud};

/// Points on a mesh (vertices, edge midpoints and triangle centroids), in its frame.
fn surface_samples(mesh: &Mesh) -> Vec<Point3<f64>> {
    let vertices: Vec<Point3<f64>> = mesh.vertices().collect();
    let mut samples = vertices.clone();
    for triangle in mesh.triangles() {
        let [a, b, c] = triangle.map(|i| vertices[i as usize]);
        samples.push(Point3::from((a.coords + b.coords + c.coords) / 3.0));
        samples.push(Point3::from((a.coords + b.coords) / 2.0));
    }
    samples
}

/// Largest distance between the surface at `estimated` and at `truth` (both world_from_mesh).
pub fn surface_deviation_m(mesh: &Mesh, estimated: &Isometry3<f64>, truth: &Isometry3<f64>) -> f64 {
    let truth_from_estimated = truth.inverse() * estimated;
    let estimated_from_truth = truth_from_estimated.inverse();
    surface_samples(mesh)
        .iter()
        .map(|s| {
            let there = mesh
                .closest_point(&(truth_from_estimated * s))
                .signed_distance
                .abs();
            let back = mesh
                .closest_point(&(estimated_from_truth * s))
                .signed_distance
                .abs();
            there.max(back)
        })
        .fold(0.0, f64::max)
}

/// Largest distance of the robot's surfaces from `origin`, m.
fn reach_from(
    body: &ArticulatedBody,
    poses: &[Isometry3<f64>],
    links: &[usize],
    origin: &Point3<f64>,
) -> f64 {
    links
        .iter()
        .filter_map(|&l| {
            let mesh = body.links()[l].surface.as_ref()?;
            Some((poses[l] * mesh.centroid() - origin).norm() + mesh.radius_m())
        })
        .fold(0.0, f64::max)
}

/// A start for the hierarchical fit: the robot displaced by the thesis's generator about its
/// centroid (radius: the robot's), as the thesis displaced its whole model, and every joint
/// moved by up to delta / (its links' reach), so that each joint alone moves its farthest
/// point by up to delta.
pub fn perturb_robot(
    body: &ArticulatedBody,
    world_from_root: &Isometry3<f64>,
    q: &[f64],
    delta_m: f64,
    rng: &mut TrialRng,
) -> (Isometry3<f64>, Vec<f64>) {
    let poses = body.link_poses(world_from_root, q);
    let root = world_from_root * Point3::origin();
    let displacement = random_displacement(rng, delta_m, 1.0);
    let base = match body.rigid_mesh(q) {
        Some(mesh) => {
            let scaled = Isometry3::from_parts(
                displacement.translation,
                UnitQuaternion::from_scaled_axis(
                    displacement.rotation.scaled_axis() / mesh.radius_m(),
                ),
            );
            super::displace_about_centroid(world_from_root, &mesh, &scaled)
        }
        None => world_from_root * displacement,
    };
    let mut start = q.to_vec();
    for (parameter, value) in start.iter_mut().enumerate() {
        let info = &body.parameters()[parameter];
        let moved = body.moved_by(parameter);
        let origin = moved.first().map_or(root, |&l| poses[l] * Point3::origin());
        let bound = if info.prismatic {
            delta_m
        } else {
            (delta_m / reach_from(body, &poses, &moved, &origin).max(0.05))
                .min(std::f64::consts::PI)
        };
        *value = (*value + (2.0 * rng.uniform() - 1.0) * bound).clamp(info.lower, info.upper);
    }
    (base, start)
}

/// Outcome of one alignment of one object (the robot or a link).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outcome {
    pub error_m: f64,
    pub time_s: f64,
}

/// Succeed / fail / mean error / mean time over trials.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Tally {
    pub succeeded: usize,
    pub failed: usize,
    pub mean_error_m: f64,
    pub mean_time_s: f64,
    /// Indices in the seeded sequence of the trials that failed, to reproduce them with
    /// `first_trial` (see [`run_robot_trials`]).
    pub failed_trials: Vec<usize>,
}

impl Tally {
    /// Tallies outcomes numbered by their trials.
    pub fn from_numbered(outcomes: &[(usize, Outcome)]) -> Self {
        let n = outcomes.len().max(1) as f64;
        let failed_trials: Vec<usize> = outcomes
            .iter()
            .filter(|(_, o)| o.error_m >= SUCCESS_THRESHOLD_M)
            .map(|(trial, _)| *trial)
            .collect();
        Self {
            succeeded: outcomes.len() - failed_trials.len(),
            failed: failed_trials.len(),
            mean_error_m: outcomes.iter().map(|(_, o)| o.error_m).sum::<f64>() / n,
            mean_time_s: outcomes.iter().map(|(_, o)| o.time_s).sum::<f64>() / n,
            failed_trials,
        }
    }
}

/// One row of the table: an object (the robot, or a link) at one delta, both methods.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotTrialRow {
    pub object: String,
    pub delta_m: f64,
    pub independent: Option<Tally>,
    pub hierarchical: Option<Tally>,
}

/// Which methods a trial run compares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Methods {
    pub independent: bool,
    pub hierarchical: bool,
}

/// The scene the trials scan: the robot's root at `world_from_root`, joints at `q`.
#[derive(Debug, Clone)]
pub struct RobotScene {
    pub world_from_root: Isometry3<f64>,
    pub q: Vec<f64>,
    pub scan: RobotScanOptions,
}

/// Mixed into the seed of the independent method's stream.
const INDEPENDENT_STREAM: u64 = 0x1D3E_7A11_0000_0001;

/// One hierarchical fit from a perturbed start: the outcome for the whole robot (its worst
/// link), then one per link of `links`.
fn hierarchical_trial(
    body: &ArticulatedBody,
    scene: &RobotScene,
    cloud: &[Point3<f64>],
    poses: &[Isometry3<f64>],
    links: &[usize],
    delta_m: f64,
    rng: &mut TrialRng,
) -> Vec<Outcome> {
    let (base, q0) = perturb_robot(body, &scene.world_from_root, &scene.q, delta_m, rng);
    let started = Instant::now();
    let fit = align_robot(
        body,
        cloud,
        &base,
        &q0,
        delta_m,
        &RobotFitOptions::default(),
    );
    let time_s = started.elapsed().as_secs_f64();
    let fitted = fit
        .as_ref()
        .ok()
        .map(|f| body.link_poses(&f.world_from_root, &f.q));
    let per_link: Vec<f64> = links
        .iter()
        .map(|&link| {
            fitted.as_ref().map_or(FAILED_ERROR_M, |fitted| {
                surface_deviation_m(
                    body.links()[link].surface.as_ref().expect("has surface"),
                    &fitted[link],
                    &poses[link],
                )
            })
        })
        .collect();
    let worst = per_link.iter().copied().fold(0.0, f64::max);
    std::iter::once(worst)
        .chain(per_link)
        .map(|error_m| Outcome {
            error_m: finite_or_delta(error_m, delta_m),
            time_s,
        })
        .collect()
}

/// A failed alignment counts with this error (it returned no pose).
const FAILED_ERROR_M: f64 = f64::INFINITY;

fn finite_or_delta(error_m: f64, delta_m: f64) -> f64 {
    if error_m.is_finite() {
        error_m
    } else {
        delta_m
    }
}

/// Runs the seeded trials `trials` (indices into each delta's sequence; the starts of the trials
/// before `trials.start` are drawn and skipped, so a long run can be split and a failed trial
/// reproduced alone) per delta: the hierarchical fit of the robot from a perturbed start and the
/// rigid alignment of the whole robot and of each link from the thesis's displacement, as
/// `methods` asks. Links are those with geometry. Each method draws from its own seeded stream,
/// so a method's figures are the same whether or not the other one runs.
pub fn run_robot_trials(
    body: &ArticulatedBody,
    scene: &RobotScene,
    deltas_m: &[f64],
    trials: Range<usize>,
    seed: u64,
    methods: Methods,
    mut on_trial: impl FnMut(f64, usize),
) -> Vec<RobotTrialRow> {
    let cloud = scan_robot(body, &scene.world_from_root, &scene.q, &scene.scan);
    let poses = body.link_poses(&scene.world_from_root, &scene.q);
    let links: Vec<usize> = (0..body.links().len())
        .filter(|&l| body.links()[l].surface.is_some())
        .collect();
    let whole = body.rigid_mesh(&scene.q);
    // The independent method's objects: the whole robot (when it has geometry), then each link.
    let objects: Vec<(&Mesh, Isometry3<f64>)> = whole
        .iter()
        .map(|mesh| (mesh, scene.world_from_root))
        .chain(links.iter().map(|&link| {
            (
                body.links()[link].surface.as_ref().expect("has surface"),
                poses[link],
            )
        }))
        .collect();
    let pca_options = PcaOptions::default();
    let mut rows = Vec::new();
    for &delta_m in deltas_m {
        let mut rng = TrialRng::new(seed ^ delta_m.to_bits());
        let mut rigid_rng = TrialRng::new(seed ^ delta_m.to_bits() ^ INDEPENDENT_STREAM);
        for _ in 0..trials.start {
            perturb_robot(body, &scene.world_from_root, &scene.q, delta_m, &mut rng);
            for (mesh, _) in &objects {
                random_displacement(&mut rigid_rng, delta_m, mesh.radius_m());
            }
        }
        // Outcomes per object: index 0 the whole robot, then one per link.
        let mut hierarchical: Vec<Vec<(usize, Outcome)>> = vec![Vec::new(); links.len() + 1];
        let mut rigid: Vec<Vec<(usize, Outcome)>> = vec![Vec::new(); links.len() + 1];
        let rigid_offset = usize::from(whole.is_none());
        for trial in trials.clone() {
            on_trial(delta_m, trial);
            if methods.hierarchical {
                hierarchical_trial(body, scene, &cloud, &poses, &links, delta_m, &mut rng)
                    .into_iter()
                    .zip(hierarchical.iter_mut())
                    .for_each(|(outcome, slot)| slot.push((trial, outcome)));
            }
            if !methods.independent {
                continue;
            }
            for (slot, (mesh, truth)) in objects.iter().enumerate() {
                let displacement = random_displacement(&mut rigid_rng, delta_m, mesh.radius_m());
                let start = super::displace_about_centroid(truth, mesh, &displacement);
                let started = Instant::now();
                let result = align_cloud(mesh, &cloud, &start, delta_m, &pca_options);
                let time_s = started.elapsed().as_secs_f64();
                let error_m = result.map_or(delta_m, |r| {
                    surface_deviation_m(mesh, &r.alignment.base_from_part, truth)
                });
                rigid[slot + rigid_offset].push((trial, Outcome { error_m, time_s }));
            }
        }
        let names = std::iter::once(body.robot.clone())
            .chain(links.iter().map(|&l| body.links()[l].name.clone()));
        for (slot, object) in names.enumerate() {
            rows.push(RobotTrialRow {
                object,
                delta_m,
                independent: methods
                    .independent
                    .then(|| Tally::from_numbered(&rigid[slot])),
                hierarchical: methods
                    .hierarchical
                    .then(|| Tally::from_numbered(&hierarchical[slot])),
            });
        }
    }
    rows
}
