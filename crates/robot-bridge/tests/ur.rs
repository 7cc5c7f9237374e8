//! The UR back end against sim-robot's RTDE server over real sockets on free ports: the
//! conformance suite, and what only RTDE has (the controller's rate by generation, the joint
//! names, the robot mode).

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

#[macro_use]
mod conformance;

use align_core::robots::ShippedRobot;
use conformance::{Cell, Client, Truth, mean_period_s, states};
use robot_bridge::backend::ur::UrConfig;
use robot_bridge::{BackendConfig, Config, Handle};
use serde_json::{Value, json};
use sim_robot::SimHandle;

/// A UR controller simulated by sim-robot, and a bridge with the UR back end.
struct UrCell {
    robot: ShippedRobot,
    /// The simulator's RTDE port, kept so a restarted simulator listens where the bridge looks.
    rtde_port: u16,
    sim: Option<Simulator>,
    bridge: Handle,
}

/// A running simulator and the control socket to script it and read its truth.
struct Simulator {
    handle: SimHandle,
    control: zmq::Socket,
    _context: zmq::Context,
    moving_since_s: f64,
}

impl Simulator {
    fn start(robot: ShippedRobot, rtde_listen: String) -> Self {
        Self::start_calibrated(robot, rtde_listen, None)
    }

    fn start_calibrated(
        robot: ShippedRobot,
        rtde_listen: String,
        calibration: Option<align_core::kinematics::DhTable>,
    ) -> Self {
        let handle = sim_robot::start(&sim_robot::Config {
            robot,
            rtde_listen,
            primary_listen: Some("127.0.0.1:0".to_owned()),
            calibration,
            control: "tcp://127.0.0.1:*".to_owned(),
            fri: sim_robot::FriSettings::default(),
        })
        .unwrap();
        let context = zmq::Context::new();
        let control = conformance::socket(
            &context,
            zmq::REQ,
            &handle.control_endpoint,
            conformance::TIMEOUT_MS,
        );
        let mut simulator = Self {
            handle,
            control,
            _context: context,
            moving_since_s: 0.0,
        };
        let sine = json!({"command": "motion", "motion": {"kind": "sine",
            "centre": [0.1, -1.4, 1.5, -1.6, -1.5, 0.2],
            "amplitude": [0.3, 0.2, 0.2, 0.3, 0.2, 0.5], "period_s": 3.0}});
        assert_eq!(simulator.send(sine)["ok"], true);
        simulator.moving_since_s = simulator.send(json!({"command": "status"}))["time"]
            .as_f64()
            .unwrap();
        simulator
    }

    fn send(&self, value: Value) -> Value {
        serde_json::from_str(&conformance::request(&self.control, &value.to_string())).unwrap()
    }
}

impl UrCell {
    fn with_robot(robot: ShippedRobot) -> Self {
        Self::with_simulator(robot, Simulator::start(robot, "127.0.0.1:0".to_owned()))
    }

    fn with_simulator(robot: ShippedRobot, sim: Simulator) -> Self {
        let rtde_port = sim.handle.rtde_port().unwrap();
        let primary_port = sim
            .handle
            .primary_address
            .as_deref()
            .and_then(|address| address.rsplit(':').next()?.parse().ok());
        let bridge = robot_bridge::start(&Config {
            backend: BackendConfig::Ur(UrConfig {
                robot_host: "127.0.0.1".to_owned(),
                rtde_port,
                primary_port,
            }),
            rep: "tcp://127.0.0.1:*".to_owned(),
            publish: "tcp://127.0.0.1:*".to_owned(),
        })
        .unwrap();
        Self {
            robot,
            rtde_port,
            sim: Some(sim),
            bridge,
        }
    }

    fn sim(&self) -> &Simulator {
        self.sim.as_ref().expect("a running simulator")
    }
}

impl Cell for UrCell {
    const BACKEND: &'static str = "ur";
    const SIDE: &'static str = "ros";
    const JOINTS: usize = 6;
    const VELOCITY_TOLERANCE: f64 = 1e-9;
    const LOSS_REASON: &'static [&'static str] = &["controller"];

    fn start() -> Self {
        Self::with_robot(ShippedRobot::Ur10)
    }

    fn bridge(&self) -> &Handle {
        &self.bridge
    }

    fn moving_since_s(&self) -> f64 {
        self.sim().moving_since_s
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

    fn drop_connection(&mut self) {
        assert_eq!(self.sim().send(json!({"command": "drop"}))["ok"], true);
    }

    fn kill_controller(&mut self) {
        self.sim.take().unwrap().handle.stop();
    }

    fn restart_controller(&mut self) {
        let listen = format!("127.0.0.1:{}", self.rtde_port);
        self.sim = Some(Simulator::start(self.robot, listen));
    }

    fn stop(self) {
        self.bridge.stop();
        if let Some(sim) = self.sim {
            sim.handle.stop();
        }
    }
}

