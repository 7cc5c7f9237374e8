//! A diagnosis applied to the session it came from (`ips diagnose SESSION --apply OUT`): the
//! fitted ball radius, TCP shift, part scale, joint offsets, joint compliance or capture latency
//! written into the model, so that aligning the new session gives the diagnosis's pose after
//! modelling without anyone typing numbers back into JSON.

use protocol::reports::{AppliedChange, EffectFit};
use protocol::session::SessionFile;

use crate::BadInput;
use crate::jobs::units::person_unit;

/// Where a fitted parameter goes in the session file.
enum Target {
    TipRadius,
    Tcp(usize),
    MeshScale,
    JointOffset(usize),
    JointCompliance(usize),
    Latency,
}

fn target(name: &str, dof: usize) -> Result<Target, BadInput> {
    let joint = |suffix: &str| -> Option<usize> {
        let index: usize = name
            .strip_prefix("joint_")?
            .strip_suffix(suffix)?
            .parse()
            .ok()?;
        (1..=dof).contains(&index).then_some(index - 1)
    };
    Ok(match name {
        "delta_radius_m" => Target::TipRadius,
        "dx_m" => Target::Tcp(0),
        "dy_m" => Target::Tcp(1),
        "dz_m" => Target::Tcp(2),
        "scale_minus_one" => Target::MeshScale,
        "latency_s" => Target::Latency,
        _ => {
            if let Some(index) = joint("_rad_per_nm") {
                Target::JointCompliance(index)
            } else if let Some(index) = joint("_rad") {
                Target::JointOffset(index)
            } else {
                return Err(BadInput(format!(
                    "the diagnosis fitted '{name}', which --apply does not know where to write"
                )));
            }
        }
    })
}

/// How a change reads for a person, in the unit people think in for `parameter`.
fn describe(key: &str, parameter: &str, before: f64, after: f64) -> String {
    let (factor, unit, decimals) = person_unit(parameter);
    let (b, a) = (before * factor, after * factor);
    format!(
        "{key}: {b:.decimals$} -> {a:.decimals$} {unit} ({:+.decimals$} {unit})",
        a - b
    )
}

fn change(key: String, parameter: &str, before: f64, after: f64, unit: &str) -> AppliedChange {
    AppliedChange {
        text: describe(&key, parameter, before, after),
        key,
        before,
        after,
        unit: unit.to_owned(),
    }
}

/// `file` with `effect`'s parameters applied to its model, and what changed. Joint effects go to
/// the robot section and need one: `dof` is its number of joints. Corrections the file already
/// declares are added to, since the diagnosis fitted what was left after them.
pub fn apply_effect(
    file: &SessionFile,
    effect: &EffectFit,
    dof: usize,
) -> Result<(SessionFile, Vec<AppliedChange>), BadInput> {
    let mut out = file.clone();
    let mut changes = Vec::new();
    for (name, &value) in &effect.params {
        if !value.is_finite() {
            return Err(BadInput(format!("the fitted {name} is not finite")));
        }
        let target = target(name, dof)?;
        match target {
            Target::TipRadius => {
                let before = out.tool.tip_radius;
                let after = before + value;
                if after < 0.0 {
                    return Err(BadInput(format!(
                        "the fitted ball radius change {:.4} mm would make the radius negative",
                        value * 1e3
                    )));
                }
                out.tool.tip_radius = after;
                changes.push(change(
                    "tool.tip_radius".to_owned(),
                    name,
                    before,
                    after,
                    "m",
                ));
            }
            Target::Tcp(axis) => {
                let before = out.tool.tcp.xyz[axis];
                out.tool.tcp.xyz[axis] += value;
                let key = format!("tool.tcp.xyz[{axis}]");
                changes.push(change(key, name, before, out.tool.tcp.xyz[axis], "m"));
            }
            Target::MeshScale => {
                let before = out.part.mesh_scale;
                out.part.mesh_scale *= 1.0 + value;
                let mut applied = change(
                    "part.mesh_scale".to_owned(),
                    name,
                    before,
                    out.part.mesh_scale,
                    "",
                );
                applied.text = format!(
                    "part.mesh_scale: {before} -> {} ({:+.4} %)",
                    out.part.mesh_scale,
                    value * 100.0
                );
                changes.push(applied);
            }
            Target::JointOffset(joint) | Target::JointCompliance(joint) => {
                let compliance = matches!(target, Target::JointCompliance(_));
                let robot = out
                    .robot
                    .as_mut()
                    .ok_or_else(|| BadInput(format!("{name} needs the session's robot section")))?;
                let (values, key, unit) = if compliance {
                    (
                        &mut robot.joint_compliance,
                        "robot.joint_compliance",
                        "rad/(N m)",
                    )
                } else {
                    (&mut robot.joint_offsets, "robot.joint_offsets", "rad")
                };
                let values = values.get_or_insert_with(|| vec![0.0; dof]);
                let before = values[joint];
                values[joint] += value;
                changes.push(change(
                    format!("{key}[{joint}]"),
                    name,
                    before,
                    values[joint],
                    unit,
                ));
            }
            Target::Latency => {
                let robot = out.robot.as_mut().ok_or_else(|| {
                    BadInput("latency_s needs the session's robot section".to_owned())
                })?;
                let before = robot.trigger_latency_s.unwrap_or(0.0);
                robot.trigger_latency_s = Some(before + value);
                changes.push(change(
                    "robot.trigger_latency_s".to_owned(),
                    name,
                    before,
                    before + value,
                    "s",
                ));
            }
        }
    }
    Ok((out, changes))
}
