//! Touch-trigger captures: with `Config::trigger` set (`ips serve --trigger DI0`), a rising edge
//! of that digital input in the hardware-state stream captures an inspection without a `get`.
//!
//! The subscription thread finds the edges (module `edges`: debounce, the edge's time and the
//! joints interpolated there); the request thread drains the queue between requests
//! ([`Service::capture_triggered`]) and adds each capture through the journal, as `get` does, so
//! a triggered inspection counts only once it is on disk.
//!
//! **No at-rest check.** A triggered capture is taken while the tool moves (slowly: that is how
//! a trigger probe is used), so `get`'s tool-speed limit does not apply; the joints are checked
//! against the robot's limits.

use protocol::JournalEntry;
use protocol::session::Inspection;

use super::handlers::Service;

impl Service {
    /// Adds the captures the trigger queued since the last call, each journaled first. Captures
    /// while the service is not mirroring (another client had the bridge stream) are dropped:
    /// this service is not in inspection mode then.
    pub(crate) fn capture_triggered(&mut self) {
        for capture in self.samples.triggers.take_all() {
            if !self.mirroring {
                tracing::info!(
                    input = %capture.input,
                    "trigger edge while not mirroring: no inspection"
                );
                continue;
            }
            if let Err(error) = self.chain.check_joints(&capture.q) {
                tracing::warn!(%error, "trigger capture refused");
                continue;
            }
            let inspection = Inspection {
                id: self.next_id.to_string(),
                q: Some(capture.q),
                flange_pose: None,
                qd: Some(capture.qd),
                stamp: Some(capture.controller_time_s),
                face: None,
                trigger: Some(capture.input.to_string()),
            };
            let entry = JournalEntry::Add {
                inspection: inspection.clone(),
            };
            if let Err(reason) = self.journal.append(&entry) {
                tracing::warn!(%reason, "journal write failed: the triggered inspection is dropped");
                continue;
            }
            tracing::info!(
                id = %inspection.id,
                input = %capture.input,
                controller_time_s = capture.controller_time_s,
                time_uncertainty_s = capture.time_uncertainty_s,
                "inspection captured by the trigger"
            );
            self.next_id += 1;
            self.inspections.push(inspection);
        }
    }
}
