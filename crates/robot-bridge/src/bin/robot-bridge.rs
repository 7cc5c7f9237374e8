use std::process::ExitCode;

use clap::{Parser, ValueEnum};
use protocol::DigitalInput;
use robot_bridge::backend::iiwa::{DEFAULT_FRI_PORT, DEFAULT_MIN_SILENCE_MS, IiwaConfig};
use robot_bridge::backend::ur::{DEFAULT_PRIMARY_PORT, DEFAULT_RTDE_PORT, UrConfig};
use robot_bridge::{BackendConfig, Config};
use signal_hook::consts::{SIGINT, SIGTERM};
use signal_hook::iterator::Signals;
use tracing_subscriber::EnvFilter;

/// Mirrors a cobot controller's joint states onto the thesis's ZeroMQ sockets.
#[derive(Debug, Parser)]
#[command(name = "robot-bridge", version)]
struct Args {
    /// Controller protocol: ur (RTDE client) or iiwa (FRI monitoring client).
    #[arg(long, value_parser = parse_backend)]
    backend: BackendChoice,
    /// Controller address (iiwa: only its FRI datagrams are accepted).
    #[arg(long)]
    robot_host: String,
    /// Instruction socket (REP).
    #[arg(long, default_value = "tcp://*:2000")]
    rep: String,
    /// Hardware-state socket (PUB).
    #[arg(long = "pub", default_value = "tcp://*:3000")]
    publish: String,
    // Each back end's own options, under its own heading in --help; a back end ignores the
    // others' (their defaults), as before.
    #[command(flatten)]
    ur: UrArgs,
    #[command(flatten)]
    iiwa: IiwaArgs,
}

/// The back ends a controller can be reached with from the command line.
#[derive(Debug, Clone, Copy, ValueEnum)]
enum BackendChoice {
    Ur,
    Iiwa,
}

// Port flags take `allow_negative_numbers` so that `-1` reaches their parser and is refused
// with its range, rather than read as an unknown flag.
#[derive(Debug, clap::Args)]
#[command(next_help_heading = "UR (--backend ur)")]
struct UrArgs {
    /// RTDE port of a UR controller, 1-65535.
    #[arg(
        long,
        default_value_t = DEFAULT_RTDE_PORT,
        value_parser = parse_controller_port,
        allow_negative_numbers = true,
    )]
    rtde_port: u16,
    /// Primary interface port of the UR controller, 1-65535: the robot's factory calibration
    /// (KINEMATICS_INFO) is read there on every connection and reported by `status`.
    #[arg(
        long,
        default_value_t = DEFAULT_PRIMARY_PORT,
        value_parser = parse_controller_port,
        allow_negative_numbers = true,
    )]
    primary_port: u16,
    /// Do not read the calibration (poses then rest on the nominal kinematics).
    #[arg(long)]
    no_calibration: bool,
}

#[derive(Debug, clap::Args)]
#[command(next_help_heading = "KUKA iiwa (--backend iiwa)")]
struct IiwaArgs {
    /// UDP port to receive FRI monitoring messages on, 0-65535; 0 picks a free one.
    #[arg(
        long,
        default_value_t = DEFAULT_FRI_PORT,
        value_parser = parse_listen_port,
        allow_negative_numbers = true,
    )]
    fri_port: u16,
    /// Publish an IO the Sunrise application registered for FRI as a digital input of hwState,
    /// NAME=INPUT (repeatable), e.g. --fri-input Probe.Trigger=DI0 for a touch-trigger probe
    /// that `ips serve --trigger DI0` then captures on. NAME as the IO configuration has it
    /// (Group.Name); INPUT one of DI0-DI7, CI0-CI7, TI0-TI1.
    #[arg(long = "fri-input", value_name = "NAME=INPUT", value_parser = parse_fri_input)]
    fri_inputs: Vec<(String, DigitalInput)>,
    /// The shortest silence, in ms (1-60000), after which the controller counts as lost; the
    /// limit is the longer of this and 3 send periods. Below 100 ms a busy host's scheduler
    /// stall can pass for a lost controller.
    #[arg(
        long = "fri-silence-ms",
        value_name = "MS",
        default_value_t = DEFAULT_MIN_SILENCE_MS,
        value_parser = clap::value_parser!(u64).range(1..=60_000),
        allow_negative_numbers = true,
    )]
    fri_min_silence_ms: u64,
}

