//! The page's JSON endpoints: `GET /api/state`, `GET /api/scene` and `POST /api/command`. A
//! command becomes the typed [`ServiceCommand`] of the same name and goes to the service; the
//! page can name no file (no save, load or align-cloud: the page reads no files).

use std::sync::Arc;

use axum::Json;
use axum::body::Bytes;
use axum::extract::State;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use protocol::{GetRequest, RemoveRequest, ServiceCommand};
use serde::Deserialize;
use serde_json::{Value, json};

use crate::service_link::LinkError;
use crate::state::Shared;

/// The largest command body accepted: a remove of a few hundred ids.
pub const MAX_COMMAND_BYTES: usize = 16 * 1024;

/// The commands the page may send, as its buttons name them.
pub const PAGE_COMMANDS: [&str; 7] = [
    "start", "stop", "get", "remove", "reset", "align", "diagnose",
];

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PageCommand {
    command: String,
    #[serde(default)]
    ids: Vec<String>,
}

/// A JSON error reply: `{"ok": false, "reason": ...}` with `status`.
pub fn refusal(status: StatusCode, reason: impl Into<String>) -> Response {
    let reason: String = reason.into();
    (status, Json(json!({"ok": false, "reason": reason}))).into_response()
}

fn link_failure(error: &LinkError) -> Response {
    let status = match error {
        LinkError::NoReply { .. } => StatusCode::GATEWAY_TIMEOUT,
        _ => StatusCode::BAD_GATEWAY,
    };
    refusal(status, error.to_string())
}

/// The page's command as the service's request, or why it is not one.
fn service_command(body: &[u8]) -> Result<ServiceCommand, String> {
    let page: PageCommand = serde_json::from_slice(body).map_err(|e| {
        format!("the body must be {{\"command\": NAME, \"ids\": [...]}} in JSON: {e}")
    })?;
    if page.command != "remove" && !page.ids.is_empty() {
        return Err(format!("'{}' takes no ids", page.command));
    }
    Ok(match page.command.as_str() {
        "start" => ServiceCommand::Start,
        "stop" => ServiceCommand::Stop,
        "get" => ServiceCommand::Get(GetRequest::default()),
        "remove" => ServiceCommand::Remove(RemoveRequest { ids: page.ids }),
        "reset" => ServiceCommand::Reset,
        "align" => ServiceCommand::Align,
        "diagnose" => ServiceCommand::Diagnose,
        other => {
            return Err(format!(
                "unknown command '{other}': the page sends one of {}",
                PAGE_COMMANDS.join(", ")
            ));
        }
    })
}

/// `POST /api/command`: 200 with the service's data, 400 for a body that is not a page command,
/// 409 with the service's reason when it refuses, 502/504 when it does not answer.
pub async fn command(State(shared): State<Arc<Shared>>, body: Bytes) -> Response {
    let command = match service_command(&body) {
        Ok(command) => command,
        Err(reason) => return refusal(StatusCode::BAD_REQUEST, reason),
    };
    let name = command.name();
    let reply = match shared.link.call(command).await {
        Ok(reply) => reply,
        Err(error) => return link_failure(&error),
    };
    // Whatever the answer, the page should see the service's state now rather than at the next
    // poll.
    shared.changed.notify_one();
    if !reply.ok {
        let reason = reply.reason.unwrap_or_else(|| "refused".to_owned());
        return refusal(StatusCode::CONFLICT, reason);
    }
    let data: Value = match reply.into_data(name) {
        Ok(data) => data,
        Err(error) => return refusal(StatusCode::BAD_GATEWAY, error.to_string()),
    };
    Json(json!({"ok": true, "command": name, "data": data})).into_response()
}

/// `GET /api/state`: status, inspections, touches and the service's latest results, asked of it
/// now.
pub async fn state(State(shared): State<Arc<Shared>>) -> Response {
    let status = match shared.fetch_status().await {
        Ok(status) => status,
        Err(reason) => return refusal(StatusCode::BAD_GATEWAY, reason),
    };
    match shared.fetch_state(status.results_serial).await {
        Ok(state) => Json(json!({"status": status, "state": state})).into_response(),
        Err(reason) => refusal(StatusCode::BAD_GATEWAY, reason),
    }
}

/// `GET /api/scene`: the part's mesh and nominal pose from the session the service loaded.
pub async fn scene(State(shared): State<Arc<Shared>>) -> Response {
    Json(shared.scene.document().clone()).into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn page_commands_become_the_service_commands_of_the_same_name() {
        for name in PAGE_COMMANDS {
            let body = format!(r#"{{"command": "{name}"}}"#);
            let command = match name {
                "remove" => service_command(br#"{"command": "remove", "ids": ["3"]}"#),
                _ => service_command(body.as_bytes()),
            };
            assert_eq!(command.map(|c| c.name()), Ok(name));
        }
    }

    #[test]
    fn files_unknown_commands_and_stray_fields_are_refused_with_the_reason() {
        let save = service_command(br#"{"command": "save", "path": "/etc/passwd"}"#);
        assert!(save.is_err_and(|reason| reason.contains("path")));
        let load = service_command(br#"{"command": "load"}"#);
        assert!(load.is_err_and(|reason| reason.contains("unknown command 'load'")));
        let ids = service_command(br#"{"command": "reset", "ids": ["1"]}"#);
        assert!(ids.is_err_and(|reason| reason.contains("takes no ids")));
        assert!(service_command(b"not json").is_err());
    }
}
