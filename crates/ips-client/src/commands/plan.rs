//! `ips plan SESSION`: where to touch the session's part at its nominal pose, the 3-2-1 way a
//! CMM programmer plans it (three touches on a primary face, two on a face square to it, one on
//! a face square to both, then extras on other faces): target points and approach directions
//! in the robot base frame, and with the session's robot the joint targets at contact and at
//! the approach point.

use std::path::PathBuf;

use align_core::robots::ShippedRobot;
use align_core::trials::planning::{PlanOptions, TouchPlan, plan_touch_points, plan_touches};
use align_service::session::LoadedSession;
use clap::Args;
use nalgebra::Vector3;
use serde::Serialize;

use crate::{BadInput, CliError, json_line, parse_number_list};

#[derive(Debug, Args)]
pub struct PlanArgs {
    /// Session file (cobot-align/session@1): its part at its nominal pose, its tool and robot.
    #[arg(value_name = "SESSION")]
    pub session: PathBuf,
    /// Touches in all (at least 6: 3-2-1); the rest spread over other faces.
    #[arg(long, default_value_t = 9)]
    pub touches: usize,
    /// Largest tilt of the probe from a face's inward normal, degrees (used where the head-on
    /// approach is blocked or, with --vary-tilt, on purpose).
    #[arg(long, value_name = "DEG", default_value_t = 34.0)]
    pub max_tilt_deg: f64,
    /// Vary the tilt from touch to touch (head-on, half, full, full the other way): tilted
    /// touches tell a ball-radius error from a TCP length error in the diagnosis.
    #[arg(long)]
    pub vary_tilt: bool,
    /// Where the arm starts, joint values in degrees (comma-separated): the IK seed. Default:
    /// the first inspection's joints, else the robot's usual home.
    #[arg(long, value_name = "DEG,...")]
    pub seed_deg: Option<String>,
    /// Plan points and approaches only, without the session's robot (no reachability check).
    #[arg(long)]
    pub no_robot: bool,
    /// Print one JSON document instead of text.
    #[arg(long)]
    pub json: bool,
}

/// One planned touch, in the robot base frame.
#[derive(Debug, Clone, Serialize)]
pub struct PlannedTouch {
    pub id: String,
    /// `primary`, `secondary`, `tertiary` (3-2-1) or `extra`.
    pub role: &'static str,
    /// Planar face of the part, numbered by decreasing area.
    pub face: usize,
    /// Where the ball touches the surface, m.
    pub point_m: [f64; 3],
    /// The probe's direction of travel into the surface (the TCP's z axis), unit vector.
    pub approach: [f64; 3],
    /// The ball's centre at contact, m.
    pub ball_centre_m: [f64; 3],
    pub tilt_rad: f64,
    /// Joints at contact and `approach_m` back along the probe, rad; absent without a robot.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub q_contact: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub q_approach: Option<Vec<f64>>,
}

#[derive(Debug, Clone, Serialize)]
pub struct Plan {
    pub base_frame: String,
    /// Whether the joint targets were solved for the session's robot.
    pub robot: bool,
    pub touches: Vec<PlannedTouch>,
}

fn role(index: usize) -> &'static str {
    match index {
        0..=2 => "primary",
        3..=4 => "secondary",
        5 => "tertiary",
        _ => "extra",
    }
}

