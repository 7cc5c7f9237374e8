//! Planning touches on any part the robot can reach, as a CMM programmer would: the 3-2-1
//! principle (three touches spread over a primary face, two on a face square to it, one on a face
//! square to both: together they fix all six degrees of freedom) plus extras spread over the
//! other faces. Each touch must be
//! - on a flat face, at least `edge_margin_m` from its edges (a ball near an edge touches the edge),
//! - approachable: the ball's centre and the first `approach_m` of the approach line clear of the
//!   part,
//! - reachable: an IK solution with the probe along the inward normal, or tilted up to
//!   `max_tilt_rad` from it (never approaching from below), tried in that order.
//!
//! Candidate points come from a lattice inside every triangle of a face; the three points of the
//! primary face are chosen to span the largest triangle, the others farthest from what is
//! already chosen. Used by sim-robot to probe a scene it is given, and by `ips demo`.

use nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::geometry::Mesh;
use crate::kinematics::{Chain, IkOptions};

#[derive(Debug, Clone, PartialEq)]
pub struct PlanOptions {
    /// Touches in all; at least 6 for 3-2-1.
    pub touches: usize,
    pub max_tilt_rad: f64,
    pub edge_margin_m: f64,
    /// Length of the approach line that must be clear of the part.
    pub approach_m: f64,
    /// Vary the probe's tilt from touch to touch (0, half and full `max_tilt_rad` in turn,
    /// where reachable) rather than coming in along the normal wherever possible: tilted touches
    /// tell a ball-radius error from a TCP shift.
    pub vary_tilt: bool,
}

impl Default for PlanOptions {
    fn default() -> Self {
        Self {
            touches: 9,
            max_tilt_rad: 0.6,
            edge_margin_m: 0.01,
            approach_m: 0.05,
            vary_tilt: false,
        }
    }
}

/// One planned touch: where (part frame), how the probe comes in, and the joints at contact.
#[derive(Debug, Clone, PartialEq)]
pub struct TouchPlan {
    pub point_in_part: Point3<f64>,
    /// Outward normal of the touched face, part frame.
    pub normal_in_part: Vector3<f64>,
    /// Angle between the probe and the inward normal, rad.
    pub tilt_rad: f64,
    /// Joints with the ball on the point.
    pub q_contact: Vec<f64>,
    /// Joints `approach_m` back along the probe axis.
    pub q_approach: Vec<f64>,
    /// Index of the planar face (faces numbered by decreasing area).
    pub face: usize,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    #[error("a touch plan needs at least 6 touches (3-2-1), {0} asked")]
    TooFewTouches(usize),
    #[error("the part has no flat face the probe can reach")]
    NoPrimaryFace,
    #[error(
        "no reachable face square to the primary face (normal {0:.2?}): the touches cannot fix every degree of freedom"
    )]
    NoSecondaryFace([f64; 3]),
    #[error(
        "no reachable face square to both the primary and the secondary face: the touches cannot fix every degree of freedom"
    )]
    NoTertiaryFace,
    #[error("only {found} reachable touch points were found, {asked} asked")]
    TooFewReachable { found: usize, asked: usize },
}

/// A flat face: triangles sharing a plane.
struct PlanarFace {
    normal: Vector3<f64>,
    area: f64,
    triangles: Vec<u32>,
}

fn planar_faces(mesh: &Mesh) -> Vec<PlanarFace> {
    let mut faces: Vec<(Vector3<f64>, f64, PlanarFace)> = Vec::new();
    let vertices: Vec<Point3<f64>> = mesh.vertices().collect();
    for (index, triangle) in mesh.triangles().iter().enumerate() {
        let index = index as u32;
        let normal = mesh.triangle_normal(index);
        let area = mesh.triangle_area(index);
        if area <= 0.0 || !normal.iter().all(|v| v.is_finite()) {
            continue;
        }
        let offset = normal.dot(&vertices[triangle[0] as usize].coords);
        // Same plane: normals within ~1 degree and offsets within 0.1 mm.
        match faces
            .iter_mut()
            .find(|(n, d, _)| n.dot(&normal) > 0.9998 && (d - offset).abs() < 1e-4)
        {
            Some((_, _, face)) => {
                face.area += area;
                face.triangles.push(index);
            }
            None => faces.push((
                normal,
                offset,
                PlanarFace {
                    normal,
                    area,
                    triangles: vec![index],
                },
            )),
        }
    }
    let mut faces: Vec<PlanarFace> = faces.into_iter().map(|(_, _, face)| face).collect();
    faces.sort_by(|a, b| b.area.total_cmp(&a.area));
    faces
}

