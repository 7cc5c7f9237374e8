//! Command-line definition of `ips`: the subcommands. Each command's arguments, its run and
//! its output live in its own file under [`crate::commands`].

use clap::{Parser, Subcommand};

use crate::commands;

#[derive(Debug, Parser)]
#[command(
    name = "ips",
    version,
    about = "Align a simulation's virtual geometry with the real cell using a collaborative robot",
    long_about = "ips is the IPS side of cobot-align: the alignment service and its clients, the \
                  alignments (touches, scanner clouds, robots in clouds), the diagnosis of what the \
                  model lacks, and the trials behind the docs' tables. Exit codes: 0 success; 2 bad \
                  input, refused by ips or by the service (a one-line reason on stderr); 1 a \
                  failure at run time (no reply from the service in time, a child process that \
                  died, a file that cannot be written)."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Forward kinematics: the pose of one link relative to another at given joint values.
    #[command(
        after_help = "Example:\n  ips fk --urdf robots/ur10.urdf --base base_link --tip tool0 \\\n         --q 0,-1.57,1.57,-1.57,-1.57,0 --json"
    )]
    Fk(commands::fk::FkArgs),
    /// A UR robot's factory calibration (from its controller's primary interface, or a
    /// calibration file) as the kinematics file UR's ROS drivers load, with its hash.
    #[command(
        after_help = "Examples:\n  ips kinematics --robot ur10e --robot-host 192.168.1.10 > my_robot_calibration.yaml\n  ips kinematics --robot ur10e --calibration calibration.json --json"
    )]
    Kinematics(commands::kinematics::KinematicsArgs),
    /// The thesis's alignment trials (PSA): random displacements of a test part, recovered by
    /// the thesis's method and by ours on the same seeds; prints the thesis's table.
    #[command(
        after_help = "Examples:\n  ips trials --trials 50 --deltas 50,100,200,500,1000 > docs/psa-trials.md\n  ips trials --robot ur10 --deltas 500 --hierarchical-only\n  ips trials --urdf my_robot.urdf --package-dir my_robot_support=/opt/my_robot_support \\\n      --home 0,0.3,-0.2,0,0.6,0 --deltas 50,100 --trials 10 --hierarchical-only"
    )]
    Trials(commands::trials::TrialsArgs),
    /// Where to touch: the 3-2-1 plan for the session's part at its nominal pose (points and
    /// approach directions in the base frame, joint targets for the session's robot).
    #[command(
        after_help = "Examples:\n  ips plan examples/step_block_ur10/session.json\n  ips plan examples/step_block_ur10/session.json --touches 12 --vary-tilt --json"
    )]
    Plan(commands::plan::PlanArgs),
    /// Point Set Alignment: move the session's part until it matches its inspections.
    #[command(
        after_help = "Examples:\n  ips align examples/step_block_ur10/session.json --json\n  ips align --service tcp://127.0.0.1:4000      (the running service's inspections)"
    )]
    Align(commands::align::AlignArgs),
    /// Point Cloud Alignment: move a part's mesh until it matches a scanner cloud (here, or
    /// by the running service with --service).
    #[command(
        name = "align-cloud",
        after_help = "Examples:\n  ips align-cloud --cloud scan.ply --mesh part.stl --mesh-scale 0.001 \\\n      --pose 0.6,0.1,0.05,0,0,0.3 --delta 0.1 --json\n  ips align-cloud --service tcp://127.0.0.1:4000 --cloud /data/scan.xyz --cloud-scale 0.001\n      (asks the running service: its session part from the nominal pose, delta 0.1 m;\n      paths as the service sees them)\n\nThe report says how sure the pose is: whether another pose fits as well (AMBIGUOUS), the\n95% limits of position and rotation from the noise measured on the scan, the weakest motion,\nand LOOSE when the pose may be --tolerance-mm (1) or more from the truth."
    )]
    AlignCloud(commands::align_cloud::AlignCloudArgs),
    /// Hierarchical alignment of a robot in a scanner cloud: its base pose and joint values,
    /// each link constrained by its parent (URDF with link geometry).
    #[command(
        name = "align-robot",
        after_help = "Example:\n  ips align-robot --urdf robots/ur10.urdf --cloud scan.xyz \\\n      --base-pose 0,0,0,0,0,0 --q0 0,-1.57,1.57,-1.57,-1.57,0 --delta 0.1 --json"
    )]
    AlignRobot(commands::align_robot::AlignRobotArgs),
    /// The alignment service: mirrors the robot through robot-bridge, captures inspections,
    /// journals them, aligns on request (REP socket, thesis envelope).
    Serve(commands::serve::ServeArgs),
    /// Ask the service to start mirroring the robot (inspection mode).
    Start(commands::service::ServiceArgs),
    /// Ask the service to stop mirroring.
    Stop(commands::service::ServiceArgs),
    /// Capture the robot's current pose as an inspection (or its pose at a controller time).
    Get(commands::service::GetArgs),
    /// List the inspections taken.
    List(commands::service::ServiceArgs),
    /// Remove inspections by id.
    Remove(commands::service::RemoveArgs),
    /// Remove every inspection.
    Reset(commands::service::ServiceArgs),
    /// Write the service's session (robot, tool, part, inspections) to a file.
    Save(commands::service::PathArgs),
    /// Replace the service's inspections with those of a session file.
    Load(commands::service::PathArgs),
    /// The service's state: mirroring, inspections, age of the latest joint state.
    Status(commands::service::ServiceArgs),
    /// The latest alignment and diagnosis the service computed (whoever asked for them), and
    /// whether they still describe its inspections; the latest next-touch suggestion.
    Results(commands::service::ServiceArgs),
    /// The whole loop on the simulator: sim-robot, robot-bridge and the service as child
    /// processes, nine touches at a hidden part pose, alignment, error against the truth.
    Demo(commands::demo::DemoArgs),
    /// Align, then trace the residual to an effect the model lacks (probe radius, TCP offset,
    /// joint offsets, part scale, trigger latency) and report the error before and after: of a
    /// SESSION file, or of the running service's inspections with --service.
    Diagnose(commands::diagnose::DiagnoseArgs),
}