fn array(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// The IK seed: given, the first inspection's joints, or a home for the robot's joint count.
fn seed(args: &PlanArgs, session: &LoadedSession, dof: usize) -> Result<Vec<f64>, BadInput> {
    if let Some(text) = &args.seed_deg {
        let degrees = parse_number_list(text, "--seed-deg")?;
        if degrees.len() != dof {
            return Err(BadInput(format!(
                "--seed-deg has {} values, the robot {dof} joints",
                degrees.len()
            )));
        }
        return Ok(degrees.iter().map(|d| d.to_radians()).collect());
    }
    if let Some(q) = session.file.inspections.iter().find_map(|i| i.q.clone())
        && q.len() == dof
    {
        return Ok(q);
    }
    Ok(ShippedRobot::ALL
        .into_iter()
        .map(ShippedRobot::home)
        .find(|home| home.len() == dof)
        .unwrap_or_else(|| vec![0.0; dof]))
}

pub fn plan(args: &PlanArgs) -> Result<Plan, CliError> {
    if !(args.max_tilt_deg.is_finite() && (0.0..=80.0).contains(&args.max_tilt_deg)) {
        return Err(BadInput(format!(
            "--max-tilt-deg must be between 0 and 80 degrees, got {}",
            args.max_tilt_deg
        ))
        .into());
    }
    let session = LoadedSession::load(&args.session)?;
    let options = PlanOptions {
        touches: args.touches,
        max_tilt_rad: args.max_tilt_deg.to_radians(),
        vary_tilt: args.vary_tilt,
        ..PlanOptions::default()
    };
    let nominal = session.base_from_part_nominal;
    let radius = session.tool.tip_radius_m;
    let chain = session.chain.as_ref().filter(|_| !args.no_robot);
    let planned: Vec<TouchPlan> = match chain {
        Some(chain) => {
            let seed = seed(args, &session, chain.dof())?;
            let flange_from_tcp = session.tool.flange_from_tcp;
            plan_touches(
                &session.mesh,
                &nominal,
                chain,
                &flange_from_tcp,
                radius,
                1.0,
                &seed,
                &options,
            )
        }
        None => plan_touch_points(&session.mesh, &nominal, radius, &options),
    }
    .map_err(|error| {
        let hint = if chain.is_some() {
            " (--no-robot plans without the reach check; --seed-deg starts the arm elsewhere)"
        } else {
            ""
        };
        BadInput(format!("cannot plan: {error}{hint}"))
    })?;
    let touches = planned
        .iter()
        .enumerate()
        .map(|(index, touch)| {
            let normal = nominal.rotation * touch.normal_in_part;
            let point = nominal * touch.point_in_part;
            let centre = point + normal * radius;
            // The probe's travel: the contact's TCP z axis from forward kinematics when there are
            // joints, else straight in along the inward normal.
            let approach = match chain {
                Some(chain) => {
                    let tcp =
                        chain.forward_unchecked(&touch.q_contact) * session.tool.flange_from_tcp;
                    tcp.rotation * Vector3::z()
                }
                None => -normal,
            };
            PlannedTouch {
                id: (index + 1).to_string(),
                role: role(index),
                face: touch.face,
                point_m: array(&point.coords),
                approach: array(&approach),
                ball_centre_m: array(&centre.coords),
                tilt_rad: touch.tilt_rad,
                q_contact: chain.map(|_| touch.q_contact.clone()),
                q_approach: chain.map(|_| touch.q_approach.clone()),
            }
        })
        .collect();
    Ok(Plan {
        base_frame: session.base_frame().to_owned(),
        robot: chain.is_some(),
        touches,
    })
}

pub fn run(args: &PlanArgs) -> Result<String, CliError> {
    let plan = plan(args)?;
    if args.json {
        return json_line(&plan);
    }
    let mut text = format!(
        "3-2-1 plan at the nominal pose, base frame '{}' ({} touches{}):\n",
        plan.base_frame,
        plan.touches.len(),
        if plan.robot {
            ", joint targets for the session's robot"
        } else {
            ", no robot: reachability not checked"
        }
    );
    let triple = |v: [f64; 3], factor: f64, decimals: usize| {
        let [x, y, z] = v.map(|c| crate::display_round(c * factor, decimals as i32));
        format!("({x:.decimals$}, {y:.decimals$}, {z:.decimals$})")
    };
    for touch in &plan.touches {
        text += &format!(
            "{:>3} {:<9} face {:>2}: point {} mm, approach {}, tilt {:.1} deg\n",
            touch.id,
            touch.role,
            touch.face,
            triple(touch.point_m, 1e3, 2),
            triple(touch.approach, 1.0, 3),
            touch.tilt_rad.to_degrees()
        );
        if let (Some(contact), Some(approach)) = (&touch.q_contact, &touch.q_approach) {
            let degrees = |q: &[f64]| {
                q.iter()
                    .map(|v| format!("{:.2}", v.to_degrees()))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            text += &format!(
                "      approach q = [{}] deg\n      contact  q = [{}] deg\n",
                degrees(approach),
                degrees(contact)
            );
        }
    }
    Ok(text)
}
