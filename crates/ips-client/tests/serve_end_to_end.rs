//! `ips serve` over real sockets with sim-robot and robot-bridge: inspections captured from the
//! live stream, journaled, restored after a restart, aligned to the hidden truth and diagnosed
//! (the same document as the offline command on the saved session); stale data and bad requests
//! refused with reasons.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use align_core::robots::ShippedRobot;
use align_service::server::{Config as ServeConfig, Handle as ServeHandle};
use serde_json::{Value, json};

fn example(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/step_block_ur10")
        .join(file)
}

fn req(context: &zmq::Context, endpoint: &str) -> zmq::Socket {
    let socket = context.socket(zmq::REQ).unwrap();
    socket.set_linger(0).unwrap();
    socket.set_rcvtimeo(10_000).unwrap();
    socket.connect(endpoint).unwrap();
    socket
}

fn call(socket: &zmq::Socket, body: Value) -> Value {
    let request =
        json!({"header": {"from": "ips", "to": "align", "type": "request"}, "body": body});
    socket.send(request.to_string().as_bytes(), 0).unwrap();
    let reply: Value = serde_json::from_slice(&socket.recv_bytes(0).unwrap()).unwrap();
    assert_eq!(reply["header"]["type"], "reply");
    reply["body"].clone()
}

/// The keys DESIGN.md 6.4 promises for `ips diagnose --json`.
const DIAGNOSIS_KEYS: [&str; 8] = [
    "verdict",
    "effect",
    "alternatives",
    "before",
    "after",
    "pose_before",
    "pose_after",
    "inspections",
];

/// Runs the `ips` binary and parses its one JSON document.
fn ips_text(args: &[&str]) -> String {
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_ips"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout).unwrap()
}

fn ips(args: &[&str]) -> Value {
    serde_json::from_str(&ips_text(args)).unwrap()
}

fn serve(config: &ServeConfig) -> ServeHandle {
    align_service::server::start(config).unwrap()
}

