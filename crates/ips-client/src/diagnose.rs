//! `ips diagnose`: align, then trace what is left to an effect the model lacks (DESIGN.md 6.4
//! keys). [`diagnose_session`] works on a session in memory and is what both the offline command
//! (a SESSION file, with an SVG of the residuals per touch written next to it) and the alignment
//! service's `diagnose` request (its current inspections) run.

use std::path::{Path, PathBuf};

use align_core::diagnosis::{Diagnosis, Fit, TouchSample, diagnose};
use align_core::pose::xyz_rpy;
use align_core::registration::psa::{PsaOptions, PsaTarget, align_touches};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use crate::BadInput;
use crate::session::LoadedSession;

#[derive(Debug, clap::Args)]
#[command(
    after_help = "Examples:\n  ips diagnose examples/step_block_ur10/session_probe_radius.json\n  ips diagnose --service tcp://127.0.0.1:4000 --json    (the running service's inspections)"
)]
pub struct DiagnoseArgs {
    /// Session file; its `noise_sigma` is the declared touch noise (m). Leave it out and give
    /// --service to diagnose the running service's inspections instead.
    #[arg(
        value_name = "SESSION",
        required_unless_present = "service",
        conflicts_with = "service"
    )]
    pub session: Option<PathBuf>,
    /// Ask the running alignment service at this REP endpoint (e.g. tcp://127.0.0.1:4000) to
    /// diagnose its current inspections (what `ips save` would write). No plot is drawn.
    #[arg(long, value_name = "ENDPOINT")]
    pub service: Option<String>,
    /// Print one JSON document instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Serialize, Deserialize)]
pub struct DiagnoseOutput {
    pub verdict: String,
    pub effect: Value,
    pub alternatives: Vec<Value>,
    pub before: Value,
    pub after: Value,
    pub pose_before: Value,
    pub pose_after: Value,
    pub inspections: Vec<Value>,
    pub explanation: String,
    pub chi_square: [f64; 2],
    /// The picture of the residuals, written next to the session file (none from the service:
    /// its session is in memory).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plot: Option<String>,
}

/// A finished diagnosis with what drawing and reporting it need.
#[derive(Debug)]
pub struct SessionDiagnosis {
    pub diagnosis: Diagnosis,
    pub samples: Vec<TouchSample>,
    pub noise_sigma_m: f64,
}

fn summary(fit: &Fit) -> Value {
    json!({"rms": fit.rms_m, "max": fit.max_m, "loo_rms": fit.loo_rms_m})
}

fn pose(fit: &Fit) -> Value {
    let (xyz, rpy) = xyz_rpy(&fit.base_from_part);
    json!({"xyz": xyz, "rpy": rpy})
}

fn effect_json(name: &str, fit: &Fit) -> Value {
    let params: serde_json::Map<String, Value> = fit
        .params
        .iter()
        .map(|(k, v, _)| (k.clone(), json!(v)))
        .collect();
    let stderr: serde_json::Map<String, Value> = fit
        .params
        .iter()
        .map(|(k, _, s)| (k.clone(), json!(s)))
        .collect();
    json!({"name": name, "params": params, "stderr": stderr, "bic": fit.bic})
}

/// The command: the SESSION file diagnosed here, or the service `--service` names asked.
pub fn run(args: &DiagnoseArgs) -> Result<DiagnoseOutput, BadInput> {
    match (&args.service, &args.session) {
        (Some(endpoint), _) => {
            let request = protocol::service_request("diagnose");
            let data = crate::client::request_data(endpoint, &request)?;
            serde_json::from_value(data).map_err(|error| {
                BadInput(format!(
                    "the service's diagnose reply is not the document: {error}"
                ))
            })
        }
        (None, Some(session)) => run_file(session),
        (None, None) => Err(BadInput(
            "diagnose needs a SESSION file or --service ENDPOINT".to_owned(),
        )),
    }
}

/// The offline command on a session file: diagnoses it and draws the residuals next to it.
pub fn run_file(path: &Path) -> Result<DiagnoseOutput, BadInput> {
    let session = LoadedSession::load(path)?;
    let diagnosed = diagnose_session(&session)?;
    let plot = path.with_extension("diagnosis.svg");
    std::fs::write(&plot, diagnosed.svg())
        .map_err(|error| BadInput(format!("cannot write '{}': {error}", plot.display())))?;
    Ok(diagnosed.output(Some(plot.display().to_string())))
}

