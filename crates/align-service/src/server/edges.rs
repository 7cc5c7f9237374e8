//! Rising edges of a touch-trigger probe's digital input in the joint-state stream: the
//! subscription thread feeds every sample to an [`EdgeDetector`] and puts what it finds in the
//! samples' trigger queue, which the request thread drains (module `trigger`).
//!
//! **Edge time.** The controller samples the input with the joints (UR: every 8 ms on a CB3,
//! 2 ms on an e-Series), so the edge lies somewhere between the last sample with the input low
//! and the first with it high. With nothing else to go on (RTDE has no latched edge time), the
//! capture takes the midpoint of the two samples' controller times, and `q` and `qd` linearly
//! interpolated there. The worst-case time error is half the sample period; a tool approaching
//! at v is then placed at most v * period / 2 from where it triggered (20 um at 5 mm/s on a CB3),
//! on top of the interpolation's chord error, which is far smaller over one period.
//!
//! **Debounce.** A probe's contact bounces and a slow release can chatter. A rise counts only
//! when the input has read low for at least [`DEBOUNCE_S`] of controller time before it (from the
//! first to the last low sample), so bounces within that window after a touch or a release
//! capture nothing more. The first rise after the service starts needs the same low run, and an
//! input already high in the first sample is not an edge. An edge across a gap in the stream
//! wider than [`MAX_EDGE_GAP_S`] (a lost connection) is not captured: its time would be unknown
//! by more than half that gap.

use protocol::DigitalInput;

use super::samples::{JointSample, TriggeredCapture};

/// How long the input must read low before a rise counts, s of controller time.
pub(crate) const DEBOUNCE_S: f64 = 0.05;
/// The widest gap between the samples around an edge that still places it, s: a dozen CB3
/// periods, so a loaded machine's late sample still counts while a reconnection (at least
/// 100 ms of backoff) does not.
pub(crate) const MAX_EDGE_GAP_S: f64 = 0.1;

/// Watches one digital input in a stream of samples for debounced rising edges.
#[derive(Debug)]
pub(crate) struct EdgeDetector {
    input: DigitalInput,
    /// The latest sample with the inputs known and whether the input was high in it.
    previous: Option<(JointSample, bool)>,
    /// Controller time of the first sample of the current run of low readings.
    low_since_s: Option<f64>,
}

impl EdgeDetector {
    pub(crate) fn new(input: DigitalInput) -> Self {
        Self {
            input,
            previous: None,
            low_since_s: None,
        }
    }

    /// Feeds the next sample; a rising edge that counts gives its capture.
    pub(crate) fn feed(&mut self, sample: &JointSample) -> Option<TriggeredCapture> {
        let Some(bits) = sample.digital_inputs else {
            // Inputs unknown: an edge across the hole could not be placed.
            self.forget();
            return None;
        };
        let high = self.input.is_high(bits);
        if self
            .previous
            .as_ref()
            .is_some_and(|(last, _)| sample.controller_time <= last.controller_time)
        {
            // A restarted controller starts its clock again: nothing before compares.
            self.forget();
        }
        let capture = match self.previous.take() {
            Some((last, false)) if high => self.rise(&last, sample),
            _ => None,
        };
        self.low_since_s = match (high, self.low_since_s) {
            (true, _) => None,
            (false, Some(since)) => Some(since),
            (false, None) => Some(sample.controller_time),
        };
        self.previous = Some((sample.clone(), high));
        capture
    }

    fn forget(&mut self) {
        self.previous = None;
        self.low_since_s = None;
    }

    /// The capture for a rise between `low` and `high`, if it counts.
    fn rise(&self, low: &JointSample, high: &JointSample) -> Option<TriggeredCapture> {
        let low_for_s = low.controller_time - self.low_since_s?;
        if low_for_s < DEBOUNCE_S {
            tracing::debug!(
                input = %self.input,
                low_for_s,
                "trigger rise ignored as a bounce"
            );
            return None;
        }
        let gap_s = high.controller_time - low.controller_time;
        if gap_s > MAX_EDGE_GAP_S || high.q.len() != low.q.len() || high.qd.len() != low.qd.len() {
            tracing::warn!(
                input = %self.input,
                gap_s,
                "a trigger edge across a gap in the joint stream is not captured: its time is unknown"
            );
            return None;
        }
        // The midpoint: the edge is equally likely anywhere between the two samples.
        let fraction = 0.5;
        let lerp = |a: &[f64], b: &[f64]| -> Vec<f64> {
            a.iter()
                .zip(b)
                .map(|(a, b)| a + (b - a) * fraction)
                .collect()
        };
        Some(TriggeredCapture {
            input: self.input,
            controller_time_s: low.controller_time + gap_s * fraction,
            q: lerp(&low.q, &high.q),
            qd: lerp(&low.qd, &high.qd),
            time_uncertainty_s: gap_s / 2.0,
        })
    }
}

#[cfg(test)]
#[path = "edges_tests.rs"]
mod tests;
