//! The operator page in a real headless Chromium (tests/browser/check_page.py, Selenium with
//! Debian's chromium and chromium-driver, installed by scripts/browser-env.sh): no console
//! errors, the WebGL twin drawn, another client's get appears without a reload, Get adds an
//! inspection element, Align shows the rms in mm, Diagnose draws its charts, and the list the
//! page shows is the service's.
//! `OPERATOR_PAGE_SCREENSHOT=docs/operator-page.png` keeps the screenshot (the README's).

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

mod common;

use std::io::{BufRead, BufReader, Write};
use std::path::PathBuf;
use std::process::{Command, Stdio};
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
    // The planned touches but the last from another client before the page opens; the last
    // while it is open, and the browser adds one more at that pose.
    let (last, earlier) = cell.planned.split_last().unwrap();
    for q in earlier {
        cell.hold(&context, q);
        assert_eq!(call(&client, json!({"command": "get"}))["ok"], true);
    }
    let screenshot = std::env::var_os("OPERATOR_PAGE_SCREENSHOT").map_or_else(
        || cell.session.with_file_name("operator-page.png"),
        |path| repo_root().join(path),
    );
    let mut browser = Command::new(repo_root().join(".venv/bin/python"))
        .arg(repo_root().join("crates/operator-page/tests/browser/check_page.py"))
        .arg(page.url() + "/")
        .arg(&screenshot)
        .arg(earlier.len().to_string())
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(browser.stdout.take().unwrap()).lines();
    let mut said = Vec::new();
    for line in lines.by_ref() {
        let line = line.unwrap();
        if line == "other-client" {
            cell.hold(&context, last);
            let got = call(&client, json!({"command": "get"}));
            assert_eq!(got["ok"], true, "{got}");
            let mut stdin = browser.stdin.take().unwrap();
            writeln!(stdin, "{}", got["data"]["id"].as_str().unwrap()).unwrap();
            break;
        }
        said.push(line);
    }
    let rest: Vec<String> = lines.map(Result::unwrap).collect();
    let output = browser.wait_with_output().unwrap();
    assert!(
        output.status.success(),
        "the browser check failed:\n{}\n{}\n{}",
        said.join("\n"),
        rest.join("\n"),
        String::from_utf8_lossy(&output.stderr)
    );
    let seen: serde_json::Value = serde_json::from_str(rest.last().unwrap().trim()).unwrap();
    assert_eq!(
        seen["labels"],
        json!([
            "Start", "Stop", "Get", "Remove", "Reset", "Align", "Diagnose"
        ])
    );
    assert_eq!(seen["added"].as_array().unwrap().len(), 1, "{seen}");
    let endpoints = seen["endpoints"].as_str().unwrap();
    assert!(
        endpoints.contains(&cell.bridge.rep_endpoint)
            && endpoints.contains(&cell.bridge.pub_endpoint),
        "{endpoints}"
    );
    let listed = call(&client, json!({"command": "list"}));
    let service_ids: Vec<&str> = listed["data"]["inspections"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| i["id"].as_str().unwrap())
        .collect();
    assert_eq!(service_ids.len(), cell.planned.len() + 1);
    assert_eq!(
        seen["listed"],
        json!(service_ids),
        "the page lists the service's inspections"
    );
    assert!(service_ids.contains(&seen["other"].as_str().unwrap()));
    // The next suggested touch is drawn (through the part, where it often is behind it).
    assert!(seen["violet"].as_u64().unwrap() > 30, "{seen}");
    let diagnosis = &seen["diagnosis"];
    assert_eq!(diagnosis["touches"], service_ids.len(), "{diagnosis}");
    assert_eq!(diagnosis["bars"], service_ids.len(), "{diagnosis}");
    assert!(std::fs::metadata(&screenshot).unwrap().len() > 10_000);
    page.stop();
}