/// Aligns the session's part to its inspections, then diagnoses the residual against the
/// session's declared `noise_sigma`.
pub fn diagnose_session(session: &LoadedSession) -> Result<SessionDiagnosis, BadInput> {
    let sigma = session.file.noise_sigma.ok_or_else(|| {
        BadInput(
            "the session declares no noise_sigma (m), which diagnosis tests against".to_owned(),
        )
    })?;
    let target = PsaTarget::new(&session.mesh)
        .with_faces(&session.faces)
        .map_err(BadInput::new)?;
    let options = PsaOptions {
        tip_radius_m: session.tool.tip_radius_m,
        ..PsaOptions::default()
    };
    let aligned = align_touches(
        &target,
        &session.touches,
        &session.base_from_part_nominal,
        &options,
    )
    .map_err(|error| BadInput(format!("cannot align: {error}")))?;
    let samples = session
        .file
        .inspections
        .iter()
        .map(|i| match &i.q {
            Some(q) => Ok(TouchSample::from_joints(
                i.id.clone(),
                q.clone(),
                i.qd.clone(),
            )),
            None => i
                .base_from_flange(None)
                .map(|pose| TouchSample::from_flange_pose(i.id.clone(), pose)),
        })
        .collect::<Result<Vec<TouchSample>, BadInput>>()?;
    let diagnosis = diagnose(
        session.chain.as_ref(),
        &session.tool,
        &session.mesh,
        &samples,
        &aligned.base_from_part,
        sigma,
    )
    .map_err(BadInput)?;
    Ok(SessionDiagnosis {
        diagnosis,
        samples,
        noise_sigma_m: sigma,
    })
}

impl SessionDiagnosis {
    /// The DESIGN.md 6.4 document; `plot` names the SVG when one was written.
    pub fn output(&self, plot: Option<String>) -> DiagnoseOutput {
        let diagnosis = &self.diagnosis;
        DiagnoseOutput {
            verdict: diagnosis.verdict.name().to_owned(),
            effect: diagnosis.effect.as_ref().map_or(Value::Null, |(name, fit)| effect_json(name, fit)),
            alternatives: diagnosis
                .alternatives
                .iter()
                .map(|a| json!({"name": a.name, "reason": a.reason, "bic": a.fit.as_ref().map(|f| f.bic), "loo_rms": a.fit.as_ref().map(|f| f.loo_rms_m)}))
                .collect(),
            before: summary(&diagnosis.before),
            after: summary(&diagnosis.after),
            pose_before: pose(&diagnosis.before),
            pose_after: pose(&diagnosis.after),
            inspections: self
                .samples
                .iter()
                .enumerate()
                .map(|(i, s)| json!({"id": s.id, "residual_before": diagnosis.before.residuals_m[i], "residual_after": diagnosis.after.residuals_m[i]}))
                .collect(),
            explanation: diagnosis.explanation.clone(),
            chi_square: [diagnosis.chi_square.0, diagnosis.chi_square.1],
            plot,
        }
    }

    pub fn svg(&self) -> String {
        svg(&self.diagnosis, &self.samples, self.noise_sigma_m)
    }
}

/// Height of the scatter panel under the bars, px.
const SCATTER_HEIGHT: f64 = 320.0;

/// Residual per touch, before (grey) and after (blue), with the +-2 sigma band; below, each
/// touch's residual against what the chosen effect explains of it (on the diagonal when the
/// effect accounts for the residual).
fn svg(diagnosis: &Diagnosis, samples: &[TouchSample], sigma: f64) -> String {
    let (width, height, margin) = (
        (80.0 + 40.0 * samples.len() as f64).max(2.0 * SCATTER_HEIGHT),
        320.0,
        40.0,
    );
    let largest = diagnosis
        .before
        .residuals_m
        .iter()
        .chain(&diagnosis.after.residuals_m)
        .fold(3.0 * sigma, |m, r| m.max(r.abs()));
    let y = |value: f64| height / 2.0 - value / largest * (height / 2.0 - margin);
    let mut out = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width}\" height=\"{}\" font-family=\"sans-serif\" font-size=\"12\">\n\
         <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n\
         <text x=\"10\" y=\"18\">Residual per touch (mm): before (grey), after {} (blue); band = +-2 sigma. Verdict: {}</text>\n\
         <rect x=\"{margin}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"#e8f0e8\"/>\n\
         <line x1=\"{margin}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"black\"/>\n",
        height + SCATTER_HEIGHT,
        diagnosis
            .effect
            .as_ref()
            .map_or("(no effect applied)".to_owned(), |(n, _)| format!(
                "modelling {n}"
            )),
        diagnosis.verdict.name(),
        y(2.0 * sigma),
        width - 2.0 * margin,
        y(-2.0 * sigma) - y(2.0 * sigma),
        y(0.0),
        width - margin,
        y(0.0)
    );
    for (i, sample) in samples.iter().enumerate() {
        let x = margin + 20.0 + 40.0 * i as f64;
        for (offset, value, colour) in [
            (-6.0, diagnosis.before.residuals_m[i], "#999"),
            (6.0, diagnosis.after.residuals_m[i], "#2a6fdb"),
        ] {
            let (top, bottom) = if value >= 0.0 {
                (y(value), y(0.0))
            } else {
                (y(0.0), y(value))
            };
            out += &format!(
                "<rect x=\"{:.1}\" y=\"{top:.1}\" width=\"10\" height=\"{:.1}\" fill=\"{colour}\"><title>{} {:+.4} mm</title></rect>\n",
                x + offset - 5.0,
                (bottom - top).max(0.5),
                sample.id,
                value * 1e3
            );
        }
        out += &format!(
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>\n",
            x,
            height - 10.0,
            sample.id
        );
    }
    out += &format!(
        "<text x=\"5\" y=\"{:.1}\">{:+.3}</text>\n",
        y(largest) + 4.0,
        largest * 1e3
    );
    out += &format!(
        "<text x=\"5\" y=\"{:.1}\">{:+.3}</text>\n",
        y(-largest) + 4.0,
        -largest * 1e3
    );
    out += &scatter(diagnosis, samples, largest, height);
    out += "</svg>\n";
    out
}

