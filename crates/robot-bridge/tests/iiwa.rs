//! The iiwa back end (FRI monitoring client) against sim-robot's FRI controller emulator over
//! real UDP and ZeroMQ sockets on free ports: the conformance suite, and what only FRI has (the
//! controller grading the link and the bridge reporting it, a 1 ms controller, a lossy and slow
//! link through a fault-injecting UDP relay, datagrams that are not the controller's).

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

#[macro_use]
mod conformance;

use std::collections::VecDeque;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use align_core::robots::ShippedRobot;
use conformance::{Cell, Client, Truth, check_against_truth, mean_period_s, states, wait_until};
use protocol::DigitalInput;
use robot_bridge::backend::iiwa::IiwaConfig;
use robot_bridge::{BackendConfig, Config, Handle};
use serde_json::{Value, json};
use sim_robot::{FriSettings, SimHandle};

/// A bridge with the iiwa back end on a free UDP port.
fn iiwa_bridge() -> Handle {
    iiwa_bridge_with_inputs(Vec::new())
}

/// The same, publishing the named FRI IOs as digital inputs.
fn iiwa_bridge_with_inputs(inputs: Vec<(String, DigitalInput)>) -> Handle {
    robot_bridge::start(&Config {
        backend: BackendConfig::Iiwa(IiwaConfig {
            robot_host: "127.0.0.1".to_owned(),
            fri_port: 0,
            inputs,
            min_silence_ms: robot_bridge::backend::iiwa::DEFAULT_MIN_SILENCE_MS,
        }),
        rep: "tcp://127.0.0.1:*".to_owned(),
        publish: "tcp://127.0.0.1:*".to_owned(),
    })
    .unwrap()
}

fn fri_address(bridge: &Handle) -> SocketAddr {
    let endpoint = bridge.controller_endpoint.as_deref().unwrap();
    let port = endpoint.rsplit(':').next().unwrap().parse().unwrap();
    SocketAddr::from(([127, 0, 0, 1], port))
}

/// A running FRI controller emulator sending to `target`, and its control socket.
struct Simulator {
    handle: SimHandle,
    control: zmq::Socket,
    _context: zmq::Context,
}

impl Simulator {
    fn start(target: SocketAddr, send_period_ms: u32) -> Self {
        Self::with_trigger_io(target, send_period_ms, None)
    }

    /// A controller whose application registered the boolean input `trigger_io` for FRI,
    /// carrying the probe's trigger.
    fn with_trigger_io(target: SocketAddr, send_period_ms: u32, trigger_io: Option<&str>) -> Self {
        let handle = sim_robot::start(&sim_robot::Config {
            robot: ShippedRobot::Iiwa14,
            rtde_listen: String::new(),
            primary_listen: None,
            calibration: None,
            control: "tcp://127.0.0.1:*".to_owned(),
            fri: FriSettings {
                target: target.to_string(),
                send_period_ms,
                receive_multiplier: 1,
                trigger_io: trigger_io.map(str::to_owned),
            },
        })
        .unwrap();
        let context = zmq::Context::new();
        let control = conformance::socket(
            &context,
            zmq::REQ,
            &handle.control_endpoint,
            conformance::TIMEOUT_MS,
        );
        Self {
            handle,
            control,
            _context: context,
        }
    }

    fn send(&self, value: Value) -> Value {
        serde_json::from_str(&conformance::request(&self.control, &value.to_string())).unwrap()
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

    /// The controller's own view of the FRI link.
    fn fri_status(&self) -> Value {
        self.send(json!({"command": "status"}))["fri"].clone()
    }
}

/// An iiwa controller emulated by sim-robot, moving, and a bridge with the iiwa back end.
struct IiwaCell {
    send_period_ms: u32,
    sim: Option<Simulator>,
    moving_since_s: f64,
    bridge: Handle,
}

impl IiwaCell {
    /// The bridge listens first; the controller is pointed at it, as on a real cell.
    fn with_send_period(send_period_ms: u32) -> Self {
        let bridge = iiwa_bridge();
        let sim = Simulator::start(fri_address(&bridge), send_period_ms);
        let moving_since_s = sim.sine();
        Self {
            send_period_ms,
            sim: Some(sim),
            moving_since_s,
            bridge,
        }
    }

