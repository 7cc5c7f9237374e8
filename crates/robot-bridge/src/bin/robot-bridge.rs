use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use clap::Parser;
use robot_bridge::{BackendKind, Config};

/// Mirrors a cobot controller's joint states onto the thesis's ZeroMQ sockets.
#[derive(Debug, Parser)]
#[command(name = "robot-bridge", version)]
struct Args {
    /// Controller protocol: ur (RTDE client) or iiwa (FRI monitoring client).
    #[arg(long)]
    backend: String,
    /// Controller address (iiwa: only its FRI datagrams are accepted).
    #[arg(long)]
    robot_host: String,
    /// RTDE port of a UR controller.
    #[arg(long, default_value_t = 30004)]
    rtde_port: u16,
    /// UDP port to receive FRI monitoring messages on (iiwa); 0 picks a free one.
    #[arg(long, default_value_t = 30200)]
    fri_port: u16,
    /// Instruction socket (REP).
    #[arg(long, default_value = "tcp://*:2000")]
    rep: String,
    /// Hardware-state socket (PUB).
    #[arg(long = "pub", default_value = "tcp://*:3000")]
    publish: String,
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
    let backend = match args.backend.as_str() {
        "ur" => BackendKind::Ur,
        "iiwa" => BackendKind::Iiwa,
        other => {
            eprintln!("robot-bridge: unknown back end '{other}' (expected ur or iiwa)");
            return ExitCode::from(2);
        }
    };
    let config = Config {
        backend,
        robot_host: args.robot_host,
        rtde_port: args.rtde_port,
        fri_port: args.fri_port,
        rep: args.rep,
        publish: args.publish,
    };
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        if let Err(error) = signal_hook::flag::register(signal, Arc::clone(&stop)) {
            eprintln!("robot-bridge: cannot handle signals: {error}");
            return ExitCode::from(1);
        }
    }
    let result = robot_bridge::run(&config, &stop, |handle| match &handle.controller_endpoint {
        Some(controller) => println!(
            "READY rep={} pub={} fri={controller}",
            handle.rep_endpoint, handle.pub_endpoint
        ),
        None => println!(
            "READY rep={} pub={}",
            handle.rep_endpoint, handle.pub_endpoint
        ),
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("robot-bridge: {error}");
            ExitCode::from(2)
        }
    }
}
