//! Scripted joint motion: a deterministic function of controller time, so the ground truth at
//! any sample time can be recomputed exactly by tests.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Motion {
    /// Stand still at `q` (rad).
    Hold { q: Vec<f64> },
    /// q_i(t) = centre_i + amplitude_i sin(2 pi t / period_s): smooth, within limits when the
    /// centre +- amplitude is.
    Sine {
        centre: Vec<f64>,
        amplitude: Vec<f64>,
        period_s: f64,
    },
}

impl Motion {
    pub fn dof(&self) -> usize {
        match self {
            Motion::Hold { q } => q.len(),
            Motion::Sine { centre, .. } => centre.len(),
        }
    }

    /// Joint positions at controller time `t_s`, rad.
    pub fn position(&self, t_s: f64) -> Vec<f64> {
        match self {
            Motion::Hold { q } => q.clone(),
            Motion::Sine {
                centre,
                amplitude,
                period_s,
            } => {
                let phase = std::f64::consts::TAU * t_s / period_s;
                centre
                    .iter()
                    .zip(amplitude)
                    .map(|(c, a)| c + a * phase.sin())
                    .collect()
            }
        }
    }

    /// Joint velocities at controller time `t_s`, rad/s.
    pub fn velocity(&self, t_s: f64) -> Vec<f64> {
        match self {
            Motion::Hold { q } => vec![0.0; q.len()],
            Motion::Sine {
                amplitude,
                period_s,
                ..
            } => {
                let omega = std::f64::consts::TAU / period_s;
                amplitude
                    .iter()
                    .map(|a| a * omega * (omega * t_s).cos())
                    .collect()
            }
        }
    }

    /// Joint accelerations at controller time `t_s`, rad/s^2.
    pub fn acceleration(&self, t_s: f64) -> Vec<f64> {
        match self {
            Motion::Hold { q } => vec![0.0; q.len()],
            Motion::Sine {
                amplitude,
                period_s,
                ..
            } => {
                let omega = std::f64::consts::TAU / period_s;
                amplitude
                    .iter()
                    .map(|a| -a * omega * omega * (omega * t_s).sin())
                    .collect()
            }
        }
    }

    /// Checks the motion fits a robot with these position limits.
    pub fn check(&self, limits: &[(f64, f64)]) -> Result<(), String> {
        if self.dof() != limits.len() {
            return Err(format!(
                "the robot has {} joints, the motion {}",
                limits.len(),
                self.dof()
            ));
        }
        let (low, high): (Vec<f64>, Vec<f64>) = match self {
            Motion::Hold { q } => (q.clone(), q.clone()),
            Motion::Sine {
                centre,
                amplitude,
                period_s,
            } => {
                if amplitude.len() != centre.len() {
                    return Err("centre and amplitude differ in length".to_owned());
                }
                if !(period_s.is_finite() && *period_s > 0.0) {
                    return Err(format!("period_s must be positive, got {period_s}"));
                }
                (
                    centre
                        .iter()
                        .zip(amplitude)
                        .map(|(c, a)| c - a.abs())
                        .collect(),
                    centre
                        .iter()
                        .zip(amplitude)
                        .map(|(c, a)| c + a.abs())
                        .collect(),
                )
            }
        };
        for (index, ((lo, hi), (lower, upper))) in low.iter().zip(&high).zip(limits).enumerate() {
            if !(lo.is_finite() && hi.is_finite()) || *lo < *lower || *hi > *upper {
                return Err(format!(
                    "joint {} would leave its limits [{lower:.4}, {upper:.4}] rad",
                    index + 1
                ));
            }
        }
        Ok(())
    }
}