    fn sim(&self) -> &Simulator {
        self.sim.as_ref().expect("a running simulator")
    }
}

impl Cell for IiwaCell {
    const BACKEND: &'static str = "iiwa";
    const SIDE: &'static str = "IiwaDrive";
    const JOINTS: usize = 7;
    /// Differentiated over one send period: a backward difference, within |q''| * period / 2 of
    /// the true velocity.
    const VELOCITY_TOLERANCE: f64 = 0.01;
    const LOSS_REASON: &'static [&'static str] =
        &["no FRI message", "limit 100 ms", "3 send periods of 5 ms"];

    fn start() -> Self {
        Self::with_send_period(5)
    }

    fn bridge(&self) -> &Handle {
        &self.bridge
    }

    fn moving_since_s(&self) -> f64 {
        self.moving_since_s
    }

    fn truth_at(&self, time_s: f64) -> Truth {
        let truth = self
            .sim()
            .send(json!({"command": "truth_at", "time": time_s}));
        let values = |key: &str| -> Vec<f64> {
            let array = truth[key].as_array().unwrap();
            array.iter().map(|v| v.as_f64().unwrap()).collect()
        };
        Truth {
            position: values("q"),
            velocity: values("qd"),
        }
    }

    /// A new FRI session: the controller's counter starts again.
    fn drop_connection(&mut self) {
        assert_eq!(self.sim().send(json!({"command": "drop"}))["ok"], true);
    }

    fn kill_controller(&mut self) {
        self.sim.take().unwrap().handle.stop();
    }

    fn restart_controller(&mut self) {
        let sim = Simulator::start(fri_address(&self.bridge), self.send_period_ms);
        self.moving_since_s = sim.sine();
        self.sim = Some(sim);
    }

    fn stop(self) {
        self.bridge.stop();
        if let Some(sim) = self.sim {
            sim.handle.stop();
        }
    }
}

conformance!(IiwaCell);

#[test]
fn the_session_becomes_ready_and_streams_at_the_send_period() {
    let cell = IiwaCell::start();
    let client = Client::new(&cell.bridge, IiwaCell::SIDE);
    // The controller grades the link from the bridge's answers: it becomes ready on its own.
    client.wait_status(Duration::from_secs(10), |s| {
        s["controller"] == "connected" && s["session_state"] == "MONITORING_READY"
    });
    let fri = cell.sim().fri_status();
    assert_eq!(fri["session_state"], "MONITORING_READY");
    assert!(fri["timely_answers"].as_u64().unwrap() > 0);
    let sub = client.subscriber();
    client.start_mirroring();
    let received = states(&sub, 60);
    let period_s = mean_period_s(&received);
    assert!(
        (0.0045..0.0075).contains(&period_s),
        "mean period {period_s} s"
    );
    for state in &received {
        assert_eq!(state["body"]["names"][6], "iiwa_joint_7");
        assert_eq!(state["body"]["effort_unit"], "N m");
        assert!(state["body"]["controller_seq"].as_u64().is_some());
    }
    cell.stop();
}

#[test]
fn a_one_millisecond_controller_is_mirrored_at_its_rate() {
    let cell = IiwaCell::with_send_period(1);
    let client = Client::new(&cell.bridge, IiwaCell::SIDE);
    client.wait_connected();
    let sub = client.subscriber();
    client.start_mirroring();
    let received = states(&sub, 300);
    check_against_truth(&cell, &received[100..160]);
    // The simulator's own clock: scheduling on a loaded machine only ever stretches it.
    let period_s = mean_period_s(&received);
    assert!(
        (0.00095..0.0025).contains(&period_s),
        "mean period {period_s} s"
    );
    cell.stop();
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
    let bridge = iiwa_bridge();
    let relay = Relay::start(fri_address(&bridge));
    let sim = Simulator::start(relay.front, 2);
    let client = Client::new(&bridge, IiwaCell::SIDE);
    let sim_fri = || sim.fri_status();
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
    client.wait_status(Duration::from_secs(10), |s| {
        s["session_state"] == "MONITORING_WAIT" && s["controller"] == "connected"
    });

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
    client.wait_status(Duration::from_secs(10), |s| {
        s["controller_samples_missed"].as_u64() > Some(20)
    });

    // Faults cleared: back to ready and good on both sides.
    relay.set(Faults::default(), Faults::default());
    wait_until(Duration::from_secs(10), sim_fri, ready);
    client.wait_status(Duration::from_secs(10), |s| {
        s["session_state"] == "MONITORING_READY" && good(&s["connection_quality"])
    });
    drop(relay);
    bridge.stop();
    sim.handle.stop();
}

