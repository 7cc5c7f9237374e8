//! Closing the loop: is anything left in the residual after alignment, and which effect the
//! model lacks explains it?
//!
//! Each touch gives a signed distance from the part's surface: forward kinematics of its joint
//! vector, the tool's TCP, the ball radius. The pose-only fit leaves residuals r_i; with the
//! declared touch noise sigma, RSS / sigma^2 follows a chi-square law with N - 6 degrees of
//! freedom when nothing is missing. If the test rejects that (99%), each candidate effect, a
//! small parameterised change of the model, is fitted together with the part pose by
//! Levenberg-Marquardt on the re-projected signed distances, and the candidates are ranked by
//! BIC and leave-one-out error:
//!
//! | effect | parameters | plausibility bound |
//! | --- | --- | --- |
//! | `probe_radius` | ball radius change (m) | 5 mm |
//! | `tcp_offset` | TCP shift in the flange frame (m) | 20 mm |
//! | `joint_offsets` | encoder offset per joint but the first and last (rad) | 0.05 rad |
//! | `part_scale` | relative size change of the part about its origin | 1 % |
//! | `trigger_latency` | delay between contact and sample (s), needs joint velocities | 0.5 s |
//!
//! A candidate is skipped, with the reason, when its parameters are not identifiable from these
//! touches (the scaled information matrix is rank-deficient or has a condition number above
//! 1e8: a joint-1 offset is the same as a part yaw), when there are too few touches, when a
//! parameter is not significant (below 3 standard errors) or when the fit leaves its bound.
//! Gravity sag (`joint_compliance`) is not modelled yet.

