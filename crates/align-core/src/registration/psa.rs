//! Point Set Alignment (thesis 2.1.5): move a part's mesh until its surface passes through touch
//! inspections.
//!
//! Each iteration finds, for every touch, the closest point of the part's surface (offset outward
//! by the probe's ball radius, since the touch reports the ball's centre), then moves the part:
//! - [`PsaMethod::PointToPoint`] is the thesis's step, the weighted SVD onto those points. It
//!   converges linearly: a touch on a plane may slide along it only a fraction per iteration.
//! - [`PsaMethod::PointToPlane`] (default) solves the linearised problem in which each touch
//!   constrains only its distance along the surface normal. Touches are free to slide along their
//!   faces, so on piecewise-planar parts it converges in a handful of iterations, to machine
//!   precision on noiseless data.
//!
//! Iteration stops with the thesis's criterion (the pose still within `tolerance_m` of each of the
//! last `window` poses, section 2.1.4) or after `max_iterations`.
//!
//! After the local alignment the touch geometry is checked: if the surface normals at the touches
//! cannot fix all six degrees of freedom (all touches on parallel faces, say), the error names the
//! free motion instead of returning an arbitrary pose.
//!
//! Beyond the local method: [`align_touches`] with [`Search::Global`] runs the local method from
//! many orientations spread over the rotation group, keeps every distinct converged pose, and
//! reports the result as ambiguous when poses other than the best fit the touches equally well (a
//! symmetric part probed on symmetric faces). Face hints restrict a touch's correspondence to one
//! named face of the part, as a CMM's 3-2-1 alignment does with datum features; coherence
//! (thesis 2.1.6) rejects correspondences whose surface normal faces away from the probe.

use std::collections::HashMap;
use std::time::Instant;

use nalgebra::{Isometry3, Matrix6, Point3, Translation3, UnitQuaternion, Vector3, Vector6};

use super::convergence::{StopCriterion, pose_distance};
use super::svd::{RegistrationError, weighted_svd};
use crate::geometry::{Mesh, SurfacePoint};

/// One touch inspection in the robot base frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Touch {
    pub id: String,
    /// Centre of the probe's ball tip (the TCP), base frame, m.
    pub point: Point3<f64>,
    /// Direction the probe travelled when it touched, base frame (the tool's z axis for a probe
    /// mounted along the flange axis). Used by coherence; `None` when unknown.
    pub approach: Option<Vector3<f64>>,
    /// Name of the part face this touch was meant for (see [`Face`]); `None` when unlabelled.
    pub face: Option<String>,
}

impl Touch {
    pub fn new(id: impl Into<String>, point: Point3<f64>) -> Self {
        Self {
            id: id.into(),
            point,
            approach: None,
            face: None,
        }
    }
}

