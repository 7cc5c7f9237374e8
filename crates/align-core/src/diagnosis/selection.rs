//! Which parameters of a candidate model the touches identify, and the candidate's fit.
//!
//! Nothing is removed by a design-time rule. A candidate starts with every parameter its effects
//! have on this robot; the data then decide:
//! 1. Identifiability, from the Jacobian at the pose-only fit: the effect columns, each scaled to
//!    a typical size (a tenth of its plausibility bound), less what the pose reproduces. Their
//!    singular values count the directions of parameter space the touches see (a combination of
//!    typical size moving the touches by at least 3 sigma in all); a QR with column pivoting of
//!    those directions picks one parameter for each (subset selection after Golub, Klema and
//!    Stewart). Parameters that only show together, such as encoder offsets on a UR's parallel
//!    joints whose difference moves the tool, are kept as long as their combination is visible.
//! 2. Backward elimination by BIC: the identifiable set is fitted, then while dropping one
//!    parameter lowers (or keeps) the BIC, the one whose removal helps most is dropped.
//! 3. Forward steps: a parameter step 1 left out is admitted again when adding it lowers the BIC
//!    by 6 or more (a real effect can be several times the typical size).

use nalgebra::{DMatrix, DVector};

use super::effects::Effect;
use super::model::{Param, Problem};
use super::{Alternative, Fit};

/// A parameter's typical size as a fraction of its plausibility bound.
const TYPICAL_FRACTION_OF_BOUND: f64 = 0.1;
/// What a parameter's unexplained signature at its typical size must reach, in sigmas.
const SEEN_SIGMAS: f64 = 3.0;
/// BIC margin below which two candidates explain the residual equally well (a likelihood ratio
/// of 20), and by which a candidate must beat the simpler one nested in it.
pub(super) const AMBIGUITY_BIC: f64 = 6.0;

/// A fitted candidate model.
#[derive(Debug, Clone)]
pub(super) struct Candidate {
    pub effects: Vec<Effect>,
    pub params: Vec<Param>,
    /// Parameters of the effects the touches could not identify beside the part pose.
    pub unseen: Vec<String>,
    pub theta: DVector<f64>,
    pub fit: Fit,
}

impl Candidate {
    pub fn name(&self) -> String {
        candidate_name(&self.effects)
    }
}

pub(super) fn candidate_name(effects: &[Effect]) -> String {
    effects
        .iter()
        .map(|e| e.name())
        .collect::<Vec<_>>()
        .join("+")
}

/// A candidate's fate.
pub(super) enum Assessment {
    Accepted(Candidate),
    /// Fits better than the pose alone, but mostly as a disguised pose change: it cannot be
    /// applied, yet it competes with the accepted candidates for the attribution.
    Absorbed(Candidate, String),
    Rejected(Alternative),
}

/// Every parameter of `effect` that could act on these touches.
fn all_params(problem: &Problem, effect: Effect) -> Vec<Param> {
    effect
        .active_parameters(problem)
        .into_iter()
        .map(|index| Param { effect, index })
        .collect()
}