conformance!(UrCell);

/// Streams from `robot` and returns 60 frames after checking what every RTDE frame carries.
fn rtde_frames(robot: ShippedRobot) -> Vec<Value> {
    let cell = UrCell::with_robot(robot);
    let client = Client::new(&cell.bridge, UrCell::SIDE);
    client.wait_connected();
    let sub = client.subscriber();
    client.start_mirroring();
    let received = states(&sub, 60);
    for state in &received {
        assert_eq!(state["body"]["names"][0], "shoulder_pan_joint");
        assert_eq!(state["body"]["effort_unit"], "A");
        assert_eq!(state["body"]["robot_mode"], 7);
    }
    cell.stop();
    received
}

#[test]
fn ur10_streams_at_125_hz_and_ur10e_at_500_hz() {
    // The simulator's own clock: scheduling on a loaded machine only ever stretches it.
    let cb3_period_s = mean_period_s(&rtde_frames(ShippedRobot::Ur10));
    assert!(
        (0.0075..0.012).contains(&cb3_period_s),
        "CB3 mean period {cb3_period_s} s"
    );
    let e_series_period_s = mean_period_s(&rtde_frames(ShippedRobot::Ur10e));
    assert!(
        (0.0019..0.004).contains(&e_series_period_s),
        "e-Series mean period {e_series_period_s} s"
    );
}

#[test]
fn status_carries_each_published_calibration_exactly_as_the_controller_reports_it() {
    // Sets A (UR10), B and C (UR10e) of UR's ROS driver tests; B and C have d offsets of
    // hundreds of metres on the parallel joints, which cancel.
    let mut hashes = Vec::new();
    for published in align_core::corpus::calibrations::ur_driver_calibrations() {
        let robot = published.robot;
        let sim = Simulator::start_calibrated(
            robot,
            "127.0.0.1:0".to_owned(),
            Some(published.delta.clone()),
        );
        let cell = UrCell::with_simulator(robot, sim);
        let client = Client::new(cell.bridge(), "ros");
        let status = client.wait_status(std::time::Duration::from_secs(10), |status| {
            status["kinematics"].is_object()
        });
        let kinematics = &status["kinematics"];
        let calibrated = published.calibrated().unwrap();
        for (key, row) in [
            ("dh_theta", &calibrated.theta),
            ("dh_a", &calibrated.a),
            ("dh_d", &calibrated.d),
            ("dh_alpha", &calibrated.alpha),
        ] {
            let reported: Vec<f64> = serde_json::from_value(kinematics[key].clone()).unwrap();
            assert_eq!(&reported, row, "set {}: {key}", published.name);
        }
        let hash = kinematics["hash"].as_str().unwrap().to_owned();
        assert!(hash.starts_with("calib_"), "{kinematics}");
        hashes.push(hash);
        cell.stop();
    }
    hashes.dedup();
    assert_eq!(hashes.len(), 3, "each calibration its own hash: {hashes:?}");
}

#[test]
fn a_controller_without_a_primary_interface_streams_on_without_calibration() {
    // The default cell's bridge reads the simulator's primary interface; this one points the
    // bridge at a port where nothing listens.
    let robot = ShippedRobot::Ur10;
    let sim = Simulator::start(robot, "127.0.0.1:0".to_owned());
    let rtde_port = sim.handle.rtde_port().unwrap();
    let unused = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let closed_port = unused.local_addr().unwrap().port();
    drop(unused);
    let bridge = robot_bridge::start(&Config {
        backend: BackendConfig::Ur(UrConfig {
            robot_host: "127.0.0.1".to_owned(),
            rtde_port,
            primary_port: Some(closed_port),
        }),
        rep: "tcp://127.0.0.1:*".to_owned(),
        publish: "tcp://127.0.0.1:*".to_owned(),
    })
    .unwrap();
    let cell = UrCell {
        robot,
        rtde_port,
        sim: Some(sim),
        bridge,
    };
    let client = Client::new(cell.bridge(), "ros");
    let status = client.wait_connected();
    assert!(status.get("kinematics").is_none(), "{status}");
    client.start_mirroring();
    let sub = client.subscriber();
    assert_eq!(states(&sub, 5).len(), 5);
    cell.stop();
}

/// The example part, its hidden pose and the probe of `examples/step_block_ur10`, probed on
/// the fly at 5 mm/s with the trigger wired to `input`.
fn probe_request(input: &str) -> Value {
    let examples = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    let truth: Value = serde_json::from_str(
        &std::fs::read_to_string(examples.join("step_block_ur10/truth.json")).unwrap(),
    )
    .unwrap();
    json!({"command": "probe",
        "mesh": examples.join("step_block_ur10/step_block.stl"), "mesh_scale": 0.001,
        "base_from_part": truth["base_from_part"],
        "tcp": {"xyz": [0.0, 0.0, 0.15], "rpy": [0.0, 0.0, 0.0]}, "tip_radius": 0.003,
        "touches": 6, "on_the_fly_speeds_m_s": [0.005], "trigger_input": input})
}

