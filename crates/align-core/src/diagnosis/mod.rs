//! Closing the loop: is anything left in the residual after alignment, and which effect the
//! model lacks explains it?
//!
//! Each touch gives a signed distance from the part's surface: forward kinematics of its joint
//! vector (or the flange pose the controller reported), the tool's TCP, the ball radius. The
//! pose-only fit leaves residuals r_i; with the declared touch noise sigma, RSS / sigma^2 follows
//! a chi-square law with N - 6 degrees of freedom when nothing is missing. If the test rejects
//! that (99%), each candidate effect, a small parameterised change of the model, and pairs of
//! them, is fitted together with the part pose by Levenberg-Marquardt on the
//! re-projected signed distances; candidates are ranked by BIC (with the declared noise: RSS /
//! sigma^2 + k ln N) and each reports its leave-one-out RMS.
//!
//! | effect | parameters | plausibility bound |
//! | --- | --- | --- |
//! | `probe_radius` | ball radius change (m) | 5 mm |
//! | `tcp_offset` | TCP shift in the flange frame (m) | 20 mm |
//! | `joint_offsets` | encoder offset per joint (rad) | 0.05 rad |
//! | `joint_compliance` | gravity sag per loaded joint: q_true = q_measured + c_j tau_g_j(q), c_j in rad/(N m) | 0 to 5e-4 rad/(N m) |
//! | `part_scale` | relative size change of the part about its origin | 1 % |
//! | `trigger_latency` | delay between contact and sample (s), needs joint velocities | 0.5 s |
//!
//! `joint_compliance` uses the gravity torque tau_g_j that the URDF inertials and the tool's
//! mass at its centre of mass put on each joint ([`Chain::gravity_torques_nm`], gravity
//! 9.80665 m/s^2 along -z of the base frame), evaluated at the measured joint vector.
//!
//! Which parameters a candidate fits is decided by the touches (see `selection`): those whose
//! signature at a typical size stays visible beside the pose and the others, then backward
//! elimination by BIC, then forward steps that admit a left-out parameter lowering the BIC by 6.
//! A joint-1 offset is a part yaw and drops out; offsets on a UR's three parallel joints stay
//! together when the data need them. Pairs (the best single effects with each other, the best
//! with every other effect) compete with the single effects on the same terms, but must beat the
//! best single effect and the pose alone by 10 in BIC.
//! Candidates within 6 of the best BIC (a likelihood ratio of 20) make the verdict `ambiguous`,
//! listing them all and the touches that would separate them; the pose is then left as the
//! pose-only fit has it. Under `no_effect`, the alternatives list the effects these touches
//! could not have revealed. Touches given as flange poses cannot show effects that act through
//! the joints (`joint_offsets`, `joint_compliance`, `trigger_latency`): those are listed as
//! skipped with the reason.
//!
//! Held-out errors: every fit reports a leave-one-out RMS from its hat matrix (PRESS); the
//! pose-only fit and the applied correction report it from real refits without each touch.

mod effects;
mod model;
mod selection;

use nalgebra::{DVector, Isometry3, Point3};

pub use effects::{Effect, UnknownEffect};
use model::Problem;
use selection::{AMBIGUITY_BIC, Assessment, Candidate};

use crate::geometry::Mesh;
use crate::kinematics::{Chain, PointMass};
use crate::tool::Tool;

/// One inspection as captured: joint positions and, when known, velocities; or the flange pose
/// the controller reported instead of joints.
#[derive(Debug, Clone, PartialEq)]
pub struct TouchSample {
    pub id: String,
    /// Joint positions; empty when `base_from_flange` is given.
    pub q: Vec<f64>,
    pub qd: Option<Vec<f64>>,
    /// The flange pose reported instead of joints.
    pub base_from_flange: Option<Isometry3<f64>>,
}

impl TouchSample {
    pub fn from_joints(id: impl Into<String>, q: Vec<f64>, qd: Option<Vec<f64>>) -> Self {
        Self {
            id: id.into(),
            q,
            qd,
            base_from_flange: None,
        }
    }