#[test]
fn inspections_are_captured_journaled_restored_and_aligned() {
    let sim = sim_robot::start(&sim_robot::Config {
        robot: ShippedRobot::Ur10,
        rtde_listen: "127.0.0.1:0".to_owned(),
        primary_listen: None,
        calibration: None,
        control: "tcp://127.0.0.1:*".to_owned(),
        fri: sim_robot::FriSettings::default(),
    })
    .unwrap();
    let port = sim.rtde_port().unwrap();
    let bridge = robot_bridge::start(&robot_bridge::Config {
        backend: robot_bridge::BackendConfig::Ur(robot_bridge::backend::ur::UrConfig {
            robot_host: "127.0.0.1".to_owned(),
            rtde_port: port,
            primary_port: None,
        }),
        rep: "tcp://127.0.0.1:*".to_owned(),
        publish: "tcp://127.0.0.1:*".to_owned(),
    })
    .unwrap();
    // The example session without its inspections, paths made absolute.
    let mut template: Value =
        serde_json::from_str(&std::fs::read_to_string(example("session.json")).unwrap()).unwrap();
    let planned: Vec<Vec<f64>> = template["inspections"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| {
            i["q"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect()
        })
        .collect();
    template["inspections"] = json!([]);
    template["robot"]["urdf"] = json!(example("../../robots/ur10.urdf").to_str().unwrap());
    template["part"]["mesh"] = json!(example("step_block.stl").to_str().unwrap());
    let folder = std::env::temp_dir().join(format!("cobot-align-serve-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&folder);
    std::fs::create_dir_all(&folder).unwrap();
    std::fs::write(folder.join("template.json"), template.to_string()).unwrap();
    let config = ServeConfig {
        session: folder.join("template.json"),
        journal: folder.join("inspections.journal"),
        rep: "tcp://127.0.0.1:*".to_owned(),
        bridge_rep: bridge.rep_endpoint.clone(),
        bridge_pub: bridge.pub_endpoint.clone(),
        max_sample_age_s: 0.1,
        max_tool_speed_m_s: 0.005,
        data_dirs: vec![folder.clone()],
        keep_session_inspections: true,
        trigger: None,
    };
    let service = serve(&config);
    let context = zmq::Context::new();
    let client = req(&context, &service.rep_endpoint);
    let control = req(&context, &sim.control_endpoint);
    let sub = context.socket(zmq::SUB).unwrap();
    sub.set_linger(0).unwrap();
    sub.set_rcvtimeo(5000).unwrap();
    sub.set_subscribe(b"").unwrap();
    sub.connect(&bridge.pub_endpoint).unwrap();

    // Nothing to diagnose yet: refused with the reason, and the service goes on.
    let refused = call(&client, json!({"command": "diagnose"}));
    assert_eq!(refused["ok"], false, "{refused}");
    assert!(refused["reason"].as_str().is_some_and(|r| !r.is_empty()));

    // Before mirroring there is no live data: get is refused with the reason.
    let refused = call(&client, json!({"command": "get"}));
    assert_eq!(refused["ok"], false);
    assert!(
        refused["reason"]
            .as_str()
            .unwrap()
            .contains("start mirroring first"),
        "{refused}"
    );

    // The bridge may still be connecting to the controller: start succeeds once it is.
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let started = call(&client, json!({"command": "start"}));
        if started["ok"] == true {
            break;
        }
        assert!(Instant::now() < deadline, "{started}");
        std::thread::sleep(Duration::from_millis(20));
    }
    for q in &planned {
        control
            .send(
                json!({"command": "motion", "motion": {"kind": "hold", "q": q}})
                    .to_string()
                    .as_bytes(),
                0,
            )
            .unwrap();
        let _ = control.recv_bytes(0).unwrap();
        // Wait for the stream to show the new pose, then two more samples: the service's own
        // subscription has seen it by then.
        let mut after = None;
        while after.is_none_or(|n: i32| n < 2) {
            let state: Value = serde_json::from_slice(&sub.recv_bytes(0).unwrap()).unwrap();
            let at_pose = state["body"]["position"]
                .as_array()
                .unwrap()
                .iter()
                .zip(q)
                .all(|(a, b)| (a.as_f64().unwrap() - b).abs() < 1e-12);
            after = match (after, at_pose) {
                (None, true) => Some(0),
                (Some(n), _) => Some(n + 1),
                (None, false) => None,
            };
        }
        let got = call(&client, json!({"command": "get"}));
        assert_eq!(got["ok"], true, "{got}");
        // The reply says where the ball is: in the base frame (mm) and from the nominal part.
        let centre = got["data"]["ball_centre_mm"].as_array().unwrap();
        assert!(
            centre.iter().all(|c| c.as_f64().unwrap().is_finite()),
            "{got}"
        );
        let distance = got["data"]["nominal_surface_distance_mm"].as_f64().unwrap();
        assert!(distance.is_finite(), "{got}");
        assert_eq!(
            got["data"]["note"].is_string(),
            distance.abs() > 30.0,
            "{got}"
        );
        // ...and where to touch next: on the nominal part, with the reason.
        let next = &got["data"]["next_touch"];
        assert!(
            next["reason"].as_str().unwrap().contains("direction"),
            "{got}"
        );
        let normal: [f64; 3] = serde_json::from_value(next["normal"].clone()).unwrap();
        let approach: [f64; 3] = serde_json::from_value(next["approach"].clone()).unwrap();
        let dot: f64 = normal.iter().zip(&approach).map(|(n, a)| n * a).sum();
        assert!(dot < -0.8, "the approach goes into the surface: {got}");
    }
    let listed = call(&client, json!({"command": "list"}));
    assert_eq!(listed["data"]["inspections"].as_array().unwrap().len(), 9);

    // A restart replays the journal: every acknowledged inspection is back.
    service.stop();
    let service = serve(&config);
    let client = req(&context, &service.rep_endpoint);
    let listed = call(&client, json!({"command": "list"}));
    assert_eq!(listed["data"]["inspections"].as_array().unwrap().len(), 9);

    let aligned = call(&client, json!({"command": "align"}));
    assert_eq!(aligned["ok"], true, "{aligned}");
    let truth: Value =
        serde_json::from_str(&std::fs::read_to_string(example("truth.json")).unwrap()).unwrap();
    for axis in 0..3 {
        let got = aligned["data"]["pose"]["xyz"][axis].as_f64().unwrap();
        let want = truth["base_from_part"]["xyz"][axis].as_f64().unwrap();
        assert!((got - want).abs() < 1e-6, "xyz[{axis}]: {got} vs {want}");
    }

    // Diagnose over the socket: the DESIGN 6.4 document of the inspections in memory...
    let diagnosed = call(&client, json!({"command": "diagnose"}));
    assert_eq!(diagnosed["ok"], true, "{diagnosed}");
    let diagnosis = &diagnosed["data"];
    for key in DIAGNOSIS_KEYS {
        assert!(diagnosis.get(key).is_some(), "missing {key}: {diagnosis}");
    }
    assert_eq!(diagnosis["inspections"].as_array().unwrap().len(), 9);

    // Save, reset, load: the list comes back from the file.
    let saved = folder.join("saved.json");
    let reply = call(
        &client,
        json!({"command": "save", "path": saved.to_str().unwrap()}),
    );
    assert_eq!(reply["data"]["inspections"], 9, "{reply}");
    // The file keeps the last alignment and diagnosis, with the inspections they came from.
    assert_eq!(reply["data"]["results"], json!(["alignment", "diagnosis"]));
    let file: Value = serde_json::from_str(&std::fs::read_to_string(&saved).unwrap()).unwrap();
    assert_eq!(
        file["results"]["alignment"]["report"]["pose"],
        aligned["data"]["pose"]
    );
    assert_eq!(
        file["results"]["diagnosis"]["report"]["verdict"],
        diagnosis["verdict"]
    );
    assert_eq!(
        file["results"]["alignment"]["inspections"]
            .as_array()
            .unwrap()
            .len(),
        9
    );
    // The service's report exports like the offline one: the touches' ball centres included.
    let csv = ips_text(&[
        "align",
        "--service",
        &service.rep_endpoint,
        "--export",
        "csv",
    ]);
    assert_eq!(csv.lines().next(), Some("id,x_m,y_m,z_m,residual_m"));
    assert_eq!(csv.lines().count(), 10, "{csv}");
    let tf = ips_text(&[
        "align",
        "--service",
        &service.rep_endpoint,
        "--export",
        "ros-tf",
    ]);
    assert!(
        tf.contains("--frame-id base_link --child-frame-id part"),
        "{tf}"
    );
    // ...and the offline command on the saved session says the same, number for number.
    let offline = ips(&["diagnose", saved.to_str().unwrap(), "--json"]);
    assert_eq!(offline["verdict"], diagnosis["verdict"]);
    for key in DIAGNOSIS_KEYS {
        assert_eq!(offline[key], diagnosis[key], "{key}");
    }
    // The client command asks the running service.
    let asked = ips(&["diagnose", "--service", &service.rep_endpoint, "--json"]);
    assert_eq!(asked["verdict"], diagnosis["verdict"]);
    assert_eq!(asked["after"], diagnosis["after"]);
    assert_eq!(
        call(&client, json!({"command": "reset"}))["data"]["inspections"],
        0
    );
    let reply = call(
        &client,
        json!({"command": "load", "path": saved.to_str().unwrap()}),
    );
    assert_eq!(reply["data"]["inspections"], 9, "{reply}");
    let missing = call(
        &client,
        json!({"command": "load", "path": "/no/such/session.json"}),
    );
    assert!(
        missing["reason"]
            .as_str()
            .unwrap()
            .starts_with("cannot read '/no/such/session.json'"),
        "{missing}"
    );

    // Remove and bad requests.
    let removed = call(&client, json!({"command": "remove", "ids": ["9"]}));
    assert_eq!(removed["data"]["inspections"], 8);
    // Results of nine inspections no longer describe eight: save leaves them out.
    let reply = call(
        &client,
        json!({"command": "save", "path": saved.to_str().unwrap()}),
    );
    assert!(reply["data"].get("results").is_none(), "{reply}");
    let file: Value = serde_json::from_str(&std::fs::read_to_string(&saved).unwrap()).unwrap();
    assert!(file.get("results").is_none());
    let unknown = call(&client, json!({"command": "remove", "ids": ["77"]}));
    assert!(
        unknown["reason"].as_str().unwrap().contains("unknown"),
        "{unknown}"
    );
    let bad = call(&client, json!({"command": "fly"}));
    assert!(
        bad["reason"]
            .as_str()
            .unwrap()
            .starts_with("unknown command 'fly'"),
        "{bad}"
    );
    client.send(&b"\xff\xfe garbage"[..], 0).unwrap();
    let reply: Value = serde_json::from_slice(&client.recv_bytes(0).unwrap()).unwrap();
    assert_eq!(reply["body"]["ok"], false);

    // The first service stopped the mirror on exit; start again and wait for live data.
    assert_eq!(call(&client, json!({"command": "start"}))["ok"], true);
    let deadline = Instant::now() + Duration::from_secs(5);
    while call(&client, json!({"command": "status"}))["data"]["stale"] != false {
        assert!(Instant::now() < deadline, "never live");
        std::thread::sleep(Duration::from_millis(20));
    }
    // Stale data: the controller stops streaming, status says stale, get is refused.
    control
        .send(json!({"command": "pause"}).to_string().as_bytes(), 0)
        .unwrap();
    let _ = control.recv_bytes(0).unwrap();
    let deadline = Instant::now() + Duration::from_secs(5);
    while call(&client, json!({"command": "status"}))["data"]["stale"] != true {
        assert!(Instant::now() < deadline, "never stale");
        std::thread::sleep(Duration::from_millis(20));
    }
    let refused = call(&client, json!({"command": "get"}));
    assert!(
        refused["reason"]
            .as_str()
            .unwrap()
            .starts_with("latest joint state is"),
        "{refused}"
    );

    service.stop();
    bridge.stop();
    sim.stop();
    let _ = std::fs::remove_dir_all(&folder);
}

#[test]
fn a_bridge_restart_mid_session_is_recovered() {
    let sim = sim_robot::start(&sim_robot::Config {
        robot: ShippedRobot::Ur10,
        rtde_listen: "127.0.0.1:0".to_owned(),
        primary_listen: None,
        calibration: None,
        control: "tcp://127.0.0.1:*".to_owned(),
        fri: sim_robot::FriSettings::default(),
    })
    .unwrap();
    let port = sim.rtde_port().unwrap();
    let bridge_config = |rep: &str, publish: &str| robot_bridge::Config {
        backend: robot_bridge::BackendConfig::Ur(robot_bridge::backend::ur::UrConfig {
            robot_host: "127.0.0.1".to_owned(),
            rtde_port: port,
            primary_port: None,
        }),
        rep: rep.to_owned(),
        publish: publish.to_owned(),
    };
    let bridge =
        robot_bridge::start(&bridge_config("tcp://127.0.0.1:*", "tcp://127.0.0.1:*")).unwrap();
    let (rep_endpoint, pub_endpoint) = (bridge.rep_endpoint.clone(), bridge.pub_endpoint.clone());
    let mut template: Value =
        serde_json::from_str(&std::fs::read_to_string(example("session.json")).unwrap()).unwrap();
    template["inspections"] = json!([]);
    template["robot"]["urdf"] = json!(example("../../robots/ur10.urdf").to_str().unwrap());
    template["part"]["mesh"] = json!(example("step_block.stl").to_str().unwrap());
    let folder =
        std::env::temp_dir().join(format!("cobot-align-bridge-restart-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&folder);
    std::fs::create_dir_all(&folder).unwrap();
    std::fs::write(folder.join("template.json"), template.to_string()).unwrap();
    let service = serve(&ServeConfig {
        session: folder.join("template.json"),
        journal: folder.join("j"),
        rep: "tcp://127.0.0.1:*".to_owned(),
        bridge_rep: rep_endpoint.clone(),
        bridge_pub: pub_endpoint.clone(),
        max_sample_age_s: 0.1,
        max_tool_speed_m_s: 0.005,
        data_dirs: vec![folder.clone()],
        keep_session_inspections: true,
        trigger: None,
    });
    let context = zmq::Context::new();
    let client = req(&context, &service.rep_endpoint);
    let start_and_get = |client: &zmq::Socket| {
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            let started = call(client, json!({"command": "start"}));
            let got = if started["ok"] == true {
                call(client, json!({"command": "get"}))
            } else {
                started
            };
            if got["ok"] == true {
                return got;
            }
            assert!(Instant::now() < deadline, "{got}");
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    assert_eq!(start_and_get(&client)["data"]["id"], "1");

    // The bridge goes away: the stream stops, get is refused as stale.
    bridge.stop();
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        let refused = call(&client, json!({"command": "get"}));
        if refused["ok"] == false {
            assert!(
                refused["reason"].as_str().unwrap().contains("old"),
                "{refused}"
            );
            break;
        }
        assert!(Instant::now() < deadline);
        std::thread::sleep(Duration::from_millis(20));
    }
    // It comes back on the same endpoints: the service's subscription reconnects by itself.
    let before = call(&client, json!({"command": "list"}))["data"]["inspections"]
        .as_array()
        .unwrap()
        .len();
    let bridge = robot_bridge::start(&bridge_config(&rep_endpoint, &pub_endpoint)).unwrap();
    // (A get taken in the first 100 ms after the bridge stopped was still fresh, and counted.)
    assert_eq!(
        start_and_get(&client)["data"]["id"],
        (before + 1).to_string()
    );
    service.stop();
    bridge.stop();
    sim.stop();
    let _ = std::fs::remove_dir_all(&folder);
}