/// A named planar face of a part (a datum feature), in the part frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Face {
    pub name: String,
    /// Outward unit normal.
    pub normal: Vector3<f64>,
    /// Any point of the face's plane.
    pub point: Point3<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PsaMethod {
    PointToPoint,
    PointToPlane,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Search {
    /// One local alignment from the start pose (the thesis's behaviour).
    Local,
    /// Local alignments from the start pose and from `starts` orientations spread over SO(3).
    Global { starts: usize },
}

#[derive(Debug, Clone, PartialEq)]
pub struct PsaOptions {
    pub method: PsaMethod,
    pub search: Search,
    /// Radius of the probe's ball tip, m.
    pub tip_radius_m: f64,
    pub max_iterations: usize,
    /// Stopping criterion: the pose must stay within `tolerance_m` (thesis eq. 22) of each of the
    /// last `window` poses. Thesis: N = 19.
    pub window: usize,
    pub tolerance_m: f64,
    /// Coherence of correspondences (thesis 2.1.6): a touch with a known approach direction
    /// corresponds only to surface whose outward normal faces the probe, within
    /// `coherence_cone_rad` of the reversed approach. A touch pushed inside the part by a wrong
    /// start pose then still finds the face it touched, not a nearer foreign one.
    pub coherence: bool,
    pub coherence_cone_rad: f64,
    /// Poses whose RMS is within `ambiguity_relative` times the best RMS plus
    /// `ambiguity_tolerance_m` are "equally good": with noise the true pose does not fit exactly.
    pub ambiguity_tolerance_m: f64,
    pub ambiguity_relative: f64,
    /// Poses closer than this (thesis eq. 22) are the same solution, m.
    pub distinct_pose_m: f64,
    /// Iterations that only translate the part before full steps begin (point-to-plane only).
    /// The global search's starts use them: their orientation is a guess, their translation a
    /// rough centroid match.
    pub slide_first: usize,
}

impl Default for PsaOptions {
    fn default() -> Self {
        Self {
            method: PsaMethod::PointToPlane,
            search: Search::Global { starts: 384 },
            tip_radius_m: 0.0,
            max_iterations: 300,
            window: 19,
            tolerance_m: 1e-9,
            coherence: true,
            coherence_cone_rad: 45f64.to_radians(),
            ambiguity_tolerance_m: 1e-5,
            ambiguity_relative: 1.25,
            distinct_pose_m: 1e-3,
            slide_first: 0,
        }
    }
}

/// Signed distance of one touch from the aligned surface (ball radius removed), m.
#[derive(Debug, Clone, PartialEq)]
pub struct TouchResidual {
    pub id: String,
    pub distance_m: f64,
}

/// A converged candidate pose of a global search.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    pub base_from_part: Isometry3<f64>,
    pub rms_m: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct PsaResult {
    pub base_from_part: Isometry3<f64>,
    pub iterations: usize,
    pub converged: bool,
    pub rms_m: f64,
    pub max_m: f64,
    pub residuals: Vec<TouchResidual>,
    /// Other distinct poses that fit as well as the chosen one (empty unless ambiguous).
    pub ambiguous_with: Vec<Candidate>,
    /// Local alignments run (1 for a local search).
    pub starts: usize,
    pub time_s: f64,
}

impl PsaResult {
    pub fn is_ambiguous(&self) -> bool {
        !self.ambiguous_with.is_empty()
    }
}

/// The part's mesh with what the alignment precomputes: one sub-mesh per named face.
#[derive(Debug)]
pub struct PsaTarget<'a> {
    mesh: &'a Mesh,
    faces: HashMap<String, Mesh>,
    /// The mesh's triangles grouped by normal direction, for coherent searches.
    normal_bins: Vec<NormalBin>,
}

#[derive(Debug)]
struct NormalBin {
    direction: Vector3<f64>,
    mesh: Mesh,
}

/// Bin directions: the 26 neighbours of a cube's centre (faces, edges, corners), about 27 degrees
/// apart, so a triangle's normal is never more than about 35 degrees from its bin's direction.
const BIN_RADIUS_RAD: f64 = 0.62;

fn bin_directions() -> Vec<Vector3<f64>> {
    let mut directions = Vec::with_capacity(26);
    for x in -1..=1 {
        for y in -1..=1 {
            for z in -1..=1 {
                if (x, y, z) != (0, 0, 0) {
                    directions.push(Vector3::new(x as f64, y as f64, z as f64).normalize());
                }
            }
        }
    }
    directions
}

impl<'a> PsaTarget<'a> {
    pub fn new(mesh: &'a Mesh) -> Self {
        let vertices: Vec<Point3<f64>> = mesh.vertices().collect();
        let directions = bin_directions();
        let mut members: Vec<Vec<[u32; 3]>> = vec![Vec::new(); directions.len()];
        for (index, triangle) in mesh.triangles().iter().enumerate() {
            let normal = mesh.triangle_normal(index as u32);
            let nearest = directions
                .iter()
                .enumerate()
                .max_by(|a, b| normal.dot(a.1).total_cmp(&normal.dot(b.1)))
                .map_or(0, |(bin, _)| bin);
            members[nearest].push(*triangle);
        }
        let normal_bins = directions
            .into_iter()
            .zip(members)
            .filter_map(|(direction, triangles)| {
                Mesh::new(&vertices, &triangles)
                    .ok()
                    .map(|mesh| NormalBin { direction, mesh })
            })
            .collect();
        Self {
            mesh,
            faces: HashMap::new(),
            normal_bins,
        }
    }

