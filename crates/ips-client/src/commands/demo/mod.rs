//! `ips demo`: the whole loop on the simulator in one command. Starts sim-robot, robot-bridge
//! and `ips serve` as child processes on free ports (the `cell` crate), places the step block at
//! a pose only the simulator knows ([`scene`]), drives the robot to its touches and captures
//! each through the service ([`capture`]), aligns, diagnoses, and prints the result beside the
//! truth. Children are stopped with SIGTERM at the end; if one dies early the demo says which
//! and fails (exit 1).

mod capture;
mod scene;

use std::time::Duration;

use align_core::pose::isometry_from_xyz_rpy;
use align_core::robots::ShippedRobot;
use cell::{Cell, ChildProcess};
use nalgebra::Isometry3;
use protocol::reports::{AlignReport, Alternative, EffectFit, FitSummary};
use protocol::sim::{Done, ProbePlan, SimCommand};
use protocol::{MirroringReply, PathRequest, Pose, SavedReply, ServiceCommand};
use serde::Serialize;

pub use scene::SimulatedEffect;

use crate::{BadInput, CliError, json_line};
use capture::{Links, capture_touches, check_alive, start_mirroring};
use scene::Scene;

#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Simulated robot: ur10 (RTDE, 125 Hz), ur10e (RTDE, 500 Hz) or iiwa14 (FRI, 5 ms).
    #[arg(long, default_value = "ur10")]
    pub robot: String,
    /// An effect the simulated cell has and the model does not declare: none, probe_radius
    /// (3.4 mm ball, 3 mm declared), tcp_offset (TCP 2.3 mm off), part_scale (part 0.4% larger
    /// than its model), joint_offsets (encoder offsets of 1-2 mrad), joint_compliance (two
    /// joints sag under gravity, 3-4e-5 rad/(N m)), cyclic_encoder (an eccentric encoder on the
    /// shoulder, 1 mrad twice per turn: outside the diagnosis library), trigger_latency (touches
    /// taken on the fly at 1-4 mm/s, each sample 50 ms later than its trigger time stamp). With an
    /// effect the demo takes 16 tilted touches and runs the diagnosis.
    #[arg(long, default_value = "none")]
    pub effect: SimulatedEffect,
    /// Encoder noise of 20 urad on every joint of every sample (the session declares 50 um).
    #[arg(long)]
    pub noise: bool,
    /// A factory-calibrated arm (UR robots): the simulated controller moves with its nominal DH
    /// table plus the deltas in FILE ({"dh_delta": {"theta": [6], "a": [6], "d": [6], "alpha":
    /// [6]}}, rad and m) and reports that table on its primary interface; the bridge reads it and
    /// the service turns joints into touches with it.
    #[arg(long, value_name = "FILE")]
    pub calibration: Option<std::path::PathBuf>,
    /// Print one JSON document instead of text.
    #[arg(long)]
    pub json: bool,
}

/// The diagnosis part of the demo's document (fields in alphabetical order, as always written).
#[derive(Debug, Serialize)]
pub struct DemoDiagnosis {
    pub after: FitSummary,
    pub alternatives: Vec<Alternative>,
    pub before: FitSummary,
    pub effect: Option<EffectFit>,
    pub explanation: String,
    pub verdict: String,
}

