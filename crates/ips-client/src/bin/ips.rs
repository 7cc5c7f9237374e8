//! `ips`: parses the arguments, runs the command, prints its output and maps its error to the
//! exit code (0 success, 2 bad input, 1 failure at run time; see the README).

use std::process::ExitCode;

use clap::Parser;
use ips_client::cli::{Cli, Command};
use ips_client::commands::{
    align, align_cloud, align_robot, demo, diagnose, fk, kinematics, plan, serve, service, trials,
};
use ips_client::{BadInput, CliError};

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(error) if !error.use_stderr() => {
            // --help and --version: clap prints them and they are successes.
            let _ = error.print();
            return ExitCode::SUCCESS;
        }
        Err(error) => return fail(&BadInput(one_line(&error.to_string())).into()),
    };
    match run(cli.command) {
        Ok(output) => {
            print!("{output}");
            ExitCode::SUCCESS
        }
        Err(error) => fail(&error),
    }
}

fn run(command: Command) -> Result<String, CliError> {
    match command {
        Command::Fk(args) => fk::command(&args),
        Command::Kinematics(args) => kinematics::run(&args),
        Command::Trials(args) => trials::command(&args),
        Command::Align(args) => align::run(&args),
        Command::AlignCloud(args) => align_cloud::run(&args),
        Command::AlignRobot(args) => align_robot::command(&args),
        Command::Serve(args) => serve::run(&args),
        Command::Start(args) => service::start(&args),
        Command::Stop(args) => service::stop(&args),
        Command::Get(args) => service::get(&args),
        Command::List(args) => service::list(&args),
        Command::Remove(args) => service::remove(&args),
        Command::Reset(args) => service::reset(&args),
        Command::Save(args) => service::save(&args),
        Command::Load(args) => service::load(&args),
        Command::Status(args) => service::status(&args),
        Command::Results(args) => service::results(&args),
        Command::Demo(args) => demo::run(&args),
        Command::Diagnose(args) => diagnose::run(&args),
        Command::Plan(args) => plan::run(&args),
    }
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

fn fail(error: &CliError) -> ExitCode {
    eprintln!("ips: {error}");
    ExitCode::from(error.exit_code())
}