    /// The closest surface point whose face normal lies within `cone_rad` of `facing` (unit,
    /// part frame), or `None` when no such surface exists.
    fn closest_coherent(
        &self,
        query: &Point3<f64>,
        facing: &Vector3<f64>,
        cone_rad: f64,
    ) -> Option<SurfacePoint> {
        let cos_cone = cone_rad.cos();
        // Usually the plain closest point is coherent, and then it is also the closest coherent
        // one: one BVH query instead of one per bin.
        let mut plain = self.mesh.closest_point(query);
        let face_normal = self.mesh.triangle_normal(plain.triangle);
        if face_normal.dot(facing) >= cos_cone {
            // On an edge the pseudo-normal blends in the incoherent neighbour; the touched face's
            // own normal is the one that constrains this touch.
            plain.normal = face_normal;
            return Some(plain);
        }
        let bin_reach = (cone_rad + BIN_RADIUS_RAD).min(std::f64::consts::PI).cos();
        let mut best: Option<SurfacePoint> = None;
        for bin in &self.normal_bins {
            if bin.direction.dot(facing) < bin_reach {
                continue;
            }
            let limit = best.map_or(f64::MAX, |b| b.signed_distance.abs());
            let Some(found) = bin.mesh.closest_point_within(query, limit) else {
                continue;
            };
            if bin.mesh.triangle_normal(found.triangle).dot(facing) < cos_cone {
                continue;
            }
            if best.is_none_or(|b| found.signed_distance.abs() < b.signed_distance.abs()) {
                best = Some(found);
            }
        }
        best.map(|mut found| {
            // Bins are open sub-meshes: recover the side from the whole part's normal.
            let side = (query - found.point).dot(&found.normal);
            found.signed_distance = if side < 0.0 && self.mesh.is_watertight() {
                -found.signed_distance.abs()
            } else {
                found.signed_distance.abs()
            };
            found
        })
    }

    /// Adds named faces: each becomes the triangles whose normal is within 1 degree of the face
    /// normal and whose vertices lie within 0.01 mm of its plane.
    pub fn with_faces(mut self, faces: &[Face]) -> Result<Self, RegistrationError> {
        let vertices: Vec<Point3<f64>> = self.mesh.vertices().collect();
        for face in faces {
            let normal = face.normal.try_normalize(1e-12).ok_or_else(|| {
                RegistrationError::Underconstrained {
                    dof: format!("face '{}' has a zero normal", face.name),
                }
            })?;
            let triangles: Vec<[u32; 3]> = self
                .mesh
                .triangles()
                .iter()
                .enumerate()
                .filter(|&(index, triangle)| {
                    self.mesh.triangle_normal(index as u32).dot(&normal) > 1f64.to_radians().cos()
                        && triangle
                            .iter()
                            .all(|&v| (vertices[v as usize] - face.point).dot(&normal).abs() < 1e-5)
                })
                .map(|(_, triangle)| *triangle)
                .collect();
            let sub_mesh = Mesh::new(&vertices, &triangles).map_err(|_| {
                RegistrationError::Underconstrained {
                    dof: format!("face '{}' matches no triangle of the part", face.name),
                }
            })?;
            self.faces.insert(face.name.clone(), sub_mesh);
        }
        Ok(self)
    }

    pub fn mesh(&self) -> &Mesh {
        self.mesh
    }