#[derive(Debug, Serialize)]
pub struct DemoOutput {
    pub robot: String,
    /// The effect the simulated cell had.
    pub effect: String,
    /// The diagnosis of the residual: verdict, effect found and its parameters.
    pub diagnosis: DemoDiagnosis,
    /// Pose error after modelling the diagnosed effect (equal to the aligned error when none
    /// was applied), m and rad.
    pub pose_error_after_diagnosis_m: f64,
    pub pose_error_after_diagnosis_rad: f64,
    pub inspections: usize,
    /// Distance between the aligned and the true part position, m.
    pub pose_error_m: f64,
    /// Angle between the aligned and the true part orientation, rad.
    pub pose_error_rad: f64,
    /// The nominal (virtual) pose's error before alignment.
    pub nominal_error_m: f64,
    pub nominal_error_rad: f64,
    pub rms_m: f64,
    pub align_time_s: f64,
    pub pose: Pose,
    pub truth: Pose,
    /// The controller's calibration the touches were made with (its hash), when the arm had one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration_hash: Option<String>,
    /// With a calibrated arm: the pose error the same touches give through the nominal
    /// kinematics, what ignoring the controller's calibration would cost, m and rad.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nominal_kinematics_pose_error_m: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nominal_kinematics_pose_error_rad: Option<f64>,
}

/// The command: runs the demo and prints its result.
pub fn run(args: &DemoArgs) -> Result<String, CliError> {
    let output = demo(args, |line| eprintln!("{line}"))?;
    if args.json {
        json_line(&output)
    } else {
        Ok(output.to_text())
    }
}

/// What the service gave at the end of the run.
struct Captured {
    aligned: Result<AlignReport, String>,
    plan: ProbePlan,
}

/// Runs the loop; `progress` gets one line per step.
pub fn demo(args: &DemoArgs, mut progress: impl FnMut(&str)) -> Result<DemoOutput, CliError> {
    let Some(robot) = ShippedRobot::from_name(&args.robot) else {
        return Err(BadInput(format!(
            "--robot '{}': expected ur10, ur10e or iiwa14",
            args.robot
        ))
        .into());
    };
    if let Some(path) = &args.calibration {
        if robot.nominal_dh().is_none() {
            return Err(BadInput(format!(
                "--calibration: {} has no DH table to calibrate (UR robots only)",
                robot.name()
            ))
            .into());
        }
        let text = std::fs::read_to_string(path).map_err(|error| {
            BadInput(format!(
                "cannot read calibration {}: {error}",
                path.display()
            ))
        })?;
        protocol::calibration::CalibrationFile::parse(&text)
            .map_err(|reason| BadInput(format!("calibration {}: {reason}", path.display())))?;
    }
    let ips_program =
        std::env::current_exe().map_err(|error| CliError::Failure(error.to_string()))?;
    let scratch = Scratch::create(
        std::env::temp_dir().join(format!("cobot-align-demo-{}", std::process::id())),
    )?;
    let folder = scratch.0.as_path();
    let scene = Scene::new(robot, args.effect, args.noise, folder)?;
    let session_path = folder.join("session.json");
    let session_text = serde_json::to_string_pretty(&scene.session).map_err(BadInput::new)?;
    std::fs::write(&session_path, session_text)
        .map_err(|error| CliError::Failure(error.to_string()))?;
    let journal = folder.join("inspections.journal");
    let _ = std::fs::remove_file(&journal);

    progress("starting sim-robot, robot-bridge and the alignment service");
    let failure = |error: cell::CellError| CliError::Failure(error.to_string());
    let calibration = args
        .calibration
        .as_deref()
        .map(|path| path.canonicalize().unwrap_or_else(|_| path.to_path_buf()));
    let cell = Cell::start_calibrated(robot, calibration.as_deref()).map_err(failure)?;
    let mut service = cell
        .serve(&ips_program, &session_path, &journal)
        .map_err(failure)?;
    let Cell {
        mut sim,
        mut bridge,
    } = cell;
    let context = zmq::Context::new();
    let links = Links::connect(
        &context,
        sim.endpoint("control").map_err(failure)?,
        service.endpoint("rep").map_err(failure)?,
    )?;
    let saved = folder.join("captured.json");
    let captured = {
        let mut children = [&mut sim, &mut bridge, &mut service];
        run_cell(&scene, &links, &mut children, &saved, &mut progress)?
    };
    for child in [service, bridge, sim] {
        child.terminate(Duration::from_secs(5));
    }
    let diagnosis = super::diagnose::run_file(&saved)?;
    let nominal_kinematics = if args.calibration.is_some() {
        Some(align_with_nominal_kinematics(&saved)?)
    } else {
        None
    };
    drop(scratch);
    let aligned = captured
        .aligned
        .map_err(|reason| CliError::Failure(format!("align failed: {reason}")))?;
    let truth = &scene.base_from_part_truth;
    let error = |pose: &Isometry3<f64>| {
        (
            (pose.translation.vector - truth.translation.vector).norm(),
            pose.rotation.angle_to(&truth.rotation),
        )
    };
    let isometry = |pose: &Pose| isometry_from_xyz_rpy(pose.xyz, pose.rpy);
    let (pose_error_m, pose_error_rad) = error(&isometry(&aligned.alignment.pose));
    let (nominal_error_m, nominal_error_rad) = error(&scene.base_from_part_nominal);
    let (pose_error_after_diagnosis_m, pose_error_after_diagnosis_rad) =
        error(&isometry(&diagnosis.pose_after));
    Ok(DemoOutput {
        robot: robot.name().to_owned(),
        effect: args.effect.name().to_owned(),
        diagnosis: DemoDiagnosis {
            after: diagnosis.after,
            alternatives: diagnosis.alternatives,
            before: diagnosis.before,
            effect: diagnosis.effect,
            explanation: diagnosis.explanation,
            verdict: diagnosis.verdict,
        },
        pose_error_after_diagnosis_m,
        pose_error_after_diagnosis_rad,
        inspections: captured.plan.touches,
        pose_error_m,
        pose_error_rad,
        nominal_error_m,
        nominal_error_rad,
        rms_m: aligned.alignment.rms,
        align_time_s: aligned.alignment.time_s,
        pose: aligned.alignment.pose,
        truth: scene.truth_pose(),
        calibration_hash: nominal_kinematics
            .as_ref()
            .and_then(|(_, hash)| hash.clone()),
        nominal_kinematics_pose_error_m: nominal_kinematics.as_ref().map(|(pose, _)| error(pose).0),
        nominal_kinematics_pose_error_rad: nominal_kinematics
            .as_ref()
            .map(|(pose, _)| error(pose).1),
    })
}

