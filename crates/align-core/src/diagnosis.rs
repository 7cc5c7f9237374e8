//! Closing the loop: is anything left in the residual after alignment, and which effect the
//! model lacks explains it?
//!
//! Each touch gives a signed distance from the part's surface: forward kinematics of its joint
//! vector, the tool's TCP, the ball radius. The pose-only fit leaves residuals r_i; with the
//! declared touch noise sigma, RSS / sigma^2 follows a chi-square law with N - 6 degrees of
//! freedom when nothing is missing. If the test rejects that (99%), each candidate effect, a
//! small parameterised change of the model, is fitted together with the part pose by
//! Levenberg-Marquardt on the re-projected signed distances, and the candidates are ranked by
//! BIC (with the declared noise: RSS / sigma^2 + k ln N); each fit also reports its
//! leave-one-out RMS.
//!
//! | effect | parameters | plausibility bound |
//! | --- | --- | --- |
//! | `probe_radius` | ball radius change (m) | 5 mm |
//! | `tcp_offset` | TCP shift in the flange frame (m) | 20 mm |
//! | `joint_offsets` | encoder offset per joint but the first and last (rad) | 0.05 rad |
//! | `joint_compliance` | gravity sag per loaded joint: q_true = q_measured + c_j tau_g_j(q), c_j in rad/(N m) | 0 to 5e-4 rad/(N m) |
//! | `part_scale` | relative size change of the part about its origin | 1 % |
//! | `trigger_latency` | delay between contact and sample (s), needs joint velocities | 0.5 s |
//!
//! `joint_compliance` uses the gravity torque tau_g_j that the URDF inertials and the tool's
//! mass at its centre of mass put on each joint ([`Chain::gravity_torques_nm`], gravity
//! 9.80665 m/s^2 along -z of the base frame), evaluated at the measured joint vector. Only joints
//! whose largest |tau_g| over the touches reaches a tenth of the most loaded joint's are fitted:
//! a lightly loaded wrist sags too little to be told from noise, and a vertical base axis
//! carries none. A compliance must be positive (a joint yields to gravity) and below 5e-4
//! rad/(N m), a stiffness of 2 kN m/rad, several times softer than any arm in service.
//!
//! Before fitting, each candidate is reduced to the parameters these touches can identify,
//! judged at the declared model: a parameter that would move no touch by a thousandth of the
//! noise even at its bound (a sideways TCP shift under head-on touches), then while the scaled
//! information matrix has a condition number above 1e8 the parameter whose own signature moves
//! the touches least, then while the pose and the other parameters reproduce more than 99% of
//! a parameter's signature (variance inflation above 100) that parameter, is dropped. After
//! fitting, the weakest parameter is dropped while one is below 3 standard errors. What is left
//! competes under the effect's name, so a TCP offset seen only along the probe meets a
//! ball-radius change on equal terms and the two come out `ambiguous` on head-on touches. A
//! candidate is skipped, with the reason, when not even one parameter is identifiable (a joint-1
//! offset is a part yaw; on a compact set of arm configurations a sag or an encoder offset is a
//! rigid motion the pose absorbs), when there are too few touches, when it stays below 3
//! standard errors (the reason says how much of it the pose absorbs) or when the fit leaves its
//! bound. Candidates within 6 of the best BIC (a likelihood ratio of 20) make the verdict
//! `ambiguous`, listing them all and the touches that would separate them; the pose is then
//! left as the pose-only fit has it. Under `no_effect`, the alternatives list the effects these
//! touches could not have revealed.

use nalgebra::{DMatrix, DVector, Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::geometry::Mesh;
use crate::kinematics::{Chain, PointMass};
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
    JointCompliance,
    PartScale,
    TriggerLatency,
}

