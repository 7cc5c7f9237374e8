//! `ips diagnose`: align, then trace what is left to an effect the model lacks (DESIGN.md 6.4
//! keys), for a SESSION file (with an SVG of the residuals per touch written next to it) or the
//! running service's inspections (`--service`). Both run
//! `align_service::jobs::diagnose::diagnose_session`.

use std::path::{Path, PathBuf};

use align_core::io::export::ExportFormat;
use align_core::pose::isometry_from_xyz_rpy;
use align_service::jobs::apply::apply_effect;
use align_service::jobs::diagnose::diagnose_session;
use align_service::jobs::units::person_unit;
use align_service::report_pages;
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
    let mut report = diagnosed.report(Some(plot.display().to_string()));
    let write = |target: &Path, text: &str| {
        std::fs::write(target, text).map_err(|error| {
            CliError::Failure(format!("cannot write '{}': {error}", target.display()))
        })
    };
    write(&plot, &report_pages::diagnosis_svg(&report))?;
    let page_path = path.with_extension("diagnosis.html");
    let name = path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    write(&page_path, &report_pages::diagnosis_page(&name, &report))?;
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
