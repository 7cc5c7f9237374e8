use std::process::ExitCode;

use clap::Parser;
use ips_client::BadInput;
use ips_client::cli::{Cli, Command};

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(error) if !error.use_stderr() => {
            // --help and --version: clap prints them and they are successes.
            let _ = error.print();
            return ExitCode::SUCCESS;
        }
        Err(error) => return bad_input(&BadInput(one_line(&error.to_string()))),
    };
    match run(cli.command) {
        Ok(output) => {
            print!("{output}");
            ExitCode::SUCCESS
        }
        Err(error) => bad_input(&error),
    }
}

fn run(command: Command) -> Result<String, BadInput> {
    match command {
        Command::Fk(args) => {
            let output = ips_client::fk::run(&args)?;
            for warning in &output.warnings {
                eprintln!("warning: {warning}");
            }
            Ok(if args.json {
                json_line(&output)?
            } else {
                output.to_text()
            })
        }
        Command::Align(args) if args.service.is_some() => {
            let endpoint = args.service.as_deref().unwrap_or_default();
            let data =
                ips_client::client::request_data(endpoint, &protocol::service_request("align"))?;
            Ok(if args.json {
                json_line(&data)?
            } else {
                ips_client::client::align_text(&data)
            })
        }
        Command::Align(args) => {
            let output = ips_client::align::run(&args)?;
            Ok(if args.json {
                json_line(&output)?
            } else {
                output.to_text()
            })
        }
        Command::AlignCloud(args) => {
            let output = ips_client::align_cloud::run(&args)?;
            Ok(if args.json {
                json_line(&output)?
            } else {
                output.to_text()
            })
        }
        Command::AlignRobot(args) => {
            let output = ips_client::align_robot::run(&args)?;
            Ok(if args.json {
                json_line(&output)?
            } else {
                output.to_text()
            })
        }
        Command::Serve(args) => serve(&args),
        Command::Start(args) => ips_client::client::call("start", Vec::new(), &args),
        Command::Stop(args) => ips_client::client::call("stop", Vec::new(), &args),
        Command::Get(args) => ips_client::client::get(args.at, &args.service),
        Command::List(args) => ips_client::client::call("list", Vec::new(), &args),
        Command::Reset(args) => ips_client::client::call("reset", Vec::new(), &args),
        Command::Status(args) => ips_client::client::call("status", Vec::new(), &args),
        Command::Save(args) => ips_client::client::call_with_path(
            "save",
            Vec::new(),
            Some(args.path.clone()),
            &args.service,
        ),
        Command::Load(args) => ips_client::client::call_with_path(
            "load",
            Vec::new(),
            Some(args.path.clone()),
            &args.service,
        ),
        Command::Remove(args) => {
            ips_client::client::call("remove", args.ids.clone(), &args.service)
        }
        Command::Diagnose(args) => {
            let output = ips_client::diagnose::run(&args)?;
            Ok(if args.json {
                json_line(&output)?
            } else {
                output.to_text()
            })
        }
        Command::Demo(args) => {
            let output = ips_client::demo::run(&args, |line| eprintln!("{line}"))?;
            Ok(if args.json {
                json_line(&output)?
            } else {
                output.to_text()
            })
        }
        Command::Trials(args) if args.robot.is_some() || args.urdf.is_some() => {
            let output = ips_client::robot_trials::run(&args, |line| eprintln!("{line}"))?;
            Ok(if args.json {
                json_line(&output)?
            } else {
                output.to_markdown()
            })
        }
        Command::Trials(args) => {
            let output = ips_client::trials::run(&args, |line| eprintln!("{line}"))?;
            Ok(if args.json {
                json_line(&output)?
            } else {
                output.to_markdown()
            })
        }
    }
}

fn serve(args: &ips_client::cli::ServeArgs) -> Result<String, BadInput> {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    let config = ips_client::serve::ServeConfig {
        session: args.session.clone(),
        journal: args.journal.clone(),
        rep: args.rep.clone(),
        bridge_rep: args.bridge_rep.clone(),
        bridge_pub: args.bridge_pub.clone(),
        max_sample_age_s: args.max_sample_age,
        max_tool_speed_m_s: args.max_tool_speed,
    };
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, Arc::clone(&stop))
            .map_err(|error| BadInput(format!("cannot handle signals: {error}")))?;
    }
    let handle = ips_client::serve::start(&config).map_err(BadInput)?;
    println!("READY rep={}", handle.rep_endpoint);
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    handle.stop();
    Ok(String::new())
}

fn json_line(value: &impl serde::Serialize) -> Result<String, BadInput> {
    serde_json::to_string(value)
        .map(|text| text + "\n")
        .map_err(|error| BadInput(format!("cannot encode the result as JSON: {error}")))
}

/// clap's messages spread over several lines followed by usage hints; the contract is one line.
fn one_line(message: &str) -> String {
    let reason: Vec<&str> = message
        .lines()
        .map(str::trim)
        .take_while(|line| !line.starts_with("Usage:") && !line.starts_with("For more information"))
        .filter(|line| !line.is_empty())
        .collect();
    let reason = reason.join(" ");
    let reason = reason.trim_start_matches("error: ");
    if reason.is_empty() {
        "invalid arguments (see ips --help)".to_owned()
    } else {
        format!("{reason} (see ips --help)")
    }
}

fn bad_input(error: &BadInput) -> ExitCode {
    eprintln!("ips: {error}");
    ExitCode::from(2)
}
