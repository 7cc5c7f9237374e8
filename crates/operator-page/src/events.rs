//! `GET /api/events`: server-sent events, so the page follows the service without reloads.
//! Events: `state` (the inspections, touches and the service's latest results; sent first and on every change, so
//! another client's `ips get` shows up), `status` (mirroring, sample age, connection; every poll)
//! and `robot` (the live joint positions and TCP, at most every 40 ms).

use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::State;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use futures_util::stream::{self, Stream};
use serde::Serialize;
use tokio::sync::watch;

use crate::scene::LiveRobot;
use crate::state::{Shared, StateDocument, StatusDocument};

/// What one page's stream waits on.
struct Watchers {
    state: watch::Receiver<Option<StateDocument>>,
    status: watch::Receiver<StatusDocument>,
    robot: watch::Receiver<Option<LiveRobot>>,
}

fn event(name: &str, data: &impl Serialize) -> Event {
    // Our documents always serialise; an empty event is the harmless fallback.
    Event::default()
        .event(name)
        .json_data(data)
        .unwrap_or_else(|_| Event::default().event(name))
}

impl Watchers {
    /// The next event, waiting until one of the sources changes; `None` when they are gone.
    async fn next(&mut self) -> Option<Event> {
        tokio::select! {
            changed = self.state.changed() => {
                changed.ok()?;
                let state = self.state.borrow_and_update().clone();
                Some(event("state", &state))
            }
            changed = self.status.changed() => {
                changed.ok()?;
                let status = self.status.borrow_and_update().clone();
                Some(event("status", &status))
            }
            changed = self.robot.changed() => {
                changed.ok()?;
                let robot = self.robot.borrow_and_update().clone();
                Some(event("robot", &robot))
            }
        }
    }
}

fn events(shared: &Shared) -> impl Stream<Item = Result<Event, Infallible>> + use<> {
    let mut watchers = Watchers {
        state: shared.state.subscribe(),
        status: shared.status.subscribe(),
        robot: shared.robot.subscribe(),
    };
    // A new page gets the current state at once, then changes.
    watchers.state.mark_changed();
    watchers.status.mark_changed();
    stream::unfold(watchers, |mut watchers| async move {
        let event = watchers.next().await?;
        Some((Ok(event), watchers))
    })
}

pub async fn stream(State(shared): State<Arc<Shared>>) -> Response {
    Sse::new(events(&shared))
        .keep_alive(KeepAlive::new().interval(Duration::from_secs(10)))
        .into_response()
}
