//! Command-line definition of `ips`.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

#[derive(Debug, Parser)]
#[command(
    name = "ips",
    version,
    about = "Align a simulation's virtual geometry with the real cell using a collaborative robot",
    long_about = "ips is the IPS side of cobot-align: the alignment service and its clients, the \
                  alignments (touches, scanner clouds, robots in clouds), the diagnosis of what the \
                  model lacks, and the trials behind the docs' tables. Exit code 0 means success, 2 \
                  bad input (with a one-line reason on stderr)."
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
    Fk(FkArgs),
    /// The thesis's alignment trials (PSA): random displacements of a test part, recovered by
    /// the thesis's method and by ours on the same seeds; prints the thesis's table.
    #[command(
        after_help = "Examples:\n  ips trials --trials 50 --deltas 50,100,200,500,1000 > docs/psa-trials.md\n  ips trials --robot ur10 --deltas 500 --hierarchical-only\n  ips trials --urdf my_robot.urdf --package-dir my_robot_support=/opt/my_robot_support \\\n      --home 0,0.3,-0.2,0,0.6,0 --deltas 50,100 --trials 10 --hierarchical-only"
    )]
    Trials(TrialsArgs),
    /// Point Set Alignment: move the session's part until it matches its inspections.
    #[command(
        after_help = "Examples:\n  ips align examples/step_block_ur10/session.json --json\n  ips align --service tcp://127.0.0.1:4000      (the running service's inspections)"
    )]
    Align(AlignArgs),
    /// Point Cloud Alignment: move a part's mesh until it matches a scanner cloud (here, or
    /// by the running service with --service).
    #[command(
        name = "align-cloud",
        after_help = "Examples:\n  ips align-cloud --cloud scan.ply --mesh part.stl --mesh-scale 0.001 \\\n      --pose 0.6,0.1,0.05,0,0,0.3 --delta 0.1 --json\n  ips align-cloud --service tcp://127.0.0.1:4000 --cloud /data/scan.xyz --cloud-scale 0.001\n      (asks the running service: its session part from the nominal pose, delta 0.1 m;\n      paths as the service sees them)"
    )]
    AlignCloud(crate::align_cloud::AlignCloudArgs),
    /// Hierarchical alignment of a robot in a scanner cloud: its base pose and joint values,
    /// each link constrained by its parent (URDF with link geometry).
    #[command(
        name = "align-robot",
        after_help = "Example:\n  ips align-robot --urdf robots/ur10.urdf --cloud scan.xyz \\\n      --base-pose 0,0,0,0,0,0 --q0 0,-1.57,1.57,-1.57,-1.57,0 --delta 0.1 --json"
    )]
    AlignRobot(crate::align_robot::AlignRobotArgs),
    /// The alignment service: mirrors the robot through robot-bridge, captures inspections,
    /// journals them, aligns on request (REP socket, thesis envelope).
    Serve(ServeArgs),
    /// Ask the service to start mirroring the robot (inspection mode).
    Start(ServiceArgs),
    /// Ask the service to stop mirroring.
    Stop(ServiceArgs),
    /// Capture the robot's current pose as an inspection (or its pose at a controller time).
    Get(GetArgs),
    /// List the inspections taken.
    List(ServiceArgs),
    /// Remove inspections by id.
    Remove(RemoveArgs),
    /// Remove every inspection.
    Reset(ServiceArgs),
    /// Write the service's session (robot, tool, part, inspections) to a file.
    Save(PathArgs),
    /// Replace the service's inspections with those of a session file.
    Load(PathArgs),
    /// The service's state: mirroring, inspections, age of the latest joint state.
    Status(ServiceArgs),
    /// The whole loop on the simulator: sim-robot, robot-bridge and the service as child
    /// processes, nine touches at a hidden part pose, alignment, error against the truth.
    Demo(crate::demo::DemoArgs),
    /// Align, then trace the residual to an effect the model lacks (probe radius, TCP offset,
    /// joint offsets, part scale, trigger latency) and report the error before and after: of a
    /// SESSION file, or of the running service's inspections with --service.
    Diagnose(crate::diagnose::DiagnoseArgs),
}

#[derive(Debug, Args)]
pub struct ServeArgs {
    /// Session file naming robot, tool and part (its inspections start the list when no
    /// journal exists yet).
    #[arg(long, value_name = "FILE")]
    pub session: PathBuf,
    /// Journal of inspections (appended and flushed before every acknowledgement).
    #[arg(long, value_name = "FILE", default_value = "inspections.journal")]
    pub journal: PathBuf,
    #[arg(long, default_value = "tcp://*:4000")]
    pub rep: String,
    #[arg(long, default_value = "tcp://127.0.0.1:2000")]
    pub bridge_rep: String,
    #[arg(long, default_value = "tcp://127.0.0.1:3000")]
    pub bridge_pub: String,
    /// Oldest joint state a `get` accepts, s.
    #[arg(long, default_value_t = 0.1)]
    pub max_sample_age: f64,
    /// Fastest tool a `get` accepts, m/s.
    #[arg(long, default_value_t = 0.005)]
    pub max_tool_speed: f64,
}