    fn surface_for(&self, touch: &Touch) -> Result<&Mesh, RegistrationError> {
        match &touch.face {
            None => Ok(self.mesh),
            Some(name) => self
                .faces
                .get(name)
                .ok_or_else(|| RegistrationError::Underconstrained {
                    dof: format!(
                        "touch '{}' names face '{name}', which the part does not define",
                        touch.id
                    ),
                }),
        }
    }
}

/// Aligns the part to the touches, starting from `base_from_part_start` (the nominal pose).
pub fn align_touches(
    target: &PsaTarget<'_>,
    touches: &[Touch],
    base_from_part_start: &Isometry3<f64>,
    options: &PsaOptions,
) -> Result<PsaResult, RegistrationError> {
    let started = Instant::now();
    validate(touches, options)?;
    let mut workspace = Workspace::new(target, touches, options)?;
    let local = workspace.run_local(base_from_part_start);
    let (mut best, starts, ambiguous_with) = match options.search {
        Search::Local => (local, 1, Vec::new()),
        Search::Global { starts } => {
            let mut solutions = vec![local];
            let centroid = touches
                .iter()
                .fold(Vector3::zeros(), |sum, touch| sum + touch.point.coords)
                / touches.len() as f64;
            let part_centroid = target.mesh.centroid().coords;
            // Exploration: a short stopping window and a coarse tolerance find where each start
            // leads; only the poses that compete for best are then refined to full precision.
            let explore = PsaOptions {
                window: 3,
                tolerance_m: 1e-6,
                max_iterations: 30,
                slide_first: 4,
                ..options.clone()
            };
            let mut explorer = Workspace::new(target, touches, &explore)?;
            let mut best_score = solutions[0].score;
            for rotation in spread_rotations(starts) {
                let translation = centroid - rotation * part_centroid;
                let start = Isometry3::from_parts(Translation3::from(translation), rotation);
                // A start still far worse than the best after its first full steps is heading
                // for another minimum: abandon it (it could at best tie, and ties that matter
                // are found by the starts that get there directly).
                explorer.abandon_above =
                    Some((20.0 * best_score).max(0.02 * target.mesh.radius_m()));
                let solution = explorer.run_local(&start);
                best_score = best_score.min(solution.score);
                solutions.push(solution);
            }
            let radius_m = target.mesh.radius_m();
            let refined = contenders(solutions, radius_m, options)
                .into_iter()
                .map(|solution| {
                    let mut refined = workspace.run_local(&solution.pose);
                    refined.iterations += solution.iterations;
                    refined
                })
                .collect();
            let (best, ambiguous_with) = choose(refined, base_from_part_start, radius_m, options);
            (best, starts + 1, ambiguous_with)
        }
    };
    // Checked where the alignment ended: far from the part every touch may find the same face,
    // which says nothing about the touches themselves.
    check_constrained(&mut workspace, &best.pose)?;
    best.iterations = best.iterations.max(1);
    let residuals = workspace.residuals(&best.pose);
    let max_m = residuals
        .iter()
        .map(|r| r.distance_m.abs())
        .fold(0.0, f64::max);
    Ok(PsaResult {
        base_from_part: best.pose,
        iterations: best.iterations,
        converged: best.converged,
        rms_m: best.rms_m,
        max_m,
        residuals,
        ambiguous_with,
        starts,
        time_s: started.elapsed().as_secs_f64(),
    })
}

fn validate(touches: &[Touch], options: &PsaOptions) -> Result<(), RegistrationError> {
    if touches.len() < 3 {
        return Err(RegistrationError::TooFewPoints(touches.len()));
    }
    for (index, touch) in touches.iter().enumerate() {
        let approach_finite = touch
            .approach
            .is_none_or(|a| a.iter().all(|c| c.is_finite()));
        if !touch.point.coords.iter().all(|c| c.is_finite()) || !approach_finite {
            return Err(RegistrationError::NonFinite { index });
        }
    }
    if !(options.tip_radius_m.is_finite() && options.tip_radius_m >= 0.0) {
        return Err(RegistrationError::NonFinite { index: usize::MAX });
    }
    Ok(())
}