/// Lattice points inside the face's triangles that keep `margin` from the face's edges.
fn candidates(mesh: &Mesh, face: &PlanarFace, margin: f64) -> Vec<Point3<f64>> {
    const DIVISIONS: usize = 8;
    let vertices: Vec<Point3<f64>> = mesh.vertices().collect();
    let normal = face.normal;
    let u = normal
        .cross(&normal.xzy().abs())
        .try_normalize(1e-9)
        .unwrap_or_else(|| {
            normal
                .cross(&Vector3::x())
                .try_normalize(1e-9)
                .unwrap_or(Vector3::y())
        });
    let v = normal.cross(&u);
    let mut points = Vec::new();
    for &triangle in &face.triangles {
        let [a, b, c] = mesh.triangles()[triangle as usize].map(|i| vertices[i as usize]);
        for i in 1..DIVISIONS {
            for j in 1..DIVISIONS - i {
                let (s, t) = (i as f64 / DIVISIONS as f64, j as f64 / DIVISIONS as f64);
                let point = a + (b - a) * s + (c - a) * t;
                // On the face all round: the ring at `margin` projects back onto this plane.
                let inside = (0..8).all(|k| {
                    let angle = k as f64 * std::f64::consts::FRAC_PI_4;
                    let probe = point + (u * angle.cos() + v * angle.sin()) * margin;
                    let surface = mesh.closest_point(&(probe + normal * 1e-4));
                    surface.normal.dot(&normal) > 0.9998 && (surface.point - probe).norm() < 1e-6
                });
                if inside {
                    points.push(point);
                }
            }
        }
    }
    points
}

/// The ball's centre (on the normal, one radius out: the ball touches the face at the point
/// whatever the tilt) and the approach line behind it, along the probe axis, are outside the part.
fn approachable(
    mesh: &Mesh,
    point: &Point3<f64>,
    normal: &Vector3<f64>,
    axis_out: &Vector3<f64>,
    radius: f64,
    approach: f64,
) -> bool {
    let centre = point + normal * radius;
    let steps = (approach / 0.002).ceil().max(1.0) as usize;
    (0..=steps).all(|k| {
        let along = centre + axis_out * (approach * k as f64 / steps as f64);
        mesh.closest_point(&along).signed_distance >= radius * 0.999 - 1e-9
    })
}

/// Probe axes to try for a face normal (base frame): along the inward normal, then tilted, never
/// pointing up.
fn probe_axes(normal_base: &Vector3<f64>, max_tilt: f64) -> Vec<(Vector3<f64>, f64)> {
    let inward = -normal_base;
    let mut axes = vec![(inward, 0.0)];
    let side = normal_base
        .cross(&Vector3::z())
        .try_normalize(1e-6)
        .unwrap_or_else(Vector3::x);
    let other = normal_base.cross(&side);
    for tilt in [max_tilt * 0.5, max_tilt] {
        for k in 0..8 {
            let angle = k as f64 * std::f64::consts::FRAC_PI_4;
            let axis = side * angle.cos() + other * angle.sin();
            let probe = UnitQuaternion::from_scaled_axis(axis * tilt) * inward;
            axes.push((probe, tilt));
        }
    }
    // Downward-pointing probes first among the tilted: a ball coming from above is what a
    // cobot reaches best.
    axes[1..].sort_by(|a, b| a.0.z.total_cmp(&b.0.z));
    axes.retain(|(probe, _)| probe.z <= 0.2);
    axes
}

/// The TCP frame with its z along `probe` at `centre`, spun by `spin` about z.
fn tcp_frame(centre: &Point3<f64>, probe: &Vector3<f64>, spin: f64) -> Isometry3<f64> {
    let helper = if probe.x.abs() > 0.9 {
        Vector3::y()
    } else {
        Vector3::x()
    };
    let y_axis = probe.cross(&helper).normalize();
    let x_axis = y_axis.cross(probe);
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_basis_unchecked(&[
        x_axis, y_axis, *probe,
    ])) * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), spin);
    Isometry3::from_parts(Translation3::from(centre.coords), rotation)
}

/// Candidate points tried per touch asked before a face counts as out of reach.
const MAX_TRIES_PER_TOUCH: usize = 12;

struct Reach<'a> {
    /// `None` plans where to touch without asking whether a robot reaches it.
    chain: Option<&'a Chain>,
    base_from_part: Isometry3<f64>,
    flange_from_tcp: Isometry3<f64>,
    radius: f64,
    part_scale: f64,
    options: &'a PlanOptions,
    mesh: &'a Mesh,
    seed: Vec<f64>,
}

