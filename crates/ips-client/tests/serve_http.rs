//! `ips serve --http 0` (a bare port: loopback): the READY line names the page as `http=http://HOST:PORT`
//! after the REP endpoint, the page answers there, and its state is the service's (the same
//! process, reached through the REP socket). A bad address is bad input (exit 2).

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

mod common;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde_json::{Value, json};

use common::Scratch;

fn example(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/step_block_ur10")
        .join(file)
}

/// The example session with absolute paths, in a fresh folder; returns the folder (removed when
/// dropped), the session and the journal.
fn session(name: &str) -> (Scratch, PathBuf, PathBuf) {
    let mut template: Value =
        serde_json::from_str(&std::fs::read_to_string(example("session.json")).unwrap()).unwrap();
    template["robot"]["urdf"] = json!(example("../../robots/ur10.urdf").to_str().unwrap());
    template["part"]["mesh"] = json!(example("step_block.stl").to_str().unwrap());
    let folder =
        std::env::temp_dir().join(format!("cobot-align-http-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&folder);
    let folder = Scratch::folder(folder);
    let session = folder.join("session.json");
    std::fs::write(&session, template.to_string()).unwrap();
    let journal = folder.join("inspections.journal");
    (folder, session, journal)
}

fn http_get(host_port: &str, path: &str) -> (u16, String) {
    let mut stream = TcpStream::connect(host_port).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(30)))
        .unwrap();
    let request = format!("GET {path} HTTP/1.1\r\nHost: {host_port}\r\nConnection: close\r\n\r\n");
    stream.write_all(request.as_bytes()).unwrap();
    let mut text = String::new();
    stream.read_to_string(&mut text).unwrap();
    let (head, body) = text.split_once("\r\n\r\n").unwrap();
    let status = head.split_whitespace().nth(1).unwrap().parse().unwrap();
    (status, body.to_owned())
}

#[test]
fn ready_names_the_page_and_the_page_shows_the_services_inspections() {
    let (_folder, session, journal) = session("ready");
    let args: Vec<String> = [
        "serve",
        "--session",
        session.to_str().unwrap(),
        "--journal",
        journal.to_str().unwrap(),
        "--rep",
        "tcp://127.0.0.1:*",
        // No bridge is needed for the page: its stream and instructions are only used later.
        "--bridge-rep",
        "tcp://127.0.0.1:1",
        "--bridge-pub",
        "tcp://127.0.0.1:1",
        // A bare port: the page listens on loopback only.
        "--http",
        "0",
    ]
    .iter()
    .map(|a| (*a).to_owned())
    .collect();
    let ips = Path::new(env!("CARGO_BIN_EXE_ips"));
    let service = cell::spawn("ips serve", ips, &args, cell::READY_WITHIN).unwrap();
    // READY rep=... http=...: the REP endpoint first, as before.
    assert_eq!(service.endpoints[0].0, "rep");
    let url = service.endpoint("http").unwrap().to_owned();
    let host_port = url.strip_prefix("http://").unwrap();
    assert!(host_port.starts_with("127.0.0.1:"), "{url}");

    let (status, page) = http_get(host_port, "/");
    assert_eq!(status, 200);
    assert!(page.contains(">Align</button>"));
    // The session file's nine inspections start the list: the page shows the service's list.
    let (status, state) = http_get(host_port, "/api/state");
    assert_eq!(status, 200, "{state}");
    let state: Value = serde_json::from_str(&state).unwrap();
    assert_eq!(state["state"]["inspections"].as_array().unwrap().len(), 9);
    assert_eq!(state["state"]["touches"].as_array().unwrap().len(), 9);
    assert_eq!(state["status"]["inspections"], 9);
    let status = service.terminate(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
}

#[test]
fn an_address_that_cannot_be_bound_is_bad_input() {
    let (_folder, session, journal) = session("bad-address");
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(["serve", "--session"])
        .arg(&session)
        .arg("--journal")
        .arg(&journal)
        .args(["--rep", "tcp://127.0.0.1:*", "--http", "not-an-address"])
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("not-an-address"), "{stderr}");
    assert!(!String::from_utf8_lossy(&output.stdout).contains("READY"));
}