#[derive(Debug, Clone)]
struct LocalSolution {
    pose: Isometry3<f64>,
    iterations: usize,
    converged: bool,
    rms_m: f64,
    /// RMS plus the incoherence penalty: what solutions are ranked by.
    score: f64,
}

/// Buffers reused across iterations and starts, so the hot loop does not allocate.
struct Workspace<'t> {
    target: &'t PsaTarget<'t>,
    touches: &'t [Touch],
    surfaces: Vec<&'t Mesh>,
    options: &'t PsaOptions,
    radius_m: f64,
    moved: Vec<Point3<f64>>,
    normals: Vec<Vector3<f64>>,
    weights: Vec<f64>,
    fixed: Vec<Point3<f64>>,
    /// Touches without a coherent surface at the last `correspond`.
    incoherent: usize,
    /// Abandon a local run whose score is still above this after its first full steps.
    abandon_above: Option<f64>,
}

impl<'t> Workspace<'t> {
    fn new(
        target: &'t PsaTarget<'t>,
        touches: &'t [Touch],
        options: &'t PsaOptions,
    ) -> Result<Self, RegistrationError> {
        let surfaces = touches
            .iter()
            .map(|touch| target.surface_for(touch))
            .collect::<Result<Vec<_>, _>>()?;
        let count = touches.len();
        Ok(Self {
            target,
            touches,
            surfaces,
            options,
            radius_m: target.mesh.radius_m(),
            moved: Vec::with_capacity(count),
            normals: Vec::with_capacity(count),
            weights: Vec::with_capacity(count),
            fixed: touches.iter().map(|touch| touch.point).collect(),
            incoherent: 0,
            abandon_above: None,
        })
    }

    /// The surface point each touch corresponds to at `pose`, offset by the ball radius, and its
    /// normal, both in the base frame; weight 0 for incoherent correspondences.
    fn correspond(&mut self, pose: &Isometry3<f64>) {
        self.moved.clear();
        self.normals.clear();
        self.weights.clear();
        self.incoherent = 0;
        let part_from_base = pose.inverse();
        for (touch, surface) in self.touches.iter().zip(&self.surfaces) {
            let in_part = part_from_base * touch.point;
            let (closest, coherent) = self.closest_for(touch, surface, &in_part, &part_from_base);
            self.incoherent += usize::from(!coherent);
            let contact_centre = closest.point + closest.normal * self.options.tip_radius_m;
            self.moved.push(pose * contact_centre);
            self.normals.push(pose.rotation * closest.normal);
            self.weights.push(1.0);
        }
    }

    /// A touch's correspondence: on its named face if it has one, else on the surface facing the
    /// probe (coherence) if its approach is known, else the plain closest point.
    fn closest_for(
        &self,
        touch: &Touch,
        surface: &Mesh,
        in_part: &Point3<f64>,
        part_from_base: &Isometry3<f64>,
    ) -> (SurfacePoint, bool) {
        if let (true, None, Some(approach)) = (self.options.coherence, &touch.face, touch.approach)
            && let Some(facing) = (part_from_base.rotation * -approach).try_normalize(1e-12)
        {
            return match self.target.closest_coherent(
                in_part,
                &facing,
                self.options.coherence_cone_rad,
            ) {
                Some(found) => (found, true),
                // No surface faces this probe at this pose: align to the nearest anyway, but the
                // pose is penalised (see `score`).
                None => (surface.closest_point(in_part), false),
            };
        }
        (surface.closest_point(in_part), true)
    }

    /// What the local search minimises and the global search ranks: the RMS distance plus one
    /// part radius per touch that no surface faces at this pose. Without the penalty a pose
    /// could "fit" by aligning touches to faces the probe could not have touched.
    fn score(&self) -> f64 {
        self.rms() + self.incoherent as f64 * self.radius_m
    }