/// The lower panel: residual before (y) against the part the effect explains (x), both mm.
fn scatter(diagnosis: &Diagnosis, samples: &[TouchSample], largest: f64, top: f64) -> String {
    let Some((name, _)) = diagnosis.effect.as_ref() else {
        return format!(
            "<text x=\"10\" y=\"{:.1}\">No effect applied: nothing to plot against.</text>\n",
            top + 30.0
        );
    };
    let (left, size) = (60.0, SCATTER_HEIGHT - 60.0);
    let to_px = |value: f64| size / 2.0 * (1.0 - value / largest);
    let mut out = format!(
        "<text x=\"10\" y=\"{:.1}\">Residual before (y) against what {name} explains of it (x), mm; on the diagonal = explained</text>\n\
         <rect x=\"{left}\" y=\"{:.1}\" width=\"{size}\" height=\"{size}\" fill=\"none\" stroke=\"#ccc\"/>\n\
         <line x1=\"{left}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"#2a6fdb\" stroke-dasharray=\"4 3\"/>\n",
        top + 20.0,
        top + 40.0,
        top + 40.0 + size,
        left + size,
        top + 40.0
    );
    for (i, sample) in samples.iter().enumerate() {
        let before = diagnosis.before.residuals_m[i];
        let explained = before - diagnosis.after.residuals_m[i];
        out += &format!(
            "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"4\" fill=\"#444\"><title>{} explained {:+.4} of {:+.4} mm</title></circle>\n",
            left + size - to_px(explained),
            top + 40.0 + to_px(before),
            sample.id,
            explained * 1e3,
            before * 1e3
        );
    }
    out += &format!(
        "<text x=\"{left}\" y=\"{:.1}\">{:+.3}</text><text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{:+.3}</text>\n",
        top + 55.0 + size,
        -largest * 1e3,
        left + size,
        top + 55.0 + size,
        largest * 1e3
    );
    out
}

impl DiagnoseOutput {
    pub fn to_text(&self) -> String {
        let mut text = format!("verdict: {}\n{}\n", self.verdict, self.explanation);
        if let Some(name) = self.effect["name"].as_str() {
            text += &format!("effect: {name}\n");
            if let Some(params) = self.effect["params"].as_object() {
                for (key, value) in params {
                    text += &format!(
                        "  {key} = {:.6e} +- {:.1e}\n",
                        value.as_f64().unwrap_or(f64::NAN),
                        self.effect["stderr"][key].as_f64().unwrap_or(f64::NAN)
                    );
                }
            }
        }
        let mm = |v: &Value, k: &str| v[k].as_f64().unwrap_or(f64::NAN) * 1e3;
        text += &format!(
            "residual rms / max / leave-one-out (mm): before {:.4} / {:.4} / {:.4}, after {:.4} / {:.4} / {:.4}\n",
            mm(&self.before, "rms"),
            mm(&self.before, "max"),
            mm(&self.before, "loo_rms"),
            mm(&self.after, "rms"),
            mm(&self.after, "max"),
            mm(&self.after, "loo_rms")
        );
        text += &format!(
            "chi-square of the pose-only fit: {:.1} (99% threshold {:.1})\n",
            self.chi_square[0], self.chi_square[1]
        );
        let pose = |v: &Value| {
            let at = |k: &str, i: usize| v[k][i].as_f64().unwrap_or(f64::NAN);
            align_core::pose::isometry_from_xyz_rpy(
                [at("xyz", 0), at("xyz", 1), at("xyz", 2)],
                [at("rpy", 0), at("rpy", 1), at("rpy", 2)],
            )
        };
        let (before, after) = (pose(&self.pose_before), pose(&self.pose_after));
        text += &format!(
            "modelling it moved the part by {:.4} mm and {:.4} mrad\n",
            (after.translation.vector - before.translation.vector).norm() * 1e3,
            after.rotation.angle_to(&before.rotation) * 1e3
        );
        text += "touch  residual before (mm)  after (mm)\n";
        for touch in &self.inspections {
            text += &format!(
                "{:>5}  {:>+20.4}  {:>+10.4}\n",
                touch["id"].as_str().unwrap_or("?"),
                touch["residual_before"].as_f64().unwrap_or(f64::NAN) * 1e3,
                touch["residual_after"].as_f64().unwrap_or(f64::NAN) * 1e3
            );
        }
        for alternative in &self.alternatives {
            text += &format!(
                "  not chosen: {}: {}\n",
                alternative["name"].as_str().unwrap_or("?"),
                alternative["reason"].as_str().unwrap_or("")
            );
        }
        if let Some(plot) = &self.plot {
            text += &format!("plot: {plot}\n");
        }
        text
    }
}
