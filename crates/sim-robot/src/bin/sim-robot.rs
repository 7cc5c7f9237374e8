use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use align_core::robots::ShippedRobot;
use clap::Parser;

/// A simulated cobot controller: UR RTDE server plus a ZeroMQ control socket for tests.
#[derive(Debug, Parser)]
#[command(name = "sim-robot", version)]
struct Args {
    /// Robot to simulate: ur10 (CB3, 125 Hz), ur10e (e-Series, 500 Hz); iiwa14 is not built yet.
    #[arg(long, default_value = "ur10")]
    robot: String,
    /// RTDE port (UR mode); 0 picks a free one.
    #[arg(long, default_value_t = 30004)]
    rtde_port: u16,
    /// Address to listen on for RTDE.
    #[arg(long, default_value = "0.0.0.0")]
    rtde_host: String,
    /// FRI target HOST:PORT (iiwa mode; not built yet).
    #[arg(long)]
    fri_target: Option<String>,
    /// Control socket endpoint.
    #[arg(long, default_value = "tcp://*:5000")]
    control: String,
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
    if args.fri_target.is_some() {
        eprintln!("sim-robot: --fri-target: FRI emulation for the iiwa is not built yet");
        return ExitCode::from(2);
    }
    let config = sim_robot::Config {
        robot,
        rtde_listen: format!("{}:{}", args.rtde_host, args.rtde_port),
        control: args.control,
    };
    let handle = match sim_robot::start(&config) {
        Ok(handle) => handle,
        Err(error) => {
            eprintln!("sim-robot: {error}");
            return ExitCode::from(2);
        }
    };
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        if let Err(error) = signal_hook::flag::register(signal, Arc::clone(&stop)) {
            eprintln!("sim-robot: cannot handle signals: {error}");
            return ExitCode::from(1);
        }
    }
    println!(
        "READY rtde={} control={}",
        handle.rtde_address, handle.control_endpoint
    );
    sim_robot::wait_for_shutdown(&stop);
    handle.stop();
    ExitCode::SUCCESS
}
