//! `ips diagnose`: align, then trace what is left to an effect the model lacks (DESIGN.md 6.4
//! keys), for a SESSION file (with an SVG of the residuals per touch written next to it) or the
//! running service's inspections (`--service`). Both run
//! `align_service::jobs::diagnose::diagnose_session`.

use std::path::{Path, PathBuf};

use align_core::diagnosis::{Diagnosis, TouchSample, Verdict};
use align_core::io::export::ExportFormat;
use align_core::pose::isometry_from_xyz_rpy;
use align_service::jobs::apply::apply_effect;
use align_service::jobs::diagnose::diagnose_session;
use align_service::jobs::units::person_unit;
use align_service::session::LoadedSession;
use protocol::reports::{AppliedReport, DiagnoseReport};
use protocol::{Pose, ServiceCommand};

use crate::{BadInput, CliError, client, json_line};

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
    #[arg(long, conflicts_with = "export")]
    pub json: bool,
    #[arg(long, value_name = "FORMAT", value_parser = crate::export::parse_format, help = crate::export::HELP)]
    pub export: Option<ExportFormat>,
    /// Write the session with the diagnosed effect applied to its model (ball radius, TCP,
    /// part scale, joint offsets, joint compliance or capture latency) to OUT and print what
    /// changed; refused unless the verdict is "effect". Aligning OUT gives the pose after
    /// modelling.
    #[arg(long, value_name = "OUT", conflicts_with_all = ["service", "export"])]
    pub apply: Option<PathBuf>,
}

/// The command: the SESSION file diagnosed here, or the service `--service` names asked.
pub fn run(args: &DiagnoseArgs) -> Result<String, CliError> {
    if let (Some(out), Some(session)) = (&args.apply, &args.session) {
        let applied = apply(session, out)?;
        return if args.json {
            json_line(&applied)
        } else {
            Ok(applied_text(&applied))
        };
    }
    let report = match (&args.service, &args.session) {
        (Some(endpoint), _) => client::request(endpoint, ServiceCommand::Diagnose)?,
        (None, Some(session)) => run_file(session)?,
        (None, None) => {
            return Err(
                BadInput("diagnose needs a SESSION file or --service ENDPOINT".to_owned()).into(),
            );
        }
    };
    if let Some(format) = args.export {
        let mesh = args
            .session
            .as_deref()
            .and_then(crate::export::session_mesh);
        crate::export::diagnosis(format, &report, mesh)
    } else if args.json {
        json_line(&report)
    } else {
        Ok(to_text(&report))
    }
}

/// The offline command on a session file: diagnoses it and draws the residuals next to it.
pub fn run_file(path: &Path) -> Result<DiagnoseReport, CliError> {
    let session = LoadedSession::load(path)?;
    let diagnosed = diagnose_session(&session)?;
    let plot = path.with_extension("diagnosis.svg");
    let picture = svg(
        &diagnosed.diagnosis,
        &diagnosed.samples,
        diagnosed.noise_sigma_m,
    );
    let write = |target: &Path, text: &str| {
        std::fs::write(target, text).map_err(|error| {
            CliError::Failure(format!("cannot write '{}': {error}", target.display()))
        })
    };
    write(&plot, &picture)?;
    let mut report = diagnosed.report(Some(plot.display().to_string()));
    let page_path = path.with_extension("diagnosis.html");
    let name = path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    write(
        &page_path,
        &crate::report_html::diagnosis_page(&name, &report, &picture),
    )?;
    report.page = Some(page_path.display().to_string());
    Ok(report)
}

