use std::process::ExitCode;

use align_core::robots::ShippedRobot;
use clap::Parser;
use signal_hook::consts::{SIGINT, SIGTERM};
use signal_hook::iterator::Signals;
use tracing_subscriber::EnvFilter;

/// A simulated cobot controller speaking the real controller's protocol (UR: RTDE server; iiwa:
/// FRI monitoring messages to a client), plus a ZeroMQ control socket for tests.
#[derive(Debug, Parser)]
#[command(name = "sim-robot", version)]
// Numeric flags take `allow_negative_numbers` so that `-5` reaches their parser and is refused
// with its range, rather than read as an unknown flag.
struct Args {
    /// Robot to simulate: ur10 (CB3, RTDE 125 Hz), ur10e (e-Series, RTDE 500 Hz), iiwa14 (FRI).
    #[arg(long, default_value = "ur10")]
    robot: String,
    /// RTDE port (UR mode), 0-65535; 0 picks a free one.
    #[arg(
        long,
        default_value_t = 30004,
        value_parser = parse_listen_port,
        allow_negative_numbers = true,
    )]
    rtde_port: u16,
    /// Address to listen on for RTDE.
    #[arg(long, default_value = "0.0.0.0")]
    rtde_host: String,
    /// Primary interface port (UR modes): the robot state with the kinematics; 0 picks a free
    /// port. Served on --rtde-host.
    #[arg(
        long,
        default_value_t = 30001,
        value_parser = parse_listen_port,
        allow_negative_numbers = true,
    )]
    primary_port: u16,
    /// The robot's calibration (UR modes): {"dh_delta": {"theta": [6], "a": [6], "d": [6],
    /// "alpha": [6]}}, rad and m, added to the nominal DH table. The arm then moves, reports
    /// and probes with the calibrated kinematics, and its primary interface says so.
    #[arg(long, value_name = "FILE")]
    calibration: Option<std::path::PathBuf>,
    /// Where the FRI client listens, HOST:PORT (iiwa mode).
    #[arg(long, default_value = "127.0.0.1:30200")]
    fri_target: String,
    /// Milliseconds between FRI monitoring messages, 1-100 (iiwa mode).
    #[arg(
        long,
        default_value_t = 5,
        value_parser = parse_send_period_ms,
        allow_negative_numbers = true,
    )]
    fri_send_period_ms: u32,
    /// The FRI client answers every n-th monitoring message, 1-100 (iiwa mode).
    #[arg(
        long,
        default_value_t = 1,
        value_parser = parse_receive_multiplier,
        allow_negative_numbers = true,
    )]
    fri_receive_multiplier: u32,
    /// Name of a boolean input the emulated Sunrise application registers for FRI, carrying the
    /// probe's trigger, e.g. Probe.Trigger (iiwa mode); without it the messages carry no IO.
    /// The bridge reads it with `--fri-input NAME=DI0`.
    #[arg(long, value_name = "NAME")]
    fri_trigger_io: Option<String>,
    /// Control socket endpoint.
    #[arg(long, default_value = "tcp://*:5000")]
    control: String,
}

/// The send periods the Sunrise controller allows. Checked here, for every robot, so that a bad
/// value is refused whatever `--robot` says (the library checks it again in iiwa mode).
const SEND_PERIOD_RANGE_MS: std::ops::RangeInclusive<u32> = 1..=100;
/// Beyond one answer in a hundred messages the link would not count as alive.
const RECEIVE_MULTIPLIER_RANGE: std::ops::RangeInclusive<u32> = 1..=100;

/// Whole milliseconds within [`SEND_PERIOD_RANGE_MS`], with the reason the library gives.
fn parse_send_period_ms(text: &str) -> Result<u32, String> {
    let period_ms = parse_whole_number(text)?;
    if !SEND_PERIOD_RANGE_MS.contains(&period_ms) {
        return Err(format!(
            "send period {period_ms} ms is outside the controller's {}-{} ms",
            SEND_PERIOD_RANGE_MS.start(),
            SEND_PERIOD_RANGE_MS.end()
        ));
    }
    Ok(period_ms)
}

