//! `ips align-robot`: hierarchical alignment of a robot (URDF with link geometry) in a scanner
//! cloud: the base pose and the joint values, each link constrained by its parent.

use std::path::PathBuf;

use align_core::io::read_cloud;
use align_core::pose::{isometry_from_xyz_rpy, xyz_rpy};
use align_core::registration::articulated::{ArticulatedBody, RobotFitOptions, align_robot};
use clap::Args;
use serde::Serialize;

use crate::{BadInput, CliError, json_line, parse_number_list};

#[derive(Debug, Args)]
pub struct AlignRobotArgs {
    /// Robot description (URDF with visual or collision geometry; expand xacro files first).
    #[arg(long, value_name = "FILE")]
    pub urdf: PathBuf,
    /// Where a ROS package named in package:// mesh URIs lives; repeatable.
    #[arg(long = "package-dir", value_name = "NAME=DIR")]
    pub package_dirs: Vec<String>,
    /// Scanner cloud (.ply, .pcd, .xyz, .csv, .txt).
    #[arg(long, value_name = "FILE")]
    pub cloud: PathBuf,
    /// Unit of the cloud file in metres (0.001 for mm).
    #[arg(long, default_value_t = 1.0)]
    pub cloud_scale: f64,
    /// Nominal pose of the URDF's root link in the cloud's frame: x,y,z (m), roll,pitch,yaw (rad).
    #[arg(long, value_name = "X,Y,Z,R,P,Y", allow_hyphen_values = true)]
    pub base_pose: String,
    /// Start joint values, one per moving joint that mimics none, in the URDF's order (rad or m).
    #[arg(long, value_name = "A,B,...", allow_hyphen_values = true)]
    pub q0: String,
    /// Upper bound of how far any point of the robot is from where the start puts it, m.
    /// Beyond the robot's radius the start is taken as not local: the base is detected
    /// anywhere within twice delta of the start and each joint is searched over its whole
    /// window (seconds instead of a fraction of a second).
    #[arg(long, allow_hyphen_values = true)]
    pub delta: f64,
    /// Print one JSON document instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Serialize)]
pub struct BasePoseJson {
    pub xyz: [f64; 3],
    pub rpy: [f64; 3],
}

#[derive(Debug, Serialize)]
pub struct LinkJson {
    pub name: String,
    pub points: usize,
    pub rms: f64,
    pub visible: bool,
}

#[derive(Debug, Serialize)]
pub struct JointJson {
    pub name: String,
    pub value: f64,
    /// False: the scan did not constrain the joint (its links unseen, or a symmetric link
    /// turning about its own axis); the value is the start value.
    pub observed: bool,
    /// True for the first joint above a round base: the scan fixes the base's yaw about the
    /// joint's axis plus the joint's value, not each; the split is the start's.
    pub turns_with_base: bool,
    /// Half the value's 95 % interval from the scan's noise and geometry, rad (m for a
    /// prismatic joint); null when the joint is not observed or not fixed on its own.
    pub within_95: Option<f64>,
    /// The interval's unit in the text: metres for a prismatic joint, else radians.
    #[serde(skip)]
    pub prismatic: bool,
}

/// DESIGN.md 6.4 keys, plus `joints`, `rms`, `iterations`, `cloud_points`.
#[derive(Debug, Serialize)]
pub struct AlignRobotOutput {
    pub base_pose: BasePoseJson,
    pub q: Vec<f64>,
    pub links: Vec<LinkJson>,
    pub joints: Vec<JointJson>,
    pub rms: f64,
    pub iterations: usize,
    pub cloud_points: usize,
    pub time_s: f64,
    /// True when another pose (`twin`) explains the scan as well: the scan cannot tell them.
    pub ambiguous: bool,
    /// The best other pose the half-turn checks found (large deltas), ambiguous or not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub twin: Option<TwinJson>,
}

#[derive(Debug, Serialize)]
pub struct TwinJson {
    pub base_pose: BasePoseJson,
    pub q: Vec<f64>,
    /// Fine keypoints it explains where it and the fit differ (near the links the two place
    /// apart), and the fit's there.
    pub coverage: i64,
    pub fit_coverage: i64,
}

/// The command: prints the fitted robot.
pub fn command(args: &AlignRobotArgs) -> Result<String, CliError> {
    let output = run(args)?;
    if args.json {
        json_line(&output)
    } else {
        Ok(output.to_text())
    }
}

pub fn run(args: &AlignRobotArgs) -> Result<AlignRobotOutput, BadInput> {
    let pose = parse_number_list(&args.base_pose, "--base-pose")?;
    let [x, y, z, roll, pitch, yaw] = pose[..] else {
        return Err(BadInput(format!(
            "--base-pose needs 6 values x,y,z,roll,pitch,yaw, got {}",
            pose.len()
        )));
    };
    let q0 = parse_number_list(&args.q0, "--q0")?;
    if !(args.delta.is_finite() && args.delta > 0.0) {
        return Err(BadInput(format!(
            "--delta must be a positive distance in m, got {}",
            args.delta
        )));
    }
    let model = crate::load_urdf(&args.urdf, &args.package_dirs)?;
    let body = ArticulatedBody::from_model(&model)
        .map_err(|error| BadInput(format!("'{}': {error}", args.urdf.display())))?;
    let cloud = read_cloud(&args.cloud, args.cloud_scale).map_err(BadInput::new)?;
    let start = isometry_from_xyz_rpy([x, y, z], [roll, pitch, yaw]);
    let fit = align_robot(
        &body,
        &cloud,
        &start,
        &q0,
        args.delta,
        &RobotFitOptions::default(),
    )
    .map_err(|error| BadInput(format!("cannot align the robot: {error}")))?;
    let (xyz, rpy) = xyz_rpy(&fit.world_from_root);
    Ok(AlignRobotOutput {
        base_pose: BasePoseJson { xyz, rpy },
        q: fit.q.clone(),
        links: body
            .links()
            .iter()
            .zip(&fit.links)
            .filter(|(link, _)| link.surface.is_some())
            .map(|(_, fit)| LinkJson {
                name: fit.name.clone(),
                points: fit.points,
                rms: fit.rms_m,
                visible: fit.visible,
            })
            .collect(),
        joints: fit
            .joints
            .iter()
            .zip(body.parameters())
            .map(|(joint, parameter)| JointJson {
                name: joint.name.clone(),
                value: joint.value,
                observed: joint.observed,
                turns_with_base: joint.turns_with_base,
                within_95: joint.within_95,
                prismatic: parameter.prismatic,
            })
            .collect(),
        rms: fit.rms_m,
        iterations: fit.iterations,
        cloud_points: cloud.len(),
        time_s: fit.time_s,
        ambiguous: fit.twin.as_ref().is_some_and(|twin| twin.ambiguous),
        twin: fit.twin.as_ref().map(|twin| {
            let (xyz, rpy) = xyz_rpy(&twin.world_from_root);
            TwinJson {
                base_pose: BasePoseJson { xyz, rpy },
                q: twin.q.clone(),
                coverage: twin.coverage,
                fit_coverage: twin.fit_coverage,
            }
        }),
    })
}

impl AlignRobotOutput {
    pub fn to_text(&self) -> String {
        let [x, y, z] = self.base_pose.xyz.map(|v| crate::display_round(v, 6));
        let [roll, pitch, yaw] = self.base_pose.rpy.map(|v| crate::display_round(v, 6));
        let mut text = format!(
            "base pose: xyz [m] {x:.6} {y:.6} {z:.6}, rpy [rad] {roll:.6} {pitch:.6} {yaw:.6}\n"
        );
        for joint in &self.joints {
            let within = joint
                .within_95
                .map(|half| {
                    // A prismatic joint's interval is in metres: shown in mm, a turn's in mrad.
                    format!(
                        "  +-{:.3} m{} (95 %)",
                        half * 1e3,
                        if joint.prismatic { "m" } else { "rad" }
                    )
                })
                .unwrap_or_default();
            text += &format!(
                "  {:<24} {:>11.6}{}{}\n",
                joint.name,
                crate::display_round(joint.value, 6),
                within,
                if !joint.observed {
                    "  (not observed: start value kept)"
                } else if joint.turns_with_base {
                    "  (round base: only base yaw + this value is observed)"
                } else {
                    ""
                }
            );
        }
        for link in &self.links {
            text += &format!(
                "  {:<24} {:>6} points, rms {:.3} mm{}\n",
                link.name,
                link.points,
                link.rms * 1e3,
                if link.visible { "" } else { "  (not visible)" }
            );
        }
        text += &format!(
            "{} cloud points, rms {:.3} mm, {} iterations, {:.1} ms\n",
            self.cloud_points,
            self.rms * 1e3,
            self.iterations,
            self.time_s * 1e3
        );
        if let (true, Some(twin)) = (self.ambiguous, &self.twin) {
            let q: Vec<String> = twin.q.iter().map(|v| format!("{v:.4}")).collect();
            text += &format!(
                "AMBIGUOUS: another pose explains the scan as well ({} keypoints against {} where the two differ): joints [{}]; a joint reading or a touch tells them apart\n",
                twin.coverage,
                twin.fit_coverage,
                q.join(", ")
            );
        }
        text
    }
}

#[cfg(test)]
mod tests {
    use super::{AlignRobotOutput, BasePoseJson, JointJson};