    /// RMS distance of the touches from the (ball-offset) surface at the current correspondences.
    fn rms(&self) -> f64 {
        let sum: f64 = self
            .moved
            .iter()
            .zip(&self.fixed)
            .map(|(moved, fixed)| (fixed - moved).norm_squared())
            .sum();
        (sum / self.moved.len() as f64).sqrt()
    }

    /// One local alignment. A step that increases the RMS distance (a linearisation that
    /// overshot, typically when a correspondence jumps to another face) is halved until it does
    /// not, which keeps the iteration monotone like the thesis's ICP.
    fn run_local(&mut self, start: &Isometry3<f64>) -> LocalSolution {
        self.run_local_from(start, self.options.slide_first)
    }

    /// A local alignment whose first `translation_only` iterations keep the orientation: from a
    /// guessed orientation with a rough translation, sliding the part into place first keeps
    /// the rotation from absorbing translation error (the global search's starts).
    fn run_local_from(&mut self, start: &Isometry3<f64>, translation_only: usize) -> LocalSolution {
        let mut pose = *start;
        let mut stop =
            StopCriterion::new(self.options.window, self.options.tolerance_m, self.radius_m);
        let mut converged = false;
        let mut iterations = 0;
        stop.update(&pose);
        self.correspond(&pose);
        let mut score = self.score();
        while iterations < self.options.max_iterations {
            iterations += 1;
            let sliding = iterations <= translation_only;
            let step = match self.options.method {
                PsaMethod::PointToPoint => weighted_svd(&self.moved, &self.fixed, &self.weights)
                    .ok()
                    .map(Twist::from_isometry),
                PsaMethod::PointToPlane => self.point_to_plane_step(sliding),
            };
            let Some(step) = step else {
                break;
            };
            let mut fraction = 1.0;
            let mut candidate;
            loop {
                candidate = step.scaled(fraction) * pose;
                self.correspond(&candidate);
                let candidate_score = self.score();
                // While sliding, the orientation may still be wrong and the RMS need not fall.
                if sliding || candidate_score <= score * (1.0 + 1e-12) || fraction < 1.0 / 64.0 {
                    score = candidate_score;
                    break;
                }
                fraction *= 0.5;
            }
            let moved_m = pose_distance(&pose, &candidate, self.radius_m);
            pose = candidate;
            if !sliding && stop.update(&pose) {
                converged = true;
                break;
            }
            if !sliding && moved_m < self.options.tolerance_m * 1e-3 {
                // Settled to far below the tolerance: every remaining iteration of the window
                // would find the same correspondences and stay within it.
                converged = true;
                break;
            }
            if let Some(limit) = self.abandon_above
                && iterations >= translation_only + 6
                && score > limit
            {
                break;
            }
        }
        LocalSolution {
            pose,
            iterations,
            converged,
            rms_m: self.rms(),
            score,
        }
    }

    /// Normal equations of the linearised point-to-plane problem about the weighted centroid `c`:
    /// unknowns x = (omega, t), moved point y' = y + omega x (y - c) + t, residual
    /// n . (y' - i) = 0. Rotation columns are scaled by the part radius so the system is
    /// well-conditioned whatever the units.
    fn normal_equations(&self) -> (Matrix6<f64>, Vector6<f64>, Point3<f64>) {
        let total: f64 = self.weights.iter().sum();
        let centre = Point3::from(
            self.moved
                .iter()
                .zip(&self.weights)
                .fold(Vector3::zeros(), |sum, (p, w)| sum + p.coords * *w)
                / total,
        );
        let scale = self.radius_m.max(1e-9);
        let mut normal_matrix = Matrix6::zeros();
        let mut rhs = Vector6::zeros();
        for (((moved, fixed), normal), weight) in self
            .moved
            .iter()
            .zip(&self.fixed)
            .zip(&self.normals)
            .zip(&self.weights)
        {
            let lever = (moved - centre).cross(normal) / scale;
            let row = Vector6::new(lever.x, lever.y, lever.z, normal.x, normal.y, normal.z);
            let residual = normal.dot(&(fixed - moved));
            normal_matrix += row * row.transpose() * *weight;
            rhs += row * (residual * weight);
        }
        (normal_matrix, rhs, centre)
    }