use nalgebra::{DMatrix, DVector, Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::geometry::Mesh;
use crate::kinematics::Chain;
use crate::tool::Tool;

/// One inspection as captured: joint positions and, when known, velocities.
#[derive(Debug, Clone, PartialEq)]
pub struct TouchSample {
    pub id: String,
    pub q: Vec<f64>,
    pub qd: Option<Vec<f64>>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Effect {
    ProbeRadius,
    TcpOffset,
    JointOffsets,
    PartScale,
    TriggerLatency,
}

impl Effect {
    pub const ALL: [Effect; 5] = [
        Effect::ProbeRadius,
        Effect::TcpOffset,
        Effect::JointOffsets,
        Effect::PartScale,
        Effect::TriggerLatency,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Effect::ProbeRadius => "probe_radius",
            Effect::TcpOffset => "tcp_offset",
            Effect::JointOffsets => "joint_offsets",
            Effect::PartScale => "part_scale",
            Effect::TriggerLatency => "trigger_latency",
        }
    }

    fn parameter_names(self, dof: usize) -> Vec<String> {
        match self {
            Effect::ProbeRadius => vec!["delta_radius_m".to_owned()],
            Effect::TcpOffset => ["dx_m", "dy_m", "dz_m"].map(str::to_owned).to_vec(),
            Effect::JointOffsets => (2..dof).map(|j| format!("joint_{j}_rad")).collect(),
            Effect::PartScale => vec!["scale_minus_one".to_owned()],
            Effect::TriggerLatency => vec!["latency_s".to_owned()],
        }
    }

    fn bound(self) -> f64 {
        match self {
            Effect::ProbeRadius => 0.005,
            Effect::TcpOffset => 0.02,
            Effect::JointOffsets => 0.05,
            Effect::PartScale => 0.01,
            Effect::TriggerLatency => 0.5,
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Fit {
    pub base_from_part: Isometry3<f64>,
    pub residuals_m: Vec<f64>,
    pub rms_m: f64,
    pub max_m: f64,
    pub loo_rms_m: f64,
    pub bic: f64,
    pub params: Vec<(String, f64, f64)>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Alternative {
    pub name: &'static str,
    /// The fit, when the candidate could be fitted.
    pub fit: Option<Fit>,
    /// Why it was not chosen.
    pub reason: String,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    NoEffect,
    Effect,
    Ambiguous,
    NotAttributable,
}

impl Verdict {
    pub fn name(self) -> &'static str {
        match self {
            Verdict::NoEffect => "no_effect",
            Verdict::Effect => "effect",
            Verdict::Ambiguous => "ambiguous",
            Verdict::NotAttributable => "not_attributable",
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Diagnosis {
    pub verdict: Verdict,
    pub effect: Option<(&'static str, Fit)>,
    pub before: Fit,
    pub after: Fit,
    pub alternatives: Vec<Alternative>,
    /// chi-square statistic of the pose-only fit and its 99% threshold.
    pub chi_square: (f64, f64),
    pub explanation: String,
}

struct Problem<'a> {
    chain: &'a Chain,
    tool: &'a Tool,
    mesh: &'a Mesh,
    touches: &'a [TouchSample],
    start: Isometry3<f64>,
    centre: Point3<f64>,
    /// Joints whose offsets `joint_offsets` fits (indices into the chain's joints).
    joints: Vec<usize>,
}

impl Problem<'_> {
    fn parameter_count(&self, effect: Option<Effect>) -> usize {
        6 + match effect {
            None => 0,
            Some(Effect::ProbeRadius | Effect::PartScale | Effect::TriggerLatency) => 1,
            Some(Effect::TcpOffset) => 3,
            // The first joint's offset is a turn of the whole cell about the base axis, the same
            // as a part yaw; the last turns the ball about its own centre on a probe along the
            // flange axis: neither is visible in touches, so only the joints between are fitted.
            Some(Effect::JointOffsets) => self.joints.len(),
        }
    }

    /// The pose a parameter vector stands for: a twist about the part centre applied to the start.
    fn pose(&self, theta: &DVector<f64>) -> Isometry3<f64> {
        let radius = self.mesh.radius_m().max(1e-6);
        let rotation =
            UnitQuaternion::from_scaled_axis(Vector3::new(theta[0], theta[1], theta[2]) / radius);
        let translation = Vector3::new(theta[3], theta[4], theta[5]);
        let centre = self.start * self.centre;
        let shift = centre.coords + translation - rotation * centre.coords;
        Isometry3::from_parts(Translation3::from(shift), rotation) * self.start
    }

    /// Signed distances of the touches (ball radius removed) for a parameter vector.
    fn residual(
        &self,
        effect: Option<Effect>,
        theta: &DVector<f64>,
        skip: Option<usize>,
    ) -> DVector<f64> {
        let pose = self.pose(theta);
        let part_from_base = pose.inverse();
        let extra = |i: usize| theta[6 + i];
        let values: Vec<f64> = self
            .touches
            .iter()
            .enumerate()
            .filter(|(index, _)| Some(*index) != skip)
            .map(|(_, touch)| {
                let mut q = touch.q.clone();
                match effect {
                    Some(Effect::JointOffsets) => {
                        for (k, &joint) in self.joints.iter().enumerate() {
                            q[joint] += extra(k);
                        }
                    }
                    Some(Effect::TriggerLatency) => {
                        if let Some(qd) = &touch.qd {
                            q.iter_mut().zip(qd).for_each(|(v, d)| *v -= d * extra(0));
                        }
                    }
                    _ => {}
                }
                let mut flange_from_tcp = self.tool.flange_from_tcp;
                if effect == Some(Effect::TcpOffset) {
                    flange_from_tcp.translation.vector +=
                        Vector3::new(extra(0), extra(1), extra(2));
                }
                let tcp = self.chain.forward_unchecked(&q) * flange_from_tcp;
                let mut in_part = part_from_base * Point3::from(tcp.translation.vector);
                let scale = if effect == Some(Effect::PartScale) {
                    1.0 + extra(0)
                } else {
                    1.0
                };
                in_part.coords /= scale;
                let distance = self.mesh.closest_point(&in_part).signed_distance * scale;
                let radius = self.tool.tip_radius_m
                    + if effect == Some(Effect::ProbeRadius) {
                        extra(0)
                    } else {
                        0.0
                    };
                distance - radius
            })
            .collect();
        DVector::from_vec(values)
    }

    fn jacobian(
        &self,
        effect: Option<Effect>,
        theta: &DVector<f64>,
        skip: Option<usize>,
    ) -> DMatrix<f64> {
        let base = self.residual(effect, theta, skip);
        let mut jacobian = DMatrix::zeros(base.len(), theta.len());
        for column in 0..theta.len() {
            let step = 1e-7;
            let (mut plus, mut minus) = (theta.clone(), theta.clone());
            plus[column] += step;
            minus[column] -= step;
            let difference = (self.residual(effect, &plus, skip)
                - self.residual(effect, &minus, skip))
                / (2.0 * step);
            jacobian.set_column(column, &difference);
        }
        jacobian
    }

    /// Levenberg-Marquardt with Marquardt's diagonal scaling.
    fn fit(&self, effect: Option<Effect>, skip: Option<usize>) -> DVector<f64> {
        let mut theta = DVector::zeros(self.parameter_count(effect));
        let mut residual = self.residual(effect, &theta, skip);
        let mut cost = residual.norm_squared();
        let mut lambda = 1e-3;
        for _ in 0..60 {
            let jacobian = self.jacobian(effect, &theta, skip);
            let normal = jacobian.transpose() * &jacobian;
            let gradient = jacobian.transpose() * &residual;
            let mut damped = normal.clone();
            for i in 0..damped.nrows() {
                damped[(i, i)] += lambda * normal[(i, i)].max(1e-12);
            }
            let Some(step) = damped.cholesky().map(|c| c.solve(&(-gradient))) else {
                lambda *= 10.0;
                continue;
            };
            let candidate = &theta + &step;
            let candidate_residual = self.residual(effect, &candidate, skip);
            let candidate_cost = candidate_residual.norm_squared();
            if candidate_cost < cost {
                let converged =
                    (cost - candidate_cost) < 1e-14 * cost.max(1e-30) || step.norm() < 1e-13;
                theta = candidate;
                residual = candidate_residual;
                cost = candidate_cost;
                lambda = (lambda * 0.3).max(1e-12);
                if converged {
                    break;
                }
            } else {
                lambda *= 10.0;
                if lambda > 1e8 {
                    break;
                }
            }
        }
        theta
    }

    fn summarise(
        &self,
        effect: Option<Effect>,
        theta: &DVector<f64>,
        sigma: f64,
    ) -> Result<Fit, String> {
        let residual = self.residual(effect, theta, None);
        let n = residual.len();
        let k = theta.len();
        if n <= k {
            return Err(format!("{n} touches cannot fit {k} parameters"));
        }
        let jacobian = self.jacobian(effect, theta, None);
        let information = jacobian.transpose() * &jacobian;
        // Condition of the information matrix after scaling each parameter to unit diagonal.
        let scale = DVector::from_iterator(
            k,
            (0..k).map(|i| information[(i, i)].max(1e-300).sqrt().recip()),
        );
        let scaled = DMatrix::from_fn(k, k, |i, j| information[(i, j)] * scale[i] * scale[j]);
        let eigen = scaled.clone().symmetric_eigen().eigenvalues;
        let (low, high) = eigen
            .iter()
            .fold((f64::MAX, 0.0f64), |(lo, hi), v| (lo.min(*v), hi.max(*v)));
        if low <= high * 1e-8 {
            return Err(format!(
                "not identifiable from these touches (scaled condition number {:.1e}): it trades off with the part pose",
                high / low.max(1e-300)
            ));
        }
        let covariance = information
            .try_inverse()
            .ok_or("singular information matrix")?;
        let rss = residual.norm_squared();
        let loo = self.leave_one_out(effect);
        let names = match effect {
            Some(Effect::JointOffsets) => self
                .joints
                .iter()
                .map(|j| format!("joint_{}_rad", j + 1))
                .collect(),
            Some(effect) => effect.parameter_names(self.chain.dof()),
            None => Vec::new(),
        };
        let params = names
            .into_iter()
            .enumerate()
            .map(|(i, name)| {
                (
                    name,
                    theta[6 + i],
                    sigma * covariance[(6 + i, 6 + i)].max(0.0).sqrt(),
                )
            })
            .collect();
        Ok(Fit {
            base_from_part: self.pose(theta),
            rms_m: (rss / n as f64).sqrt(),
            max_m: residual.iter().fold(0.0f64, |m, r| m.max(r.abs())),
            residuals_m: residual.iter().copied().collect(),
            loo_rms_m: loo,
            bic: n as f64 * (rss / n as f64).max(1e-30).ln() + k as f64 * (n as f64).ln(),
            params,
        })
    }

    /// RMS of each touch's residual predicted by a fit without it.
    fn leave_one_out(&self, effect: Option<Effect>) -> f64 {
        let n = self.touches.len();
        if n <= self.parameter_count(effect) + 1 {
            return f64::NAN;
        }
        let sum: f64 = (0..n)
            .map(|held| {
                let theta = self.fit(effect, Some(held));
                let all = self.residual(effect, &theta, None);
                all[held] * all[held]
            })
            .sum();
        (sum / n as f64).sqrt()
    }
}

/// Upper 99% point of chi-square with `dof` degrees of freedom (Wilson-Hilferty).
fn chi_square_99(dof: f64) -> f64 {
    let z = 2.326_347_874;
    let a = 2.0 / (9.0 * dof);
    dof * (1.0 - a + z * a.sqrt()).powi(3)
}

/// Diagnoses the residual of a touch alignment. `base_from_part` is the aligned pose (the start
/// of every fit); `noise_sigma_m` the declared touch noise.
pub fn diagnose(
    chain: &Chain,
    tool: &Tool,
    mesh: &Mesh,
    touches: &[TouchSample],
    base_from_part: &Isometry3<f64>,
    noise_sigma_m: f64,
) -> Result<Diagnosis, String> {
    if touches.len() < 7 {
        return Err(format!(
            "diagnosis needs at least 7 touches (6 fix the pose), got {}",
            touches.len()
        ));
    }
    if !(noise_sigma_m.is_finite() && noise_sigma_m > 0.0) {
        return Err(format!(
            "noise_sigma must be a positive distance, got {noise_sigma_m}"
        ));
    }
    if let Some(touch) = touches.iter().find(|t| t.q.len() != chain.dof()) {
        return Err(format!(
            "inspection '{}' has {} joint values, the chain {}",
            touch.id,
            touch.q.len(),
            chain.dof()
        ));
    }
    let mut problem = Problem {
        chain,
        tool,
        mesh,
        touches,
        start: *base_from_part,
        centre: mesh.centroid(),
        joints: (1..chain.dof().saturating_sub(1)).collect(),
    };
    let sigma = noise_sigma_m;
    let baseline_theta = problem.fit(None, None);
    let before = problem.summarise(None, &baseline_theta, sigma)?;
    let n = touches.len() as f64;
    let statistic = before.residuals_m.iter().map(|r| r * r).sum::<f64>() / (sigma * sigma);
    let threshold = chi_square_99(n - 6.0);
    if statistic <= threshold {
        return Ok(Diagnosis {
            verdict: Verdict::NoEffect,
            effect: None,
            after: before.clone(),
            before,
            alternatives: Vec::new(),
            chi_square: (statistic, threshold),
            explanation: format!(
                "the pose-only residual is what the declared noise explains (chi-square {statistic:.1} <= {threshold:.1} at 99%)"
            ),
        });
    }
    let has_velocities = touches
        .iter()
        .all(|t| t.qd.as_ref().is_some_and(|qd| qd.iter().any(|v| *v != 0.0)));
    let mut accepted: Vec<(Effect, Fit)> = Vec::new();
    let mut alternatives = Vec::new();
    for effect in Effect::ALL {
        if effect == Effect::TriggerLatency && !has_velocities {
            alternatives.push(Alternative {
                name: effect.name(),
                fit: None,
                reason: "needs joint velocities at the touches".to_owned(),
            });
            continue;
        }
        let mut theta = problem.fit(Some(effect), None);
        let mut summary = problem.summarise(Some(effect), &theta, sigma);
        // Joint offsets are fitted for the subset of joints the touches can tell apart: the
        // least significant joint is dropped and the rest refitted while any is insignificant.
        while effect == Effect::JointOffsets && problem.joints.len() > 1 {
            let Ok(fit) = &summary else { break };
            let weakest = fit
                .params
                .iter()
                .enumerate()
                .map(|(k, (_, value, se))| (k, value.abs() / se.max(1e-300)))
                .min_by(|a, b| a.1.total_cmp(&b.1));
            match weakest {
                Some((k, z)) if z < 3.0 => {
                    problem.joints.remove(k);
                    theta = problem.fit(Some(effect), None);
                    summary = problem.summarise(Some(effect), &theta, sigma);
                }
                _ => break,
            }
        }
        match summary {
            Err(reason) => alternatives.push(Alternative {
                name: effect.name(),
                fit: None,
                reason,
            }),
            Ok(fit) => {
                let out_of_bounds = fit
                    .params
                    .iter()
                    .find(|(_, value, _)| value.abs() > effect.bound());
                let insignificant = fit
                    .params
                    .iter()
                    .find(|(_, value, se)| value.abs() < 3.0 * se);
                let reason = if let Some((name, value, _)) = out_of_bounds {
                    Some(format!(
                        "{name} = {value:.3e} leaves the plausibility bound {:.3e}",
                        effect.bound()
                    ))
                } else if let Some((name, value, se)) = insignificant {
                    Some(format!(
                        "{name} = {value:.3e} is within 3 standard errors ({se:.1e}) of zero"
                    ))
                } else if fit.bic >= before.bic {
                    Some(format!(
                        "BIC {:.1} is no better than the pose-only fit's {:.1}",
                        fit.bic, before.bic
                    ))
                } else {
                    None
                };
                match reason {
                    Some(reason) => alternatives.push(Alternative {
                        name: effect.name(),
                        fit: Some(fit),
                        reason,
                    }),
                    None => accepted.push((effect, fit)),
                }
            }
        }
    }
    accepted.sort_by(|a, b| a.1.bic.total_cmp(&b.1.bic));
    let Some((best_effect, best)) = accepted.first().cloned() else {
        let worst = before
            .residuals_m
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .map(|(i, r)| {
                format!(
                    "largest at inspection '{}' ({:+.3} mm)",
                    touches[i].id,
                    r * 1e3
                )
            })
            .unwrap_or_default();
        return Ok(Diagnosis {
            verdict: Verdict::NotAttributable,
            effect: None,
            after: before.clone(),
            before,
            alternatives,
            chi_square: (statistic, threshold),
            explanation: format!(
                "the residual exceeds the noise (chi-square {statistic:.1} > {threshold:.1}) but no candidate effect explains it; {worst}"
            ),
        });
    };
    for (effect, fit) in accepted.iter().skip(1) {
        alternatives.push(Alternative {
            name: effect.name(),
            fit: Some(fit.clone()),
            reason: format!(
                "BIC {:.1} against {:.1} for {}",
                fit.bic,
                best.bic,
                best_effect.name()
            ),
        });
    }
    let rival = accepted.get(1).filter(|(_, fit)| fit.bic - best.bic < 2.0);
    let after_statistic = best.residuals_m.iter().map(|r| r * r).sum::<f64>() / (sigma * sigma);
    let after_threshold = chi_square_99(n - 6.0 - best.params.len() as f64);
    let (verdict, explanation, applied) = if let Some((other, _)) = rival {
        (
            Verdict::Ambiguous,
            format!(
                "{} and {} explain the residual about equally well (BIC within 2); touches that separate them: for probe radius vs TCP offset, touches tilted differently on one face; for scale, touches far from the part origin on opposite faces; for joint offsets, touches in different arm configurations",
                best_effect.name(),
                other.name()
            ),
            // Which one to apply is unknown: keep the pose-only result.
            false,
        )
    } else if after_statistic > after_threshold {
        (
            Verdict::NotAttributable,
            format!(
                "{} is the best candidate but leaves more than the noise (chi-square {after_statistic:.1} > {after_threshold:.1}): something outside the library remains",
                best_effect.name()
            ),
            false,
        )
    } else {
        (
            Verdict::Effect,
            format!(
                "{} explains the residual down to the noise",
                best_effect.name()
            ),
            true,
        )
    };
    let after = if applied {
        best.clone()
    } else {
        before.clone()
    };
    Ok(Diagnosis {
        verdict,
        after,
        effect: (verdict != Verdict::NotAttributable).then(|| (best_effect.name(), best)),
        before,
        alternatives,
        chi_square: (statistic, threshold),
        explanation,
    })
}
