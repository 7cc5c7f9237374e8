//! `ips align`: Point Set Alignment of a session's part to its inspections, here (a SESSION
//! file) or by the running service (`--service`, its inspections).

use std::path::PathBuf;

use align_core::io::export::ExportFormat;
use align_service::jobs::align::{AlignChoices, align_session, report};
use align_service::session::LoadedSession;
use clap::Args;
use protocol::ServiceCommand;
use protocol::reports::{AlignReport, Uncertainty};

use crate::{BadInput, CliError, client, json_line};

#[derive(Debug, Args)]
pub struct AlignArgs {
    /// Session file (cobot-align/session@1; paths inside are relative to it).
    #[arg(value_name = "SESSION", required_unless_present = "service")]
    pub session: Option<PathBuf>,
    /// Ask the running service (`ips serve`) to align its inspections instead, with its
    /// defaults (global search, point-to-plane, coherence).
    #[arg(long, value_name = "ENDPOINT", conflicts_with_all = ["session", "local", "point_to_point", "no_coherence"])]
    pub service: Option<String>,
    /// One local alignment from the nominal pose (the thesis's behaviour), no global search.
    #[arg(long)]
    pub local: bool,
    /// Use the thesis's SVD (point-to-point) step instead of point-to-plane.
    #[arg(long)]
    pub point_to_point: bool,
    /// Ignore the probe's approach direction when matching touches to faces.
    #[arg(long)]
    pub no_coherence: bool,
    /// Print one JSON document instead of text.
    #[arg(long, conflicts_with = "export")]
    pub json: bool,
    #[arg(long, value_name = "FORMAT", value_parser = crate::export::parse_format, help = crate::export::HELP)]
    pub export: Option<ExportFormat>,
}

pub fn run(args: &AlignArgs) -> Result<String, CliError> {
    let report = match (&args.service, &args.session) {
        (Some(endpoint), _) => client::request(endpoint, ServiceCommand::Align)?,
        (None, Some(path)) => {
            let session = LoadedSession::load(path)?;
            let choices = AlignChoices {
                local: args.local,
                point_to_point: args.point_to_point,
                no_coherence: args.no_coherence,
            };
            report(&session, &align_session(&session, choices)?)
        }
        (None, None) => {
            return Err(
                BadInput("align needs a SESSION file or --service ENDPOINT".to_owned()).into(),
            );
        }
    };
    if let Some(format) = args.export {
        let mesh = args
            .session
            .as_deref()
            .and_then(crate::export::session_mesh);
        crate::export::alignment(format, &report, mesh)
    } else if args.json {
        json_line(&report)
    } else {
        Ok(to_text(&report))
    }
}

/// The pose's 95 % confidence limits, its weakest direction and the pose distance from the truth
/// it is within at 95 %, for people.
pub fn confidence_text(found: &Uncertainty) -> String {
    let position = &found.position_95_mm;
    let rotation = &found.rotation_95_mrad;
    let mut text = format!(
        "95% confidence (noise sigma {:.4} mm, {}): position +-{:.3} / {:.3} / {:.3} mm (x/y/z), \
         rotation +-{:.3} / {:.3} / {:.3} mrad (rx/ry/rz)\n  {}\n",
        found.sigma_m * 1e3,
        found.sigma_source,
        position.x,
        position.y,
        position.z,
        rotation.rx,
        rotation.ry,
        rotation.rz,
        found.weak_direction.text
    );
    if let Some(mm) = found.pose_distance_95_mm {
        text += &format!(
            "  the pose is within {mm:.3} mm of the truth at 95% confidence (the thesis's pose distance)\n"
        );
    }
    text
}

/// The report for people: the pose, how the search went, its uncertainty and the residuals.
pub fn to_text(report: &AlignReport) -> String {
    let mut text = crate::pose_line("base_from_part", &report.alignment.pose);
    text += &format!(
        "{} after {} iterations ({} starts) in {:.1} ms; residual rms {:.4} mm, max {:.4} mm\n",
        if report.alignment.converged {
            "converged"
        } else {
            "NOT converged"
        },
        report.alignment.iterations,
        report.starts,
        report.alignment.time_s * 1e3,
        report.alignment.rms * 1e3,
        report.alignment.max * 1e3
    );
    if let Some(found) = &report.uncertainty {
        text += &confidence_text(found);
        if let Some(residual) = found.residual_sigma_m
            && found.sigma_source == "declared"
            && residual > 2.0 * found.sigma_m
        {
            text += &format!(
                "  the residuals suggest a noise of {:.4} mm against the declared {:.4} mm: \
                 the model lacks an effect (ips diagnose) and these limits are optimistic\n",
                residual * 1e3,
                found.sigma_m * 1e3
            );
        }
    } else if let Some(why) = &report.uncertainty_error {
        text += &format!("pose uncertainty not available: {why}\n");
    }
    if report.ambiguous {
        text += &format!(
            "AMBIGUOUS: {} other poses fit the inspections as well (symmetric part or too few touches); \
             the pose shown is the one nearest the nominal pose. Add touches on distinguishing features \
             or label touches with faces.\n",
            report.candidates.len()
        );
        for candidate in &report.candidates {
            let [x, y, z] = candidate.pose.xyz;
            let [roll, pitch, yaw] = candidate.pose.rpy;
            text += &format!(
                "  candidate: xyz {x:.6} {y:.6} {z:.6}, rpy {roll:.4} {pitch:.4} {yaw:.4}, rms {:.4} mm\n",
                candidate.rms * 1e3
            );
        }
    }
    text += "residuals (mm):\n";
    for residual in &report.alignment.residuals {
        text += &format!("  {:>6}  {:+.4}\n", residual.id, residual.distance * 1e3);
    }
    for note in &report.notes {
        text += &format!("note: {note}\n");
    }
    text
}
