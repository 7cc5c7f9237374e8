//! The operator page against a real simulated cell (sim-robot, robot-bridge and the alignment
//! service in this process), over raw HTTP: the page and its assets, the state matching the
//! service's own list, commands going through the service, another client's changes arriving on
//! the event stream without a reload, the live robot, and bad requests refused with a reason
//! while the server keeps serving.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

mod common;

use std::time::{Duration, Instant};

use common::{Events, SimCell, call, command, get, http, req};
use serde_json::{Value, json};

const LABELS: [&str; 7] = [
    "Start", "Stop", "Get", "Remove", "Reset", "Align", "Diagnose",
];

fn ids(inspections: &Value) -> Vec<String> {
    inspections
        .as_array()
        .unwrap()
        .iter()
        .map(|i| i["id"].as_str().unwrap().to_owned())
        .collect()
}

/// `start` succeeds once the bridge has connected to the simulated controller.
fn start_mirroring(page: std::net::SocketAddr) {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let started = command(page, json!({"command": "start"}));
        if started.status == 200 {
            assert_eq!(started.json()["data"]["mirroring"], true);
            return;
        }
        assert!(Instant::now() < deadline, "{}", started.body);
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn the_page_drives_the_service_and_follows_other_clients() {
    let cell = SimCell::start("drive");
    let page = cell.page();
    let addr = page.local_addr;
    let context = zmq::Context::new();
    let other_client = req(&context, &cell.service.rep_endpoint);

    // The page, with the seven buttons, and everything it loads, from this server.
    let index = get(addr, "/");
    assert_eq!(index.status, 200);
    assert!(index.headers.contains("content-type: text/html"));
    for label in LABELS {
        assert!(
            index.body.contains(&format!(">{label}</button>")),
            "{label}"
        );
    }
    assert!(index.body.contains(r#"id="result""#));
    for asset in [
        "/page.js",
        "/twin.js",
        "/page.css",
        "/vendor/three.module.min.js",
    ] {
        let response = get(addr, asset);
        assert_eq!(response.status, 200, "{asset}");
        assert!(!response.body.is_empty(), "{asset}");
    }
    assert!(!index.body.contains("http://") && !index.body.contains("https://"));

    // The twin's part: the session's mesh, in metres.
    let scene = get(addr, "/api/scene").json();
    assert!(scene["part"]["vertices"].as_array().unwrap().len() >= 8);
    assert!(scene["part"]["triangles"].as_array().unwrap().len() >= 12);
    assert_eq!(scene["base_frame"], "base_link");
    // The robot's own primitives from its URDF, each in its link's frame.
    let shapes = scene["robot_shapes"].as_array().unwrap();
    assert!(shapes.len() >= 6, "{shapes:?}");
    assert!(shapes.iter().any(|s| s["link"] == "forearm_link"));

    let mut events = Events::open(addr);
    events.wait_for("state", Duration::from_secs(10), |state| {
        state["inspections"].as_array().is_some_and(Vec::is_empty)
    });

    // Get through the page: the service holds the inspection.
    start_mirroring(addr);
    cell.hold(&context, &cell.planned[0]);
    let got = command(addr, json!({"command": "get"}));
    assert_eq!(got.status, 200, "{}", got.body);
    let got = got.json();
    let first = got["data"]["id"].as_str().unwrap().to_owned();
    assert!(got["data"]["next_touch"]["point_mm"].is_array(), "{got}");
    let listed = call(&other_client, json!({"command": "list"}));
    assert_eq!(ids(&listed["data"]["inspections"]), vec![first.clone()]);
    let state = get(addr, "/api/state").json();
    assert_eq!(
        state["state"]["inspections"], listed["data"]["inspections"],
        "/api/state shows the service's list"
    );
    // The twin's touches are where the service places the balls, not a second computation.
    let balls = listed["data"]["balls"].as_array().unwrap();
    let touches = state["state"]["touches"].as_array().unwrap();
    assert_eq!(balls.len(), touches.len());
    for (ball, touch) in balls.iter().zip(touches) {
        assert_eq!(ball["id"], touch["id"]);
        for axis in 0..3 {
            let want = ball["centre_mm"][axis].as_f64().unwrap() * 1e-3;
            let got = touch["ball_centre_m"][axis].as_f64().unwrap();
            assert!((got - want).abs() < 1e-12, "{ball} vs {touch}");
        }
    }
    assert_eq!(state["status"]["mirroring"], true);

    // Another client's get shows up on the open stream, no reload.
    cell.hold(&context, &cell.planned[1]);
    let other = call(&other_client, json!({"command": "get"}));
    assert_eq!(other["ok"], true, "{other}");
    let second = other["data"]["id"].as_str().unwrap().to_owned();
    let seen = events.wait_for("state", Duration::from_secs(10), |state| {
        ids(&state["inspections"]).contains(&second)
    });
    assert_eq!(seen["touches"].as_array().unwrap().len(), 2, "{seen}");
    // The service's suggestion after that get, whoever asked for it.
    assert!(
        seen["results"]["next_touch"]["point_mm"].is_array(),
        "{seen}"
    );
    // The live robot streams too: the TCP at the held pose.
    let robot = events.wait_for("robot", Duration::from_secs(10), |_| true);
    assert_eq!(robot["joints_m"].as_array().unwrap().len(), 7, "{robot}");
    assert!(robot["tcp_m"].as_array().unwrap().len() == 3);
    let links = robot["links"].as_array().unwrap();
    assert!(links.iter().any(|l| l["link"] == "forearm_link"), "{robot}");
    let status = events.wait_for("status", Duration::from_secs(10), |s| {
        s["connected"] == true
    });
    assert_eq!(status["status"]["mirroring"], true);
    // The connection box: where the page reaches the service and the bridge.
    assert_eq!(
        status["endpoints"]["service"],
        cell.service.rep_endpoint.as_str()
    );
    assert_eq!(
        status["endpoints"]["bridge_rep"],
        cell.bridge.rep_endpoint.as_str()
    );
    assert_eq!(
        status["endpoints"]["bridge_pub"],
        cell.bridge.pub_endpoint.as_str()
    );

    // The rest of the planned touches, then Align through the page: an rms in the reply.
    for q in &cell.planned[2..] {
        cell.hold(&context, q);
        let got = command(addr, json!({"command": "get"}));
        assert_eq!(got.status, 200, "{}", got.body);
    }
    // Another client's align shows on the page: the service keeps its latest results.
    let other_aligned = call(&other_client, json!({"command": "align"}));
    assert_eq!(other_aligned["ok"], true, "{other_aligned}");
    let with_result = events.wait_for("state", Duration::from_secs(10), |s| {
        s["results"]["alignment"]["current"] == true
    });
    assert_eq!(
        with_result["results"]["alignment"]["report"],
        other_aligned["data"]
    );
    let first_serial = with_result["results"]["alignment"]["serial"]
        .as_u64()
        .unwrap();
    let aligned = command(addr, json!({"command": "align"}));
    assert_eq!(aligned.status, 200, "{}", aligned.body);
    let rms = aligned.json()["data"]["rms"].as_f64().unwrap();
    assert!(rms.is_finite() && rms < 1e-4, "rms {rms} m");
    let state = get(addr, "/api/state").json();
    let alignment = &state["state"]["results"]["alignment"];
    assert_eq!(alignment["current"], true);
    assert_eq!(alignment["report"]["rms"].as_f64(), Some(rms));
    assert!(alignment["serial"].as_u64().unwrap() > first_serial);

    // Diagnose through the page: the DESIGN 6.4 document, and it becomes the result shown.
    let diagnosed = command(addr, json!({"command": "diagnose"}));
    assert_eq!(diagnosed.status, 200, "{}", diagnosed.body);
    assert!(diagnosed.json()["data"]["verdict"].is_string());
    let state = get(addr, "/api/state").json();
    let results = &state["state"]["results"];
    assert!(
        results["diagnosis"]["serial"].as_u64() > results["alignment"]["serial"].as_u64(),
        "{results}"
    );
    // Drawn by the page server from the report: verdict, the residual plot, the candidates.
    let drawn = state["state"]["diagnosis_html"].as_str().unwrap();
    assert!(drawn.contains("<strong id=\"verdict\">"), "{drawn}");
    assert!(drawn.contains("<svg"));
    assert!(drawn.contains("<table id=\"alternatives\">"));

    // Remove through the page, and the service agrees.
    let removed = command(addr, json!({"command": "remove", "ids": [first]}));
    assert_eq!(removed.status, 200, "{}", removed.body);
    let listed = call(&other_client, json!({"command": "list"}));
    assert!(!ids(&listed["data"]["inspections"]).contains(&first));
    let stale = get(addr, "/api/state").json();
    assert_eq!(stale["state"]["results"]["alignment"]["current"], false);
    assert_eq!(stale["state"]["results"]["diagnosis"]["current"], false);

    let stopped = command(addr, json!({"command": "stop"}));
    assert_eq!(stopped.status, 200, "{}", stopped.body);
    page.stop();
}

#[test]
fn bad_requests_are_refused_with_a_reason_and_the_page_keeps_serving() {
    let cell = SimCell::start("refuse");
    let page = cell.page();
    let addr = page.local_addr;
    let reason = |response: &common::Response| {
        response.json()["reason"]
            .as_str()
            .unwrap_or_default()
            .to_owned()
    };

    let unknown = command(addr, json!({"command": "fly"}));
    assert_eq!(unknown.status, 400);
    assert!(
        reason(&unknown).contains("unknown command 'fly'"),
        "{}",
        unknown.body
    );
    // The page reads no files: save, load and align-cloud are not page commands.
    for refused in [
        json!({"command": "save", "path": "/tmp/x.json"}),
        json!({"command": "load"}),
        json!({"command": "align-cloud"}),
    ] {
        let response = command(addr, refused.clone());
        assert_eq!(response.status, 400, "{refused}: {}", response.body);
        assert!(!reason(&response).is_empty());
    }
    let not_json = http(
        addr,
        "POST",
        "/api/command",
        Some("application/json"),
        b"{nope",
    );
    assert_eq!(not_json.status, 400);
    assert!(reason(&not_json).contains("JSON"), "{}", not_json.body);
    let form = http(
        addr,
        "POST",
        "/api/command",
        Some("text/plain"),
        br#"{"command":"reset"}"#,
    );
    assert_eq!(form.status, 415, "{}", form.body);
    let huge = format!(
        r#"{{"command": "remove", "ids": ["{}"]}}"#,
        "9".repeat(64 * 1024)
    );
    let oversized = http(
        addr,
        "POST",
        "/api/command",
        Some("application/json"),
        huge.as_bytes(),
    );
    assert_eq!(oversized.status, 413, "{}", oversized.body);
    assert!(reason(&oversized).contains("bytes"));
    // Refused by the service itself: its reason comes through with a 409.
    let missing = command(addr, json!({"command": "remove", "ids": ["77"]}));
    assert_eq!(missing.status, 409, "{}", missing.body);
    assert!(reason(&missing).contains("77"), "{}", missing.body);
    let no_data = command(addr, json!({"command": "get"}));
    assert_eq!(no_data.status, 409);
    assert!(
        reason(&no_data).contains("start mirroring first"),
        "{}",
        no_data.body
    );
    assert_eq!(get(addr, "/nowhere").status, 404);
    // A page under another name (DNS rebinding) cannot press the buttons.
    let rebound = common::http_with_host(addr, "evil.example:8080", br#"{"command":"reset"}"#);
    assert_eq!(rebound.status, 403, "{}", rebound.body);
    assert!(reason(&rebound).contains("evil.example"));

    // Still serving.
    let state = get(addr, "/api/state");
    assert_eq!(state.status, 200, "{}", state.body);
    assert!(state.json()["state"]["inspections"].is_array());
    page.stop();
}