    pub fn from_flange_pose(id: impl Into<String>, base_from_flange: Isometry3<f64>) -> Self {
        Self {
            id: id.into(),
            q: Vec::new(),
            qd: None,
            base_from_flange: Some(base_from_flange),
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Fit {
    pub base_from_part: Isometry3<f64>,
    /// Each touch's ball centre in the base frame under the fitted effect.
    pub ball_centres_m: Vec<Point3<f64>>,
    pub residuals_m: Vec<f64>,
    pub rms_m: f64,
    pub max_m: f64,
    /// Leave-one-out RMS: each touch predicted by the fit without it.
    pub loo_rms_m: f64,
    pub bic: f64,
    /// Name, value and standard error of each fitted effect parameter.
    pub params: Vec<(String, f64, f64)>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Alternative {
    /// An effect's name, or two joined by `+` for a pair.
    pub name: String,
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
    /// The best candidate (an effect's name, or a pair's joined by `+`) and its fit.
    pub effect: Option<(String, Fit)>,
    pub before: Fit,
    pub after: Fit,
    pub alternatives: Vec<Alternative>,
    /// chi-square statistic of the pose-only fit and its 99% threshold.
    pub chi_square: (f64, f64),
    pub explanation: String,
}

/// BIC margin by which a candidate the part pose mostly absorbs must beat every other to be
/// applied: 10, "very strong" on Kass and Raftery's scale (a likelihood ratio of 150), since
/// applying it moves the part by what the touches barely check.
const ABSORBED_MARGIN_BIC: f64 = 10.0;

/// BIC margin by which a pair must beat every single effect and the pose alone: "very strong"
/// (10 on Kass and Raftery's scale), since two flexible effects together also fit errors outside
/// the library (an eccentric encoder was fitted as a TCP shift plus joint offsets, which moved
/// the part further off).
const PAIR_MARGIN_BIC: f64 = 10.0;

/// Single effects whose fits rank best are paired with each other, this many at most.
const PAIRED_SINGLES: usize = 4;

/// The pairs to fit, from the single effects that could be fitted (best BIC first): the best
/// few with each other, and the best with every other effect, fitted alone or not. The second is
/// forward selection's next step: an effect that explains nothing alone, because the first one
/// dominates the residual, can still be what remains once the first is fitted (a TCP error hides
/// a part scale, whose fit alone ranked last or was not even seen).
fn pairs_to_try(fitted_singles: &[(Effect, f64)]) -> Vec<[Effect; 2]> {
    let mut pairs: Vec<[Effect; 2]> = Vec::new();
    let mut add = |first: Effect, second: Effect| {
        let mut pair = [first, second];
        pair.sort();
        if first != second && !pairs.contains(&pair) {
            pairs.push(pair);
        }
    };
    let best = fitted_singles.iter().take(PAIRED_SINGLES);
    for (i, (first, _)) in best.clone().enumerate() {
        for (second, _) in best.clone().skip(i + 1) {
            add(*first, *second);
        }
    }
    if let Some((first, _)) = fitted_singles.first() {
        for second in Effect::ALL {
            add(*first, second);
        }
    }
    pairs
}

/// Upper 99% point of chi-square with `dof` degrees of freedom (Wilson-Hilferty).
fn chi_square_99(dof: f64) -> f64 {
    let z = 2.326_347_874;
    let a = 2.0 / (9.0 * dof);
    dof * (1.0 - a + z * a.sqrt()).powi(3)
}

fn check_input(
    chain: Option<&Chain>,
    touches: &[TouchSample],
    noise_sigma_m: f64,
) -> Result<(), String> {
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
    for touch in touches.iter().filter(|t| t.base_from_flange.is_none()) {
        let chain = chain.ok_or_else(|| {
            format!(
                "inspection '{}' gives joints but there is no robot to turn them into a flange pose",
                touch.id
            )
        })?;
        if touch.q.len() != chain.dof() {
            return Err(format!(
                "inspection '{}' has {} joint values, the chain {}",
                touch.id,
                touch.q.len(),
                chain.dof()
            ));
        }
    }
    Ok(())
}

/// Diagnoses the residual of a touch alignment. `base_from_part` is the aligned pose (the start
/// of every fit); `noise_sigma_m` the declared touch noise. `chain` may be `None` when every
/// touch gives its flange pose.
pub fn diagnose(
    chain: Option<&Chain>,
    tool: &Tool,
    mesh: &Mesh,
    touches: &[TouchSample],
    base_from_part: &Isometry3<f64>,
    noise_sigma_m: f64,
) -> Result<Diagnosis, String> {
    check_input(chain, touches, noise_sigma_m)?;
    let payload = PointMass {
        mass_kg: tool.mass_kg,
        com_in_tip: tool.com_in_flange,
    };
    let gravity_torques_nm = touches
        .iter()
        .map(|touch| match (chain, &touch.base_from_flange) {
            (Some(chain), None) => chain.gravity_torques_nm(&touch.q, Some(&payload)),
            _ => Vec::new(),
        })
        .collect();
    let problem = Problem::new(
        chain,
        tool,
        mesh,
        touches,
        *base_from_part,
        gravity_torques_nm,
    );
    let sigma = noise_sigma_m;
    let pose_theta = problem.fit(&[], None);
    let mut before = problem
        .summarise(&[], &pose_theta, sigma)
        .map_err(|reason| format!("the part pose alone: {reason}"))?;
    before.loo_rms_m = problem.leave_one_out(&[], &pose_theta);
    let n = touches.len() as f64;
    let statistic = before.residuals_m.iter().map(|r| r * r).sum::<f64>() / (sigma * sigma);
    let threshold = chi_square_99(n - 6.0);
    if statistic <= threshold {
        // Nothing to fit; but say which effects these touches could not have revealed, so that
        // "no effect" is not read as "no compliance" on a session that cannot see it.
        let alternatives = Effect::ALL
            .iter()
            .filter_map(|&effect| {
                selection::unseen(&problem, effect, &pose_theta, sigma).map(|reason| Alternative {
                    name: effect.name().to_owned(),
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
    let found = candidates(&problem, &pose_theta, sigma, before.bic);
    Ok(verdict(
        &problem,
        found,
        before,
        (statistic, threshold),
        sigma,
    ))
}

/// The candidates' fates.
struct Candidates {
    /// Best BIC first.
    accepted: Vec<Candidate>,
    alternatives: Vec<Alternative>,
    /// The best BIC of the candidates that fit but are mostly a pose change.
    absorbed_best_bic: f64,
    /// The best pair not applied (name, BIC): if it fits better than the best candidate, that
    /// one is not the whole story.
    pair_rival: (String, f64),
}

/// Every single effect, then pairs of the best-fitting ones.
fn candidates(
    problem: &Problem,
    pose_theta: &DVector<f64>,
    sigma: f64,
    pose_only_bic: f64,
) -> Candidates {
    let mut accepted: Vec<Candidate> = Vec::new();
    let mut absorbed: Vec<(Candidate, String)> = Vec::new();
    // The best-fitting pair that was not decisive enough to apply.
    let mut pair_rival = (String::new(), f64::INFINITY);
    let mut alternatives = Vec::new();
    let mut fitted_singles: Vec<(Effect, f64)> = Vec::new();
    for effect in Effect::ALL {
        match selection::assess(problem, &[effect], pose_theta, sigma, pose_only_bic) {
            Assessment::Accepted(candidate) => {
                fitted_singles.push((effect, candidate.fit.bic));
                accepted.push(candidate);
            }
            Assessment::Absorbed(candidate, reason) => {
                fitted_singles.push((effect, candidate.fit.bic));
                absorbed.push((candidate, reason));
            }
            Assessment::Rejected(alternative) => {
                if let Some(fit) = &alternative.fit {
                    fitted_singles.push((effect, fit.bic));
                }
                alternatives.push(alternative);
            }
        }
    }
    fitted_singles.sort_by(|a, b| a.1.total_cmp(&b.1));
    for pair in pairs_to_try(&fitted_singles) {
        match selection::assess(problem, &pair, pose_theta, sigma, pose_only_bic) {
            Assessment::Accepted(candidate) => {
                // Two effects are a stronger claim than one: a pair must beat every single
                // effect clearly, or the simpler explanation stands.
                let (single, single_bic) = accepted
                    .iter()
                    .filter(|c| c.effects.len() == 1)
                    .map(|c| (c.name(), c.fit.bic))
                    .chain(std::iter::once((
                        "the pose alone".to_owned(),
                        pose_only_bic,
                    )))
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .unwrap_or_else(|| ("the pose alone".to_owned(), pose_only_bic));
                if candidate.fit.bic > single_bic - PAIR_MARGIN_BIC {
                    if candidate.fit.bic < pair_rival.1 {
                        pair_rival = (candidate.name(), candidate.fit.bic);
                    }
                    alternatives.push(Alternative {
                        name: candidate.name(),
                        reason: format!(
                            "BIC {:.1} does not beat {single}'s {single_bic:.1} by {PAIR_MARGIN_BIC}: the simpler explanation stands",
                            candidate.fit.bic
                        ),
                        fit: Some(candidate.fit),
                    });
                } else {
                    accepted.push(candidate);
                }
            }
            Assessment::Absorbed(candidate, reason) => absorbed.push((candidate, reason)),
            Assessment::Rejected(alternative) => alternatives.push(alternative),
        }
    }
    accepted.sort_by(|a, b| a.fit.bic.total_cmp(&b.fit.bic));
    absorbed.sort_by(|a, b| a.0.fit.bic.total_cmp(&b.0.fit.bic));
    // A candidate the pose mostly absorbs is still the answer when what the pose leaves of it
    // explains the residual decisively better than anything else (a UR's shoulder offset: 99.5%
    // a part rotation, the rest plain in the data): "very strong" evidence, not merely strong.
    let best_accepted = accepted
        .first()
        .map_or(pose_only_bic, |c| c.fit.bic.min(pose_only_bic));
    let mut absorbed = absorbed.into_iter();
    if let Some((candidate, _)) = absorbed
        .as_slice()
        .first()
        .filter(|(c, _)| c.fit.bic < best_accepted - ABSORBED_MARGIN_BIC)
        .cloned()
    {
        absorbed.next();
        accepted.insert(0, candidate);
    }
    let mut absorbed_best_bic = f64::INFINITY;
    for (candidate, reason) in absorbed {
        absorbed_best_bic = absorbed_best_bic.min(candidate.fit.bic);
        alternatives.push(Alternative {
            name: candidate.name(),
            fit: Some(candidate.fit),
            reason,
        });
    }
    Candidates {
        accepted,
        alternatives,
        absorbed_best_bic,
        pair_rival,
    }
}

/// The verdict from the accepted candidates.
fn verdict(
    problem: &Problem,
    found: Candidates,
    before: Fit,
    chi_square: (f64, f64),
    sigma: f64,
) -> Diagnosis {
    let Candidates {
        accepted,
        mut alternatives,
        absorbed_best_bic,
        pair_rival,
    } = found;
    let (statistic, threshold) = chi_square;
    let Some(best) = accepted.first().cloned() else {
        let worst = before
            .residuals_m
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .map(|(i, r)| {
                format!(
                    "largest at inspection '{}' ({:+.3} mm)",
                    problem.touches[i].id,
                    r * 1e3
                )
            })
            .unwrap_or_default();
        return Diagnosis {
            verdict: Verdict::NotAttributable,
            effect: None,
            after: before.clone(),
            before,
            alternatives,
            chi_square,
            explanation: format!(
                "the residual exceeds the noise (chi-square {statistic:.1} > {threshold:.1}) but no candidate effect explains it; {worst}"
            ),
        };
    };
    for candidate in accepted.iter().skip(1) {
        alternatives.push(Alternative {
            name: candidate.name(),
            fit: Some(candidate.fit.clone()),
            reason: format!(
                "BIC {:.1} against {:.1} for {}",
                candidate.fit.bic,
                best.fit.bic,
                best.name()
            ),
        });
    }
    let rivals: Vec<&Candidate> = accepted
        .iter()
        .skip(1)
        .filter(|candidate| candidate.fit.bic - best.fit.bic < AMBIGUITY_BIC)
        .collect();
    let n = problem.touches.len() as f64;
    let after_statistic = best.fit.residuals_m.iter().map(|r| r * r).sum::<f64>() / (sigma * sigma);
    let after_threshold = chi_square_99(n - 6.0 - best.fit.params.len() as f64);
    // A pair strongly (by 6) but not very strongly (by 10) better than the best candidate: the
    // simpler model is not established either.
    let (verdict, explanation, applied) = if pair_rival.1 < best.fit.bic - AMBIGUITY_BIC {
        (
            Verdict::Ambiguous,
            format!(
                "{} explains the residual, but {} fits clearly better (BIC {:.1} against {:.1}) without being decisive: the residual may come from outside the library; see the alternatives",
                best.name(),
                pair_rival.0,
                pair_rival.1,
                best.fit.bic
            ),
            false,
        )
    } else if absorbed_best_bic < best.fit.bic + AMBIGUITY_BIC {
        // Name every candidate tied with the best too: the absorbed one is not the only rival.
        let explains = if rivals.is_empty() {
            format!("{} explains the residual", best.name())
        } else {
            let tied: Vec<String> = std::iter::once(&best)
                .chain(rivals.iter().copied())
                .map(Candidate::name)
                .collect();
            format!(
                "{} explain the residual about equally well (BIC within {AMBIGUITY_BIC})",
                tied.join(", ")
            )
        };
        (
            Verdict::Ambiguous,
            format!(
                "{explains}, but an effect the part pose absorbs fits as well (BIC {absorbed_best_bic:.1} against {:.1}; see the alternatives): touches in more varied configurations would separate them",
                best.fit.bic
            ),
            false,
        )
    } else if !rivals.is_empty() {
        let tied: Vec<&Candidate> = std::iter::once(&best).chain(rivals).collect();
        let mut hints: Vec<&str> = tied
            .iter()
            .flat_map(|c| c.effects.iter().map(|e| e.separating_touches()))
            .collect();
        hints.dedup();
        (
            Verdict::Ambiguous,
            format!(
                "{} explain the residual about equally well (BIC within {AMBIGUITY_BIC}); touches that would separate them: {}",
                tied.iter().map(|c| c.name()).collect::<Vec<_>>().join(", "),
                hints.join("; ")
            ),
            // Which one to apply is unknown: keep the pose-only result.
            false,
        )
    } else if after_statistic > after_threshold {
        (
            Verdict::NotAttributable,
            format!(
                "{} is the best candidate but leaves more than the noise (chi-square {after_statistic:.1} > {after_threshold:.1}): something outside the library remains",
                best.name()
            ),
            false,
        )
    } else {
        let partial = if best.unseen.is_empty() {
            String::new()
        } else {
            format!(
                "; these touches cannot see {} beside the part pose: whatever they hide stays in the pose after",
                best.unseen.join(", ")
            )
        };
        (
            Verdict::Effect,
            format!(
                "{} explains the residual down to the noise{partial}",
                best.name()
            ),
            true,
        )
    };
    let after = if applied {
        let mut after = best.fit.clone();
        after.loo_rms_m = problem.leave_one_out(&best.params, &best.theta);
        after
    } else {
        before.clone()
    };
    let effect_fit = if applied {
        after.clone()
    } else {
        best.fit.clone()
    };
    Diagnosis {
        verdict,
        effect: (verdict != Verdict::NotAttributable).then(|| (best.name(), effect_fit)),
        after,
        before,
        alternatives,
        chi_square,
        explanation,
    }
}
