//! Joint-space sessions: the sampled touches made by a "true" robot that differs from its model
//! by effects the alignment is not told about (joint offsets, a TCP error, joint compliance, a
//! part scale). Each touch is reached by inverse kinematics of the true robot; what the session
//! records is what the controller reports: the encoder angles and the nominal flange pose.
//!
//! Hidden-effect conventions: the true joint angle is `q_reported + joint_offsets_rad +
//! compliance_rad_per_nm * tau(q_true)` (tau the gravity torque, see
//! [`Chain::gravity_torques_nm`]: the robot sags the way gravity pulls); the true TCP is the
//! nominal one moved by `tcp_error_m` in the flange frame; the real part is the CAD part scaled by
//! `part_scale` about its frame's origin.

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

use super::CorpusError;
use super::touches::{SampledTouch, TouchOptions, TouchSet, on_table, sample_touches};
use crate::geometry::{Mesh, MeshError};
use crate::kinematics::{Chain, IkOptions};
use crate::rng::SplitMix64;

/// The probe as the alignment knows it: ball centre at the TCP, stylus along the TCP's z axis.
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeTool {
    pub flange_from_tcp: Isometry3<f64>,
    pub ball_radius_m: f64,
}

impl ProbeTool {
    /// A straight probe along the flange axis, `length_m` from the flange to the ball centre.
    pub fn straight(length_m: f64, ball_radius_m: f64) -> Self {
        Self {
            flange_from_tcp: Isometry3::translation(0.0, 0.0, length_m),
            ball_radius_m,
        }
    }
}

/// What the true robot, tool and part do that the model does not say.
#[derive(Debug, Clone, PartialEq)]
pub struct HiddenEffects {
    /// True angle minus encoder angle, per joint, rad.
    pub joint_offsets_rad: Vec<f64>,
    /// True TCP minus nominal TCP, in the flange frame, m.
    pub tcp_error_m: Vector3<f64>,
    /// Real part size over CAD size (1 for none).
    pub part_scale: f64,
    /// Joint deflection per gravity torque, rad per N m, per joint (empty for none).
    pub compliance_rad_per_nm: Vec<f64>,
}

impl HiddenEffects {
    /// A robot exactly as modelled.
    pub fn none(dof: usize) -> Self {
        Self {
            joint_offsets_rad: vec![0.0; dof],
            tcp_error_m: Vector3::zeros(),
            part_scale: 1.0,
            compliance_rad_per_nm: Vec::new(),
        }
    }

    /// The tool as it really is.
    pub fn true_flange_from_tcp(&self, tool: &ProbeTool) -> Isometry3<f64> {
        Translation3::from(self.tcp_error_m) * tool.flange_from_tcp
    }

    /// The true joint angles behind reported ones, found by fixed-point iteration on the
    /// compliance term (it is micro-radians, the iteration contracts at once).
    pub fn true_joints(&self, chain: &Chain, q_reported: &[f64]) -> Vec<f64> {
        let offset = |i: usize| self.joint_offsets_rad.get(i).copied().unwrap_or(0.0);
        let mut q: Vec<f64> = q_reported
            .iter()
            .enumerate()
            .map(|(i, v)| v + offset(i))
            .collect();
        if self.compliance_rad_per_nm.iter().any(|&c| c != 0.0) {
            for _ in 0..20 {
                let tau = chain.gravity_torques_nm(&q, None);
                q = q_reported
                    .iter()
                    .enumerate()
                    .map(|(i, v)| {
                        v + offset(i)
                            + self.compliance_rad_per_nm.get(i).copied().unwrap_or(0.0) * tau[i]
                    })
                    .collect();
            }
        }
        q
    }

    /// Where the true robot puts the ball centre when the encoders read `q_reported`.
    pub fn true_ball_centre(
        &self,
        chain: &Chain,
        tool: &ProbeTool,
        q_reported: &[f64],
    ) -> Point3<f64> {
        let q = self.true_joints(chain, q_reported);
        let base_from_tcp = chain.forward_unchecked(&q) * self.true_flange_from_tcp(tool);
        Point3::from(base_from_tcp.translation.vector)
    }
}

/// One touch as the controller reports it.
#[derive(Debug, Clone, PartialEq)]
pub struct JointTouch {
    /// The touch that was aimed at (its ball centre includes the noise).
    pub touch: SampledTouch,
    /// Encoder angles, rad.
    pub q_reported: Vec<f64>,
    /// Nominal forward kinematics of the reported angles.
    pub base_from_flange_nominal: Isometry3<f64>,
}

