//! The hardware-state subscription: the latest joint sample and a short history, kept by a
//! thread of its own that requests never block, and the captures a touch-trigger probe's edges
//! asked for, waiting for the request thread.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use protocol::DigitalInput;

/// Samples kept for a get at a given controller time: 4 s at 1 kHz, 8 s at 500 Hz.
pub(crate) const HISTORY_SAMPLES: usize = 4096;

/// A joint state received from the bridge.
#[derive(Debug, Clone)]
pub(crate) struct JointSample {
    pub q: Vec<f64>,
    pub qd: Vec<f64>,
    pub controller_time: f64,
    pub received: Instant,
    /// The controller's digital inputs with this sample, where the bridge sends them.
    pub digital_inputs: Option<u64>,
}

/// What the subscription thread shares with the request thread.
#[derive(Debug, Default)]
pub(crate) struct Samples {
    latest: Mutex<Option<JointSample>>,
    /// The last [`HISTORY_SAMPLES`] samples, for a get at a given controller time.
    history: Mutex<VecDeque<JointSample>>,
    /// Inspections a touch-trigger probe's edges asked for, not yet taken (module `edges`).
    pub(crate) triggers: TriggerQueue,
}

impl Samples {
    pub(crate) fn latest(&self) -> Option<JointSample> {
        self.latest
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    fn record(&self, sample: JointSample) {
        {
            let mut history = self.history.lock().unwrap_or_else(|p| p.into_inner());
            // A controller restart starts its clock again: older samples would be found first.
            if history
                .back()
                .is_some_and(|last| last.controller_time > sample.controller_time)
            {
                history.clear();
            }
            history.push_back(sample.clone());
            while history.len() > HISTORY_SAMPLES {
                history.pop_front();
            }
        }
        *self.latest.lock().unwrap_or_else(|p| p.into_inner()) = Some(sample);
    }

    /// The first recorded sample at or after controller time `time_s`, at most 50 ms after it.
    pub(crate) fn at(&self, time_s: f64) -> Result<JointSample, String> {
        if !time_s.is_finite() {
            return Err("get: time_s must be a finite controller time".to_owned());
        }
        let history = self.history.lock().unwrap_or_else(|p| p.into_inner());
        let found = history
            .iter()
            .find(|sample| sample.controller_time >= time_s - 1e-9);
        match found {
            Some(sample) if sample.controller_time - time_s <= 0.05 => Ok(sample.clone()),
            _ => Err(format!(
                "no joint sample at controller time {time_s:.4} s (the {} kept cover {:.4}-{:.4} s)",
                history.len(),
                history.front().map_or(f64::NAN, |s| s.controller_time),
                history.back().map_or(f64::NAN, |s| s.controller_time)
            )),
        }
    }
}

/// Captures waiting for the request thread (it drains them at least every 100 ms unless a
/// long request runs); more than this are dropped with a warning rather than held without end.
const MAX_PENDING: usize = 256;

/// A capture at a trigger edge, waiting to be journaled.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct TriggeredCapture {
    pub input: DigitalInput,
    /// The edge's estimated controller time, s: the midpoint of the samples around it.
    pub controller_time_s: f64,
    pub q: Vec<f64>,
    pub qd: Vec<f64>,
    /// Half the gap between the samples around the edge: the edge time's worst-case error, s.
    pub time_uncertainty_s: f64,
}

/// Captures handed from the subscription thread to the request thread.
#[derive(Debug, Default)]
pub(crate) struct TriggerQueue {
    pending: Mutex<VecDeque<TriggeredCapture>>,
}

impl TriggerQueue {
    pub(crate) fn push(&self, capture: TriggeredCapture) {
        let mut pending = self.pending.lock().unwrap_or_else(|p| p.into_inner());
        if pending.len() >= MAX_PENDING {
            tracing::warn!(
                controller_time_s = capture.controller_time_s,
                "trigger capture dropped: {MAX_PENDING} captures already wait for the request thread"
            );
            return;
        }
        pending.push_back(capture);
    }

    pub(crate) fn take_all(&self) -> Vec<TriggeredCapture> {
        self.pending
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .drain(..)
            .collect()
    }
}

/// Receives hardware-state messages until `stop`, keeping the valid ones; queues the capture
/// `detect` finds in a sample (a touch-trigger's edge, module `edges`).
pub(crate) fn subscribe_loop(
    sub: zmq::Socket,
    samples: Arc<Samples>,
    mut detect: impl FnMut(&JointSample) -> Option<TriggeredCapture>,
    stop: Arc<AtomicBool>,
) {
    while !stop.load(Ordering::Relaxed) {
        let Ok(bytes) = sub.recv_bytes(0) else {
            continue;
        };
        let Ok(message) = serde_json::from_slice::<protocol::HwState>(&bytes) else {
            continue;
        };
        if message.body.validate().is_err() {
            continue;
        }
        let sample = JointSample {
            q: message.body.position,
            qd: message.body.velocity,
            controller_time: message.body.controller_time,
            received: Instant::now(),
            digital_inputs: message.body.digital_inputs,
        };
        if let Some(capture) = detect(&sample) {
            samples.triggers.push(capture);
        }
        samples.record(sample);
    }
}