/// The parameters of `params` the touches identify (see the module docs), in their order, and
/// the most visible one left out with the size its unexplained signature would have.
pub(super) fn identifiable(
    problem: &Problem,
    params: &[Param],
    pose_theta: &DVector<f64>,
    sigma: f64,
) -> (Vec<Param>, Option<(Param, f64)>) {
    let mut theta = DVector::zeros(6 + params.len());
    theta.rows_mut(0, 6).copy_from(&pose_theta.rows(0, 6));
    let jacobian = problem.jacobian(params, &theta, None);
    let mut basis: Vec<DVector<f64>> = Vec::new();
    let project_out = |v: &mut DVector<f64>, basis: &[DVector<f64>]| {
        for u in basis {
            let along = u.dot(v);
            v.axpy(-along, u, 1.0);
        }
    };
    for column in 0..6 {
        let mut v = jacobian.column(column).into_owned();
        project_out(&mut v, &basis);
        let norm = v.norm();
        if norm > 1e-12 * jacobian.column(column).norm().max(1e-300) {
            basis.push(v / norm);
        }
    }
    // The effect columns at their typical sizes, less what the pose reproduces.
    let unexplained = DMatrix::from_fn(jacobian.nrows(), params.len(), |_, _| 0.0);
    let mut unexplained = unexplained;
    for (k, param) in params.iter().enumerate() {
        let mut v = jacobian.column(6 + k) * (TYPICAL_FRACTION_OF_BOUND * param.effect.bound());
        project_out(&mut v, &basis);
        unexplained.set_column(k, &v);
    }
    // Directions of parameter space the touches see: singular values of at least 3 sigma (a
    // combination of typical size that moves the touches visibly beyond the pose).
    let svd = unexplained.clone().svd(false, true);
    let Some(v_t) = svd.v_t else {
        return (Vec::new(), None);
    };
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|a, b| svd.singular_values[*b].total_cmp(&svd.singular_values[*a]));
    let rank = order
        .iter()
        .take_while(|&&i| svd.singular_values[i] >= SEEN_SIGMAS * sigma)
        .count();
    if rank == 0 {
        // The most visible parameter, for the reason.
        let largest = (0..params.len())
            .max_by(|a, b| {
                unexplained
                    .column(*a)
                    .norm()
                    .total_cmp(&unexplained.column(*b).norm())
            })
            .map(|k| (params[k], svd.singular_values.max()));
        return (Vec::new(), largest);
    }
    // One parameter per seen direction: a QR with column pivoting of the seen directions'
    // components (Golub, Klema and Stewart's subset selection).
    let mut components: Vec<DVector<f64>> = (0..params.len())
        .map(|k| DVector::from_iterator(rank, order[..rank].iter().map(|&i| v_t[(i, k)])))
        .collect();
    let mut kept = Vec::with_capacity(rank);
    for _ in 0..rank {
        let Some(k) = (0..params.len())
            .filter(|k| !kept.contains(k))
            .max_by(|a, b| components[*a].norm().total_cmp(&components[*b].norm()))
        else {
            break;
        };
        let norm = components[k].norm();
        if norm < 1e-9 {
            break;
        }
        let u = components[k].clone() / norm;
        for other in &mut components {
            let along = u.dot(other);
            other.axpy(-along, &u, 1.0);
        }
        kept.push(k);
    }
    let unseen = (0..params.len())
        .filter(|k| !kept.contains(k))
        .max_by(|a, b| {
            unexplained
                .column(*a)
                .norm()
                .total_cmp(&unexplained.column(*b).norm())
        })
        .map(|k| (params[k], unexplained.column(k).norm()));
    kept.sort_unstable();
    (kept.into_iter().map(|k| params[k]).collect(), unseen)
}

/// Fits `params`, then drops parameters while that lowers or keeps the BIC.
fn eliminate(
    problem: &Problem,
    params: Vec<Param>,
    sigma: f64,
) -> Result<(Vec<Param>, DVector<f64>, Fit), String> {
    let theta = problem.fit(&params, None);
    let fit = problem.summarise(&params, &theta, sigma)?;
    let mut current = (params, theta, fit);
    while current.0.len() > 1 {
        let best = (0..current.0.len())
            .filter_map(|k| {
                let mut fewer = current.0.clone();
                fewer.remove(k);
                let theta = problem.fit(&fewer, None);
                let fit = problem.summarise(&fewer, &theta, sigma).ok()?;
                Some((fewer, theta, fit))
            })
            .min_by(|a, b| a.2.bic.total_cmp(&b.2.bic));
        match best {
            Some(fewer) if fewer.2.bic <= current.2.bic => current = fewer,
            _ => break,
        }
    }
    Ok(current)
}

/// BIC decrease by which a parameter the identifiability rule left out must improve a fit to be
/// admitted again: strong evidence (a likelihood ratio of 20 beyond BIC's own penalty), since the
/// rule judged it invisible at a typical size.
const READMIT_BIC: f64 = 6.0;

