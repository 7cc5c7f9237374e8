//! sim-robot (RTDE server) + robot-bridge (UR back end) over real sockets on free ports: the
//! thesis's exact start text, positions equal to the simulator's truth, stop and restart,
//! controller loss and recovery, and bad requests answered while good ones are served.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::time::{Duration, Instant};

use align_core::robots::ShippedRobot;
use robot_bridge::{BackendKind, Config, Handle};
use serde_json::{Value, json};
use sim_robot::SimHandle;

const THESIS_START: &str = r#"{"header":{"from":"ips","to":"ros","type":"instruction"},"body":{"command":"start","content":"hwState"}}"#;
const THESIS_STOP: &str = r#"{"header":{"from":"ips","to":"ros","type":"instruction"},"body":{"command":"stop","content":"hwState"}}"#;
const THESIS_OK: &str = r#"{"header":{"from":"ros","to":"ips","type":"instruction"},"body":{"command":"ack","content":"ok"}}"#;
const STATUS: &str = r#"{"header":{"from":"ips","to":"ros","type":"instruction"},"body":{"command":"status","content":"bridge"}}"#;

struct Cell {
    sim: Option<SimHandle>,
    bridge: Handle,
    context: zmq::Context,
    control: zmq::Socket,
}

fn socket(
    context: &zmq::Context,
    kind: zmq::SocketType,
    endpoint: &str,
    timeout_ms: i32,
) -> zmq::Socket {
    let socket = context.socket(kind).unwrap();
    socket.set_linger(0).unwrap();
    socket.set_rcvtimeo(timeout_ms).unwrap();
    socket.set_sndtimeo(timeout_ms).unwrap();
    socket.connect(endpoint).unwrap();
    socket
}

fn request(socket: &zmq::Socket, text: &str) -> String {
    socket.send(text.as_bytes(), 0).unwrap();
    String::from_utf8(socket.recv_bytes(0).expect("a reply within the timeout")).unwrap()
}

fn control(cell: &Cell, value: Value) -> Value {
    serde_json::from_str(&request(&cell.control, &value.to_string())).unwrap()
}

fn cell(robot: ShippedRobot) -> Cell {
    let sim = sim_robot::start(&sim_robot::Config {
        robot,
        rtde_listen: "127.0.0.1:0".to_owned(),
        control: "tcp://127.0.0.1:*".to_owned(),
        fri: sim_robot::FriSettings::default(),
    })
    .unwrap();
    let port = sim.rtde_port().unwrap();
    let bridge = robot_bridge::start(&Config {
        backend: BackendKind::Ur,
        robot_host: "127.0.0.1".to_owned(),
        rtde_port: port,
        fri_port: 30200,
        rep: "tcp://127.0.0.1:*".to_owned(),
        publish: "tcp://127.0.0.1:*".to_owned(),
    })
    .unwrap();
    let context = zmq::Context::new();
    let control_socket = socket(&context, zmq::REQ, &sim.control_endpoint, 5000);
    let cell = Cell {
        sim: Some(sim),
        bridge,
        context,
        control: control_socket,
    };
    let sine = json!({"command": "motion", "motion": {"kind": "sine",
        "centre": [0.1, -1.4, 1.5, -1.6, -1.5, 0.2], "amplitude": [0.3, 0.2, 0.2, 0.3, 0.2, 0.5], "period_s": 3.0}});
    assert_eq!(control(&cell, sine)["ok"], true);
    cell
}

