//! `ips start|stop|get|list|remove|reset|save|load|status|results`: one request to a running `ips
//! serve`, printed for people or as the reply's JSON document with `--json`.

use std::time::Duration;

use clap::Args;
use protocol::{
    GetReply, GetRequest, InspectionCountReply, InspectionsReply, MirroringReply, PathRequest,
    RemoveRequest, ResultsReply, SavedReply, ServiceCommand, StatusReply,
};
use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::{BadInput, CliError, client, json_line};

#[derive(Debug, Args)]
pub struct ServiceArgs {
    /// The service's REP endpoint.
    #[arg(long, default_value = "tcp://127.0.0.1:4000")]
    pub service: String,
    /// Print the reply's JSON document.
    #[arg(long)]
    pub json: bool,
    /// How long to wait for the reply, s (the service answers in turn: a request may wait
    /// behind a diagnose).
    #[arg(long, value_name = "SECONDS", default_value_t = 30.0)]
    pub timeout: f64,
}

#[derive(Debug, Args)]
pub struct PathArgs {
    /// Session file, as the service sees the path.
    pub path: String,
    #[command(flatten)]
    pub service: ServiceArgs,
}

#[derive(Debug, Args)]
pub struct GetArgs {
    /// The controller time of the touch, s (a touch-trigger probe's time stamp): the sample at
    /// or just after it instead of the latest; the service keeps the last 4096 samples.
    #[arg(long, value_name = "SECONDS")]
    pub at: Option<f64>,
    #[command(flatten)]
    pub service: ServiceArgs,
}

#[derive(Debug, Args)]
pub struct RemoveArgs {
    /// Inspection ids.
    #[arg(required = true)]
    pub ids: Vec<String>,
    #[command(flatten)]
    pub service: ServiceArgs,
}

/// Sends `command` and prints its typed reply with `text` (or as JSON).
fn call<T: DeserializeOwned + Serialize>(
    args: &ServiceArgs,
    command: ServiceCommand,
    text: impl FnOnce(&T) -> String,
) -> Result<String, CliError> {
    if !(args.timeout.is_finite() && args.timeout > 0.0) {
        return Err(BadInput(format!(
            "--timeout must be a positive number of seconds, got {}",
            args.timeout
        ))
        .into());
    }
    let timeout = Duration::from_secs_f64(args.timeout.min(86_400.0));
    let reply: T = client::request_within(&args.service, command, timeout)?;
    if args.json {
        json_line(&reply)
    } else {
        Ok(text(&reply))
    }
}

/// Joint values in degrees, as a person reads them (the JSON keeps radians).
fn joints_deg(q: Option<&Vec<f64>>) -> String {
    match q {
        Some(q) => {
            let values: Vec<String> = q.iter().map(|v| format!("{:.3}", v.to_degrees())).collect();
            format!("[{}]", values.join(", "))
        }
        None => "null".to_owned(),
    }
}

fn mirroring_text(reply: &MirroringReply) -> String {
    format!("mirroring: {}\n", reply.mirroring)
}

fn count_text(reply: &InspectionCountReply) -> String {
    format!("inspections: {}\n", reply.inspections)
}

pub fn start(args: &ServiceArgs) -> Result<String, CliError> {
    call(args, ServiceCommand::Start, mirroring_text)
}

pub fn stop(args: &ServiceArgs) -> Result<String, CliError> {
    call(args, ServiceCommand::Stop, mirroring_text)
}

pub fn status(args: &ServiceArgs) -> Result<String, CliError> {
    call(args, ServiceCommand::Status, |reply: &StatusReply| {
        let age = reply
            .sample_age_s
            .map_or("none yet".to_owned(), |age| format!("{age:.3} s"));
        let mut text = format!(
            "mirroring: {}, inspections: {}, latest joint state: {age}{}\n",
            reply.mirroring,
            reply.inspections,
            if reply.stale { " (stale)" } else { "" }
        );
        if let Some(kinematics) = &reply.kinematics {
            text += &format!("kinematics: {kinematics}\n");
        }
        text
    })
}

