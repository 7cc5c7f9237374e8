//! The instruction server: owns the REP socket and answers `start`, `stop` and `status` with
//! the thesis's acks; anything else gets an error ack with a reason.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use protocol::{Command, RobotSide, StatusBody};
use reply_socket::{ReplySocket, Wait};

use crate::controller::{ControllerState, Shared};

/// Requests larger than this are refused unread (a JSON instruction is ~100 bytes).
pub const MAX_REQUEST_BYTES: usize = 64 * 1024;

/// Who the bridge is in its replies.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Identity {
    /// The status reply's `backend` value.
    pub(crate) backend_name: &'static str,
    pub(crate) robot_side: RobotSide,
}

pub(crate) fn instruction_loop(
    socket: ReplySocket,
    shared: Arc<Shared>,
    stop: Arc<AtomicBool>,
    identity: Identity,
) {
    while !stop.load(Ordering::Relaxed) {
        let request = match socket.receive() {
            Wait::Request(request) => request,
            Wait::Nothing => continue,
            Wait::Closed => return,
        };
        let reply = match request.single_frame(MAX_REQUEST_BYTES) {
            Ok(frame) => answer(frame, &shared, identity),
            Err(reason) => {
                tracing::warn!(%reason, "malformed instruction refused");
                protocol::to_json(&protocol::ack_error(identity.robot_side, reason))
                    .unwrap_or_default()
            }
        };
        tracing::debug!(reply = %reply, "instruction answered");
        // A reply to a client that has gone is dropped; nothing is left owing.
        let _ = socket.reply(&request, reply.as_bytes());
    }
}

fn answer(request: &[u8], shared: &Shared, identity: Identity) -> String {
    let robot_side = identity.robot_side;
    let error = |reason: String| {
        protocol::to_json(&protocol::ack_error(robot_side, reason)).unwrap_or_default()
    };
    if request.len() > MAX_REQUEST_BYTES {
        return error(format!(
            "request of {} bytes exceeds the {MAX_REQUEST_BYTES}-byte limit",
            request.len()
        ));
    }
    let parsed = match protocol::parse_request(request) {
        Ok(parsed) => parsed,
        Err(reason) => {
            tracing::warn!(%reason, "malformed instruction refused");
            return error(reason.to_string());
        }
    };
    let controller = shared.controller.lock().unwrap_or_else(|p| p.into_inner());
    match parsed.command {
        Command::Start => {
            if controller.state != ControllerState::Connected {
                let why = controller
                    .reason
                    .clone()
                    .unwrap_or_else(|| "not connected yet".to_owned());
                return error(format!("controller {}: {why}", controller.state.name()));
            }
            shared.mirroring.store(true, Ordering::Relaxed);
            protocol::to_json(&protocol::ack_ok(robot_side)).unwrap_or_default()
        }
        Command::Stop => {
            shared.mirroring.store(false, Ordering::Relaxed);
            protocol::to_json(&protocol::ack_ok(robot_side)).unwrap_or_default()
        }
        Command::Status => {
            let body = StatusBody {
                backend: identity.backend_name.to_owned(),
                controller: controller.state.name().to_owned(),
                mirroring: shared.mirroring.load(Ordering::Relaxed),
                sample_rate_hz: controller.recent.len() as f64,
                last_sample_age_s: controller.last_sample.map(|t| t.elapsed().as_secs_f64()),
                published: shared.published.load(Ordering::Relaxed),
                reconnects: controller.reconnects,
                reason: controller.reason.clone(),
                controller_samples_missed: controller
                    .counts_controller_seq
                    .then_some(controller.controller_samples_missed),
                session_state: controller
                    .link
                    .as_ref()
                    .and_then(|link| link.session_state)
                    .map(str::to_owned),
                connection_quality: controller
                    .link
                    .as_ref()
                    .and_then(|link| link.quality)
                    .map(str::to_owned),
                rejected_datagrams: controller.rejected_datagrams,
                kinematics: controller.kinematics.clone(),
            };
            protocol::to_json(&protocol::status(robot_side, body)).unwrap_or_default()
        }
    }
}