    fn point_to_plane_step(&self, translation_only: bool) -> Option<Twist> {
        let (normal_matrix, rhs, centre) = self.normal_equations();
        if translation_only {
            let block = normal_matrix.fixed_view::<3, 3>(3, 3).into_owned();
            let translation = block
                .cholesky()?
                .solve(&rhs.fixed_rows::<3>(3).into_owned());
            return Some(Twist {
                omega: Vector3::zeros(),
                translation,
                centre,
            });
        }
        let solution = normal_matrix.cholesky()?.solve(&rhs);
        let scale = self.radius_m.max(1e-9);
        Some(Twist {
            omega: Vector3::new(solution[0], solution[1], solution[2]) / scale,
            translation: Vector3::new(solution[3], solution[4], solution[5]),
            centre,
        })
    }

    fn residuals(&mut self, pose: &Isometry3<f64>) -> Vec<TouchResidual> {
        let part_from_base = pose.inverse();
        self.touches
            .iter()
            .zip(&self.surfaces)
            .map(|(touch, surface)| {
                let (closest, _) = self.closest_for(
                    touch,
                    surface,
                    &(part_from_base * touch.point),
                    &part_from_base,
                );
                TouchResidual {
                    id: touch.id.clone(),
                    distance_m: closest.signed_distance - self.options.tip_radius_m,
                }
            })
            .collect()
    }
}

/// A rigid step: rotation `omega` (rotation vector) about `centre`, then `translation`.
#[derive(Debug, Clone, Copy)]
struct Twist {
    omega: Vector3<f64>,
    translation: Vector3<f64>,
    centre: Point3<f64>,
}

impl Twist {
    fn from_isometry(step: Isometry3<f64>) -> Self {
        Self {
            omega: step.rotation.scaled_axis(),
            translation: step.translation.vector,
            centre: Point3::origin(),
        }
    }

    /// The step shortened to `fraction` of its rotation and translation: y' = R (y - c) + c + t.
    fn scaled(&self, fraction: f64) -> Isometry3<f64> {
        let rotation = UnitQuaternion::from_scaled_axis(self.omega * fraction);
        let shift =
            self.centre.coords + self.translation * fraction - rotation * self.centre.coords;
        Isometry3::from_parts(Translation3::from(shift), rotation)
    }
}

/// Refuses touch sets whose surface normals leave a rigid motion unconstrained: the smallest
/// eigenvalue of the point-to-plane normal matrix (rotation scaled by the part radius) is
/// negligible. The eigenvector names the free motion.
fn check_constrained(
    workspace: &mut Workspace<'_>,
    start: &Isometry3<f64>,
) -> Result<(), RegistrationError> {
    workspace.correspond(start);
    workspace.weights.iter_mut().for_each(|w| *w = 1.0);
    let (normal_matrix, _, centre) = workspace.normal_equations();
    let eigen = normal_matrix.symmetric_eigen();
    let (smallest, value) = eigen
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .map(|(index, value)| (index, *value))
        .unwrap_or((0, 0.0));
    let largest = eigen.eigenvalues.iter().copied().fold(0.0, f64::max);
    if value > largest * 1e-9 {
        return Ok(());
    }
    let direction = eigen.eigenvectors.column(smallest);
    let rotation = Vector3::new(direction[0], direction[1], direction[2]);
    let translation = Vector3::new(direction[3], direction[4], direction[5]);
    // Rounded first so that -0.0001 prints as 0.000, not -0.000.
    let round = |c: f64| (c * 1000.0).round() / 1000.0 + 0.0;
    let fmt =
        |v: &Vector3<f64>| format!("({:.3}, {:.3}, {:.3})", round(v.x), round(v.y), round(v.z));
    let dof = if rotation.norm() < 1e-6 {
        format!(
            "translation along {} in the base frame (no touch has a normal along it)",
            fmt(&translation.normalize())
        )
    } else if translation.norm() < 1e-6 {
        format!(
            "rotation about the axis {} through ({:.4}, {:.4}, {:.4}) m in the base frame",
            fmt(&rotation.normalize()),
            centre.x,
            centre.y,
            centre.z
        )
    } else {
        format!(
            "a combined rotation about {} and translation along {} (base frame)",
            fmt(&rotation.normalize()),
            fmt(&translation.normalize())
        )
    };
    Err(RegistrationError::Underconstrained { dof })
}

