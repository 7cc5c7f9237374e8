//! robot-bridge: the thesis's "ROS to IPS link" without ROS. It keeps a connection to the robot
//! controller through a back end ([`backend::Backend`], chosen and configured by
//! [`BackendConfig`]) and serves two ZeroMQ sockets:
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
mod controller;
mod instructions;
mod service;

pub use backend::{BackendConfig, BackendKind};
pub use instructions::MAX_REQUEST_BYTES;
pub use service::{BridgeError, Config, Handle, run, start};
