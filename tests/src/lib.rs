//! Helpers for cross-service tests: spawning the project's binaries, reading their `READY` line
//! (bounded by a timeout, never a sleep), and stopping them with SIGTERM.

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
    let mut child = Command::new(&program)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap_or_else(|error| panic!("cannot spawn {}: {error}", program.display()));
    let stdout = child.stdout.take().expect("piped stdout");
    let (sender, receiver) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if line.starts_with("READY") {
                let _ = sender.send(line);
            }
        }
    });
    let line = receiver.recv_timeout(within).unwrap_or_else(|_| {
        panic!(
            "{} printed no READY line within {within:?}",
            program.display()
        )
    });
    let endpoints = line
        .split_whitespace()
        .skip(1)
        .filter_map(|pair| {
            pair.split_once('=')
                .map(|(k, v)| (k.to_owned(), v.to_owned()))
        })
        .collect();
    Service { child, endpoints }
}
