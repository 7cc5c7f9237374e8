//! The README's two set-up commands are the project's promise to a new user: CI must run the
//! test command verbatim, and the main-job command must work. This pins both.

use std::path::PathBuf;
use std::process::Command;

fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The command lines of the README's `sh` blocks under "Set up and run", comments dropped.
fn setup_commands() -> Vec<String> {
    let readme = std::fs::read_to_string(repo_root().join("README.md")).expect("README.md");
    let section = readme
        .split("## Set up and run")
        .nth(1)
        .and_then(|rest| rest.split("\n## ").next())
        .expect("README has a 'Set up and run' section");
    let mut commands = Vec::new();
    let mut in_block = false;
    for line in section.lines() {
        match line.trim() {
            "```sh" => in_block = true,
            "```" => in_block = false,
            text if in_block && !text.is_empty() && !text.starts_with('#') => {
                commands.push(text.to_owned());
            }
            _ => {}
        }
    }
    commands
}

#[test]
fn readme_has_exactly_two_setup_commands_and_ci_runs_the_test_command() {
    let commands = setup_commands();
    assert_eq!(commands.len(), 2, "{commands:?}");
    let ci = std::fs::read_to_string(repo_root().join(".ci/run")).expect(".ci/run");
    assert!(
        ci.lines().any(|line| line.trim() == commands[1]),
        ".ci/run does not run the README's test command '{}'",
        commands[1]
    );
}

/// The services the demo starts sit next to `ips`: build them with the tests' own profile.
fn ensure_services_built() {
    cell::build_workspace_binaries(&repo_root()).expect("the workspace binaries build");
}

#[test]
fn readme_main_job_runs() {
    let main_job = &setup_commands()[0];
    // "cargo build ... && target/release/ips ARGS": run ARGS with this build's ips.
    let (build, ips_args) = main_job
        .split_once("target/release/ips ")
        .expect("the main job runs target/release/ips");
    assert!(
        build.starts_with("cargo build --release --locked --workspace &&"),
        "the main job builds every binary the demo starts: {main_job}"
    );
    ensure_services_built();
    let output = Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(ips_args.split_whitespace())
        .current_dir(repo_root())
        .output()
        .expect("spawn ips");
    assert!(
        output.status.success(),
        "README main job failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("aligned pose error"), "{stdout}");
}