/// The distinct solutions that may end up equally good once refined: those within the
/// ambiguity band of the best, with slack for the exploration's coarse tolerance.
fn contenders(
    mut solutions: Vec<LocalSolution>,
    radius_m: f64,
    options: &PsaOptions,
) -> Vec<LocalSolution> {
    solutions.sort_by(|a, b| a.score.total_cmp(&b.score));
    let limit = solutions[0].score * options.ambiguity_relative * 2.0
        + options.ambiguity_tolerance_m * 2.0
        + 1e-5;
    let mut distinct: Vec<LocalSolution> = Vec::new();
    for solution in solutions.into_iter().take_while(|s| s.score <= limit) {
        let seen = distinct.iter().any(|other| {
            pose_distance(&other.pose, &solution.pose, radius_m) < options.distinct_pose_m
        });
        if !seen {
            distinct.push(solution);
        }
    }
    distinct
}

/// Picks the best-fitting solution; other distinct solutions fitting as well make it ambiguous.
/// Among equally good poses the one nearest the start (the user's nominal pose) is reported.
fn choose(
    mut solutions: Vec<LocalSolution>,
    start: &Isometry3<f64>,
    radius_m: f64,
    options: &PsaOptions,
) -> (LocalSolution, Vec<Candidate>) {
    solutions.sort_by(|a, b| a.score.total_cmp(&b.score));
    let best_score = solutions[0].score;
    let mut distinct: Vec<LocalSolution> = Vec::new();
    for solution in solutions {
        if solution.score > best_score * options.ambiguity_relative + options.ambiguity_tolerance_m
        {
            break;
        }
        let seen = distinct.iter().any(|other| {
            pose_distance(&other.pose, &solution.pose, radius_m) < options.distinct_pose_m
        });
        if !seen {
            distinct.push(solution);
        }
    }
    distinct.sort_by(|a, b| {
        pose_distance(&a.pose, start, radius_m).total_cmp(&pose_distance(&b.pose, start, radius_m))
    });
    let best = distinct.remove(0);
    let others = distinct
        .into_iter()
        .map(|solution| Candidate {
            base_from_part: solution.pose,
            rms_m: solution.rms_m,
        })
        .collect();
    (best, others)
}

/// `count` rotations spread evenly over SO(3) (Alexa's super-Fibonacci spirals, CVPR 2022):
/// deterministic, no clustering at the poles as with Euler-angle grids.
pub fn spread_rotations(count: usize) -> Vec<UnitQuaternion<f64>> {
    let phi = std::f64::consts::SQRT_2;
    let psi = 1.533_751_168_755_204_3;
    (0..count)
        .map(|i| {
            let s = i as f64 + 0.5;
            let r = (s / count as f64).sqrt();
            let big_r = (1.0 - s / count as f64).sqrt();
            let alpha = 2.0 * std::f64::consts::PI * s / phi;
            let beta = 2.0 * std::f64::consts::PI * s / psi;
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                r * alpha.sin(),
                r * alpha.cos(),
                big_r * beta.sin(),
                big_r * beta.cos(),
            ))
        })
        .collect()
}
