//! The page's view of the service, always fetched from it: status and inspections by `status`
//! and `list` requests (the service is the one source of truth; nothing here keeps inspections
//! between polls), and the last alignment or diagnosis the page asked for. A poller asks every
//! [`POLL_PERIOD`] and publishes what changed for the event stream.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use protocol::session::Inspection;
use protocol::{InspectionsReply, ServiceCommand, StatusReply};
use serde::Serialize;
use tokio::sync::{Notify, watch};

use crate::scene::{LiveRobot, Scene, TouchPoint};
use crate::service_link::ServiceLink;

/// How often the page's server asks the service for its status and inspections.
pub const POLL_PERIOD: Duration = Duration::from_millis(200);

/// The last `align` or `diagnose` report the page received, with the inspections it used (it
/// describes the list only while that is unchanged).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LastResult {
    /// `align` or `diagnose`.
    pub command: String,
    pub inspections: Vec<String>,
    pub report: serde_json::Value,
}

/// `GET /api/state` and the `state` event: the session as the service holds it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StateDocument {
    pub inspections: Vec<Inspection>,
    /// Where each inspection's ball is, for the twin.
    pub touches: Vec<TouchPoint>,
    pub result: Option<LastResult>,
    /// True when `result` was computed from exactly `inspections`.
    pub result_current: bool,
}

/// The `status` event: the service's status, or why there is none.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StatusDocument {
    /// Whether the service answered the last poll.
    pub connected: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub status: Option<StatusReply>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// What the HTTP handlers share.
#[derive(Debug)]
pub struct Shared {
    pub link: ServiceLink,
    pub scene: Scene,
    pub last_result: Mutex<Option<LastResult>>,
    /// Wakes the poller at once after a command, so the page sees its effect without waiting.
    pub changed: Notify,
    pub state: watch::Sender<Option<StateDocument>>,
    pub status: watch::Sender<StatusDocument>,
    /// The robot's latest pose from the bridge's stream (module `live`).
    pub robot: watch::Sender<Option<LiveRobot>>,
}

impl Shared {
    pub fn new(link: ServiceLink, scene: Scene) -> Self {
        Self {
            link,
            scene,
            last_result: Mutex::new(None),
            changed: Notify::new(),
            state: watch::Sender::new(None),
            status: watch::Sender::new(StatusDocument {
                connected: false,
                status: None,
                error: Some("not asked yet".to_owned()),
            }),
            robot: watch::Sender::new(None),
        }
    }

    pub fn last_result(&self) -> Option<LastResult> {
        self.last_result
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
            .clone()
    }

    pub fn set_last_result(&self, result: LastResult) {
        *self
            .last_result
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner()) = Some(result);
    }

    /// Asks the service for its status.
    pub async fn fetch_status(&self) -> Result<StatusReply, String> {
        let body = self
            .link
            .call(ServiceCommand::Status)
            .await
            .map_err(|e| e.to_string())?;
        body.into_data("status").map_err(|e| e.to_string())
    }

    /// Asks the service for its inspections and builds the state document around them.
    pub async fn fetch_state(&self) -> Result<StateDocument, String> {
        let body = self
            .link
            .call(ServiceCommand::List)
            .await
            .map_err(|e| e.to_string())?;
        let list: InspectionsReply = body.into_data("list").map_err(|e| e.to_string())?;
        let result = self.last_result();
        let ids: Vec<String> = list.inspections.iter().map(|i| i.id.clone()).collect();
        Ok(StateDocument {
            touches: self.scene.touches(&list.inspections),
            result_current: result.as_ref().is_some_and(|r| r.inspections == ids),
            result,
            inspections: list.inspections,
        })
    }
}

/// Polls the service until the process ends while any page follows the events, publishing the
/// status every time and the state when it changed.
pub async fn poll(shared: Arc<Shared>) {
    let mut ticks = tokio::time::interval(POLL_PERIOD);
    ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            _ = ticks.tick() => {}
            () = shared.changed.notified() => {}
        }
        // Nobody follows the events: no need to keep the service busy answering.
        if shared.status.receiver_count() == 0 {
            continue;
        }
        let status = match shared.fetch_status().await {
            Ok(status) => StatusDocument {
                connected: true,
                status: Some(status),
                error: None,
            },
            Err(error) => StatusDocument {
                connected: false,
                status: None,
                error: Some(error),
            },
        };
        let connected = status.connected;
        shared.status.send_replace(status);
        if !connected {
            continue;
        }
        if let Ok(state) = shared.fetch_state().await {
            shared.state.send_if_modified(|current| {
                let changed = current.as_ref() != Some(&state);
                if changed {
                    *current = Some(state);
                }
                changed
            });
        }
    }
}