/// The demo's folder (the session, the journal, the saved capture), removed when the demo
/// ends, however it ends: a child that died early or an align that failed returned through `?`
/// and left a `cobot-align-demo-<pid>` folder behind per run. The inspections in it are the
/// simulator's, made again by the next run.
struct Scratch(std::path::PathBuf);

impl Scratch {
    fn create(folder: std::path::PathBuf) -> Result<Self, CliError> {
        std::fs::create_dir_all(&folder).map_err(|error| {
            CliError::Failure(format!("cannot create {}: {error}", folder.display()))
        })?;
        Ok(Self(folder))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The saved session aligned again with its robot's nominal kinematics (the controller's
/// calibration dropped), and the calibration's hash: what ignoring the calibration gives.
fn align_with_nominal_kinematics(
    saved: &std::path::Path,
) -> Result<(Isometry3<f64>, Option<String>), CliError> {
    let text = std::fs::read_to_string(saved)
        .map_err(|error| CliError::Failure(format!("cannot read {}: {error}", saved.display())))?;
    let mut file = align_service::session::parse_session_file(&text, &saved.display().to_string())?;
    let robot = file
        .robot
        .as_mut()
        .ok_or_else(|| CliError::Failure("the saved session has no robot".to_owned()))?;
    let kinematics = robot.kinematics.take().ok_or_else(|| {
        CliError::Failure(
            "the service did not use the controller's calibration (no robot.kinematics in the saved session)".to_owned(),
        )
    })?;
    let folder = saved.parent().unwrap_or(std::path::Path::new("."));
    let session = align_service::session::LoadedSession::resolve(file, folder)?;
    let result = align_service::jobs::align::align_session(&session, Default::default())?;
    Ok((result.alignment.base_from_part, kinematics.hash))
}

/// Sets the simulator's effects, mirrors, plans and captures the touches, aligns and saves the
/// session to `saved`.
fn run_cell(
    scene: &Scene,
    links: &Links,
    children: &mut [&mut ChildProcess],
    saved: &std::path::Path,
    progress: &mut impl FnMut(&str),
) -> Result<Captured, CliError> {
    let reply_within = Duration::from_secs(10);
    if let Some(effects) = &scene.encoder_effects {
        links
            .control::<Done>(&SimCommand::Effects(effects.clone()), reply_within)
            .map_err(|error| CliError::Failure(format!("sim-robot refused the effect: {error}")))?;
    }
    start_mirroring(links, children)?;
    progress(&format!(
        "sim-robot plans {} touches on the part at its hidden pose",
        scene.probe.touches
    ));
    // Planning runs dozens of IK solves per touch: give it longer than a plain request.
    let plan: ProbePlan = links
        .control(
            &SimCommand::Probe(Box::new(scene.probe.clone())),
            Duration::from_secs(120),
        )
        .map_err(|error| {
            CliError::Failure(format!("sim-robot could not probe the part: {error}"))
        })?;
    let tilts_deg: Vec<String> = plan
        .tilts_rad
        .iter()
        .map(|tilt| format!("{:.0}", tilt.to_degrees()))
        .collect();
    progress(&format!(
        "probe tilts from the normal (deg): {}",
        tilts_deg.join(" ")
    ));
    capture_touches(links, children, &plan, scene.on_the_fly(), &mut *progress)?;
    let aligned = links.service::<AlignReport>(ServiceCommand::Align)?;
    let path = saved.display().to_string();
    links
        .service::<SavedReply>(ServiceCommand::Save(PathRequest { path }))?
        .map_err(|reason| CliError::Failure(format!("save failed: {reason}")))?;
    // Stopping the mirror is a courtesy: the children are terminated next either way.
    let _ = links.service::<MirroringReply>(ServiceCommand::Stop);
    check_alive(children)?;
    Ok(Captured { aligned, plan })
}

impl DemoOutput {
    pub fn to_text(&self) -> String {
        let mut text = format!(
            "{} touches on the {} aligned the part:\n  nominal pose error: {:8.3} mm  {:8.3} mrad\n  aligned pose error: {:8.5} mm  {:8.5} mrad\n  residual rms {:.4} mm, alignment {:.1} ms\n",
            self.inspections,
            self.robot,
            self.nominal_error_m * 1e3,
            self.nominal_error_rad * 1e3,
            self.pose_error_m * 1e3,
            self.pose_error_rad * 1e3,
            self.rms_m * 1e3,
            self.align_time_s * 1e3
        );
        text += &format!(
            "simulated effect: {}; diagnosis: {} ({})\n",
            self.effect, self.diagnosis.verdict, self.diagnosis.explanation
        );
        if let Some(effect) = &self.diagnosis.effect {
            for (key, value) in &effect.params {
                let stderr = effect.stderr.get(key).copied().unwrap_or(f64::NAN);
                text += &format!("  {key} = {value:.4e} +- {stderr:.1e}\n");
            }
        }
        text += &format!(
            "  pose error after modelling it: {:8.5} mm  {:8.5} mrad\n",
            self.pose_error_after_diagnosis_m * 1e3,
            self.pose_error_after_diagnosis_rad * 1e3
        );
        if let (Some(m), Some(rad)) = (
            self.nominal_kinematics_pose_error_m,
            self.nominal_kinematics_pose_error_rad,
        ) {
            text += &format!(
                "controller calibration {} used; with the nominal kinematics instead: {:8.3} mm  {:8.3} mrad\n",
                self.calibration_hash.as_deref().unwrap_or("(no hash)"),
                m * 1e3,
                rad * 1e3
            );
        }
        text
    }
}
