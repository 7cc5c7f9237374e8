//! Helpers for cross-service tests: building and spawning the project's binaries, reading their
//! `READY` line (bounded by a timeout, never a sleep), stopping them with SIGTERM, and the
//! Python venv third-party clients run from.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

/// A spawned service, killed when dropped.
#[derive(Debug)]
pub struct Service {
    pub child: Child,
    /// `key=value` pairs of its READY line.
    pub endpoints: Vec<(String, String)>,
}

impl Service {
    pub fn endpoint(&self, key: &str) -> &str {
        self.endpoints
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
            .unwrap_or_else(|| panic!("no '{key}' in the READY line {:?}", self.endpoints))
    }

    /// Sends SIGTERM and returns the exit status, waiting at most `within`.
    pub fn terminate(mut self, within: Duration) -> Option<std::process::ExitStatus> {
        let _ = Command::new("kill")
            .arg("-TERM")
            .arg(self.child.id().to_string())
            .status();
        let deadline = std::time::Instant::now() + within;
        loop {
            if let Ok(Some(status)) = self.child.try_wait() {
                return Some(status);
            }
            if std::time::Instant::now() > deadline {
                return None;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Service {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Path of a binary of this workspace, next to the test executable's profile directory.
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
    let mut child = Command::new(&program)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .map_err(|error| format!("cannot spawn {}: {error}", program.display()))?;
    let stdout = child.stdout.take().expect("piped stdout");
    let (sender, receiver) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if line.starts_with("READY") {
                let _ = sender.send(line);
            }
        }
    });
    // The reader drops the sender when stdout closes, so an early exit ends the wait at once.
    let Ok(line) = receiver.recv_timeout(within) else {
        let _ = child.kill();
        let status = child.wait();
        return Err(format!(
            "{} {args:?} printed no READY line within {within:?} (exit: {status:?})",
            program.display()
        ));
    };
    let endpoints = line
        .split_whitespace()
        .skip(1)
        .filter_map(|pair| {
            pair.split_once('=')
                .map(|(k, v)| (k.to_owned(), v.to_owned()))
        })
        .collect();
    Ok(Service { child, endpoints })
}

/// The workspace root.
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// `cargo test -p system-tests` does not build other packages' binaries: build the workspace's.
/// Always, not only when missing: a binary left from before a source change would be tested
/// instead of the code in the tree (cargo makes this a quick no-op when they are fresh).
pub fn ensure_binaries() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_owned());
    let mut command = Command::new(cargo);
    // The profile these tests were built with, so that the build reuses their artifacts (a
    // plain `cargo build` would compile every dependency again for the dev profile) and the
    // binaries land next to the tests.
    let release = binary("").components().any(|c| c.as_os_str() == "release");
    let profile = if release { "release" } else { "test" };
    // Every binary of the workspace, features unified as `cargo test --workspace` unifies them:
    // building only some packages could pick other features and recompile shared dependencies.
    command
        .args(["build", "--profile", profile, "--workspace", "--bins"])
        .current_dir(repo_root());
    let status = command.status().expect("cargo runs");
    assert!(
        status.success(),
        "cargo build of the workspace binaries failed"
    );
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