#[test]
fn datagrams_that_are_not_the_controllers_are_dropped_and_counted() {
    let cell = IiwaCell::start();
    let client = Client::new(&cell.bridge, IiwaCell::SIDE);
    client.wait_connected();
    let target = fri_address(&cell.bridge);
    let stranger = UdpSocket::bind("127.0.0.1:0").unwrap();
    for garbage in [&b"\xde\xad\xbe\xef"[..], &[0u8; 1600][..], b"{\"json\":1}"] {
        stranger.send_to(garbage, target).unwrap();
    }
    // Another host on the loopback net, not the controller: even a valid-looking message is
    // refused.
    let other_host = UdpSocket::bind("127.0.0.2:0").unwrap();
    other_host.send_to(&[0x0A, 0x00], target).unwrap();
    let status = client.wait_status(Duration::from_secs(5), |s| {
        s["rejected_datagrams"].as_u64() >= Some(4)
    });
    assert_eq!(status["controller"], "connected");
    assert_eq!(status["reconnects"], 0);
    cell.stop();
}

/// The example part at its hidden pose, probed on the fly by the iiwa at 5 mm/s.
fn probe_request() -> Value {
    let examples = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    let truth: Value = serde_json::from_str(
        &std::fs::read_to_string(examples.join("step_block_ur10/truth.json")).unwrap(),
    )
    .unwrap();
    json!({"command": "probe",
        "mesh": examples.join("step_block_ur10/step_block.stl"), "mesh_scale": 0.001,
        "base_from_part": truth["base_from_part"],
        "tcp": {"xyz": [0.0, 0.0, 0.15], "rpy": [0.0, 0.0, 0.0]}, "tip_radius": 0.003,
        "touches": 6, "on_the_fly_speeds_m_s": [0.005]})
}

/// A probe's trigger wired to the controller and registered for FRI as `Probe.Trigger`: the
/// bridge publishes it as the input it was told (CI3, bit 11), high exactly while the ball is
/// on the part. An IO the
/// controller does not send leaves `digital_inputs` out rather than reporting it low.
#[test]
fn a_registered_fri_io_reaches_the_hw_state_as_the_named_input_while_the_probe_touches() {
    let ci3: DigitalInput = "CI3".parse().unwrap();
    let bridge = iiwa_bridge_with_inputs(vec![("Probe.Trigger".to_owned(), ci3)]);
    let sim = Simulator::with_trigger_io(fri_address(&bridge), 5, Some("Probe.Trigger"));
    let client = Client::new(&bridge, IiwaCell::SIDE);
    client.wait_connected();
    let sub = client.subscriber();
    client.start_mirroring();
    let plan = sim.send(probe_request());
    assert_eq!(plan["ok"], true, "{plan}");
    let windows: Vec<(f64, f64)> = plan["contacts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            (
                c["at_s"].as_f64().unwrap(),
                c["released_s"].as_f64().unwrap(),
            )
        })
        .collect();
    let until_s = windows[1].1 + 0.05;
    let mut high_per_touch = [0usize; 2];
    loop {
        let state = conformance::next_state(&sub);
        let body = &state["body"];
        let time_s = body["controller_time"].as_f64().unwrap();
        if time_s > until_s {
            break;
        }
        let bits = body["digital_inputs"]
            .as_u64()
            .unwrap_or_else(|| panic!("no digital_inputs: {state}"));
        let touching = windows.iter().position(|(a, r)| (*a..*r).contains(&time_s));
        let expected = if touching.is_some() { ci3.mask() } else { 0 };
        assert_eq!(bits, expected, "at {time_s} s, contacts {windows:?}");
        if let Some(touch @ 0..2) = touching {
            high_per_touch[touch] += 1;
        }
    }
    // 1 mm in and back out at 5 mm/s: over 0.2 s of contact, 40 messages at 5 ms.
    assert!(
        high_per_touch.iter().all(|n| *n >= 30),
        "{high_per_touch:?}"
    );
    bridge.stop();
    sim.handle.stop();

    // The bridge told of an IO the application did not register: no bits, not zeros.
    let bridge = iiwa_bridge_with_inputs(vec![("Probe.Other".to_owned(), ci3)]);
    let sim = Simulator::with_trigger_io(fri_address(&bridge), 5, Some("Probe.Trigger"));
    let client = Client::new(&bridge, IiwaCell::SIDE);
    client.wait_connected();
    let sub = client.subscriber();
    client.start_mirroring();
    for state in states(&sub, 5) {
        assert!(state["body"].get("digital_inputs").is_none(), "{state}");
    }
    bridge.stop();
    sim.handle.stop();
}
