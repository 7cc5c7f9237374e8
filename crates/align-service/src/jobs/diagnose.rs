//! Align, then trace what is left to an effect the model lacks (DESIGN.md 6.4 keys).
//! [`diagnose_session`] works on a session in memory: the offline `ips diagnose SESSION` and the
//! service's `diagnose` request (its current inspections) both run it.

use align_core::diagnosis::{Diagnosis, Fit, TouchSample, diagnose};
use align_core::pose::xyz_rpy;
use protocol::Pose;
use protocol::reports::{Alternative, DiagnoseReport, EffectFit, FitSummary, InspectionResidual};

use crate::BadInput;
use crate::jobs::align::{AlignChoices, align_session};
use crate::session::{LoadedSession, base_from_flange};

/// A finished diagnosis with what drawing and reporting it need.
#[derive(Debug)]
pub struct SessionDiagnosis {
    pub diagnosis: Diagnosis,
    pub samples: Vec<TouchSample>,
    pub noise_sigma_m: f64,
    /// The session's robot base frame, which the poses are relative to.
    pub base_frame: String,
}

/// Aligns the session's part to its inspections, then diagnoses the residual against the
/// session's declared `noise_sigma`.
pub fn diagnose_session(session: &LoadedSession) -> Result<SessionDiagnosis, BadInput> {
    let sigma = session.file.noise_sigma.ok_or_else(|| {
        BadInput(
            "the session declares no noise_sigma (m), which diagnosis tests against".to_owned(),
        )
    })?;
    let aligned = align_session(session, AlignChoices::default())?;
    let samples = session
        .file
        .inspections
        .iter()
        .map(|i| match (&i.q, &session.chain) {
            // The joints as the session's model uses them (its declared corrections applied).
            (Some(q), Some(chain)) => Ok(TouchSample::from_joints(
                i.id.clone(),
                session.corrections.corrected(q, i.qd.as_deref(), chain),
                i.qd.clone(),
            )),
            (Some(q), None) => Ok(TouchSample::from_joints(
                i.id.clone(),
                q.clone(),
                i.qd.clone(),
            )),
            (None, _) => base_from_flange(i, None)
                .map(|pose| TouchSample::from_flange_pose(i.id.clone(), pose)),
        })
        .collect::<Result<Vec<TouchSample>, BadInput>>()?;
    let diagnosis = diagnose(
        session.chain.as_ref(),
        &session.tool,
        &session.mesh,
        &samples,
        &aligned.alignment.base_from_part,
        sigma,
    )
    .map_err(BadInput)?;
    Ok(SessionDiagnosis {
        diagnosis,
        samples,
        noise_sigma_m: sigma,
        base_frame: session.base_frame().to_owned(),
    })
}

impl SessionDiagnosis {
    /// The DESIGN.md 6.4 document; `plot` names the SVG when one was written.
    pub fn report(&self, plot: Option<String>) -> DiagnoseReport {
        let diagnosis = &self.diagnosis;
        DiagnoseReport {
            verdict: diagnosis.verdict.name().to_owned(),
            effect: diagnosis
                .effect
                .as_ref()
                .map(|(name, fit)| effect_fit(name, fit)),
            alternatives: diagnosis
                .alternatives
                .iter()
                .map(|a| Alternative {
                    bic: a.fit.as_ref().map(|f| f.bic),
                    loo_rms: a.fit.as_ref().map(|f| f.loo_rms_m),
                    name: a.name.clone(),
                    reason: a.reason.clone(),
                })
                .collect(),
            before: summary(&diagnosis.before),
            after: summary(&diagnosis.after),
            pose_before: pose(&diagnosis.before),
            pose_after: pose(&diagnosis.after),
            inspections: self
                .samples
                .iter()
                .enumerate()
                .map(|(i, s)| InspectionResidual {
                    id: s.id.clone(),
                    residual_after: diagnosis.after.residuals_m[i],
                    residual_before: diagnosis.before.residuals_m[i],
                    ball_centre_after: diagnosis
                        .after
                        .ball_centres_m
                        .get(i)
                        .map(|p| [p.x, p.y, p.z]),
                })
                .collect(),
            explanation: diagnosis.explanation.clone(),
            chi_square: [diagnosis.chi_square.0, diagnosis.chi_square.1],
            plot,
            page: None,
            base_frame: Some(self.base_frame.clone()),
            noise_sigma_m: Some(self.noise_sigma_m),
        }
    }
}

fn summary(fit: &Fit) -> FitSummary {
    FitSummary {
        loo_rms: fit.loo_rms_m,
        max: fit.max_m,
        rms: fit.rms_m,
    }
}

fn pose(fit: &Fit) -> Pose {
    let (xyz, rpy) = xyz_rpy(&fit.base_from_part);
    Pose::new(xyz, rpy)
}

fn effect_fit(name: &str, fit: &Fit) -> EffectFit {
    EffectFit {
        bic: fit.bic,
        name: name.to_owned(),
        params: fit.params.iter().map(|(k, v, _)| (k.clone(), *v)).collect(),
        stderr: fit.params.iter().map(|(k, _, s)| (k.clone(), *s)).collect(),
    }
}