/// `Group.Name=DI0`: an FRI IO and the digital input it becomes.
fn parse_fri_input(text: &str) -> Result<(String, DigitalInput), String> {
    let (name, input) = text
        .rsplit_once('=')
        .ok_or_else(|| format!("'{text}' is not NAME=INPUT (e.g. Probe.Trigger=DI0)"))?;
    let name = name.trim();
    if name.is_empty() || name.len() > kuka_fri::MAX_IO_NAME_BYTES || !name.is_ascii() {
        return Err(format!(
            "FRI IO name '{name}' must be 1-{} ASCII characters",
            kuka_fri::MAX_IO_NAME_BYTES
        ));
    }
    let input = input.parse::<DigitalInput>().map_err(|e| e.to_string())?;
    Ok((name.to_owned(), input))
}

/// As clap's own parser, with the reason users of earlier versions know.
fn parse_backend(name: &str) -> Result<BackendChoice, String> {
    BackendChoice::from_str(name, false).map_err(|_| {
        let known: Vec<String> = BackendChoice::value_variants()
            .iter()
            .filter_map(ValueEnum::to_possible_value)
            .map(|value| value.get_name().to_owned())
            .collect();
        format!(
            "unknown back end '{name}' (expected {})",
            known.join(" or ")
        )
    })
}

/// A port to connect to: 0 names no server.
fn parse_controller_port(text: &str) -> Result<u16, String> {
    match parse_listen_port(text)? {
        0 => Err("port 0 names no controller (expected 1-65535)".to_owned()),
        port => Ok(port),
    }
}

/// A port to listen on, 0 for a free one; `nan`, fractions, signs and values past 65535 are
/// refused by name.
fn parse_listen_port(text: &str) -> Result<u16, String> {
    text.parse()
        .map_err(|_| format!("'{text}' is not a port (expected a whole number 0-65535)"))
}

impl Args {
    fn into_config(self) -> Config {
        let robot_host = self.robot_host;
        let backend = match self.backend {
            BackendChoice::Ur => BackendConfig::Ur(UrConfig {
                robot_host,
                rtde_port: self.ur.rtde_port,
                primary_port: (!self.ur.no_calibration).then_some(self.ur.primary_port),
            }),
            BackendChoice::Iiwa => BackendConfig::Iiwa(IiwaConfig {
                robot_host,
                fri_port: self.iiwa.fri_port,
                inputs: self.iiwa.fri_inputs,
                min_silence_ms: self.iiwa.fri_min_silence_ms,
            }),
        };
        Config {
            backend,
            rep: self.rep,
            publish: self.publish,
        }
    }
}

fn main() -> ExitCode {
    let args = match Args::try_parse() {
        Ok(args) => args,
        Err(error) if !error.use_stderr() => {
            let _ = error.print();
            return ExitCode::SUCCESS;
        }
        Err(error) => {
            eprintln!(
                "robot-bridge: {}",
                error.to_string().lines().next().unwrap_or("bad arguments")
            );
            return ExitCode::from(2);
        }
    };
    init_logs();
    let config = args.into_config();
    let mut signals = match Signals::new([SIGINT, SIGTERM]) {
        Ok(signals) => signals,
        Err(error) => {
            eprintln!("robot-bridge: cannot handle signals: {error}");
            return ExitCode::from(1);
        }
    };
    let ready = |handle: &robot_bridge::Handle| match &handle.controller_endpoint {
        Some(controller) => println!(
            "READY rep={} pub={} fri={controller}",
            handle.rep_endpoint, handle.pub_endpoint
        ),
        None => println!(
            "READY rep={} pub={}",
            handle.rep_endpoint, handle.pub_endpoint
        ),
    };
    // Blocks until SIGINT or SIGTERM.
    let result = robot_bridge::run(&config, ready, || {
        signals.forever().next();
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("robot-bridge: {error}");
            ExitCode::from(2)
        }
    }
}

/// Logs to stderr at the levels `RUST_LOG` names (default `info`); stdout carries only the
/// READY line.
fn init_logs() {
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    let logs = tracing_subscriber::fmt().with_env_filter(filter);
    let _ = logs
        .with_writer(std::io::stderr)
        .with_target(false)
        .try_init();
}