impl Reach<'_> {
    /// The touch at `point` if the probe can get there; `index` is its place in the plan.
    fn try_touch(
        &self,
        point: &Point3<f64>,
        normal: &Vector3<f64>,
        face: usize,
        index: usize,
    ) -> Option<TouchPlan> {
        let surface = Point3::from(point.coords * self.part_scale);
        let normal_base = self.base_from_part.rotation * normal;
        let ik = IkOptions {
            max_attempts: 8,
            ..IkOptions::default()
        };
        let mut axes = probe_axes(&normal_base, self.options.max_tilt_rad);
        if self.options.vary_tilt {
            // Head-on, half, full tilt, then full tilt the other way round: a ball-radius error
            // moves every touch along its normal, a TCP shift only as far as the probe axis
            // leans, and opposite leans tell the TCP's sideways shifts apart.
            let levels = [0.0, 0.5, 1.0, 1.0].map(|f| f * self.options.max_tilt_rad);
            let preferred = levels[index % levels.len()];
            let at_level = |tilt: &f64| (tilt - preferred).abs() <= 1e-9;
            let (mut first, rest): (Vec<_>, Vec<_>) =
                axes.into_iter().partition(|(_, tilt)| at_level(tilt));
            if index % levels.len() == 3 {
                first.reverse();
            }
            first.extend(rest);
            axes = first;
        }
        for (probe, tilt) in axes {
            let axis_out_part = self.base_from_part.rotation.inverse() * -probe;
            if !approachable(
                self.mesh,
                point,
                normal,
                &axis_out_part,
                self.radius,
                self.options.approach_m,
            ) {
                continue;
            }
            let contact_centre = self.base_from_part * (surface + normal * self.radius);
            let Some(chain) = self.chain else {
                return Some(TouchPlan {
                    point_in_part: *point,
                    normal_in_part: *normal,
                    tilt_rad: tilt,
                    q_contact: Vec::new(),
                    q_approach: Vec::new(),
                    face,
                });
            };
            for spin in [0.0, 1.5, 3.0, -1.5] {
                let contact = tcp_frame(&contact_centre, &probe, spin);
                let Ok(at_contact) =
                    chain.inverse(&(contact * self.flange_from_tcp.inverse()), &self.seed, &ik)
                else {
                    continue;
                };
                let back = Translation3::from(-probe * self.options.approach_m) * contact;
                let Ok(at_approach) =
                    chain.inverse(&(back * self.flange_from_tcp.inverse()), &at_contact.q, &ik)
                else {
                    continue;
                };
                return Some(TouchPlan {
                    point_in_part: *point,
                    normal_in_part: *normal,
                    tilt_rad: tilt,
                    q_contact: at_contact.q,
                    q_approach: at_approach.q,
                    face,
                });
            }
        }
        None
    }

    /// Up to `count` reachable touches on `face`, each farthest from `chosen` and each other.
    fn pick(
        &self,
        points: &[Point3<f64>],
        normal: &Vector3<f64>,
        face: usize,
        count: usize,
        chosen: &[TouchPlan],
    ) -> Vec<TouchPlan> {
        let mut picked: Vec<TouchPlan> = Vec::new();
        let mut remaining: Vec<Point3<f64>> = points.to_vec();
        // Each try may run dozens of IK solves: a face that keeps refusing is given up on.
        let mut tries = 0;
        while picked.len() < count && !remaining.is_empty() && tries < MAX_TRIES_PER_TOUCH * count {
            let spread = |p: &Point3<f64>| {
                chosen
                    .iter()
                    .chain(&picked)
                    .map(|t| (t.point_in_part - p).norm())
                    .fold(f64::INFINITY, f64::min)
            };
            // Without anything chosen yet, start from the point farthest from the face's middle.
            let middle = remaining.iter().fold(Vector3::zeros(), |s, p| s + p.coords)
                / remaining.len() as f64;
            let score = |p: &Point3<f64>| {
                let s = spread(p);
                if s.is_finite() {
                    s
                } else {
                    (p.coords - middle).norm()
                }
            };
            let Some(best) = remaining
                .iter()
                .enumerate()
                .max_by(|a, b| score(a.1).total_cmp(&score(b.1)))
                .map(|(i, _)| i)
            else {
                break;
            };
            let point = remaining.swap_remove(best);
            tries += 1;
            if let Some(touch) = self.try_touch(&point, normal, face, chosen.len() + picked.len()) {
                picked.push(touch);
            }
        }
        picked
    }
}

