//! Controller back ends: each turns a controller's own protocol into [`Sample`]s.

pub mod iiwa;
pub mod ur;

use std::time::Duration;

/// One joint-state sample from the controller.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    pub effort: Option<Vec<f64>>,
    pub controller_time: f64,
    pub controller_seq: Option<u64>,
    pub robot_mode: Option<i32>,
    pub safety_mode: Option<i32>,
    /// The link as the controller grades it, where the protocol says (FRI).
    pub link: Option<LinkState>,
}

/// A controller's own view of the link (FRI session state and connection quality).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LinkState {
    pub session_state: Option<&'static str>,
    pub quality: Option<&'static str>,
}

/// What a back end reports.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    Connecting,
    Connected { description: String },
    Sample(Sample),
    Lost { reason: String },
}

/// A controller connection. `next_event` blocks at most `timeout`; `None` means nothing new.
pub trait Backend: Send {
    fn joint_names(&self) -> Vec<String>;
    /// Unit of [`Sample::effort`].
    fn effort_unit(&self) -> Option<&'static str>;
    fn next_event(&mut self, timeout: Duration) -> Option<Event>;
    /// Datagrams dropped as not from the controller or not its messages, and the latest reason
    /// (datagram protocols only).
    fn rejected_datagrams(&self) -> Option<(u64, Option<String>)> {
        None
    }
}
