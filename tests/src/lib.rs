//! Helpers for cross-service tests: the `cell` crate's launcher (the one `ips demo` uses) with
//! panicking shorthands, and the Python venv third-party clients run from.

use std::path::PathBuf;
use std::process::Command;
use std::time::Duration;

pub use cell::{Cell, ChildProcess as Service};

/// Path of a binary of this workspace, next to the test executable's profile directory (it may
/// not exist yet: [`ensure_binaries`] builds it).
pub fn binary(name: &str) -> PathBuf {
    let mut path = std::env::current_exe().expect("test executable path");
    path.pop();
    if path.ends_with("deps") {
        path.pop();
    }
    path.join(name)
}

/// Spawns `program` and waits up to `within` for its `READY key=value ...` line.
pub fn spawn(program: PathBuf, args: &[&str], within: Duration) -> Service {
    try_spawn(program, args, within).unwrap_or_else(|reason| panic!("{reason}"))
}

/// As [`spawn`], but a program that exits or stays silent is reported (and killed), not a
/// panic: for callers that retry, e.g. with another address.
pub fn try_spawn(program: PathBuf, args: &[&str], within: Duration) -> Result<Service, String> {
    let name = program.file_name().map_or_else(
        || program.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    let args: Vec<String> = args.iter().map(|a| (*a).to_owned()).collect();
    cell::spawn(&name, &program, &args, within).map_err(|error| format!("{error} (args {args:?})"))
}

/// sim-robot as `robot` and a bridge for it, on free ports, as `ips demo` starts them.
pub fn start_cell(robot: align_core::robots::ShippedRobot) -> Cell {
    Cell::start(robot).unwrap_or_else(|error| panic!("{error}"))
}

/// The workspace root.
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Builds the workspace's binaries (`cargo test -p system-tests` alone does not).
pub fn ensure_binaries() {
    cell::build_workspace_binaries(&repo_root()).unwrap_or_else(|error| panic!("{error}"));
}

/// The venv's Python after `scripts/python-env.sh` made sure its clients are installed. Its
/// output is shown on failure, e.g. when pip cannot reach the package index.
pub fn python() -> PathBuf {
    let output = Command::new("bash")
        .arg(repo_root().join("scripts/python-env.sh"))
        .output()
        .expect("bash runs scripts/python-env.sh");
    assert!(
        output.status.success(),
        "scripts/python-env.sh failed, so the third-party clients these tests need are missing:\n{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    repo_root().join(".venv/bin/python")
}