/// `get`, optionally at a controller time (s).
pub fn get(args: &GetArgs) -> Result<String, CliError> {
    if args.at.is_some_and(|t| !t.is_finite()) {
        return Err(BadInput("--at must be a finite controller time in s".to_owned()).into());
    }
    let command = ServiceCommand::Get(GetRequest { time_s: args.at });
    call(&args.service, command, |reply: &GetReply| {
        let mut text = format!(
            "inspection \"{}\" at q = {} deg\n",
            reply.inspection.id,
            joints_deg(reply.inspection.q.as_ref())
        );
        if let (Some([x, y, z]), Some(distance)) =
            (reply.ball_centre_mm, reply.nominal_surface_distance_mm)
        {
            text += &format!(
                "  ball centre ({x:.2}, {y:.2}, {z:.2}) mm in the base frame, {distance:+.2} mm from the nominal part's surface\n"
            );
        }
        if let Some(note) = &reply.note {
            text += &format!("  note: {note}\n");
        }
        if let Some(next) = &reply.next_touch {
            let [x, y, z] = next.point_mm;
            let [ax, ay, az] = next.approach.map(|v| crate::display_round(v, 3));
            text += &format!(
                "  next: touch ({x:.1}, {y:.1}, {z:.1}) mm moving along ({ax:.3}, {ay:.3}, {az:.3}){}\n        because {}\n",
                if next.tilt_deg > 0.0 {
                    format!(", tilted {:.0} deg from the normal", next.tilt_deg)
                } else {
                    String::new()
                },
                next.reason
            );
        }
        text
    })
}

pub fn list(args: &ServiceArgs) -> Result<String, CliError> {
    call(args, ServiceCommand::List, |reply: &InspectionsReply| {
        let mut text = String::new();
        for inspection in &reply.inspections {
            text += &format!(
                "{:>6}  q = {} deg\n",
                inspection.id,
                joints_deg(inspection.q.as_ref())
            );
        }
        if text.is_empty() {
            text = "no inspections\n".to_owned();
        }
        text
    })
}

pub fn remove(args: &RemoveArgs) -> Result<String, CliError> {
    let command = ServiceCommand::Remove(RemoveRequest {
        ids: args.ids.clone(),
    });
    call(&args.service, command, count_text)
}

pub fn reset(args: &ServiceArgs) -> Result<String, CliError> {
    call(args, ServiceCommand::Reset, count_text)
}

pub fn save(args: &PathArgs) -> Result<String, CliError> {
    let command = ServiceCommand::Save(PathRequest {
        path: args.path.clone(),
    });
    call(&args.service, command, |reply: &SavedReply| {
        let results = if reply.results.is_empty() {
            String::new()
        } else {
            format!(" with the last {}", reply.results.join(" and "))
        };
        format!(
            "saved {} inspections{results} to {}\n",
            reply.inspections, reply.path
        )
    })
}

pub fn load(args: &PathArgs) -> Result<String, CliError> {
    let command = ServiceCommand::Load(PathRequest {
        path: args.path.clone(),
    });
    call(&args.service, command, count_text)
}

/// `results`: the latest alignment and diagnosis, each as `ips align` / `ips diagnose` print
/// them, under a line that says which inspections they used and whether those are still all.
pub fn results(args: &ServiceArgs) -> Result<String, CliError> {
    call(args, ServiceCommand::Results, |reply: &ResultsReply| {
        let heading = |what: &str, inspections: &[String], current: bool| {
            format!(
                "== latest {what}, of {} inspection(s){}\n",
                inspections.len(),
                if current {
                    ""
                } else {
                    " (stale: the inspections changed since)"
                }
            )
        };
        let mut text = String::new();
        if let Some(alignment) = &reply.alignment {
            text += &heading("alignment", &alignment.inspections, alignment.current);
            text += &super::align::to_text(&alignment.report);
        }
        if let Some(diagnosis) = &reply.diagnosis {
            text += &heading("diagnosis", &diagnosis.inspections, diagnosis.current);
            text += &super::diagnose::to_text(&diagnosis.report);
        }
        if text.is_empty() {
            text = "no alignment or diagnosis yet\n".to_owned();
        }
        if let Some(next) = &reply.next_touch {
            let [x, y, z] = next.point_mm;
            text += &format!(
                "next suggested touch: ({x:.1}, {y:.1}, {z:.1}) mm: {}\n",
                next.reason
            );
        }
        text
    })
}
