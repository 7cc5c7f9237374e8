//! Damped-least-squares inverse kinematics with joint limits and restarts.
//!
//! Each attempt is a Levenberg-Marquardt iteration on the 6-D pose error (position in m, rotation
//! vector in rad): `dq = J^T (J J^T + lambda^2 I)^-1 e`, clamped to the joint limits, with lambda
//! lowered after a step that reduced the error and raised after one that did not. The damping keeps
//! steps bounded near singularities (wrist aligned, arm stretched) where plain Gauss-Newton jumps.
//! When an attempt stalls (a local minimum against a limit, or a singular configuration), the next
//! starts from a pseudo-random seed drawn within the limits, deterministically from
//! [`IkOptions::random_seed`].

use nalgebra::{Isometry3, Matrix6, Vector6};

use super::chain::Chain;
use super::error::KinematicsError;
use crate::pose::rotation_error;
use crate::rng::SplitMix64;

#[derive(Debug, Clone, PartialEq)]
pub struct IkOptions {
    /// Iterations per attempt.
    pub max_iterations: usize,
    /// Attempts, the caller's seed first.
    pub max_attempts: usize,
    pub position_tolerance_m: f64,
    pub rotation_tolerance_rad: f64,
    /// False to solve for the tip position only (chains with fewer than 6 joints, or targets
    /// whose orientation is free).
    pub match_orientation: bool,
    /// Seed of the generator that draws restart configurations.
    pub random_seed: u64,
}

impl Default for IkOptions {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            max_attempts: 20,
            position_tolerance_m: 1e-9,
            rotation_tolerance_rad: 1e-9,
            match_orientation: true,
            random_seed: 0x5eed,
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct IkSolution {
    pub q: Vec<f64>,
    pub position_error_m: f64,
    pub rotation_error_rad: f64,
    /// Iterations summed over all attempts.
    pub iterations: usize,
    pub attempts: usize,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IkError {
    #[error(transparent)]
    Seed(#[from] KinematicsError),
    #[error("the IK target is not finite")]
    NonFiniteTarget,
    #[error(
        "no joint configuration within the limits reaches the target (tolerance {position_tolerance_m} m / {rotation_tolerance_rad} rad) after {attempts} attempts; closest found is {best_position_error_m:.6} m and {best_rotation_error_rad:.6} rad away"
    )]
    Unreachable {
        attempts: usize,
        position_tolerance_m: f64,
        rotation_tolerance_rad: f64,
        best_position_error_m: f64,
        best_rotation_error_rad: f64,
        best_q: Vec<f64>,
    },
}

impl Chain {
    /// Joint values putting the tip at `base_from_target`, starting from `seed`.
    pub fn inverse(
        &self,
        base_from_target: &Isometry3<f64>,
        seed: &[f64],
        options: &IkOptions,
    ) -> Result<IkSolution, IkError> {
        self.check_joints(seed)?;
        let target_finite = base_from_target
            .translation
            .vector
            .iter()
            .all(|v| v.is_finite())
            && base_from_target
                .rotation
                .coords
                .iter()
                .all(|v| v.is_finite());
        if !target_finite {
            return Err(IkError::NonFiniteTarget);
        }
        let mut rng = SplitMix64::new(options.random_seed);
        let mut best: Option<Attempt> = None;
        let mut iterations = 0;
        for attempt in 0..options.max_attempts.max(1) {
            let mut start = if attempt == 0 {
                seed.to_vec()
            } else {
                self.random_configuration(&mut rng)
            };
            self.clamp_to_limits(&mut start);
            let result = self.solve_from(base_from_target, start, options);
            iterations += result.iterations;
            let solved = result.position_error_m <= options.position_tolerance_m
                && (!options.match_orientation
                    || result.rotation_error_rad <= options.rotation_tolerance_rad);
            if solved {
                return Ok(IkSolution {
                    q: result.q,
                    position_error_m: result.position_error_m,
                    rotation_error_rad: result.rotation_error_rad,
                    iterations,
                    attempts: attempt + 1,
                });
            }
            if best.as_ref().is_none_or(|b| result.cost < b.cost) {
                best = Some(result);
            }
        }
        let best = best.expect("at least one attempt ran");
        Err(IkError::Unreachable {
            attempts: options.max_attempts.max(1),
            position_tolerance_m: options.position_tolerance_m,
            rotation_tolerance_rad: options.rotation_tolerance_rad,
            best_position_error_m: best.position_error_m,
            best_rotation_error_rad: best.rotation_error_rad,
            best_q: best.q,
        })
    }