/// Forward steps after the backward elimination: a parameter the identifiability rule left out
/// (its signature at a typical size stays under 3 sigma) is admitted when the data clearly need
/// it, the one that lowers the BIC most first, until none lowers it by [`READMIT_BIC`]. The rule
/// judges at a typical size; a real effect can be several times that (a part 0.4% larger than
/// its CAD model, hidden beside a TCP error), and no design-time rule may remove what the data
/// need. `current` is the fit so far (`None`: the pose alone, of BIC `pose_only_bic`).
fn readmit(
    problem: &Problem,
    mut current: Option<(Vec<Param>, DVector<f64>, Fit)>,
    mut left_out: Vec<Param>,
    sigma: f64,
    pose_only_bic: f64,
) -> Option<(Vec<Param>, DVector<f64>, Fit)> {
    loop {
        let current_bic = current.as_ref().map_or(pose_only_bic, |c| c.2.bic);
        let base: Vec<Param> = current.as_ref().map_or_else(Vec::new, |c| c.0.clone());
        let best = left_out
            .iter()
            .enumerate()
            .filter_map(|(i, &param)| {
                let mut more = base.clone();
                more.push(param);
                more.sort_unstable();
                let theta = problem.fit(&more, None);
                let fit = problem.summarise(&more, &theta, sigma).ok()?;
                Some((i, more, theta, fit))
            })
            .min_by(|a, b| a.3.bic.total_cmp(&b.3.bic));
        match best {
            Some((i, more, theta, fit)) if fit.bic < current_bic - READMIT_BIC => {
                left_out.remove(i);
                current = Some((more, theta, fit));
            }
            _ => return current,
        }
    }
}

/// Fits the candidate made of `effects` (one, or a pair) and accepts it or says why not.
pub(super) fn assess(
    problem: &Problem,
    effects: &[Effect],
    pose_theta: &DVector<f64>,
    sigma: f64,
    pose_only_bic: f64,
) -> Assessment {
    let name = candidate_name(effects);
    let reject = |fit: Option<Fit>, reason: String| {
        Assessment::Rejected(Alternative {
            name: name.clone(),
            fit,
            reason,
        })
    };
    if let Some(reason) = unavailable(problem, effects) {
        return reject(None, reason);
    }
    let params: Vec<Param> = effects
        .iter()
        .flat_map(|&effect| all_params(problem, effect))
        .collect();
    let (kept, unseen) = identifiable(problem, &params, pose_theta, sigma);
    let left_out: Vec<Param> = params
        .iter()
        .copied()
        .filter(|p| !kept.contains(p))
        .collect();
    let eliminated = if kept.is_empty() {
        None
    } else {
        match eliminate(problem, kept.clone(), sigma) {
            Ok(found) => Some(found),
            Err(reason) => return reject(None, reason),
        }
    };
    let Some((params, theta, fit)) =
        readmit(problem, eliminated, left_out.clone(), sigma, pose_only_bic)
    else {
        let reason = unseen.map_or_else(
            || "the effect has no parameter on this robot".to_owned(),
            |(param, size)| unseen_reason(problem, param, size, sigma, effects.len() > 1),
        );
        return reject(None, reason);
    };
    let unseen_names = problem.names(
        &left_out
            .iter()
            .copied()
            .filter(|p| !params.contains(p))
            .collect::<Vec<_>>(),
    );
    if let Some(missing) = effects
        .iter()
        .find(|e| !params.iter().any(|p| p.effect == **e))
    {
        let reason = if kept.iter().any(|p| p.effect == *missing) {
            format!(
                "reduces to one effect: the parameters of {} do not lower the BIC",
                missing.name()
            )
        } else {
            format!(
                "reduces to one effect: no parameter of {} is identifiable beside the other's, nor lowers the BIC by {READMIT_BIC} when fitted with it",
                missing.name()
            )
        };
        return reject(Some(fit), reason);
    }
    if let Some(reason) = implausible(&params, &fit) {
        return reject(Some(fit), reason);
    }
    if fit.bic >= pose_only_bic {
        let reason = format!(
            "BIC {:.1} is no better than the pose-only fit's {pose_only_bic:.1}",
            fit.bic
        );
        return reject(Some(fit), reason);
    }
    let absorbed = absorbed_by_pose(problem, &params, &theta);
    let candidate = Candidate {
        effects: effects.to_vec(),
        params,
        unseen: unseen_names,
        theta,
        fit,
    };
    match absorbed {
        Some(reason) => Assessment::Absorbed(candidate, reason),
        None => Assessment::Accepted(candidate),
    }
}

/// Why the touches cannot show one of `effects` at all, if so.
fn unavailable(problem: &Problem, effects: &[Effect]) -> Option<String> {
    let flange_only: Vec<&str> = problem
        .touches
        .iter()
        .filter(|t| t.base_from_flange.is_some())
        .map(|t| t.id.as_str())
        .collect();
    if let Some(effect) = effects.iter().find(|e| e.needs_joints())
        && !flange_only.is_empty()
    {
        return Some(format!(
            "{} needs joint values: {} of the {} inspections give only a flange pose (first '{}')",
            effect.name(),
            flange_only.len(),
            problem.touches.len(),
            flange_only[0]
        ));
    }
    // (Only effects that fitted alone are paired, so at most one of a pair is unavailable.)
    effects
        .iter()
        .find_map(|effect| effect.unavailable(problem))
}

