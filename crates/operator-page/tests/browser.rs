//! The operator page in a real headless Chromium (tests/browser/check_page.py, Selenium with
//! Debian's chromium and chromium-driver, installed by scripts/browser-env.sh): no console
//! errors, the WebGL twin drawn, Get adds an inspection element, Align shows the rms in mm.
//! `OPERATOR_PAGE_SCREENSHOT=docs/operator-page.png` keeps the screenshot (the README's).

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

mod common;

use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant};

use common::{SimCell, call, req};
use serde_json::json;

fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn run(command: &mut Command) -> String {
    let output = command.output().unwrap();
    assert!(
        output.status.success(),
        "{command:?} failed:\n{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

#[test]
fn a_headless_chromium_takes_a_touch_and_aligns_on_the_page() {
    run(Command::new("bash").arg(repo_root().join("scripts/browser-env.sh")));
    let cell = SimCell::start("browser");
    let page = cell.page();
    let context = zmq::Context::new();
    let client = req(&context, &cell.service.rep_endpoint);
    let deadline = Instant::now() + Duration::from_secs(10);
    while call(&client, json!({"command": "start"}))["ok"] != true {
        assert!(
            Instant::now() < deadline,
            "the bridge never started mirroring"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // The planned touches from another client; the browser adds one more at the last pose.
    for q in &cell.planned {
        cell.hold(&context, q);
        assert_eq!(call(&client, json!({"command": "get"}))["ok"], true);
    }
    let screenshot = std::env::var_os("OPERATOR_PAGE_SCREENSHOT").map_or_else(
        || cell.session.with_file_name("operator-page.png"),
        |path| repo_root().join(path),
    );
    let seen = run(Command::new(repo_root().join(".venv/bin/python"))
        .arg(repo_root().join("crates/operator-page/tests/browser/check_page.py"))
        .arg(page.url() + "/")
        .arg(&screenshot)
        .arg(cell.planned.len().to_string()));
    let seen: serde_json::Value = serde_json::from_str(seen.trim()).unwrap();
    assert_eq!(
        seen["labels"],
        json!([
            "Start", "Stop", "Get", "Remove", "Reset", "Align", "Diagnose"
        ])
    );
    assert_eq!(seen["added"].as_array().unwrap().len(), 1, "{seen}");
    let listed = call(&client, json!({"command": "list"}));
    assert_eq!(
        listed["data"]["inspections"].as_array().unwrap().len(),
        cell.planned.len() + 1
    );
    assert!(std::fs::metadata(&screenshot).unwrap().len() > 10_000);
    page.stop();
}