    /// A configuration drawn uniformly within the limits, with unbounded or very wide ranges
    /// narrowed to one turn (every pose reachable by a revolute joint is reachable within it).
    fn random_configuration(&self, rng: &mut SplitMix64) -> Vec<f64> {
        use std::f64::consts::PI;
        self.joints()
            .iter()
            .map(|joint| {
                let lower = joint.limits.lower.max(-PI);
                let upper = joint.limits.upper.min(PI);
                let (lower, upper) = if lower < upper {
                    (lower, upper)
                } else {
                    (joint.limits.lower, joint.limits.upper)
                };
                let lower = if lower.is_finite() { lower } else { -1.0 };
                let upper = if upper.is_finite() { upper } else { 1.0 };
                lower + (upper - lower) * rng.uniform()
            })
            .collect()
    }

    fn solve_from(&self, target: &Isometry3<f64>, mut q: Vec<f64>, options: &IkOptions) -> Attempt {
        let rotation_weight = if options.match_orientation { 1.0 } else { 0.0 };
        let error_of = |pose: &Isometry3<f64>| {
            let position = target.translation.vector - pose.translation.vector;
            let rotation = rotation_error(&pose.rotation, &target.rotation) * rotation_weight;
            Vector6::new(
                position.x, position.y, position.z, rotation.x, rotation.y, rotation.z,
            )
        };
        let (mut pose, mut jacobian) = self.jacobian_unchecked(&q);
        let mut error = error_of(&pose);
        let mut cost = error.norm_squared();
        let mut damping = 1e-3;
        let mut iterations = 0;
        let mut trial = q.clone();
        while iterations < options.max_iterations {
            let position_error = error.fixed_rows::<3>(0).norm();
            let rotation_error = error.fixed_rows::<3>(3).norm();
            if position_error <= options.position_tolerance_m
                && rotation_error <= options.rotation_tolerance_rad
            {
                break;
            }
            iterations += 1;
            // Idempotent (the weight is 0 or 1), so a retried step may scale again.
            for row in 3..6 {
                jacobian.row_mut(row).scale_mut(rotation_weight);
            }
            let normal = &jacobian * jacobian.transpose() + Matrix6::identity() * damping;
            let Some(cholesky) = normal.cholesky() else {
                damping *= 10.0;
                continue;
            };
            let step = jacobian.transpose() * cholesky.solve(&error);
            for ((value, current), delta) in trial.iter_mut().zip(&q).zip(step.iter()) {
                *value = current + delta;
            }
            self.clamp_to_limits(&mut trial);
            let (trial_pose, trial_jacobian) = self.jacobian_unchecked(&trial);
            let trial_error = error_of(&trial_pose);
            let trial_cost = trial_error.norm_squared();
            if trial_cost < cost {
                std::mem::swap(&mut q, &mut trial);
                pose = trial_pose;
                jacobian = trial_jacobian;
                error = trial_error;
                cost = trial_cost;
                damping = (damping * 0.1).max(1e-12);
            } else {
                damping *= 10.0;
                if damping > 1e3 {
                    // No step of any length reduces the error: a local minimum.
                    break;
                }
            }
        }
        let rotation_error_rad = pose.rotation.angle_to(&target.rotation);
        Attempt {
            position_error_m: error.fixed_rows::<3>(0).norm(),
            rotation_error_rad,
            cost,
            q,
            iterations,
        }
    }
}

struct Attempt {
    q: Vec<f64>,
    position_error_m: f64,
    rotation_error_rad: f64,
    cost: f64,
    iterations: usize,
}
