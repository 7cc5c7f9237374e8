//! The simulated cell as child processes: sim-robot standing in for the controller, robot-bridge
//! and, if asked, `ips serve`, each on free ports read back from its `READY key=value ...` line.
//! `ips demo` and the system tests launch the cell through this one crate, so they start it the
//! same way a user would.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use align_core::robots::ShippedRobot;

/// Why the cell could not be started or a child failed.
#[derive(Debug, thiserror::Error)]
pub enum CellError {
    #[error("'{}' not found; build the services first: cargo build --locked -p sim-robot -p robot-bridge -p ips-client", path.display())]
    BinaryMissing { path: PathBuf },
    #[error("cannot start {name}: {source}")]
    Spawn {
        name: String,
        source: std::io::Error,
    },
    #[error("{name} did not report READY within {within:?} ({state})")]
    NotReady {
        name: String,
        within: Duration,
        state: String,
    },
    #[error("{name} printed no '{key}' endpoint")]
    NoEndpoint { name: String, key: String },
    #[error("cargo build of the workspace binaries failed ({status})")]
    Build { status: ExitStatus },
    #[error("{name} was still running after {within:?}")]
    StillRunning { name: String, within: Duration },
    #[error("{name} exited early ({status})")]
    Exited { name: String, status: ExitStatus },
}

/// A spawned service, killed when dropped.
#[derive(Debug)]
pub struct ChildProcess {
    pub name: String,
    pub child: Child,
    /// The `key=value` pairs of its READY line.
    pub endpoints: Vec<(String, String)>,
}

impl ChildProcess {
    /// The value of `key` in the READY line.
    pub fn endpoint(&self, key: &str) -> Result<&str, CellError> {
        self.endpoints
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
            .ok_or_else(|| CellError::NoEndpoint {
                name: self.name.clone(),
                key: key.to_owned(),
            })
    }

    /// The port of a `host:port` (or `udp://host:port`) endpoint.
    pub fn port(&self, key: &str) -> Result<String, CellError> {
        let endpoint = self.endpoint(key)?;
        Ok(endpoint.rsplit(':').next().unwrap_or(endpoint).to_owned())
    }

    /// An error when the child has exited.
    pub fn check_alive(&mut self) -> Result<(), CellError> {
        match self.child.try_wait() {
            Ok(Some(status)) => Err(CellError::Exited {
                name: self.name.clone(),
                status,
            }),
            _ => Ok(()),
        }
    }

