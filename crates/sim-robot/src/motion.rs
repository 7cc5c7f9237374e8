//! Scripted joint motion: a deterministic function of controller time, so the ground truth at
//! any sample time can be recomputed exactly by tests.

pub use protocol::sim::{Motion, Waypoint};

/// Position, velocity and acceleration fractions of a segment at phase `s`: the start-stop blend
/// (1 - cos(pi s)) / 2, or constant speed for a linear segment.
fn profile(linear: bool, s: f64, duration_s: f64) -> (f64, f64, f64) {
    use std::f64::consts::PI;
    if linear {
        return (s, 1.0 / duration_s, 0.0);
    }
    let rate = PI / duration_s;
    (
        (1.0 - (PI * s).cos()) / 2.0,
        (PI * s).sin() * rate / 2.0,
        (PI * s).cos() * rate * rate / 2.0,
    )
}

/// Where `t_s` falls on a path: the segment's ends and the phase s in [0, 1].
fn segment(waypoints: &[Waypoint], t_s: f64) -> Option<(&Waypoint, &Waypoint, f64)> {
    let index = waypoints.windows(2).position(|pair| t_s < pair[1].time_s)?;
    let (a, b) = (&waypoints[index], &waypoints[index + 1]);
    if t_s <= a.time_s {
        return None;
    }
    Some((a, b, (t_s - a.time_s) / (b.time_s - a.time_s)))
}

/// The waypoint held at `t_s` outside every moving segment.
fn held(waypoints: &[Waypoint], t_s: f64) -> Vec<f64> {
    let last = waypoints.iter().rev().find(|w| w.time_s <= t_s);
    last.or(waypoints.first())
        .map(|w| w.q.clone())
        .unwrap_or_default()
}

/// What sim-robot computes of a [`Motion`] (the wire type lives in the protocol crate).
pub trait Trajectory {
    fn dof(&self) -> usize;
    /// Joint positions at controller time `t_s`, rad.
    fn position(&self, t_s: f64) -> Vec<f64>;
    /// True when no joint moves at `t_s`.
    fn at_rest(&self, t_s: f64) -> bool;
    /// Joint velocities at `t_s`, rad/s.
    fn velocity(&self, t_s: f64) -> Vec<f64>;
    /// Joint accelerations at `t_s`, rad/s^2.
    fn acceleration(&self, t_s: f64) -> Vec<f64>;
    /// Refuses a motion for another joint count, outside `limits` or with bad numbers.
    fn check(&self, limits: &[(f64, f64)]) -> Result<(), String>;
}

impl Trajectory for Motion {
    fn dof(&self) -> usize {
        match self {
            Motion::Hold { q } => q.len(),
            Motion::Sine { centre, .. } => centre.len(),
            Motion::Path { waypoints } => waypoints.first().map_or(0, |w| w.q.len()),
        }
    }

    /// Joint positions at controller time `t_s`, rad.
    fn position(&self, t_s: f64) -> Vec<f64> {
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
            Motion::Path { waypoints } => match segment(waypoints, t_s) {
                Some((a, b, s)) => {
                    let (blend, _, _) = profile(b.linear, s, b.time_s - a.time_s);
                    a.q.iter()
                        .zip(&b.q)
                        .map(|(qa, qb)| qa + (qb - qa) * blend)
                        .collect()
                }
                None => held(waypoints, t_s),
            },
        }
    }

    /// Whether the joints stand still at `t_s`.
    fn at_rest(&self, t_s: f64) -> bool {
        self.velocity(t_s).iter().all(|v| *v == 0.0)
    }

    /// Joint velocities at controller time `t_s`, rad/s.
    fn velocity(&self, t_s: f64) -> Vec<f64> {
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
            Motion::Path { waypoints } => match segment(waypoints, t_s) {
                Some((a, b, s)) => {
                    let (_, blend_rate, _) = profile(b.linear, s, b.time_s - a.time_s);
                    a.q.iter()
                        .zip(&b.q)
                        .map(|(qa, qb)| (qb - qa) * blend_rate)
                        .collect()
                }
                None => vec![0.0; self.dof()],
            },
        }
    }

    /// Joint accelerations at controller time `t_s`, rad/s^2.
    fn acceleration(&self, t_s: f64) -> Vec<f64> {
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
            Motion::Path { waypoints } => match segment(waypoints, t_s) {
                Some((a, b, s)) => {
                    let (_, _, blend_acceleration) = profile(b.linear, s, b.time_s - a.time_s);
                    a.q.iter()
                        .zip(&b.q)
                        .map(|(qa, qb)| (qb - qa) * blend_acceleration)
                        .collect()
                }
                None => vec![0.0; self.dof()],
            },
        }
    }

    /// Checks the motion fits a robot with these position limits.
    fn check(&self, limits: &[(f64, f64)]) -> Result<(), String> {
        if self.dof() != limits.len() {
            return Err(format!(
                "the robot has {} joints, the motion {}",
                limits.len(),
                self.dof()
            ));
        }
        let (low, high): (Vec<f64>, Vec<f64>) = match self {
            Motion::Hold { q } => (q.clone(), q.clone()),
            Motion::Path { waypoints } => {
                if waypoints.is_empty() {
                    return Err("a path needs at least one waypoint".to_owned());
                }
                if waypoints.iter().any(|w| w.q.len() != limits.len()) {
                    return Err(format!(
                        "every waypoint needs {} joint values",
                        limits.len()
                    ));
                }
                if !waypoints
                    .windows(2)
                    .all(|pair| pair[1].time_s > pair[0].time_s)
                    || !waypoints.iter().all(|w| w.time_s.is_finite())
                {
                    return Err("waypoint times must be finite and increasing".to_owned());
                }
                // The blend stays between its ends, so the waypoints bound the whole path.
                let fold = |pick: fn(f64, f64) -> f64| {
                    (0..limits.len())
                        .map(|j| {
                            waypoints
                                .iter()
                                .map(|w| w.q[j])
                                .reduce(pick)
                                .unwrap_or(f64::NAN)
                        })
                        .collect::<Vec<f64>>()
                };
                (fold(f64::min), fold(f64::max))
            }
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