impl JointTouch {
    /// The ball centre the model computes (what an alignment sees), base frame.
    pub fn nominal_ball_centre(&self, tool: &ProbeTool) -> Point3<f64> {
        Point3::from(
            (self.base_from_flange_nominal * tool.flange_from_tcp)
                .translation
                .vector,
        )
    }

    /// The model's approach direction: the nominal TCP's z axis.
    pub fn nominal_approach(&self, tool: &ProbeTool) -> Vector3<f64> {
        (self.base_from_flange_nominal * tool.flange_from_tcp).rotation * Vector3::z()
    }
}

/// A session ready to be turned into an alignment input.
#[derive(Debug, Clone, PartialEq)]
pub struct JointSession {
    pub touches: Vec<JointTouch>,
    /// Ids of sampled touches no configuration within the joint limits reaches.
    pub unreachable: Vec<String>,
    pub base_from_part_truth: Isometry3<f64>,
    /// The tool as the model knows it.
    pub tool: ProbeTool,
    pub hidden: HiddenEffects,
    pub sigma_m: f64,
}

/// Spins about the tool axis tried for each touch (a probe's ball is round: its spin is free).
const SPINS_DEG: [f64; 6] = [0.0, 90.0, 180.0, 270.0, 45.0, 225.0];

/// A rotation whose z axis is `z` and whose x axis is turned by `spin_rad` about it.
fn frame_with_z(z: &Vector3<f64>, spin_rad: f64) -> UnitQuaternion<f64> {
    let z = z.normalize();
    let helper = if z.x.abs() < 0.8 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let x = (helper - z * z.dot(&helper)).normalize();
    let base = UnitQuaternion::from_basis_unchecked(&[x, z.cross(&x), z]);
    base * UnitQuaternion::from_axis_angle(&Unit::new_unchecked(Vector3::z()), spin_rad)
}

/// Joint angles for each touch: the true robot (offsets, compliance, TCP error) puts the ball
/// centre on the touch's noisy centre with the tool's z axis along its approach. Each touch
/// tries the previous touch's solution, then `seeds`, with several spins about the tool axis;
/// touches nothing reaches within the joint limits are listed, not returned.
pub fn joint_session(
    chain: &Chain,
    tool: &ProbeTool,
    touch_set: &TouchSet,
    base_from_part_truth: &Isometry3<f64>,
    hidden: &HiddenEffects,
    seeds: &[Vec<f64>],
) -> Result<JointSession, CorpusError> {
    for seed in seeds {
        chain.check_joints(seed)?;
    }
    let tcp_from_flange = hidden.true_flange_from_tcp(tool).inverse();
    let options = IkOptions {
        max_iterations: 200,
        max_attempts: 6,
        position_tolerance_m: 1e-10,
        rotation_tolerance_rad: 1e-9,
        ..IkOptions::default()
    };
    let mut touches = Vec::with_capacity(touch_set.touches.len());
    let mut unreachable = Vec::new();
    let mut previous: Option<Vec<f64>> = None;
    for (index, touch) in touch_set.touches.iter().enumerate() {
        let mut starts: Vec<Vec<f64>> = previous.iter().cloned().collect();
        starts.extend(seeds.iter().cloned());
        if starts.is_empty() {
            starts.push(vec![0.0; chain.dof()]);
        }
        let mut solution = None;
        'search: for &spin in &SPINS_DEG {
            let base_from_tcp = Isometry3::from_parts(
                Translation3::from(touch.ball_centre_in_base.coords),
                frame_with_z(&touch.approach_in_base, spin.to_radians()),
            );
            let target = base_from_tcp * tcp_from_flange;
            for (k, start) in starts.iter().enumerate() {
                let attempt = IkOptions {
                    random_seed: options.random_seed ^ ((index as u64) << 16) ^ (k as u64),
                    ..options.clone()
                };
                if let Ok(found) = chain.inverse(&target, start, &attempt)
                    && chain.within_limits(&found.q)
                {
                    solution = Some(found.q);
                    break 'search;
                }
            }
        }
        let Some(q_true) = solution else {
            unreachable.push(touch.id.clone());
            continue;
        };
        let q_reported = reported_joints(chain, hidden, &q_true);
        let base_from_flange_nominal = chain.forward(&q_reported)?;
        previous = Some(q_true);
        touches.push(JointTouch {
            touch: touch.clone(),
            q_reported,
            base_from_flange_nominal,
        });
    }
    Ok(JointSession {
        touches,
        unreachable,
        base_from_part_truth: *base_from_part_truth,
        tool: tool.clone(),
        hidden: hidden.clone(),
        sigma_m: touch_set.sigma_m,
    })
}

