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