fn parse_receive_multiplier(text: &str) -> Result<u32, String> {
    let multiplier = parse_whole_number(text)?;
    if !RECEIVE_MULTIPLIER_RANGE.contains(&multiplier) {
        return Err(format!(
            "receive multiplier {multiplier} is outside {}-{}",
            RECEIVE_MULTIPLIER_RANGE.start(),
            RECEIVE_MULTIPLIER_RANGE.end()
        ));
    }
    Ok(multiplier)
}

/// A port to listen on, 0 for a free one; `nan`, fractions, signs and values past 65535 are
/// refused by name.
fn parse_listen_port(text: &str) -> Result<u16, String> {
    text.parse()
        .map_err(|_| format!("'{text}' is not a port (expected a whole number 0-65535)"))
}

/// A non-negative whole number; `nan`, `inf`, fractions and signs are refused by name.
fn parse_whole_number(text: &str) -> Result<u32, String> {
    text.parse()
        .map_err(|_| format!("'{text}' is not a whole number"))
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
                "sim-robot: {}",
                error.to_string().lines().next().unwrap_or("bad arguments")
            );
            return ExitCode::from(2);
        }
    };
    let Some(robot) = ShippedRobot::from_name(&args.robot) else {
        eprintln!(
            "sim-robot: unknown robot '{}' (expected ur10, ur10e or iiwa14)",
            args.robot
        );
        return ExitCode::from(2);
    };
    let calibration = match args
        .calibration
        .as_deref()
        .map(read_calibration)
        .transpose()
    {
        Ok(calibration) => calibration,
        Err(reason) => {
            eprintln!("sim-robot: {reason}");
            return ExitCode::from(2);
        }
    };
    init_logs();
    let config = sim_robot::Config {
        robot,
        rtde_listen: format!("{}:{}", args.rtde_host, args.rtde_port),
        primary_listen: Some(format!("{}:{}", args.rtde_host, args.primary_port)),
        calibration,
        control: args.control,
        fri: sim_robot::FriSettings {
            target: args.fri_target,
            send_period_ms: args.fri_send_period_ms,
            receive_multiplier: args.fri_receive_multiplier,
            trigger_io: args.fri_trigger_io,
        },
    };
    let handle = match sim_robot::start(&config) {
        Ok(handle) => handle,
        Err(error) => {
            eprintln!("sim-robot: {error}");
            return ExitCode::from(2);
        }
    };
    let mut signals = match Signals::new([SIGINT, SIGTERM]) {
        Ok(signals) => signals,
        Err(error) => {
            eprintln!("sim-robot: cannot handle signals: {error}");
            return ExitCode::from(1);
        }
    };
    match (
        &handle.rtde_address,
        &handle.fri_address,
        &handle.fri_target,
    ) {
        (Some(rtde), _, _) => match &handle.primary_address {
            Some(primary) => println!(
                "READY rtde={rtde} primary={primary} control={}",
                handle.control_endpoint
            ),
            None => println!("READY rtde={rtde} control={}", handle.control_endpoint),
        },
        (None, Some(fri), Some(target)) => println!(
            "READY fri={fri} fri_target={target} control={}",
            handle.control_endpoint
        ),
        _ => println!("READY control={}", handle.control_endpoint),
    }
    // Blocks until SIGINT or SIGTERM.
    signals.forever().next();
    handle.stop();
    ExitCode::SUCCESS
}

/// Logs to stderr at the levels `RUST_LOG` names (default `info`); stdout carries only the
/// READY line.
/// The calibration file's deltas as a DH table, or why not.
fn read_calibration(path: &std::path::Path) -> Result<align_core::kinematics::DhTable, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|error| format!("cannot read calibration {}: {error}", path.display()))?;
    let file = protocol::calibration::CalibrationFile::parse(&text)
        .map_err(|reason| format!("calibration {}: {reason}", path.display()))?;
    let delta = file.dh_delta;
    align_core::kinematics::DhTable::new(delta.theta, delta.a, delta.d, delta.alpha)
        .map_err(|error| format!("calibration {}: {error}", path.display()))
}

fn init_logs() {
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    let logs = tracing_subscriber::fmt().with_env_filter(filter);
    let _ = logs
        .with_writer(std::io::stderr)
        .with_target(false)
        .try_init();
}