/// Polls the bridge's status until `predicate` holds or `within` passes.
fn wait_status(cell: &Cell, within: Duration, predicate: impl Fn(&Value) -> bool) -> Value {
    let rep = socket(&cell.context, zmq::REQ, &cell.bridge.rep_endpoint, 5000);
    let deadline = Instant::now() + within;
    loop {
        let status: Value = serde_json::from_str(&request(&rep, STATUS)).unwrap();
        if predicate(&status["body"]) {
            return status;
        }
        assert!(Instant::now() < deadline, "status never matched: {status}");
        // Bounded polling of a status that changes on its own: no event to wait on.
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn subscriber(cell: &Cell) -> zmq::Socket {
    let sub = socket(&cell.context, zmq::SUB, &cell.bridge.pub_endpoint, 3000);
    sub.set_subscribe(b"").unwrap();
    sub
}

fn next_state(sub: &zmq::Socket) -> Value {
    serde_json::from_slice(&sub.recv_bytes(0).expect("a hwState within the timeout")).unwrap()
}

/// Receives until `count` frames arrived (skipping the slow-joiner gap of a new SUB socket).
fn states(sub: &zmq::Socket, count: usize) -> Vec<Value> {
    (0..count).map(|_| next_state(sub)).collect()
}

#[test]
fn ur10_stream_matches_the_simulator_truth_and_stops_and_resumes() {
    let cell = cell(ShippedRobot::Ur10);
    wait_status(&cell, Duration::from_secs(10), |s| {
        s["controller"] == "connected"
    });
    let sub = subscriber(&cell);
    let rep = socket(&cell.context, zmq::REQ, &cell.bridge.rep_endpoint, 5000);
    assert_eq!(request(&rep, THESIS_START), THESIS_OK);
    let received = states(&sub, 60);
    let mut previous_seq = None;
    for state in &received {
        assert_eq!(
            state["header"],
            json!({"from": "ros", "to": "ips", "type": "hwState"})
        );
        let body = &state["body"];
        let time = body["controller_time"].as_f64().unwrap();
        let truth = control(&cell, json!({"command": "truth_at", "time": time}));
        for joint in 0..6 {
            let got = body["position"][joint].as_f64().unwrap();
            let want = truth["q"][joint].as_f64().unwrap();
            assert!((got - want).abs() <= 1e-9, "joint {joint}: {got} vs {want}");
        }
        let seq = body["seq"].as_u64().unwrap();
        if let Some(previous) = previous_seq {
            assert_eq!(seq, previous + 1, "no gaps in the bridge's sequence");
        }
        previous_seq = Some(seq);
        assert_eq!(body["names"][0], "shoulder_pan_joint");
        assert_eq!(body["robot_mode"], 7);
    }
    // CB3 streams at 125 Hz: controller timestamps 8 ms apart on average (the simulator's own
    // clock; scheduling on a loaded machine only ever stretches it).
    let first = received[0]["body"]["controller_time"].as_f64().unwrap();
    let last = received[59]["body"]["controller_time"].as_f64().unwrap();
    let mean_period = (last - first) / 59.0;
    assert!(
        (0.0075..0.012).contains(&mean_period),
        "mean period {mean_period} s"
    );

    assert_eq!(request(&rep, THESIS_STOP), THESIS_OK);
    // Frames published before the stop took effect may still be in flight: drain them, then
    // the stream must stay silent.
    sub.set_rcvtimeo(300).unwrap();
    let mut drained = 0;
    while sub.recv_bytes(0).is_ok() {
        drained += 1;
        assert!(drained < 50, "the stream did not stop");
    }
    let published_at_stop =
        wait_status(&cell, Duration::from_secs(1), |_| true)["body"]["published"]
            .as_u64()
            .unwrap();
    sub.set_rcvtimeo(3000).unwrap();
    assert_eq!(request(&rep, THESIS_START), THESIS_OK);
    let resumed = next_state(&sub);
    assert!(resumed["body"]["seq"].as_u64().unwrap() >= published_at_stop);
    cell.bridge.stop();
    cell.sim.unwrap().stop();
}

#[test]
fn controller_loss_is_detected_recovered_and_counted() {
    let cell = cell(ShippedRobot::Ur10e);
    wait_status(&cell, Duration::from_secs(10), |s| {
        s["controller"] == "connected"
    });
    let sub = subscriber(&cell);
    let rep = socket(&cell.context, zmq::REQ, &cell.bridge.rep_endpoint, 5000);
    assert_eq!(request(&rep, THESIS_START), THESIS_OK);
    let before = states(&sub, 20);
    let last_seq = before[19]["body"]["seq"].as_u64().unwrap();
    // e-Series: 500 Hz.
    let span = before[19]["body"]["controller_time"].as_f64().unwrap()
        - before[0]["body"]["controller_time"].as_f64().unwrap();
    assert!(
        (0.0019..0.004).contains(&(span / 19.0)),
        "mean period {}",
        span / 19.0
    );

    assert_eq!(control(&cell, json!({"command": "drop"}))["ok"], true);
    let status = wait_status(&cell, Duration::from_secs(10), |s| {
        s["reconnects"].as_u64() >= Some(1) && s["controller"] == "connected"
    });
    assert_eq!(status["body"]["mirroring"], true);
    // The stream resumes on its own, the sequence continues.
    let after = next_state(&sub);
    assert!(after["body"]["seq"].as_u64().unwrap() > last_seq);

    // The controller killed and started again on its port: the bridge reconnects by itself,
    // the stream resumes and its sequence continues.
    let mut cell = cell;
    let port = cell.sim.as_ref().unwrap().rtde_port().unwrap();
    let last_seq = next_state(&sub)["body"]["seq"].as_u64().unwrap();
    let reconnects_before =
        wait_status(&cell, Duration::from_secs(1), |_| true)["body"]["reconnects"]
            .as_u64()
            .unwrap();
    cell.sim.take().unwrap().stop();
    wait_status(&cell, Duration::from_secs(10), |s| {
        s["controller"] != "connected"
    });
    cell.sim = Some(
        sim_robot::start(&sim_robot::Config {
            robot: ShippedRobot::Ur10e,
            rtde_listen: format!("127.0.0.1:{port}"),
            control: "tcp://127.0.0.1:*".to_owned(),
            fri: sim_robot::FriSettings::default(),
        })
        .unwrap(),
    );
    let status = wait_status(&cell, Duration::from_secs(10), |s| {
        s["controller"] == "connected"
    });
    assert!(
        status["body"]["reconnects"].as_u64().unwrap() > reconnects_before,
        "{status}"
    );
    sub.set_rcvtimeo(5000).unwrap();
    let resumed = next_state(&sub);
    assert!(resumed["body"]["seq"].as_u64().unwrap() > last_seq);

    // Controller gone for good: loss reported, start refused with the reason.
    cell.sim.take().unwrap().stop();
    let status = wait_status(&cell, Duration::from_secs(10), |s| {
        s["controller"] != "connected"
    });
    assert!(status["body"]["reason"].as_str().is_some());
    let reply: Value = serde_json::from_str(&request(&rep, THESIS_START)).unwrap();
    assert_eq!(reply["body"]["content"], "error");
    assert!(
        reply["body"]["reason"]
            .as_str()
            .unwrap()
            .starts_with("controller "),
        "{reply}"
    );
    cell.bridge.stop();
}

#[test]
fn bad_requests_get_error_acks_while_good_clients_are_served() {
    let cell = cell(ShippedRobot::Ur10);
    let bad = socket(&cell.context, zmq::REQ, &cell.bridge.rep_endpoint, 5000);
    let good = socket(&cell.context, zmq::REQ, &cell.bridge.rep_endpoint, 5000);
    let huge = "x".repeat(1024 * 1024);
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (b"{not json".to_vec(), "not valid JSON"),
        (br#"{"header":{"from":"ips"},"body":{}}"#.to_vec(), "expected shape"),
        (br#"{"header":{"from":"ips","to":"ros","type":"instruction"},"body":{"command":"fly","content":"hwState"}}"#.to_vec(), "unknown command 'fly'"),
        (huge.into_bytes(), "exceeds the 65536-byte limit"),
        (vec![0xde, 0xad, 0xbe, 0xef, 0x00, 0xff], "not valid JSON"),
    ];
    for (payload, reason) in &cases {
        bad.send(payload.as_slice(), 0).unwrap();
        let reply: Value = serde_json::from_slice(&bad.recv_bytes(0).unwrap()).unwrap();
        assert_eq!(reply["body"]["content"], "error");
        assert!(
            reply["body"]["reason"].as_str().unwrap().contains(reason),
            "{reply}"
        );
    }
    for round in 0..10_000 {
        bad.send(&b"garbage"[..], 0).unwrap();
        let reply: Value = serde_json::from_slice(&bad.recv_bytes(0).unwrap()).unwrap();
        assert_eq!(reply["body"]["content"], "error");
        if round % 1000 == 0 {
            let status: Value = serde_json::from_str(&request(&good, STATUS)).unwrap();
            assert_eq!(status["header"]["type"], "status");
        }
    }
    cell.bridge.stop();
    cell.sim.unwrap().stop();
}
