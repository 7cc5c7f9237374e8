//! The alignment service as a library, apart from the `ips` command line:
//!
//! - [`session`]: a session file resolved into chain, tool, mesh and touches;
//! - [`jobs`]: Point Set Alignment, Point Cloud Alignment and the diagnosis, each returning the
//!   report document the service replies and `ips` prints;
//! - [`report_pages`]: the diagnosis as pictures (SVG, an HTML section and a page);
//! - [`server`]: the ZeroMQ service behind `ips serve` ([`server::run`], [`server::start`]).
//!
//! Errors the user can fix are [`BadInput`]; the server's start-up failures are
//! [`server::ServiceError`].

pub mod jobs;
pub mod report_pages;
pub mod server;
pub mod session;

/// An error the user caused (bad arguments, a missing or malformed file, data that cannot be
/// aligned): the `ips` command line exits 2 with it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct BadInput(pub String);

impl BadInput {
    pub fn new(message: impl std::fmt::Display) -> Self {
        Self(message.to_string())
    }
}
