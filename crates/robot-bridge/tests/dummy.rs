//! The dummy back end (in process, no network) through the conformance suite: the suite's own
//! check that a back end needs nothing but a [`Cell`] to be held to the others' behaviour.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

#[macro_use]
mod conformance;

use conformance::{Cell, Truth};
use robot_bridge::backend::dummy::{self, DummyConfig, DummyController};
use robot_bridge::{BackendConfig, Config, Handle};

struct DummyCell {
    controller: DummyController,
    bridge: Handle,
}

impl Cell for DummyCell {
    const BACKEND: &'static str = "dummy";
    const SIDE: &'static str = "ros";
    const JOINTS: usize = 5;
    /// The trajectory's own derivative, computed as the truth is.
    const VELOCITY_TOLERANCE: f64 = 1e-9;
    const LOSS_REASON: &'static [&'static str] = &["link was cut"];

    fn start() -> Self {
        let config = DummyConfig::new(Self::JOINTS);
        let controller = config.controller.clone();
        let bridge = robot_bridge::start(&Config {
            backend: BackendConfig::Dummy(config),
            rep: "tcp://127.0.0.1:*".to_owned(),
            publish: "tcp://127.0.0.1:*".to_owned(),
        })
        .unwrap();
        Self { controller, bridge }
    }

    fn bridge(&self) -> &Handle {
        &self.bridge
    }

    /// The trajectory has no start: every sample is on it.
    fn moving_since_s(&self) -> f64 {
        f64::NEG_INFINITY
    }

    fn truth_at(&self, time_s: f64) -> Truth {
        let (position, velocity) = dummy::trajectory_at(Self::JOINTS, time_s);
        Truth { position, velocity }
    }

    fn drop_connection(&mut self) {
        self.controller.new_session();
    }

    fn kill_controller(&mut self) {
        self.controller.cut_link();
    }

    fn restart_controller(&mut self) {
        self.controller.restore_link();
    }

    fn stop(self) {
        self.bridge.stop();
    }
}

conformance!(DummyCell);
