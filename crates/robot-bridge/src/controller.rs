//! The controller as the bridge knows it: the back end's thread turns each [`Event`] into the
//! record the status reply reads, and hands samples to the publisher.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use crate::backend::{Backend, Event, LinkState, Sample};

/// What the threads share.
pub(crate) struct Shared {
    /// One switch for all clients, as in the thesis.
    pub(crate) mirroring: AtomicBool,
    pub(crate) published: AtomicU64,
    pub(crate) controller: Mutex<ControllerRecord>,
}

/// The controller link as the status reply names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) enum ControllerState {
    #[default]
    Connecting,
    Connected,
    Lost,
}

impl ControllerState {
    /// The status reply's `controller` value.
    pub(crate) fn name(self) -> &'static str {
        match self {
            ControllerState::Connecting => "connecting",
            ControllerState::Connected => "connected",
            ControllerState::Lost => "lost",
        }
    }
}

/// Everything the status reply says about the controller.
#[derive(Debug, Default)]
pub(crate) struct ControllerRecord {
    pub(crate) state: ControllerState,
    pub(crate) reason: Option<String>,
    pub(crate) last_sample: Option<Instant>,
    /// Arrival times of the samples of the last second.
    pub(crate) recent: VecDeque<Instant>,
    pub(crate) reconnects: u64,
    pub(crate) link: Option<LinkState>,
    /// The controller's counter of the previous sample in this session, where it has one.
    last_controller_seq: Option<u64>,
    pub(crate) counts_controller_seq: bool,
    pub(crate) controller_samples_missed: u64,
    pub(crate) rejected_datagrams: Option<u64>,
    /// The calibrated DH table of the latest connection that reported one.
    pub(crate) kinematics: Option<protocol::calibration::ControllerKinematics>,
}

impl ControllerRecord {
    fn on_connecting(&mut self) {
        self.state = ControllerState::Connecting;
    }

    fn on_connected(&mut self) {
        // A new session straight after the old one (a controller restarted faster than the
        // loss timeout) is a gap in the stream too.
        if self.state == ControllerState::Connected {
            self.reconnects += 1;
        }
        self.state = ControllerState::Connected;
        self.reason = None;
        // A new session counts from its own start.
        self.last_controller_seq = None;
    }

    fn on_lost(&mut self, reason: String) {
        if self.state == ControllerState::Connected {
            self.reconnects += 1;
        }
        self.state = ControllerState::Lost;
        self.reason = Some(reason);
        self.link = None;
        self.last_controller_seq = None;
    }

    fn on_sample(&mut self, sample: &Sample) {
        if let Some(seq) = sample.controller_seq {
            self.counts_controller_seq = true;
            if let Some(previous) = self.last_controller_seq {
                self.controller_samples_missed += seq.saturating_sub(previous).saturating_sub(1);
            }
            self.last_controller_seq = Some(seq);
        }
        self.link.clone_from(&sample.link);
        let now = Instant::now();
        self.last_sample = Some(now);
        self.recent.push_back(now);
        while self
            .recent
            .front()
            .is_some_and(|t| now.duration_since(*t) > Duration::from_secs(1))
        {
            self.recent.pop_front();
        }
    }
}

fn unix_now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// The back end's thread: records every event and sends each sample, stamped with its arrival
/// (Unix s), to the publisher.
pub(crate) fn backend_loop(
    mut backend: Box<dyn Backend>,
    shared: Arc<Shared>,
    stop: Arc<AtomicBool>,
    samples: Sender<(Sample, f64)>,
) {
    while !stop.load(Ordering::Relaxed) {
        let event = backend.next_event(Duration::from_millis(50));
        let mut controller = shared.controller.lock().unwrap_or_else(|p| p.into_inner());
        controller.rejected_datagrams = backend.rejected_datagrams().map(|(count, _)| count);
        let Some(event) = event else {
            continue;
        };
        match event {
            Event::Connecting => {
                tracing::debug!("connecting to the controller");
                controller.on_connecting();
            }
            Event::Connected { description } => {
                tracing::info!(%description, "controller connected");
                controller.on_connected();
            }
            Event::Kinematics(kinematics) => {
                tracing::info!(
                    hash = kinematics.hash.as_deref().unwrap_or("-"),
                    "controller kinematics read"
                );
                controller.kinematics = Some(kinematics);
            }
            Event::Lost { reason } => {
                tracing::warn!(%reason, "controller lost");
                controller.on_lost(reason);
            }
            Event::Sample(sample) => {
                controller.on_sample(&sample);
                drop(controller);
                if samples.send((sample, unix_now())).is_err() {
                    return;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn states_are_named_as_the_status_reply_always_named_them() {
        let names = [
            ControllerState::Connecting,
            ControllerState::Connected,
            ControllerState::Lost,
        ]
        .map(ControllerState::name);
        assert_eq!(names, ["connecting", "connected", "lost"]);
        assert_eq!(ControllerState::default(), ControllerState::Connecting);
    }

    #[test]
    fn sessions_ended_while_connected_count_as_reconnects_and_failed_retries_do_not() {
        let mut record = ControllerRecord::default();
        record.on_connecting();
        record.on_connected();
        // A new session straight after the old one, then a loss, then a failed retry.
        record.on_connected();
        record.on_lost("gone".to_owned());
        record.on_lost("still gone".to_owned());
        assert_eq!(record.reconnects, 2);
        assert_eq!(record.state, ControllerState::Lost);
        assert_eq!(record.reason.as_deref(), Some("still gone"));
        record.on_connected();
        assert_eq!(record.reason, None);
    }
}
