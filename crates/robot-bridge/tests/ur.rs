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
