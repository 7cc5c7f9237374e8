//! sim-robot (FRI controller emulator) + robot-bridge (iiwa back end, FRI monitoring client)
//! over real UDP and ZeroMQ sockets on free ports: the thesis's exact start text with the iiwa's
//! side name, positions equal to the simulator's truth at the controller's rate, stop and
//! restart, a controller killed and restarted, a lossy and slow link between the two (through a
//! fault-injecting UDP relay), and datagrams that are not the controller's.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::collections::VecDeque;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use align_core::robots::ShippedRobot;
use robot_bridge::{BackendKind, Config, Handle};
use serde_json::{Value, json};
use sim_robot::{FriSettings, SimHandle};

const THESIS_START: &str = r#"{"header":{"from":"ips","to":"IiwaDrive","type":"instruction"},"body":{"command":"start","content":"hwState"}}"#;
const THESIS_STOP: &str = r#"{"header":{"from":"ips","to":"IiwaDrive","type":"instruction"},"body":{"command":"stop","content":"hwState"}}"#;
const THESIS_OK: &str = r#"{"header":{"from":"IiwaDrive","to":"ips","type":"instruction"},"body":{"command":"ack","content":"ok"}}"#;
const STATUS: &str = r#"{"header":{"from":"ips","to":"IiwaDrive","type":"instruction"},"body":{"command":"status","content":"bridge"}}"#;

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

fn bridge() -> Handle {
    robot_bridge::start(&Config {
        backend: BackendKind::Iiwa,
        robot_host: "127.0.0.1".to_owned(),
        rtde_port: 30004,
        fri_port: 0,
        rep: "tcp://127.0.0.1:*".to_owned(),
        publish: "tcp://127.0.0.1:*".to_owned(),
    })
    .unwrap()
}

fn fri_port(bridge: &Handle) -> u16 {
    let endpoint = bridge.controller_endpoint.as_deref().unwrap();
    endpoint.rsplit(':').next().unwrap().parse().unwrap()
}

fn simulator(target: SocketAddr, send_period_ms: u32) -> SimHandle {
    sim_robot::start(&sim_robot::Config {
        robot: ShippedRobot::Iiwa14,
        rtde_listen: String::new(),
        control: "tcp://127.0.0.1:*".to_owned(),
        fri: FriSettings {
            target: target.to_string(),
            send_period_ms,
            receive_multiplier: 1,
        },
    })
    .unwrap()
}

struct Control {
    socket: zmq::Socket,
}

impl Control {
    fn new(context: &zmq::Context, sim: &SimHandle) -> Self {
        Self {
            socket: socket(context, zmq::REQ, &sim.control_endpoint, 5000),
        }
    }

    fn send(&self, value: Value) -> Value {
        serde_json::from_str(&request(&self.socket, &value.to_string())).unwrap()
    }

    /// Switches to a sine motion; returns the controller time after the switch. The switch is a
    /// jump (the simulator teleports), so velocities differentiated across it are meaningless.
    fn sine(&self) -> f64 {
        let sine = json!({"command": "motion", "motion": {"kind": "sine",
            "centre": [0.1, 0.5, -0.2, -1.2, 0.3, 0.9, 0.1],
            "amplitude": [0.3, 0.2, 0.2, 0.3, 0.2, 0.3, 0.5], "period_s": 3.0}});
        assert_eq!(self.send(sine)["ok"], true);
        self.send(json!({"command": "status"}))["time"]
            .as_f64()
            .unwrap()
    }
}