#[test]
fn the_trigger_input_reaches_the_hw_state_exactly_while_the_probe_touches() {
    let cell = UrCell::with_robot(ShippedRobot::Ur10);
    let client = Client::new(cell.bridge(), UrCell::SIDE);
    client.wait_connected();
    let sub = client.subscriber();
    client.start_mirroring();
    // CI3 is bit 11 of actual_digital_input_bits.
    let plan = cell.sim().send(probe_request("CI3"));
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
    for (at_s, released_s) in &windows {
        assert!(released_s > at_s, "{plan}");
    }
    // Two touches are enough to see rises and falls at the planned times.
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
        let expected = if touching.is_some() { 1 << 11 } else { 0 };
        assert_eq!(bits, expected, "at {time_s} s, contacts {windows:?}");
        if let Some(touch @ 0..2) = touching {
            high_per_touch[touch] += 1;
        }
    }
    // 1 mm in and back out at 5 mm/s: over 0.2 s of contact, 25 samples at 125 Hz.
    assert!(
        high_per_touch.iter().all(|n| *n >= 20),
        "{high_per_touch:?}"
    );
    cell.stop();
}

/// A UR controller that knows no `actual_digital_input_bits` (NOT_FOUND) and streams whatever
/// else it is asked for at 125 Hz; returns its port.
fn controller_without_digital_inputs() -> u16 {
    use ur_rtde::{Package, encode_value, output_type, package, recipe_names};
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    std::thread::spawn(move || {
        let Ok((mut stream, _)) = listener.accept() else {
            return;
        };
        let mut types = Vec::new();
        loop {
            let Ok(request) = Package::read_from(&mut stream) else {
                return;
            };
            let reply = match request.kind {
                package::REQUEST_PROTOCOL_VERSION => vec![1],
                package::GET_URCONTROL_VERSION => [3u32, 15, 7, 106]
                    .iter()
                    .flat_map(|part| part.to_be_bytes())
                    .collect(),
                package::CONTROL_PACKAGE_SETUP_OUTPUTS => {
                    let names = String::from_utf8_lossy(&request.payload[8..]).into_owned();
                    types = recipe_names(&names)
                        .into_iter()
                        .map(|name| output_type(name).filter(|_| !name.contains("digital")))
                        .collect();
                    let text: Vec<&str> = types
                        .iter()
                        .map(|t| t.map_or("NOT_FOUND", ur_rtde::ValueType::name))
                        .collect();
                    let complete = types.iter().all(Option::is_some);
                    let mut payload = vec![u8::from(complete)];
                    payload.extend_from_slice(text.join(",").as_bytes());
                    payload
                }
                package::CONTROL_PACKAGE_START => vec![1],
                _ => continue,
            };
            let started = request.kind == package::CONTROL_PACKAGE_START;
            if Package::new(request.kind, reply)
                .write_to(&mut stream)
                .is_err()
            {
                return;
            }
            if started {
                break;
            }
        }
        for tick in 0u32.. {
            let mut payload = vec![1];
            for kind in types.iter().flatten() {
                let value = if *kind == ur_rtde::ValueType::Double {
                    f64::from(tick) * 0.008
                } else {
                    0.0
                };
                encode_value(*kind, &vec![value; kind.count()], &mut payload);
            }
            if Package::new(package::DATA_PACKAGE, payload)
                .write_to(&mut stream)
                .is_err()
            {
                return;
            }
            // A stand-in controller's send clock, not a synchronisation.
            std::thread::sleep(std::time::Duration::from_millis(8));
        }
    });
    port
}

#[test]
fn a_controller_without_digital_inputs_streams_on_without_them() {
    let bridge = robot_bridge::start(&Config {
        backend: BackendConfig::Ur(UrConfig {
            robot_host: "127.0.0.1".to_owned(),
            rtde_port: controller_without_digital_inputs(),
            primary_port: None,
        }),
        rep: "tcp://127.0.0.1:*".to_owned(),
        publish: "tcp://127.0.0.1:*".to_owned(),
    })
    .unwrap();
    let client = Client::new(&bridge, UrCell::SIDE);
    client.wait_connected();
    let sub = client.subscriber();
    client.start_mirroring();
    for state in states(&sub, 10) {
        assert!(state["body"].get("digital_inputs").is_none(), "{state}");
        assert_eq!(state["body"]["position"].as_array().unwrap().len(), 6);
    }
    bridge.stop();
}