/// Plans `options.touches` touches on `mesh` (part frame, already in metres) standing at
/// `base_from_part`, for a probe with its ball centre at `flange_from_tcp` and radius
/// `tip_radius_m`. `part_scale` scales the real part about its origin (a part larger than its
/// model); `seed` is where the arm starts.
#[allow(clippy::too_many_arguments)]
pub fn plan_touches(
    mesh: &Mesh,
    base_from_part: &Isometry3<f64>,
    chain: &Chain,
    flange_from_tcp: &Isometry3<f64>,
    tip_radius_m: f64,
    part_scale: f64,
    seed: &[f64],
    options: &PlanOptions,
) -> Result<Vec<TouchPlan>, PlanError> {
    plan(
        mesh,
        base_from_part,
        Some((chain, flange_from_tcp, seed)),
        tip_radius_m,
        part_scale,
        options,
    )
}

/// Plans where to touch `mesh` standing at `base_from_part` with a ball of `tip_radius_m`, for
/// no robot in particular: the same 3-2-1 choice of faces and points, approachable by the probe
/// (tilted where the normal is blocked, never from below), without the reachability check. Each
/// touch's joints are empty.
pub fn plan_touch_points(
    mesh: &Mesh,
    base_from_part: &Isometry3<f64>,
    tip_radius_m: f64,
    options: &PlanOptions,
) -> Result<Vec<TouchPlan>, PlanError> {
    plan(mesh, base_from_part, None, tip_radius_m, 1.0, options)
}

fn plan(
    mesh: &Mesh,
    base_from_part: &Isometry3<f64>,
    robot: Option<(&Chain, &Isometry3<f64>, &[f64])>,
    tip_radius_m: f64,
    part_scale: f64,
    options: &PlanOptions,
) -> Result<Vec<TouchPlan>, PlanError> {
    if options.touches < 6 {
        return Err(PlanError::TooFewTouches(options.touches));
    }
    let reach = Reach {
        chain: robot.map(|(chain, _, _)| chain),
        base_from_part: *base_from_part,
        flange_from_tcp: robot.map_or(Isometry3::identity(), |(_, tcp, _)| *tcp),
        radius: tip_radius_m,
        part_scale,
        options,
        mesh,
        seed: robot.map_or(Vec::new(), |(_, _, seed)| seed.to_vec()),
    };
    let faces = planar_faces(mesh);
    let points: Vec<Vec<Point3<f64>>> = faces
        .iter()
        .map(|face| candidates(mesh, face, options.edge_margin_m.max(tip_radius_m)))
        .collect();
    let mut plan: Vec<TouchPlan> = Vec::new();
    let mut used = Vec::new();
    // Primary: the largest face that takes three touches.
    let primary = (0..faces.len())
        .find_map(|i| {
            let three = reach.pick(&points[i], &faces[i].normal, i, 3, &[]);
            (three.len() == 3).then_some((i, three))
        })
        .ok_or(PlanError::NoPrimaryFace)?;
    used.push(primary.0);
    plan.extend(primary.1);
    let n1 = faces[primary.0].normal;
    let secondary = (0..faces.len())
        .filter(|&i| faces[i].normal.dot(&n1).abs() < 0.3)
        .find_map(|i| {
            let two = reach.pick(&points[i], &faces[i].normal, i, 2, &plan);
            (two.len() == 2).then_some((i, two))
        })
        .ok_or(PlanError::NoSecondaryFace([n1.x, n1.y, n1.z]))?;
    used.push(secondary.0);
    plan.extend(secondary.1);
    let n2 = faces[secondary.0].normal;
    let tertiary = (0..faces.len())
        .filter(|&i| faces[i].normal.dot(&n1).abs() < 0.3 && faces[i].normal.dot(&n2).abs() < 0.3)
        .find_map(|i| {
            let one = reach.pick(&points[i], &faces[i].normal, i, 1, &plan);
            (one.len() == 1).then_some((i, one))
        })
        .ok_or(PlanError::NoTertiaryFace)?;
    used.push(tertiary.0);
    plan.extend(tertiary.1);
    // Extras: faces not used yet first (they tell corners and features apart), largest first,
    // then more on the used ones.
    let order: Vec<usize> = (0..faces.len())
        .filter(|i| !used.contains(i))
        .chain(used.iter().copied())
        .collect();
    let mut open: Vec<usize> = order;
    while plan.len() < options.touches && !open.is_empty() {
        open.retain(|&i| {
            if plan.len() >= options.touches {
                return true;
            }
            // A point already planned again adds nothing.
            let fresh: Vec<Point3<f64>> = points[i]
                .iter()
                .filter(|p| plan.iter().all(|t| (t.point_in_part - *p).norm() > 1e-6))
                .copied()
                .collect();
            match reach.pick(&fresh, &faces[i].normal, i, 1, &plan).pop() {
                Some(touch) => {
                    plan.push(touch);
                    true
                }
                None => false,
            }
        });
    }
    if plan.len() < options.touches {
        return Err(PlanError::TooFewReachable {
            found: plan.len(),
            asked: options.touches,
        });
    }
    Ok(plan)
}