    /// Sends SIGTERM and returns the exit status, waiting at most `within`; a child still
    /// running then is killed (on drop) and `None` returned.
    pub fn terminate(mut self, within: Duration) -> Option<ExitStatus> {
        let _ = Command::new("kill")
            .arg("-TERM")
            .arg(self.child.id().to_string())
            .status();
        let deadline = Instant::now() + within;
        loop {
            if let Ok(Some(status)) = self.child.try_wait() {
                return Some(status);
            }
            if Instant::now() > deadline {
                return None;
            }
            // A child's exit raises no event this process can wait on with a timeout.
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for ChildProcess {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// The binary `name` next to the running executable (`ips` finds `sim-robot` this way), or in
/// the profile directory above a test executable in `deps/`.
pub fn sibling_binary(name: &str) -> Result<PathBuf, CellError> {
    let here = std::env::current_exe().map_err(|source| CellError::Spawn {
        name: name.to_owned(),
        source,
    })?;
    let mut folder = here.parent().map(Path::to_owned).unwrap_or_default();
    if folder.ends_with("deps") {
        folder.pop();
    }
    let path = folder.join(name);
    if path.exists() {
        Ok(path)
    } else {
        Err(CellError::BinaryMissing { path })
    }
}

/// Spawns `program` and waits up to `within` for its `READY key=value ...` line; a program that
/// exits or stays silent is reported and killed.
pub fn spawn(
    name: &str,
    program: &Path,
    args: &[String],
    within: Duration,
) -> Result<ChildProcess, CellError> {
    let mut command = Command::new(program);
    // The services log at info to stderr; a child of the demo or a test says only what is
    // wrong unless the user asks for more.
    if std::env::var_os("RUST_LOG").is_none() {
        command.env("RUST_LOG", "warn");
    }
    let mut child = command
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .map_err(|source| CellError::Spawn {
            name: name.to_owned(),
            source,
        })?;
    let stdout = child.stdout.take();
    let (sender, receiver) = mpsc::channel();
    std::thread::spawn(move || {
        for line in stdout
            .into_iter()
            .flat_map(|out| BufReader::new(out).lines().map_while(Result::ok))
        {
            if line.starts_with("READY") {
                let _ = sender.send(line);
            }
        }
    });
    let mut process = ChildProcess {
        name: name.to_owned(),
        child,
        endpoints: Vec::new(),
    };
    // The reader drops the sender when stdout closes, so an early exit ends the wait at once.
    let line = receiver.recv_timeout(within).map_err(|_| {
        let state = match process.check_alive() {
            Ok(()) => "still running".to_owned(),
            Err(error) => error.to_string(),
        };
        CellError::NotReady {
            name: name.to_owned(),
            within,
            state,
        }
    })?;
    process.endpoints = line
        .split_whitespace()
        .skip(1)
        .filter_map(|pair| {
            pair.split_once('=')
                .map(|(k, v)| (k.to_owned(), v.to_owned()))
        })
        .collect();
    Ok(process)
}

/// Builds every binary of the workspace at `workspace_root`, for tests: `cargo test -p X` does
/// not build other packages' binaries, and one left from before a source change would be tested
/// instead of the code in the tree (cargo makes this a quick no-op when they are fresh). The
/// profile is the running executable's (`release` or the tests' own), so the build reuses its
/// artifacts and the binaries land next to it; every binary at once, so features unify as in
/// `cargo test --workspace` and shared dependencies are not compiled again.
pub fn build_workspace_binaries(workspace_root: &Path) -> Result<(), CellError> {
    let here = std::env::current_exe().map_err(|source| CellError::Spawn {
        name: "cargo".to_owned(),
        source,
    })?;
    let release = here.components().any(|c| c.as_os_str() == "release");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_owned());
    let status = Command::new(cargo)
        .args([
            "build",
            "--profile",
            if release { "release" } else { "test" },
        ])
        .args(["--workspace", "--bins"])
        .current_dir(workspace_root)
        .status()
        .map_err(|source| CellError::Spawn {
            name: "cargo".to_owned(),
            source,
        })?;
    if status.success() {
        Ok(())
    } else {
        Err(CellError::Build { status })
    }
}

/// Runs `program` with `args` to its exit and returns its exit code and stderr; a program still
/// running after `within` (it accepted its arguments and went on to serve) is killed and
/// reported. For tests of refused arguments.
pub fn run_to_exit(
    program: &Path,
    args: &[&str],
    within: Duration,
) -> Result<(Option<i32>, String), CellError> {
    let name = program.display().to_string();
    let mut child = Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|source| CellError::Spawn {
            name: name.clone(),
            source,
        })?;
    let stderr_pipe = child.stderr.take();
    let (sender, receiver) = mpsc::channel();
    // The pipe reaches its end when the process exits.
    std::thread::spawn(move || {
        let mut stderr = String::new();
        if let Some(mut pipe) = stderr_pipe {
            let _ = std::io::Read::read_to_string(&mut pipe, &mut stderr);
        }
        let _ = sender.send(stderr);
    });
    match receiver.recv_timeout(within) {
        Ok(stderr) => {
            let status = child.wait().map_err(|source| CellError::Spawn {
                name: name.clone(),
                source,
            })?;
            Ok((status.code(), stderr))
        }
        Err(_) => {
            let _ = child.kill();
            let _ = child.wait();
            Err(CellError::StillRunning { name, within })
        }
    }
}

/// How long a service may take to print READY.
pub const READY_WITHIN: Duration = Duration::from_secs(30);

fn owned(args: &[&str]) -> Vec<String> {
    args.iter().map(|a| (*a).to_owned()).collect()
}

/// The simulated controller and the bridge, on free ports.
#[derive(Debug)]
pub struct Cell {
    pub sim: ChildProcess,
    pub bridge: ChildProcess,
}

impl Cell {
    /// Starts sim-robot as `robot` and a bridge for it. A UR controller serves RTDE and the
    /// bridge connects to it; an iiwa controller sends FRI to the bridge, so the bridge listens
    /// first. The binaries are looked for next to the running executable.
    pub fn start(robot: ShippedRobot) -> Result<Self, CellError> {
        Self::start_calibrated(robot, None)
    }

    /// [`Cell::start`] with a UR arm whose true kinematics are its nominal DH table plus the
    /// deltas in the `calibration` file (`sim-robot --calibration`): its primary interface
    /// reports the calibrated table, and the bridge reads it.
    pub fn start_calibrated(
        robot: ShippedRobot,
        calibration: Option<&Path>,
    ) -> Result<Self, CellError> {
        let sim_program = sibling_binary("sim-robot")?;
        let bridge_program = sibling_binary("robot-bridge")?;
        let zmq_endpoints = ["--rep", "tcp://127.0.0.1:*", "--pub", "tcp://127.0.0.1:*"];
        if robot == ShippedRobot::Iiwa14 {
            let mut bridge_args = owned(&[
                "--backend",
                "iiwa",
                "--robot-host",
                "127.0.0.1",
                "--fri-port",
                "0",
            ]);
            bridge_args.extend(owned(&zmq_endpoints));
            let bridge = spawn("robot-bridge", &bridge_program, &bridge_args, READY_WITHIN)?;
            let fri_target = format!("127.0.0.1:{}", bridge.port("fri")?);
            let sim = spawn(
                "sim-robot",
                &sim_program,
                &owned(&[
                    "--robot",
                    robot.name(),
                    "--fri-target",
                    &fri_target,
                    "--control",
                    "tcp://127.0.0.1:*",
                ]),
                READY_WITHIN,
            )?;
            return Ok(Self { sim, bridge });
        }
        let mut sim_args = owned(&[
            "--robot",
            robot.name(),
            "--rtde-host",
            "127.0.0.1",
            "--rtde-port",
            "0",
            "--primary-port",
            "0",
            "--control",
            "tcp://127.0.0.1:*",
        ]);
        if let Some(calibration) = calibration {
            sim_args.push("--calibration".to_owned());
            sim_args.push(calibration.display().to_string());
        }
        let sim = spawn("sim-robot", &sim_program, &sim_args, READY_WITHIN)?;
        let rtde_port = sim.port("rtde")?;
        let primary_port = sim.port("primary")?;
        let mut bridge_args = owned(&[
            "--backend",
            "ur",
            "--robot-host",
            "127.0.0.1",
            "--rtde-port",
            &rtde_port,
            "--primary-port",
            &primary_port,
        ]);
        bridge_args.extend(owned(&zmq_endpoints));
        let bridge = spawn("robot-bridge", &bridge_program, &bridge_args, READY_WITHIN)?;
        Ok(Self { sim, bridge })
    }

    /// Starts `ips serve` (the binary next to the running executable, or `ips_program`) for
    /// `session`, journaling to `journal`, connected to this cell's bridge.
    pub fn serve(
        &self,
        ips_program: &Path,
        session: &Path,
        journal: &Path,
    ) -> Result<ChildProcess, CellError> {
        let args = vec![
            "serve".to_owned(),
            "--session".to_owned(),
            session.display().to_string(),
            "--journal".to_owned(),
            journal.display().to_string(),
            "--rep".to_owned(),
            "tcp://127.0.0.1:*".to_owned(),
            "--bridge-rep".to_owned(),
            self.bridge.endpoint("rep")?.to_owned(),
            "--bridge-pub".to_owned(),
            self.bridge.endpoint("pub")?.to_owned(),
        ];
        spawn("ips serve", ips_program, &args, READY_WITHIN)
    }
}
