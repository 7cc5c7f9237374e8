//! The page's view of the service, always fetched from it: status, inspections and the latest
//! results by `status`, `list` and `results` requests (the service is the one source of truth;
//! nothing here keeps inspections or results of its own, so an alignment another client asked
//! for shows as well). A poller asks every [`POLL_PERIOD`] and publishes what changed for the
//! event stream.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use protocol::session::Inspection;
use protocol::{InspectionsReply, ResultsReply, ServiceCommand, StatusReply};
use serde::Serialize;
use tokio::sync::{Notify, watch};

use crate::scene::{LiveRobot, Scene, TouchPoint};
use crate::service_link::ServiceLink;

/// How often the page's server asks the service for its status and inspections.
pub const POLL_PERIOD: Duration = Duration::from_millis(200);

/// `GET /api/state` and the `state` event: the session as the service holds it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StateDocument {
    pub inspections: Vec<Inspection>,
    /// Where each inspection's ball is, for the twin.
    pub touches: Vec<TouchPoint>,
    /// The service's latest alignment and diagnosis (each with `current` and `serial`) and its
    /// next-touch suggestion.
    pub results: ResultsReply,
    /// The latest diagnosis drawn ([`align_service::report_pages::diagnosis_section`]): HTML
    /// made here from the report, every text in it escaped.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub diagnosis_html: Option<String>,
}

/// Where the page's server reaches the service and the bridge: the thesis dialog's connection
/// box.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Endpoints {
    /// The alignment service's REP endpoint.
    pub service: String,
    /// The bridge's instruction REP endpoint (the service's) and its hwState PUB endpoint.
    pub bridge_rep: String,
    pub bridge_pub: String,
}

/// The `status` event: the service's status, or why there is none.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StatusDocument {
    /// Whether the service answered the last poll.
    pub connected: bool,
    pub endpoints: Endpoints,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub status: Option<StatusReply>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// The results as last asked, and what they were asked at: asked again only when the service's
/// `results_serial` or the inspection list changed (`current` and the suggestion follow the
/// list).
#[derive(Debug, Clone)]
struct ResultsCache {
    serial: u64,
    ids: Vec<String>,
    results: ResultsReply,
    diagnosis_html: Option<String>,
}

/// What the HTTP handlers share.
#[derive(Debug)]
pub struct Shared {
    pub link: ServiceLink,
    pub scene: Scene,
    pub endpoints: Endpoints,
    results: Mutex<Option<ResultsCache>>,
    /// Wakes the poller at once after a command, so the page sees its effect without waiting.
    pub changed: Notify,
    pub state: watch::Sender<Option<StateDocument>>,
    pub status: watch::Sender<StatusDocument>,
    /// The robot's latest pose from the bridge's stream (module `live`).
    pub robot: watch::Sender<Option<LiveRobot>>,
}

impl Shared {
    pub fn new(link: ServiceLink, scene: Scene, endpoints: Endpoints) -> Self {
        Self {
            link,
            scene,
            endpoints: endpoints.clone(),
            results: Mutex::new(None),
            changed: Notify::new(),
            state: watch::Sender::new(None),
            status: watch::Sender::new(StatusDocument {
                connected: false,
                endpoints,
                status: None,
                error: Some("not asked yet".to_owned()),
            }),
            robot: watch::Sender::new(None),
        }
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

    /// The service's results for `serial` (its `status`) and inspections `ids`: the cached ones
    /// when neither changed since they were asked.
    async fn fetch_results(
        &self,
        serial: u64,
        ids: &[String],
    ) -> Result<(ResultsReply, Option<String>), String> {
        let cached = self
            .results
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
            .clone()
            .filter(|cache| cache.serial == serial && cache.ids == ids);
        if let Some(cache) = cached {
            return Ok((cache.results, cache.diagnosis_html));
        }
        let body = self
            .link
            .call(ServiceCommand::Results)
            .await
            .map_err(|e| e.to_string())?;
        let results: ResultsReply = body.into_data("results").map_err(|e| e.to_string())?;
        let diagnosis_html = results
            .diagnosis
            .as_ref()
            .map(|d| align_service::report_pages::diagnosis_section(&d.report));
        *self
            .results
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner()) = Some(ResultsCache {
            serial: results.serial,
            ids: ids.to_vec(),
            results: results.clone(),
            diagnosis_html: diagnosis_html.clone(),
        });
        Ok((results, diagnosis_html))
    }

    /// Asks the service for its inspections (and its results when `results_serial`, from the
    /// status just asked, or the list changed) and builds the state document around them.
    pub async fn fetch_state(&self, results_serial: u64) -> Result<StateDocument, String> {
        let body = self
            .link
            .call(ServiceCommand::List)
            .await
            .map_err(|e| e.to_string())?;
        let list: InspectionsReply = body.into_data("list").map_err(|e| e.to_string())?;
        let ids: Vec<String> = list.inspections.iter().map(|i| i.id.clone()).collect();
        let (results, diagnosis_html) = self.fetch_results(results_serial, &ids).await?;
        Ok(StateDocument {
            touches: list.balls.iter().map(TouchPoint::from).collect(),
            results,
            diagnosis_html,
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
                endpoints: shared.endpoints.clone(),
                status: Some(status),
                error: None,
            },
            Err(error) => StatusDocument {
                connected: false,
                endpoints: shared.endpoints.clone(),
                status: None,
                error: Some(error),
            },
        };
        let serial = status.status.as_ref().map(|s| s.results_serial);
        shared.status.send_replace(status);
        let Some(serial) = serial else {
            continue;
        };
        if let Ok(state) = shared.fetch_state(serial).await {
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
