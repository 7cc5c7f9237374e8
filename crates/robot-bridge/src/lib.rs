//! robot-bridge: the thesis's "ROS to IPS link" without ROS. It keeps a connection to the robot
//! controller through a back end ([`backend::Backend`]) and serves two ZeroMQ sockets:
//!
//! - instruction REP (default `tcp://*:2000`): `start` / `stop` mirroring with the thesis's
//!   messages and acks, and `status`. Mirroring is one switch shared by all clients, as in the
//!   thesis: any client's `stop` stops the stream for every subscriber. Requests are served in
//!   turn; a malformed, oversized or unknown request gets an error ack with a reason.
//! - hardware-state PUB (default `tcp://*:3000`): one hwState frame per controller sample while
//!   mirroring. A sample is published once, when it arrives; nothing is republished, so silence
//!   on the stream means the controller is silent.
//!
//! A lost controller (EOF, or 2 s without data on TCP) is reconnected with backoff; meanwhile
//! `status` says `"lost"` or `"connecting"` and `start` is refused with the reason.

pub mod backend;
mod service;

pub use service::{Config, Handle, run, start};

/// Which controller protocol the bridge speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BackendKind {
    Ur,
    Iiwa,
}

impl BackendKind {
    pub fn name(self) -> &'static str {
        match self {
            BackendKind::Ur => "ur",
            BackendKind::Iiwa => "iiwa",
        }
    }
}