/// Polls a status (the bridge's or the simulator's) until `predicate` holds or `within` passes.
fn wait_until(
    within: Duration,
    mut poll: impl FnMut() -> Value,
    predicate: impl Fn(&Value) -> bool,
) -> Value {
    let deadline = Instant::now() + within;
    loop {
        let status = poll();
        if predicate(&status) {
            return status;
        }
        assert!(Instant::now() < deadline, "status never matched: {status}");
        // Bounded polling of a status that changes on its own: no event to wait on.
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn bridge_status(rep: &zmq::Socket) -> Value {
    let status: Value = serde_json::from_str(&request(rep, STATUS)).unwrap();
    status["body"].clone()
}

/// Waits until the bridge reports its controller connected.
fn wait_connected(rep: &zmq::Socket) -> Value {
    wait_until(
        Duration::from_secs(10),
        || bridge_status(rep),
        |s| s["controller"] == "connected",
    )
}

fn subscriber(context: &zmq::Context, bridge: &Handle) -> zmq::Socket {
    let sub = socket(context, zmq::SUB, &bridge.pub_endpoint, 3000);
    sub.set_subscribe(b"").unwrap();
    sub
}

fn next_state(sub: &zmq::Socket) -> Value {
    serde_json::from_slice(&sub.recv_bytes(0).expect("a hwState within the timeout")).unwrap()
}

/// Checks the states after controller time `after_s` against the simulator's truth.
fn check_against_truth(control: &Control, states: &[Value], after_s: f64, velocity_tolerance: f64) {
    let mut previous_seq = None;
    let mut checked = 0;
    for state in states {
        assert_eq!(
            state["header"],
            json!({"from": "IiwaDrive", "to": "ips", "type": "hwState"})
        );
        let body = &state["body"];
        let time = body["controller_time"].as_f64().unwrap();
        // The previous message, the velocity's other end, must be after the switch too.
        if time <= after_s + 0.02 {
            continue;
        }
        checked += 1;
        let truth = control.send(json!({"command": "truth_at", "time": time}));
        for joint in 0..7 {
            let got = body["position"][joint].as_f64().unwrap();
            let want = truth["q"][joint].as_f64().unwrap();
            assert!((got - want).abs() <= 1e-9, "joint {joint}: {got} vs {want}");
            // Differentiated over one send period: a backward difference, so within
            // |q''| * period / 2 of the true velocity.
            let got = body["velocity"][joint].as_f64().unwrap();
            let want = truth["qd"][joint].as_f64().unwrap();
            assert!(
                (got - want).abs() <= velocity_tolerance,
                "joint {joint} velocity: {got} vs {want}"
            );
        }
        let seq = body["seq"].as_u64().unwrap();
        if let Some(previous) = previous_seq {
            assert_eq!(seq, previous + 1, "no gaps in the bridge's sequence");
        }
        previous_seq = Some(seq);
        assert_eq!(body["names"][6], "iiwa_joint_7");
        assert!(body["controller_seq"].as_u64().is_some());
    }
    assert!(
        checked >= states.len() / 2,
        "only {checked} states after the motion began"
    );
}

fn mean_period_s(states: &[Value]) -> f64 {
    let first = states[0]["body"]["controller_time"].as_f64().unwrap();
    let last = states[states.len() - 1]["body"]["controller_time"]
        .as_f64()
        .unwrap();
    (last - first) / (states.len() - 1) as f64
}

#[test]
fn iiwa14_stream_matches_the_simulator_truth_and_stops_and_resumes() {
    let context = zmq::Context::new();
    let bridge = bridge();
    let target = SocketAddr::from(([127, 0, 0, 1], fri_port(&bridge)));
    let sim = simulator(target, 5);
    let control = Control::new(&context, &sim);
    let moving_since = control.sine();
    let rep = socket(&context, zmq::REQ, &bridge.rep_endpoint, 5000);
    // The controller grades the link from the bridge's answers: it becomes ready on its own.
    let status = wait_until(
        Duration::from_secs(10),
        || bridge_status(&rep),
        |s| s["controller"] == "connected" && s["session_state"] == "MONITORING_READY",
    );
    assert_eq!(status["backend"], "iiwa");
    let sim_status = control.send(json!({"command": "status"}));
    assert_eq!(sim_status["fri"]["session_state"], "MONITORING_READY");
    assert!(sim_status["fri"]["timely_answers"].as_u64().unwrap() > 0);

    let sub = subscriber(&context, &bridge);
    assert_eq!(request(&rep, THESIS_START), THESIS_OK);
    let received: Vec<Value> = (0..60).map(|_| next_state(&sub)).collect();
    check_against_truth(&control, &received, moving_since, 0.01);
    let period = mean_period_s(&received);
    assert!((0.0045..0.0075).contains(&period), "mean period {period} s");
    assert_eq!(received[0]["body"]["effort_unit"], "N m");

    assert_eq!(request(&rep, THESIS_STOP), THESIS_OK);
    sub.set_rcvtimeo(300).unwrap();
    let mut drained = 0;
    while sub.recv_bytes(0).is_ok() {
        drained += 1;
        assert!(drained < 100, "the stream did not stop");
    }
    let published_at_stop = bridge_status(&rep)["published"].as_u64().unwrap();
    sub.set_rcvtimeo(3000).unwrap();
    assert_eq!(request(&rep, THESIS_START), THESIS_OK);
    let resumed = next_state(&sub);
    assert!(resumed["body"]["seq"].as_u64().unwrap() >= published_at_stop);
    bridge.stop();
    sim.stop();
}

#[test]
fn a_one_millisecond_controller_is_mirrored_at_its_rate() {
    let context = zmq::Context::new();
    let bridge = bridge();
    let target = SocketAddr::from(([127, 0, 0, 1], fri_port(&bridge)));
    let sim = simulator(target, 1);
    let control = Control::new(&context, &sim);
    let moving_since = control.sine();
    let rep = socket(&context, zmq::REQ, &bridge.rep_endpoint, 5000);
    wait_connected(&rep);
    let sub = subscriber(&context, &bridge);
    assert_eq!(request(&rep, THESIS_START), THESIS_OK);
    let received: Vec<Value> = (0..300).map(|_| next_state(&sub)).collect();
    check_against_truth(&control, &received[100..160], moving_since, 0.01);
    // The simulator's own clock: scheduling on a loaded machine only ever stretches it.
    let period = mean_period_s(&received);
    assert!(
        (0.00095..0.0025).contains(&period),
        "mean period {period} s"
    );
    bridge.stop();
    sim.stop();
}

#[test]
fn a_controller_killed_and_restarted_is_detected_and_the_stream_resumes() {
    let context = zmq::Context::new();
    let bridge = bridge();
    let target = SocketAddr::from(([127, 0, 0, 1], fri_port(&bridge)));
    let sim = simulator(target, 2);
    let control = Control::new(&context, &sim);
    control.sine();
    let rep = socket(&context, zmq::REQ, &bridge.rep_endpoint, 5000);
    wait_connected(&rep);
    let sub = subscriber(&context, &bridge);
    assert_eq!(request(&rep, THESIS_START), THESIS_OK);
    let before: Vec<Value> = (0..20).map(|_| next_state(&sub)).collect();
    let last_seq = before[19]["body"]["seq"].as_u64().unwrap();

    // A new FRI session at once (the controller's counter starts again, faster than the loss
    // timeout): the stream goes on and the restart counts as a gap.
    assert_eq!(control.send(json!({"command": "drop"}))["ok"], true);
    wait_until(
        Duration::from_secs(10),
        || bridge_status(&rep),
        |s| s["reconnects"].as_u64() >= Some(1) && s["controller"] == "connected",
    );
    assert!(next_state(&sub)["body"]["seq"].as_u64().unwrap() > last_seq);
    let last_seq = next_state(&sub)["body"]["seq"].as_u64().unwrap();

    sim.stop();
    let status = wait_until(
        Duration::from_secs(5),
        || bridge_status(&rep),
        |s| s["controller"] == "lost",
    );
    let reason = status["reason"].as_str().unwrap();
    assert!(reason.contains("3 send periods of 2 ms"), "{reason}");
    // The last sample is never republished while the controller is away.
    let published = status["published"].as_u64().unwrap();
    sub.set_rcvtimeo(200).unwrap();
    while sub.recv_bytes(0).is_ok() {}
    assert!(bridge_status(&rep)["published"].as_u64().unwrap() <= published + 1);
    let refused: Value = serde_json::from_str(&request(&rep, THESIS_START)).unwrap();
    assert_eq!(refused["body"]["content"], "error");
    assert!(
        refused["body"]["reason"]
            .as_str()
            .unwrap()
            .contains("no FRI message"),
        "{refused}"
    );

    let restarted = simulator(target, 2);
    Control::new(&context, &restarted).sine();
    sub.set_rcvtimeo(5000).unwrap();
    let after = next_state(&sub);
    assert!(
        after["body"]["seq"].as_u64().unwrap() > last_seq,
        "the bridge's sequence continues"
    );
    let status = bridge_status(&rep);
    assert_eq!(status["controller"], "connected");
    assert!(status["reconnects"].as_u64().unwrap() >= 1, "{status}");
    bridge.stop();
    restarted.stop();
}

/// What the relay does to datagrams in one direction.
#[derive(Debug, Clone, Copy, Default)]
struct Faults {
    /// Drop n of every 4 datagrams.
    drop_of_four: u32,
    delay: Duration,
}

/// A UDP relay between the controller and the bridge that can drop and delay datagrams.
struct Relay {
    /// The address the controller sends to.
    front: SocketAddr,
    to_bridge: Arc<Mutex<Faults>>,
    to_controller: Arc<Mutex<Faults>>,
    stop: Arc<AtomicBool>,
    threads: Vec<std::thread::JoinHandle<()>>,
}

impl Relay {
    fn start(bridge: SocketAddr) -> Self {
        let front = UdpSocket::bind("127.0.0.1:0").unwrap();
        let back = UdpSocket::bind("127.0.0.1:0").unwrap();
        back.connect(bridge).unwrap();
        let controller: Arc<Mutex<Option<SocketAddr>>> = Arc::new(Mutex::new(None));
        let to_bridge = Arc::new(Mutex::new(Faults::default()));
        let to_controller = Arc::new(Mutex::new(Faults::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let address = front.local_addr().unwrap();
        let forward = {
            let (front, back) = (front.try_clone().unwrap(), back.try_clone().unwrap());
            let (faults, controller, stop) = (to_bridge.clone(), controller.clone(), stop.clone());
            std::thread::spawn(move || {
                relay(&front, &faults, &stop, |bytes, from| {
                    *controller.lock().unwrap() = Some(from);
                    let _ = back.send(bytes);
                });
            })
        };
        let backward = {
            let (faults, stop) = (to_controller.clone(), stop.clone());
            std::thread::spawn(move || {
                relay(&back, &faults, &stop, |bytes, _| {
                    if let Some(controller) = *controller.lock().unwrap() {
                        let _ = front.send_to(bytes, controller);
                    }
                });
            })
        };
        Self {
            front: address,
            to_bridge,
            to_controller,
            stop,
            threads: vec![forward, backward],
        }
    }

    fn set(&self, to_bridge: Faults, to_controller: Faults) {
        *self.to_bridge.lock().unwrap() = to_bridge;
        *self.to_controller.lock().unwrap() = to_controller;
    }
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
    }
}

/// Receives on `socket` and passes each datagram to `deliver` after the configured delay,
/// dropping the configured share.
fn relay(
    socket: &UdpSocket,
    faults: &Mutex<Faults>,
    stop: &AtomicBool,
    mut deliver: impl FnMut(&[u8], SocketAddr),
) {
    let mut queue: VecDeque<(Instant, Vec<u8>, SocketAddr)> = VecDeque::new();
    let mut count: u32 = 0;
    let mut buffer = [0u8; 2048];
    while !stop.load(Ordering::Relaxed) {
        while queue
            .front()
            .is_some_and(|(due, _, _)| *due <= Instant::now())
        {
            let (_, bytes, from) = queue.pop_front().unwrap();
            deliver(&bytes, from);
        }
        let wait = queue
            .front()
            .map_or(Duration::from_millis(20), |(due, _, _)| {
                due.saturating_duration_since(Instant::now())
            });
        socket
            .set_read_timeout(Some(wait.max(Duration::from_micros(50))))
            .unwrap();
        if let Ok((size, from)) = socket.recv_from(&mut buffer) {
            let faults = *faults.lock().unwrap();
            count = count.wrapping_add(1);
            if count % 4 < faults.drop_of_four {
                continue;
            }
            queue.push_back((Instant::now() + faults.delay, buffer[..size].to_vec(), from));
        }
    }
}

#[test]
fn a_lossy_or_slow_link_degrades_the_session_and_it_recovers() {
    let context = zmq::Context::new();
    let bridge = bridge();
    let relay = Relay::start(SocketAddr::from(([127, 0, 0, 1], fri_port(&bridge))));
    let sim = simulator(relay.front, 2);
    let control = Control::new(&context, &sim);
    let rep = socket(&context, zmq::REQ, &bridge.rep_endpoint, 5000);
    let sim_fri = || control.send(json!({"command": "status"}))["fri"].clone();
    // GOOD or better: on a loaded machine the odd answer is late even on a clean link.
    let good = |quality: &Value| quality == "GOOD" || quality == "EXCELLENT";
    let ready = |s: &Value| s["session_state"] == "MONITORING_READY" && good(&s["quality"]);
    wait_until(Duration::from_secs(10), sim_fri, ready);

    // Half the answers lost: the controller grades the link POOR and stops being ready, and
    // the bridge reports what the controller says.
    let half = Faults {
        drop_of_four: 2,
        delay: Duration::ZERO,
    };
    relay.set(Faults::default(), half);
    wait_until(Duration::from_secs(10), sim_fri, |s| {
        s["quality"] == "POOR" && s["session_state"] == "MONITORING_WAIT"
    });
    wait_until(
        Duration::from_secs(10),
        || bridge_status(&rep),
        |s| s["session_state"] == "MONITORING_WAIT" && s["controller"] == "connected",
    );

    // Answers arriving three send periods late are as good as lost.
    let late = Faults {
        drop_of_four: 0,
        delay: Duration::from_millis(6),
    };
    relay.set(Faults::default(), Faults::default());
    wait_until(Duration::from_secs(10), sim_fri, ready);
    relay.set(Faults::default(), late);
    wait_until(Duration::from_secs(10), sim_fri, |s| s["quality"] == "POOR");

    // Every second monitoring message lost on the way to the bridge: the gaps are counted.
    relay.set(half, Faults::default());
    wait_until(
        Duration::from_secs(10),
        || bridge_status(&rep),
        |s| s["controller_samples_missed"].as_u64() > Some(20),
    );

    // Faults cleared: back to ready and good on both sides.
    relay.set(Faults::default(), Faults::default());
    wait_until(Duration::from_secs(10), sim_fri, ready);
    wait_until(
        Duration::from_secs(10),
        || bridge_status(&rep),
        |s| s["session_state"] == "MONITORING_READY" && good(&s["connection_quality"]),
    );
    drop(relay);
    bridge.stop();
    sim.stop();
}

#[test]
fn datagrams_that_are_not_the_controllers_are_dropped_and_counted() {
    let context = zmq::Context::new();
    let bridge = bridge();
    let port = fri_port(&bridge);
    let target = SocketAddr::from(([127, 0, 0, 1], port));
    let sim = simulator(target, 5);
    let rep = socket(&context, zmq::REQ, &bridge.rep_endpoint, 5000);
    wait_connected(&rep);
    let stranger = UdpSocket::bind("127.0.0.1:0").unwrap();
    for garbage in [&b"\xde\xad\xbe\xef"[..], &[0u8; 1600][..], b"{\"json\":1}"] {
        stranger.send_to(garbage, target).unwrap();
    }
    // Another host on the loopback net, not the controller: even a valid-looking message is
    // refused.
    let other_host = UdpSocket::bind("127.0.0.2:0").unwrap();
    other_host.send_to(&[0x0A, 0x00], target).unwrap();
    let status = wait_until(
        Duration::from_secs(5),
        || bridge_status(&rep),
        |s| s["rejected_datagrams"].as_u64() >= Some(4),
    );
    assert_eq!(status["controller"], "connected");
    assert_eq!(status["reconnects"], 0);
    bridge.stop();
    sim.stop();
}
