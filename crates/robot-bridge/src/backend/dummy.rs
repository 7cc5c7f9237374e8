//! In-process stand-in for a controller, for tests: no network, a deterministic joint trajectory
//! ([`trajectory_at`]) sampled on the controller's own clock, and a [`DummyController`] handle
//! through which a test cuts the link, restores it, or starts a new session, as a real
//! controller's crash, restart or dropped connection would.
//!
//! The controller clock ticks every `send_period` from the back end's opening; sample `n` is the
//! trajectory at `n * send_period`, so a test knows the truth of any sample from its
//! `controller_time` alone. Ticks while the link is cut are never sent.

use std::f64::consts::TAU;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use protocol::RobotSide;

use super::{Backend, BackendKind, BackendSettings, Event, OpenError, Sample};

/// 250 Hz: fast enough to exercise the stream, slow enough for a loaded test machine.
pub const DEFAULT_SEND_PERIOD: Duration = Duration::from_millis(4);
/// Period of the trajectory's sine (s).
const TRAJECTORY_PERIOD_S: f64 = 3.0;
const AMPLITUDE_RAD: f64 = 0.3;

/// Joint positions (rad) and velocities (rad/s) of the dummy trajectory at controller time
/// `time_s`: a sine per joint, each with its own centre and phase.
pub fn trajectory_at(joints: usize, time_s: f64) -> (Vec<f64>, Vec<f64>) {
    let angular_rate = TAU / TRAJECTORY_PERIOD_S;
    (0..joints)
        .map(|joint| {
            let joint = joint as f64;
            let phase = angular_rate * time_s + 0.5 * joint;
            (
                0.1 * joint + AMPLITUDE_RAD * phase.sin(),
                AMPLITUDE_RAD * angular_rate * phase.cos(),
            )
        })
        .unzip()
}

/// The dummy controller's settings.
#[derive(Debug, Clone)]
pub struct DummyConfig {
    pub joints: usize,
    pub send_period: Duration,
    /// The test's side of the link.
    pub controller: DummyController,
}

impl DummyConfig {
    /// `joints` joints at [`DEFAULT_SEND_PERIOD`], the link up.
    pub fn new(joints: usize) -> Self {
        Self {
            joints,
            send_period: DEFAULT_SEND_PERIOD,
            controller: DummyController::default(),
        }
    }
}

impl BackendSettings for DummyConfig {
    fn kind(&self) -> BackendKind {
        BackendKind::Dummy
    }

    fn robot_side(&self) -> RobotSide {
        RobotSide::Ros
    }

    fn open(&self) -> Result<Box<dyn Backend>, OpenError> {
        Ok(Box::new(DummyBackend {
            joints: self.joints,
            send_period: self.send_period.max(Duration::from_micros(100)),
            controller: self.controller.clone(),
            clock_start: Instant::now(),
            announced_connecting: false,
            session: None,
            next_tick: 0,
        }))
    }
}

/// The link as the test sets it.
#[derive(Debug, Clone, Copy)]
struct Link {
    up: bool,
    session: u64,
}

/// The test's handle on the dummy controller; clones share the link.
#[derive(Debug, Clone)]
pub struct DummyController {
    link: Arc<Mutex<Link>>,
}

impl Default for DummyController {
    fn default() -> Self {
        Self {
            link: Arc::new(Mutex::new(Link {
                up: true,
                session: 0,
            })),
        }
    }
}

impl DummyController {
    /// The controller goes silent, as if it crashed: the back end reports the loss.
    pub fn cut_link(&self) {
        self.update(|link| link.up = false);
    }

    /// The controller is back: a new session starts.
    pub fn restore_link(&self) {
        self.update(|link| {
            if !link.up {
                link.up = true;
                link.session += 1;
            }
        });
    }

    /// A new session at once, faster than any loss timeout (a dropped and reopened connection).
    pub fn new_session(&self) {
        self.update(|link| link.session += 1);
    }

    fn update(&self, change: impl FnOnce(&mut Link)) {
        change(&mut self.link.lock().unwrap_or_else(|p| p.into_inner()));
    }

    fn link(&self) -> Link {
        *self.link.lock().unwrap_or_else(|p| p.into_inner())
    }
}

struct DummyBackend {
    joints: usize,
    send_period: Duration,
    controller: DummyController,
    clock_start: Instant,
    announced_connecting: bool,
    /// The session being streamed, none while the link is cut.
    session: Option<u64>,
    /// The controller tick of the next sample.
    next_tick: u64,
}

impl DummyBackend {
    /// The latest tick of the controller clock.
    fn current_tick(&self) -> u64 {
        (self.clock_start.elapsed().as_secs_f64() / self.send_period.as_secs_f64()) as u64
    }

    fn tick_due_at(&self, tick: u64) -> Instant {
        self.clock_start + self.send_period.mul_f64(tick as f64)
    }

    fn sample(&self, tick: u64) -> Sample {
        let time_s = tick as f64 * self.send_period.as_secs_f64();
        let (position, velocity) = trajectory_at(self.joints, time_s);
        Sample {
            position,
            velocity,
            effort: None,
            controller_time: time_s,
            controller_seq: Some(tick),
            robot_mode: None,
            safety_mode: None,
            link: None,
            digital_inputs: None,
        }
    }
}

impl Backend for DummyBackend {
    fn joint_names(&self) -> Vec<String> {
        (1..=self.joints)
            .map(|joint| format!("joint_{joint}"))
            .collect()
    }

    fn effort_unit(&self) -> Option<&'static str> {
        None
    }

    fn next_event(&mut self, timeout: Duration) -> Option<Event> {
        if !self.announced_connecting {
            self.announced_connecting = true;
            return Some(Event::Connecting);
        }
        let link = self.controller.link();
        if !link.up {
            if self.session.take().is_some() {
                return Some(Event::Lost {
                    reason: "the dummy controller's link was cut".to_owned(),
                });
            }
            // The controller's clock runs on while nobody listens; look again a tick later.
            std::thread::sleep(timeout.min(self.send_period));
            return None;
        }
        if self.session != Some(link.session) {
            self.session = Some(link.session);
            self.next_tick = self.current_tick();
            return Some(Event::Connected {
                description: format!(
                    "dummy controller, {} joints every {} ms, session {}",
                    self.joints,
                    self.send_period.as_secs_f64() * 1e3,
                    link.session
                ),
            });
        }
        let wait = self
            .tick_due_at(self.next_tick)
            .saturating_duration_since(Instant::now());
        // The controller's own send clock; a link change is noticed within one period.
        std::thread::sleep(wait.min(timeout));
        if wait > timeout {
            return None;
        }
        let sample = self.sample(self.next_tick);
        self.next_tick += 1;
        Some(Event::Sample(sample))
    }
}
