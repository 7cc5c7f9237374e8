//! The arguments of `ips trials`.

use std::path::PathBuf;

use clap::Args;

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