/// `--apply OUT`: diagnoses SESSION, writes it to OUT with the effect in its model.
fn apply(session_path: &Path, out: &Path) -> Result<AppliedReport, CliError> {
    let session = LoadedSession::load(session_path)?;
    let report = diagnose_session(&session)?.report(None);
    let effect = match (&report.effect, report.verdict.as_str()) {
        (Some(effect), "effect") => effect,
        (_, verdict) => {
            return Err(BadInput(format!(
                "nothing applied: the verdict is {verdict} ({})",
                report.explanation
            ))
            .into());
        }
    };
    let dof = session.chain.as_ref().map_or(0, |chain| chain.dof());
    let (mut file, changes) = apply_effect(&session.file, effect, dof)?;
    rebase_paths(&mut file, session_path, out);
    let text = serde_json::to_string_pretty(&file)
        .map_err(|error| CliError::Failure(format!("cannot encode the session: {error}")))?;
    std::fs::write(out, text + "\n")
        .map_err(|error| CliError::Failure(format!("cannot write '{}': {error}", out.display())))?;
    Ok(AppliedReport {
        path: out.display().to_string(),
        effect: effect.name.clone(),
        changes,
        rms_before: report.before.rms,
        rms_after: report.after.rms,
    })
}

/// The session's paths (relative to the file they were in) made absolute when the new file
/// lands in another folder, so that it finds the same robot and part.
fn rebase_paths(file: &mut protocol::session::SessionFile, from: &Path, to: &Path) {
    let folder = |path: &Path| {
        let parent = path.parent().filter(|p| !p.as_os_str().is_empty());
        std::path::absolute(parent.unwrap_or(Path::new("."))).ok()
    };
    let (Some(source), target) = (folder(from), folder(to)) else {
        return;
    };
    if target.as_ref() == Some(&source) {
        return;
    }
    let absolute = |relative: &mut String| {
        if Path::new(relative.as_str()).is_relative() {
            *relative = source.join(relative.as_str()).display().to_string();
        }
    };
    absolute(&mut file.part.mesh);
    if let Some(robot) = &mut file.robot {
        absolute(&mut robot.urdf);
        robot.package_dirs.values_mut().for_each(absolute);
    }
}

fn applied_text(applied: &AppliedReport) -> String {
    let mut text = format!(
        "applied {} to the model and wrote {} (residual rms {:.4} mm before, {:.4} mm after):\n",
        applied.effect,
        applied.path,
        applied.rms_before * 1e3,
        applied.rms_after * 1e3
    );
    for change in &applied.changes {
        text += &format!("  {}\n", change.text);
    }
    text
}

/// Height of the scatter panel under the bars, px.
const SCATTER_HEIGHT: f64 = 320.0;