#[derive(Debug, Args)]
pub struct ServiceArgs {
    /// The service's REP endpoint.
    #[arg(long, default_value = "tcp://127.0.0.1:4000")]
    pub service: String,
    /// Print the reply's JSON document.
    #[arg(long)]
    pub json: bool,
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
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
#[command(group(clap::ArgGroup::new("robot_source").args(["robot", "urdf"])))]
pub struct TrialsArgs {
    /// Trials per delta.
    #[arg(long, default_value_t = 50)]
    pub trials: usize,
    /// Displacement bounds delta, mm, comma-separated.
    #[arg(long, default_value = "50,100,200,500,1000")]
    pub deltas: String,
    /// Touch count (6 = 3-2-1, 9 = 3-2-1 plus top, back and the asymmetric step); default both.
    #[arg(long)]
    pub touches: Option<usize>,
    /// Seed of the displacement generator.
    #[arg(long, default_value_t = 2024)]
    pub seed: u64,
    /// Point Cloud Alignment trials instead (a cluttered scan of the part: floor, a neighbouring
    /// box, 10% outliers, 0.3 mm noise).
    #[arg(long)]
    pub pca: bool,
    /// Robot trials instead: a shipped robot (ur10, ur10e, iiwa14) in a cluttered scan, the
    /// whole robot and each link aligned independently (thesis PCA) and hierarchically.
    #[arg(long, value_name = "NAME", conflicts_with_all = ["pca", "touches"])]
    pub robot: Option<String>,
    /// Robot trials on a robot of your own instead: its URDF with link geometry (visual or
    /// collision meshes or primitives; expand xacro files first), in the scene of --robot.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["pca", "touches"])]
    pub urdf: Option<PathBuf>,
    /// With --urdf: where a ROS package named in package:// mesh URIs lives; repeatable.
    /// Packages not given are looked for among the URDF file's parent folders.
    #[arg(long = "package-dir", value_name = "NAME=DIR", requires = "urdf")]
    pub package_dirs: Vec<String>,
    /// With --robot or --urdf: the joint values the robot is scanned at, one per moving joint
    /// that mimics none, in the URDF's order (rad or m). Default: the shipped robot's home
    /// pose; for --urdf every joint at 0, or at the limit nearest 0.
    #[arg(
        long,
        value_name = "A,B,...",
        allow_hyphen_values = true,
        requires = "robot_source"
    )]
    pub home: Option<String>,
    /// With --robot or --urdf: only the hierarchical alignment (the independent one takes most
    /// of the time).
    #[arg(long, requires = "robot_source")]
    pub hierarchical_only: bool,
    /// With --robot or --urdf: only the independent alignment (each method draws its own
    /// seeded starts, so its figures match those of a run with both).
    #[arg(long, requires = "robot_source", conflicts_with = "hierarchical_only")]
    pub independent_only: bool,
    /// With --robot or --urdf: start at this trial (0-based) of each delta's seeded sequence;
    /// the starts before it are drawn and skipped, so `--first-trial 31 --trials 1` reproduces
    /// trial 31 alone and a long run can be split into parts with the same figures.
    #[arg(long, value_name = "N", default_value_t = 0, requires = "robot_source")]
    pub first_trial: usize,
    /// Print one JSON document instead of Markdown tables.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct FkArgs {
    /// Robot description (URDF; expand xacro files first).
    #[arg(long, value_name = "FILE")]
    pub urdf: PathBuf,
    /// Where a ROS package named in package:// mesh URIs lives; repeatable. Packages not given
    /// are looked for among the URDF file's parent folders.
    #[arg(long = "package-dir", value_name = "NAME=DIR")]
    pub package_dirs: Vec<String>,
    /// Link the pose is expressed in.
    #[arg(long, value_name = "LINK")]
    pub base: String,
    /// Link whose pose is computed.
    #[arg(long, value_name = "LINK")]
    pub tip: String,
    /// Joint values of the chain's movable joints from base to tip, comma-separated
    /// (rad for revolute, m for prismatic). Use --q=-1,... when the first value is negative.
    #[arg(long, value_name = "A,B,C,...", allow_hyphen_values = true)]
    pub q: String,
    /// Print one JSON document instead of text.
    #[arg(long)]
    pub json: bool,
}