    fn joint(name: &str, within_95: Option<f64>, prismatic: bool, observed: bool) -> JointJson {
        JointJson {
            name: name.to_owned(),
            value: 0.5,
            observed,
            turns_with_base: false,
            within_95,
            prismatic,
        }
    }

    #[test]
    fn the_text_gives_a_turns_interval_in_mrad_a_slides_in_mm_and_none_where_there_is_none() {
        let output = AlignRobotOutput {
            base_pose: BasePoseJson {
                xyz: [0.0; 3],
                rpy: [0.0; 3],
            },
            q: vec![0.5; 3],
            links: Vec::new(),
            joints: vec![
                joint("elbow", Some(0.000_25), false, true),
                joint("carriage", Some(0.000_4), true, true),
                joint("flange", None, false, false),
            ],
            rms: 0.0004,
            iterations: 10,
            cloud_points: 1000,
            time_s: 0.05,
            ambiguous: false,
            twin: None,
        };
        let text = output.to_text();
        let line = |name: &str| text.lines().find(|l| l.contains(name)).unwrap_or_default();
        assert!(line("elbow").contains("+-0.250 mrad (95 %)"), "{text}");
        assert!(line("carriage").contains("+-0.400 mm (95 %)"), "{text}");
        assert!(!line("flange").contains("+-"), "{text}");
        assert!(line("flange").contains("not observed"), "{text}");
        // The unit is the text's alone: the JSON gives metres or radians and no flag.
        let json = serde_json::to_value(&output).unwrap_or_default();
        assert!(json["joints"][1].get("prismatic").is_none(), "{json}");
        assert_eq!(json["joints"][1]["within_95"], 0.0004);
    }
}