impl Effect {
    pub const ALL: [Effect; 6] = [
        Effect::ProbeRadius,
        Effect::TcpOffset,
        Effect::JointOffsets,
        Effect::JointCompliance,
        Effect::PartScale,
        Effect::TriggerLatency,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Effect::ProbeRadius => "probe_radius",
            Effect::TcpOffset => "tcp_offset",
            Effect::JointOffsets => "joint_offsets",
            Effect::JointCompliance => "joint_compliance",
            Effect::PartScale => "part_scale",
            Effect::TriggerLatency => "trigger_latency",
        }
    }

    /// Every parameter the effect can have; a fit uses the subset the touches identify.
    fn parameter_names(self, dof: usize) -> Vec<String> {
        match self {
            Effect::ProbeRadius => vec!["delta_radius_m".to_owned()],
            Effect::TcpOffset => ["dx_m", "dy_m", "dz_m"].map(str::to_owned).to_vec(),
            Effect::JointOffsets => (1..=dof).map(|j| format!("joint_{j}_rad")).collect(),
            Effect::JointCompliance => (1..=dof).map(|j| format!("joint_{j}_rad_per_nm")).collect(),
            Effect::PartScale => vec!["scale_minus_one".to_owned()],
            Effect::TriggerLatency => vec!["latency_s".to_owned()],
        }
    }

    /// What a session needs for this effect to stand out from the others and from the pose.
    fn separating_touches(self) -> &'static str {
        match self {
            Effect::ProbeRadius | Effect::TcpOffset => {
                "for the ball radius and the TCP, each face touched head-on and tilted both ways"
            }
            Effect::JointOffsets => "for joint offsets, touches in different arm configurations",
            Effect::JointCompliance => {
                "for joint compliance, touches with the arm folded and stretched (different gravity loads)"
            }
            Effect::PartScale => {
                "for the part's scale, faces at different distances from the part origin"
            }
            Effect::TriggerLatency => "for latency, touches at different approach speeds",
        }
    }

    fn bound(self) -> f64 {
        match self {
            Effect::ProbeRadius => 0.005,
            Effect::TcpOffset => 0.02,
            Effect::JointOffsets => 0.05,
            Effect::JointCompliance => 5e-4,
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
    /// Gravity torque on each joint at each touch (N m), for `joint_compliance`.
    gravity_torques_nm: Vec<Vec<f64>>,
    /// Indices into the current effect's parameters of the ones being fitted.
    active: Vec<usize>,
}

/// Why a fit cannot be reported, and for an unidentifiable one, which of the effect's fitted
/// parameters to give up first.
struct Rejection {
    reason: String,
    unseen_parameter: Option<usize>,
}

impl From<String> for Rejection {
    fn from(reason: String) -> Self {
        Self {
            reason,
            unseen_parameter: None,
        }
    }
}

impl Problem<'_> {
    fn parameter_count(&self, effect: Option<Effect>) -> usize {
        6 + if effect.is_some() {
            self.active.len()
        } else {
            0
        }
    }

    /// The parameters an effect starts from, before the touches reduce them.
    fn initial_parameters(&self, effect: Effect) -> Vec<usize> {
        let dof = self.chain.dof();
        match effect {
            // The first joint's offset is a turn of the whole cell about the base axis, the same
            // as a part yaw; the last turns the ball about its own centre on a probe along the
            // flange axis: neither is visible in touches, so only the joints between are fitted.
            Effect::JointOffsets => (1..dof.saturating_sub(1)).collect(),
            Effect::JointCompliance => {
                let largest: Vec<f64> = (0..dof)
                    .map(|j| {
                        self.gravity_torques_nm
                            .iter()
                            .fold(0.0f64, |m, torques| m.max(torques[j].abs()))
                    })
                    .collect();
                let most = largest.iter().copied().fold(0.0f64, f64::max);
                (0..dof)
                    .filter(|&j| most > 0.0 && largest[j] >= COMPLIANCE_TORQUE_FRACTION * most)
                    .collect()
            }
            Effect::TcpOffset => vec![0, 1, 2],
            Effect::ProbeRadius | Effect::PartScale | Effect::TriggerLatency => vec![0],
        }
    }

    fn active_names(&self, effect: Effect) -> Vec<String> {
        let all = effect.parameter_names(self.chain.dof());
        self.active.iter().map(|&i| all[i].clone()).collect()
    }

    /// The effect's full parameter vector (inactive ones zero) from a fit's parameter vector.
    fn effect_parameters(&self, effect: Effect, theta: &DVector<f64>) -> Vec<f64> {
        let mut full = vec![0.0; effect.parameter_names(self.chain.dof()).len()];
        for (k, &index) in self.active.iter().enumerate() {
            full[index] = theta[6 + k];
        }
        full
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
        let extras = effect.map_or_else(Vec::new, |effect| self.effect_parameters(effect, theta));
        let extra = |i: usize| extras[i];
        let values: Vec<f64> = self
            .touches
            .iter()
            .enumerate()
            .filter(|(index, _)| Some(*index) != skip)
            .map(|(index, touch)| {
                let mut q = touch.q.clone();
                match effect {
                    Some(Effect::JointOffsets) => {
                        q.iter_mut()
                            .zip(&extras)
                            .for_each(|(v, offset)| *v += offset);
                    }
                    Some(Effect::JointCompliance) => {
                        let torques = &self.gravity_torques_nm[index];
                        for ((v, compliance), torque) in q.iter_mut().zip(&extras).zip(torques) {
                            *v += compliance * torque;
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
        self.fit_from(effect, skip, DVector::zeros(self.parameter_count(effect)))
    }

    /// Levenberg-Marquardt from `theta`.
    fn fit_from(
        &self,
        effect: Option<Effect>,
        skip: Option<usize>,
        mut theta: DVector<f64>,
    ) -> DVector<f64> {
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
    ) -> Result<Fit, Rejection> {
        let residual = self.residual(effect, theta, None);
        let n = residual.len();
        let k = theta.len();
        if n <= k {
            return Err(format!("{n} touches cannot fit {k} parameters").into());
        }
        let names = effect.map_or_else(Vec::new, |effect| self.active_names(effect));
        let information =
            self.jacobian(effect, theta, None).transpose() * self.jacobian(effect, theta, None);
        identifiable(&information, &names, effect.map_or(1.0, Effect::bound))?;
        let covariance = information
            .clone()
            .try_inverse()
            .ok_or_else(|| "singular information matrix".to_owned())?;
        let rss = residual.norm_squared();
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
            // Costs a fit per touch: filled in once the candidate's parameters are settled.
            loo_rms_m: f64::NAN,
            // The noise is declared, not estimated: -2 log-likelihood is RSS / sigma^2. (With
            // the variance estimated from RSS, two fits both below the noise would differ by
            // n ln(RSS ratio), tens of units for a meaningless difference.)
            bic: rss / (sigma * sigma) + k as f64 * (n as f64).ln(),
            params,
        })
    }

    /// RMS of each touch's residual predicted by a fit without it. Each of those fits starts
    /// from `theta`, the fit with every touch, which one touch less moves only a little.
    fn leave_one_out(&self, effect: Option<Effect>, theta: &DVector<f64>) -> f64 {
        let n = self.touches.len();
        if n <= self.parameter_count(effect) + 1 {
            return f64::NAN;
        }
        let sum: f64 = (0..n)
            .map(|held| {
                let without = self.fit_from(effect, Some(held), theta.clone());
                let all = self.residual(effect, &without, None);
                all[held] * all[held]
            })
            .sum();
        (sum / n as f64).sqrt()
    }
}

/// Fraction of the most loaded joint's largest gravity torque below which a joint's compliance
/// is not fitted.
const COMPLIANCE_TORQUE_FRACTION: f64 = 0.1;

/// BIC margin below which a second candidate counts as explaining the residual as well as the
/// best: 6 is "strong" evidence (a likelihood ratio of 20), so an `effect` verdict means the
/// data favour it at least 20:1 over every other candidate.
const AMBIGUITY_BIC: f64 = 6.0;

/// Variance inflation above which an effect parameter counts as absorbed by the pose (see
/// [`absorbed`]).
const POSE_ABSORPTION_LIMIT: f64 = 100.0;

/// Largest scaled condition number of the information matrix at which parameters still count
/// as identifiable.
const CONDITION_LIMIT: f64 = 1e8;

/// The information matrix scaled to unit diagonal: its condition number and null directions do
/// not depend on the units of the parameters.
fn scaled(information: &DMatrix<f64>) -> DMatrix<f64> {
    let k = information.nrows();
    let scale = DVector::from_iterator(
        k,
        (0..k).map(|i| information[(i, i)].max(1e-300).sqrt().recip()),
    );
    DMatrix::from_fn(k, k, |i, j| information[(i, j)] * scale[i] * scale[j])
}

/// An effect parameter that would change the touches' residuals by less than a thousandth of
/// the noise even at its plausibility bound is not seen at all (a sideways TCP shift under
/// head-on touches). It has to be caught before the scaled condition number: scaling its
/// column of rounding noise to unit length would make it look correlated with anything.
fn invisible(
    information: &DMatrix<f64>,
    names: &[String],
    bound: f64,
    sigma: f64,
) -> Option<Rejection> {
    let (index, change_m) = (0..names.len())
        .map(|i| (i, information[(6 + i, 6 + i)].max(0.0).sqrt() * bound))
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    (change_m < 1e-3 * sigma).then(|| Rejection {
        reason: format!(
            "not identifiable from these touches: {} at its bound {bound:.1e} would move them by {change_m:.1e} m in all",
            names[index]
        ),
        unseen_parameter: Some(index),
    })
}

/// Checks that the pose (first six parameters) and the effect parameters `names` are
/// identifiable; if not, says which trade off with what.
fn identifiable(information: &DMatrix<f64>, names: &[String], bound: f64) -> Result<(), Rejection> {
    let scaled_information = scaled(information);
    let eigen = scaled_information.clone().symmetric_eigen();
    let (mut low, mut low_index, mut high) = (f64::MAX, 0, 0.0f64);
    for (index, value) in eigen.eigenvalues.iter().enumerate() {
        if *value < low {
            (low, low_index) = (*value, index);
        }
        high = high.max(*value);
    }
    if low > high / CONDITION_LIMIT {
        return Ok(());
    }
    // The direction the touches do not see: which parameters move together along it.
    let null = eigen.eigenvectors.column(low_index);
    let pose_weight: f64 = null.rows(0, 6).norm_squared();
    let effect_weights: Vec<f64> = null.rows(6, names.len()).iter().map(|v| v * v).collect();
    // The parameter to give up is the one whose own signature, at its plausibility bound and
    // beyond what the others reproduce, moves the touches least. Not the largest component of
    // the null eigenvector: when two parameters are unseen, that vector is any mix of them and
    // of what they trade off with; and not the unexplained fraction alone: a faint but real
    // signature scaled to unit length trades off with anything.
    let unseen_parameter = (0..names.len())
        .map(|i| {
            let size_at_bound = information[(6 + i, 6 + i)].max(0.0).sqrt() * bound;
            (
                i,
                size_at_bound * unexplained_fraction(&scaled_information, 6 + i).sqrt(),
            )
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(index, _)| index);
    let involved: Vec<&str> = names
        .iter()
        .zip(&effect_weights)
        .filter(|(_, weight)| **weight > 0.05)
        .map(|(name, _)| name.as_str())
        .collect();
    let partner = if pose_weight > 0.05 {
        "the part pose"
    } else {
        "each other"
    };
    Err(Rejection {
        reason: format!(
            "not identifiable from these touches (scaled condition number {:.1e}): {} trade off with {partner}",
            high / low.max(1e-300),
            if involved.is_empty() {
                "the pose parameters".to_owned()
            } else {
                involved.join(", ")
            }
        ),
        unseen_parameter,
    })
}

/// Rejects the effect parameter the pose (and the other parameters) absorb most when they
/// reproduce more than 1 - 1/POSE_ABSORPTION_LIMIT (99%) of its signature: its estimate would
/// then rest on a sliver of its signature, which an unmodelled effect a hundredth its size would
/// swamp; and under `no_effect` such an effect could shift the part pose by ten times what the
/// residual shows without being noticed.
fn absorbed(
    information: &DMatrix<f64>,
    names: &[String],
    separating_touches: &str,
) -> Result<(), Rejection> {
    let Some((index, inflation)) = (0..names.len())
        .map(|i| (i, variance_inflation(information, 6 + i)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
    else {
        return Ok(());
    };
    if inflation <= POSE_ABSORPTION_LIMIT {
        return Ok(());
    }
    // Name the partner: the pose alone, or the pose with the effect's other parameters.
    let with_pose_only = DMatrix::from_fn(7, 7, |a, b| {
        let map = |i: usize| if i < 6 { i } else { 6 + index };
        information[(map(a), map(b))]
    });
    let partner = if variance_inflation(&with_pose_only, 6) * 2.0 >= inflation {
        "the part pose".to_owned()
    } else {
        let others: Vec<&str> = names
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != index)
            .map(|(_, name)| name.as_str())
            .collect();
        format!("the part pose and {}", others.join(", "))
    };
    Err(Rejection {
        reason: format!(
            "not identifiable from these touches: {} trades off with {partner}, which reproduce {:.2}% of its signature (variance inflation {inflation:.0}); {separating_touches} would separate them",
            names[index],
            100.0 * (1.0 - inflation.recip())
        ),
        unseen_parameter: Some(index),
    })
}

/// The part of parameter `index`'s signature the other parameters cannot reproduce, 0 to 1,
/// from the information matrix scaled to unit diagonal (a Schur complement; the others may be
/// degenerate among themselves, hence the pseudo-inverse).
fn unexplained_fraction(scaled_information: &DMatrix<f64>, index: usize) -> f64 {
    let k = scaled_information.nrows();
    let others: Vec<usize> = (0..k).filter(|&j| j != index).collect();
    let block = DMatrix::from_fn(others.len(), others.len(), |a, b| {
        scaled_information[(others[a], others[b])]
    });
    let cross = DVector::from_iterator(
        others.len(),
        others.iter().map(|&j| scaled_information[(j, index)]),
    );
    let explained = block
        .svd(true, true)
        .solve(&cross, 1e-12)
        .map_or(0.0, |weights| cross.dot(&weights));
    (scaled_information[(index, index)] - explained).max(0.0)
}

/// How much the variance of parameter `index` grows because the others are fitted with it
/// (1 when it is independent of them; 100 when they absorb 99% of its signature).
fn variance_inflation(information: &DMatrix<f64>, index: usize) -> f64 {
    information
        .clone()
        .try_inverse()
        .map_or(f64::INFINITY, |covariance| {
            covariance[(index, index)] * information[(index, index)]
        })
}

/// Upper 99% point of chi-square with `dof` degrees of freedom (Wilson-Hilferty).
fn chi_square_99(dof: f64) -> f64 {
    let z = 2.326_347_874;
    let a = 2.0 / (9.0 * dof);
    dof * (1.0 - a + z * a.sqrt()).powi(3)
}

/// Sets the problem's active parameters of `effect` to the ones these touches can identify, or
/// says why none can be.
///
/// What the touches can see is a property of where they are, judged at the declared model where
/// small effects live: a fit first would wander along an unseen direction until the geometry
/// turns nonlinear (a 2 cm sideways TCP shift reaches an edge) and seems to see it.
fn reduce_to_identifiable(problem: &mut Problem, effect: Effect, sigma: f64) -> Result<(), String> {
    problem.active = problem.initial_parameters(effect);
    if problem.active.is_empty() {
        return Err(
            "no joint carries a gravity torque: the URDF has no inertials and the tool no mass"
                .to_owned(),
        );
    }
    loop {
        let nominal = DVector::zeros(problem.parameter_count(Some(effect)));
        let jacobian = problem.jacobian(Some(effect), &nominal, None);
        let names = problem.active_names(effect);
        let information = jacobian.transpose() * &jacobian;
        let check = invisible(&information, &names, effect.bound(), sigma)
            .map_or_else(|| identifiable(&information, &names, effect.bound()), Err)
            .and_then(|()| absorbed(&information, &names, effect.separating_touches()));
        match check {
            Ok(()) => return Ok(()),
            Err(rejection) => match rejection.unseen_parameter {
                Some(k) if problem.active.len() > 1 => {
                    problem.active.remove(k);
                }
                _ => return Err(rejection.reason),
            },
        }
    }
}

/// A candidate effect's fate.
enum Assessment {
    Accepted(Fit),
    Rejected(Alternative),
}

/// Fits one candidate effect, reduced to the parameters the touches identify (see the module
/// docs), and accepts it or says why not.
fn assess(problem: &mut Problem, effect: Effect, sigma: f64, pose_only_bic: f64) -> Assessment {
    let reject = |fit: Option<Fit>, reason: String| Alternative {
        name: effect.name(),
        fit,
        reason,
    };
    if let Err(reason) = reduce_to_identifiable(problem, effect, sigma) {
        return Assessment::Rejected(reject(None, reason));
    }
    let (theta, fit) = loop {
        let theta = problem.fit(Some(effect), None);
        let summary = problem.summarise(Some(effect), &theta, sigma);
        let reducible = problem.active.len() > 1;
        let drop = match &summary {
            Err(rejection) if reducible => rejection.unseen_parameter,
            Ok(fit) if reducible => fit
                .params
                .iter()
                .enumerate()
                .map(|(k, (_, value, se))| (k, value.abs() / se.max(1e-300)))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .filter(|(_, z)| *z < 3.0)
                .map(|(k, _)| k),
            _ => None,
        };
        match (drop, summary) {
            (Some(k), _) => {
                problem.active.remove(k);
            }
            (None, Ok(mut fit)) => {
                fit.loo_rms_m = problem.leave_one_out(Some(effect), &theta);
                break (theta, fit);
            }
            (None, Err(rejection)) => return Assessment::Rejected(reject(None, rejection.reason)),
        }
    };
    let out_of_bounds = fit
        .params
        .iter()
        .find(|(_, value, _)| value.abs() > effect.bound());
    // A joint cannot stiffen against gravity: a compliance that survived the significance test
    // below zero is something else.
    let unphysical = fit
        .params
        .iter()
        .find(|(_, value, _)| effect == Effect::JointCompliance && *value < 0.0);
    let insignificant = fit
        .params
        .iter()
        .enumerate()
        .find(|(_, (_, value, se))| value.abs() < 3.0 * se);
    let reason = if let Some((name, value, _)) = out_of_bounds {
        Some(format!(
            "{name} = {value:.3e} leaves the plausibility bound {:.3e}",
            effect.bound()
        ))
    } else if let Some((name, value, se)) = unphysical {
        Some(format!(
            "{name} = {value:.3e} +- {se:.1e} is negative: a joint does not lean against gravity"
        ))
    } else if let Some((k, (name, value, se))) = insignificant {
        let jacobian = problem.jacobian(Some(effect), &theta, None);
        let inflation = variance_inflation(&(jacobian.transpose() * &jacobian), 6 + k);
        // Say when the cause is a confound rather than a small effect.
        let confound = if inflation > 10.0 {
            format!(
                ": it trades off with the part pose (variance inflation {inflation:.0}, the pose absorbs {:.0}% of its signature)",
                100.0 * (1.0 - inflation.recip())
            )
        } else {
            String::new()
        };
        Some(format!(
            "{name} = {value:.3e} is within 3 standard errors ({se:.1e}) of zero{confound}"
        ))
    } else if fit.bic >= pose_only_bic {
        Some(format!(
            "BIC {:.1} is no better than the pose-only fit's {pose_only_bic:.1}",
            fit.bic
        ))
    } else {
        None
    };
    match reason {
        Some(reason) => Assessment::Rejected(reject(Some(fit), reason)),
        None => Assessment::Accepted(fit),
    }
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
    let payload = PointMass {
        mass_kg: tool.mass_kg,
        com_in_tip: tool.com_in_flange,
    };
    let mut problem = Problem {
        chain,
        tool,
        mesh,
        touches,
        start: *base_from_part,
        centre: mesh.centroid(),
        gravity_torques_nm: touches
            .iter()
            .map(|touch| chain.gravity_torques_nm(&touch.q, Some(&payload)))
            .collect(),
        active: Vec::new(),
    };
    let sigma = noise_sigma_m;
    let baseline_theta = problem.fit(None, None);
    let mut before = problem
        .summarise(None, &baseline_theta, sigma)
        .map_err(|rejection| format!("the part pose alone: {}", rejection.reason))?;
    before.loo_rms_m = problem.leave_one_out(None, &baseline_theta);
    let n = touches.len() as f64;
    let statistic = before.residuals_m.iter().map(|r| r * r).sum::<f64>() / (sigma * sigma);
    let threshold = chi_square_99(n - 6.0);
    let has_velocities = touches
        .iter()
        .all(|t| t.qd.as_ref().is_some_and(|qd| qd.iter().any(|v| *v != 0.0)));
    let candidates: Vec<Effect> = Effect::ALL
        .into_iter()
        .filter(|effect| *effect != Effect::TriggerLatency || has_velocities)
        .collect();
    if statistic <= threshold {
        // Nothing to fit; but say which effects these touches could not have revealed, so that
        // "no effect" is not read as "no compliance" on a session that cannot see it.
        let alternatives = candidates
            .iter()
            .filter_map(|&effect| {
                reduce_to_identifiable(&mut problem, effect, sigma)
                    .err()
                    .map(|reason| Alternative {
                        name: effect.name(),
                        fit: None,
                        reason: format!("would go unseen: {reason}"),
                    })
            })
            .collect();
        return Ok(Diagnosis {
            verdict: Verdict::NoEffect,
            effect: None,
            after: before.clone(),
            before,
            alternatives,
            chi_square: (statistic, threshold),
            explanation: format!(
                "the pose-only residual is what the declared noise explains (chi-square {statistic:.1} <= {threshold:.1} at 99%)"
            ),
        });
    }
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
        match assess(&mut problem, effect, sigma, before.bic) {
            Assessment::Accepted(fit) => accepted.push((effect, fit)),
            Assessment::Rejected(alternative) => alternatives.push(alternative),
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
    let rivals: Vec<Effect> = accepted
        .iter()
        .skip(1)
        .filter(|(_, fit)| fit.bic - best.bic < AMBIGUITY_BIC)
        .map(|(effect, _)| *effect)
        .collect();
    let after_statistic = best.residuals_m.iter().map(|r| r * r).sum::<f64>() / (sigma * sigma);
    let after_threshold = chi_square_99(n - 6.0 - best.params.len() as f64);
    let (verdict, explanation, applied) = if !rivals.is_empty() {
        let tied: Vec<Effect> = std::iter::once(best_effect).chain(rivals).collect();
        (
            Verdict::Ambiguous,
            format!(
                "{} explain the residual about equally well (BIC within {AMBIGUITY_BIC}); touches that would separate them: {}",
                tied.iter().map(|e| e.name()).collect::<Vec<_>>().join(", "),
                {
                    let mut hints: Vec<&str> =
                        tied.iter().map(|e| e.separating_touches()).collect();
                    hints.dedup();
                    hints.join("; ")
                }
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
