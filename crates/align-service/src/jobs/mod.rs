//! The work a request or a command asks for, whoever asks: each job takes resolved inputs and
//! returns the [`protocol::reports`] document that `ips ... --json` prints and the service
//! replies.

pub mod align;
pub mod apply;
pub mod cloud;
pub mod diagnose;
pub mod units;