/// Encoder angles of the true angles `q_true`: minus the offsets and the gravity sag.
fn reported_joints(chain: &Chain, hidden: &HiddenEffects, q_true: &[f64]) -> Vec<f64> {
    let tau = if hidden.compliance_rad_per_nm.iter().any(|&c| c != 0.0) {
        chain.gravity_torques_nm(q_true, None)
    } else {
        vec![0.0; q_true.len()]
    };
    q_true
        .iter()
        .enumerate()
        .map(|(i, q)| {
            q - hidden.joint_offsets_rad.get(i).copied().unwrap_or(0.0)
                - hidden.compliance_rad_per_nm.get(i).copied().unwrap_or(0.0) * tau[i]
        })
        .collect()
}

/// The mesh scaled about its frame's origin (a part a little larger or smaller than its CAD).
pub fn scale_mesh(mesh: &Mesh, scale: f64) -> Result<Mesh, MeshError> {
    let vertices: Vec<Point3<f64>> = mesh.vertices().map(|p| p * scale).collect();
    Mesh::new(&vertices, mesh.triangles())
}

/// The farthest the flange gets from the chain's base origin over `samples` random
/// configurations within the limits, m: a rough reach.
pub fn reach_estimate_m(chain: &Chain, samples: usize, rng: &mut SplitMix64) -> f64 {
    let mut reach: f64 = 0.0;
    let mut q = vec![0.0; chain.dof()];
    for _ in 0..samples.max(1) {
        for (value, joint) in q.iter_mut().zip(chain.joints()) {
            let (low, high) = (
                joint.limits.lower.max(-std::f64::consts::PI),
                joint.limits.upper.min(std::f64::consts::PI),
            );
            *value = low + (high - low) * rng.uniform();
        }
        reach = reach.max(chain.forward_unchecked(&q).translation.vector.norm());
    }
    reach
}

/// A part pose in front of the robot: standing on the table plane z = `table_z_m` (base frame),
/// its centroid `distance_m` from the base axis at an azimuth within 40 degrees of +x, turned
/// about z at random.
pub fn place_part(
    mesh: &Mesh,
    distance_m: f64,
    table_z_m: f64,
    rng: &mut SplitMix64,
) -> Isometry3<f64> {
    let azimuth = (rng.uniform() * 2.0 - 1.0) * 40f64.to_radians();
    let yaw = rng.uniform() * std::f64::consts::TAU;
    on_table(
        mesh,
        yaw,
        [distance_m * azimuth.cos(), distance_m * azimuth.sin()],
        table_z_m,
    )
}

/// The true robot of a session: its chain, the tool as modelled, what is hidden, IK seeds.
#[derive(Debug, Clone, Copy)]
pub struct SessionRobot<'a> {
    pub chain: &'a Chain,
    pub tool: &'a ProbeTool,
    pub hidden: &'a HiddenEffects,
    pub seeds: &'a [Vec<f64>],
}

/// One session end to end: the part (scaled by the hidden part scale) placed at about half the
/// robot's reach on a table level with the robot's base, `count` touches drawn on it, and the
/// true robot's joint angles for them.
pub fn generate_session(
    robot: &SessionRobot<'_>,
    mesh: &Mesh,
    count: usize,
    options: &TouchOptions,
    rng: &mut SplitMix64,
) -> Result<JointSession, CorpusError> {
    let hidden = robot.hidden;
    let real_part = if hidden.part_scale == 1.0 {
        mesh.clone()
    } else {
        scale_mesh(mesh, hidden.part_scale)?
    };
    let reach = reach_estimate_m(robot.chain, 500, rng);
    let base_from_part = place_part(&real_part, 0.5 * reach, 0.0, rng);
    let options = TouchOptions {
        ball_radius_m: robot.tool.ball_radius_m,
        floor_z_in_base: Some(options.floor_z_in_base.unwrap_or(0.0)),
        ..options.clone()
    };
    let touch_set = sample_touches(&real_part, &base_from_part, count, &options, rng)?;
    joint_session(
        robot.chain,
        robot.tool,
        &touch_set,
        &base_from_part,
        hidden,
        robot.seeds,
    )
}
