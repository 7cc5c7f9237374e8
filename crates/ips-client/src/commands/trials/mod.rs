//! `ips trials`: the thesis's alignment trials on its test part ([`parts`]: PSA and PCA tables)
//! or on a robot in a cloud ([`robots`]), printed as the docs' markdown tables or as JSON.

mod args;
pub mod parts;
pub mod robots;

pub use args::TrialsArgs;

use crate::{CliError, json_line};

/// The command: the thesis's table of part trials, or of a robot's with `--robot` or `--urdf`
/// (progress on stderr).
pub fn command(args: &TrialsArgs) -> Result<String, CliError> {
    let progress = |line: &str| eprintln!("{line}");
    if args.robot.is_some() || args.urdf.is_some() {
        let output = robots::run(args, progress)?;
        return if args.json {
            json_line(&output)
        } else {
            Ok(output.to_markdown())
        };
    }
    let output = parts::run(args, progress)?;
    if args.json {
        json_line(&output)
    } else {
        Ok(output.to_markdown())
    }
}