/// Residual per touch, before (grey) and after (blue), with the +-2 sigma band; below, each
/// touch's residual against what the chosen effect explains of it (on the diagonal when the
/// effect accounts for the residual).
fn svg(diagnosis: &Diagnosis, samples: &[TouchSample], sigma: f64) -> String {
    let applied = applied_effect(diagnosis);
    let titles = [
        "Residual per touch (mm): before (grey), after (blue); green band = +-2 sigma".to_owned(),
        match (applied, &diagnosis.effect) {
            (Some(name), _) => format!(
                "Verdict: {}; after = modelling {name}",
                diagnosis.verdict.name()
            ),
            (None, Some((name, _))) => format!(
                "Verdict: {}; nothing applied (best candidate {name}): after = before",
                diagnosis.verdict.name()
            ),
            (None, None) => format!(
                "Verdict: {}; nothing applied: after = before",
                diagnosis.verdict.name()
            ),
        },
    ];
    // Wide enough for the longest title (about 7 px per character at 12 px sans-serif).
    let longest_title = titles.iter().map(|t| t.chars().count()).max().unwrap_or(0);
    let (width, height, margin) = (
        (80.0 + 40.0 * samples.len() as f64)
            .max(2.0 * SCATTER_HEIGHT)
            .max(20.0 + 7.0 * longest_title as f64),
        340.0,
        50.0,
    );
    let largest = diagnosis
        .before
        .residuals_m
        .iter()
        .chain(&diagnosis.after.residuals_m)
        .fold(3.0 * sigma, |m, r| m.max(r.abs()));
    let y = |value: f64| height / 2.0 - value / largest * (height / 2.0 - margin);
    let mut out = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width:.0}\" height=\"{}\" font-family=\"sans-serif\" font-size=\"12\">\n\
         <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n\
         <text x=\"10\" y=\"18\">{}</text>\n\
         <text x=\"10\" y=\"34\">{}</text>\n\
         <rect x=\"{margin}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"#e8f0e8\"/>\n\
         <line x1=\"{margin}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"black\"/>\n",
        // The scatter panel only when an effect was applied; otherwise one line says why not.
        height
            + if applied.is_some() {
                SCATTER_HEIGHT
            } else {
                50.0
            },
        titles[0],
        titles[1],
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
            let (mut top, mut bottom) = if value >= 0.0 {
                (y(value), y(0.0))
            } else {
                (y(0.0), y(value))
            };
            // A residual near zero still shows as a bar of MIN_BAR_PX about the axis: a bar
            // thinner than a pixel reads as a missing one.
            if bottom - top < MIN_BAR_PX {
                let middle = (top + bottom) / 2.0;
                (top, bottom) = (middle - MIN_BAR_PX / 2.0, middle + MIN_BAR_PX / 2.0);
            }
            out += &format!(
                "<rect x=\"{:.1}\" y=\"{top:.1}\" width=\"10\" height=\"{:.1}\" fill=\"{colour}\"><title>{} {:+.4} mm</title></rect>\n",
                x + offset - 5.0,
                bottom - top,
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
/// The effect the diagnosis applied: its best candidate only when the verdict is `effect` (an
/// ambiguous or unattributable verdict names a candidate but applies nothing).
fn applied_effect(diagnosis: &Diagnosis) -> Option<&str> {
    match (&diagnosis.effect, diagnosis.verdict) {
        (Some((name, _)), Verdict::Effect) => Some(name.as_str()),
        _ => None,
    }
}

/// Smallest drawn bar, px.
const MIN_BAR_PX: f64 = 2.0;

fn scatter(diagnosis: &Diagnosis, samples: &[TouchSample], largest: f64, top: f64) -> String {
    let Some(name) = applied_effect(diagnosis) else {
        return format!(
            "<text x=\"10\" y=\"{:.1}\">No effect applied (verdict {}): nothing to plot against.</text>\n",
            top + 30.0,
            diagnosis.verdict.name()
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

pub fn to_text(report: &DiagnoseReport) -> String {
    let mut text = format!("verdict: {}\n{}\n", report.verdict, report.explanation);
    if let Some(effect) = &report.effect {
        text += &format!("effect: {}\n", effect.name);
        for (key, value) in &effect.params {
            let stderr = effect.stderr.get(key).copied().unwrap_or(f64::NAN);
            let (factor, unit, decimals) = person_unit(key);
            text += &format!(
                "  {key} = {:+.decimals$} {unit} +- {:.decimals$} {unit}\n",
                value * factor,
                stderr * factor
            );
        }
    }
    let (before, after) = (&report.before, &report.after);
    text += &format!(
        "residual rms / max / leave-one-out (mm): before {:.4} / {:.4} / {:.4}, after {:.4} / {:.4} / {:.4}\n",
        before.rms * 1e3,
        before.max * 1e3,
        before.loo_rms * 1e3,
        after.rms * 1e3,
        after.max * 1e3,
        after.loo_rms * 1e3
    );
    text += &format!(
        "chi-square of the pose-only fit: {:.1} (99% threshold {:.1})\n",
        report.chi_square[0], report.chi_square[1]
    );
    let pose = |pose: &Pose| isometry_from_xyz_rpy(pose.xyz, pose.rpy);
    let (before, after) = (pose(&report.pose_before), pose(&report.pose_after));
    text += &format!(
        "modelling it moved the part by {:.4} mm and {:.4} mrad\n",
        (after.translation.vector - before.translation.vector).norm() * 1e3,
        after.rotation.angle_to(&before.rotation) * 1e3
    );
    text += "touch  residual before (mm)  after (mm)\n";
    for touch in &report.inspections {
        text += &format!(
            "{:>5}  {:>+20.4}  {:>+10.4}\n",
            touch.id,
            touch.residual_before * 1e3,
            touch.residual_after * 1e3
        );
    }
    for alternative in &report.alternatives {
        text += &format!(
            "  not chosen: {}: {}\n",
            alternative.name, alternative.reason
        );
    }
    if let Some(plot) = &report.plot {
        text += &format!("plot: {plot}\n");
    }
    if let Some(page) = &report.page {
        text += &format!("report: {page}\n");
    }
    text
}