fn unseen_reason(problem: &Problem, param: Param, size: f64, sigma: f64, pair: bool) -> String {
    let name = &problem.names(&[param])[0];
    let typical = TYPICAL_FRACTION_OF_BOUND * param.effect.bound();
    let others = if pair {
        "the part pose and the other effect"
    } else {
        "the part pose and the effect's other parameters"
    };
    format!(
        "not identifiable from these touches: {name} at {typical:.1e} would move them by {size:.1e} m in all beyond what {others} reproduce, under {SEEN_SIGMAS} sigma ({:.1e} m); {} would separate them",
        SEEN_SIGMAS * sigma,
        param.effect.separating_touches()
    )
}

/// Variance inflation above which a fitted parameter counts as absorbed by the part pose: the
/// pose reproduces more than 99% of its signature, so its estimate is mostly a pose error in
/// disguise and applying it would move the part by an amount the touches cannot check.
const POSE_ABSORPTION_LIMIT: f64 = 100.0;

/// Why a fitted candidate must not be applied because a parameter of it is mostly a part pose
/// change, if so. Judged against the pose alone: parameters that trade off with each other (a
/// UR's parallel joints) are fine as long as their combination stands apart from the pose.
fn absorbed_by_pose(problem: &Problem, params: &[Param], theta: &DVector<f64>) -> Option<String> {
    let jacobian = problem.jacobian(params, theta, None);
    let names = problem.names(params);
    params.iter().enumerate().find_map(|(k, _)| {
        let columns: Vec<usize> = (0..6).chain(std::iter::once(6 + k)).collect();
        let information = DMatrix::from_fn(7, 7, |a, b| {
            jacobian.column(columns[a]).dot(&jacobian.column(columns[b]))
        });
        let inflation = super::model::scaled_inverse(&information)
            .map_or(f64::INFINITY, |covariance| covariance[(6, 6)] * information[(6, 6)]);
        (inflation > POSE_ABSORPTION_LIMIT).then(|| {
            format!(
                "{} trades off with the part pose, which reproduces {:.2}% of its signature (variance inflation {inflation:.0}): applying it would move the part by what the touches cannot check; {} would separate them",
                names[k],
                100.0 * (1.0 - inflation.recip()),
                params[k].effect.separating_touches()
            )
        })
    })
}

/// A fitted value no real cell has: beyond its plausibility bound, or a joint that leans
/// against gravity.
fn implausible(params: &[Param], fit: &Fit) -> Option<String> {
    for (param, (name, value, se)) in params.iter().zip(&fit.params) {
        let bound = param.effect.bound();
        if value.abs() > bound {
            return Some(format!(
                "{name} = {value:.3e} leaves the plausibility bound {bound:.3e}"
            ));
        }
        if let Some(reason) = param.effect.implausible(name, *value, *se) {
            return Some(reason);
        }
    }
    None
}

/// Whether the touches could show every parameter of `effect` at a typical size, and if not,
/// which they could not and why.
pub(super) fn unseen(
    problem: &Problem,
    effect: Effect,
    pose_theta: &DVector<f64>,
    sigma: f64,
) -> Option<String> {
    if let Some(reason) = unavailable(problem, &[effect]) {
        return Some(reason);
    }
    let params = all_params(problem, effect);
    let (kept, unseen) = identifiable(problem, &params, pose_theta, sigma);
    if kept.len() == params.len() {
        return None;
    }
    if kept.is_empty() {
        return unseen.map(|(param, size)| unseen_reason(problem, param, size, sigma, false));
    }
    let missing: Vec<String> = problem.names(
        &params
            .iter()
            .copied()
            .filter(|p| !kept.contains(p))
            .collect::<Vec<_>>(),
    );
    Some(format!(
        "only {} of its {} parameters are identifiable from these touches: {} trade off with the part pose and the others; {} would separate them",
        kept.len(),
        params.len(),
        missing.join(", "),
        effect.separating_touches()
    ))
}
