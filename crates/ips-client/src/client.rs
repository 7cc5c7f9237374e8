//! One request to a running `ips serve` and its typed reply: what `ips start|stop|get|...`,
//! `ips align --service`, `ips align-cloud --service` and `ips diagnose --service` send.

use std::time::Duration;

use protocol::{ReplyError, ServiceCommand, ServiceReply};
use serde::de::DeserializeOwned;

use crate::{BadInput, CliError};

/// How long a client waits for a reply unless told otherwise. The service answers in turn, so
/// this covers a queue of slow requests (an align-cloud takes a fraction of a second, see
/// align-service's server).
pub const DEFAULT_REPLY_TIMEOUT: Duration = Duration::from_secs(30);

/// Sends `command` to the service at `endpoint` and returns the reply's data as `T`, waiting
/// [`DEFAULT_REPLY_TIMEOUT`]. A request the service refuses is bad input (exit 2) with the
/// service's reason; no reply in time is a failure (exit 1).
pub fn request<T: DeserializeOwned>(
    endpoint: &str,
    command: ServiceCommand,
) -> Result<T, CliError> {
    request_within(endpoint, command, DEFAULT_REPLY_TIMEOUT)
}

/// As [`request`], waiting at most `timeout` for the reply.
pub fn request_within<T: DeserializeOwned>(
    endpoint: &str,
    command: ServiceCommand,
    timeout: Duration,
) -> Result<T, CliError> {
    let name = command.name();
    let failure = |error: zmq::Error| CliError::Failure(format!("{endpoint}: {error}"));
    let context = zmq::Context::new();
    let socket = context.socket(zmq::REQ).map_err(failure)?;
    socket.set_linger(0).map_err(failure)?;
    let timeout_ms = i32::try_from(timeout.as_millis())
        .unwrap_or(i32::MAX)
        .max(1);
    socket.set_rcvtimeo(timeout_ms).map_err(failure)?;
    socket.set_sndtimeo(5_000).map_err(failure)?;
    socket
        .connect(endpoint)
        .map_err(|error| BadInput(format!("{endpoint}: {error}")))?;
    let text = protocol::to_json(&protocol::service_request(command)).map_err(BadInput::new)?;
    socket.send(text.as_bytes(), 0).map_err(failure)?;
    let reply = socket.recv_bytes(0).map_err(|_| {
        CliError::Failure(format!(
            "no reply from the service at {endpoint} within {:.1} s: is `ips serve` running there?",
            timeout.as_secs_f64()
        ))
    })?;
    let reply: ServiceReply = serde_json::from_slice(&reply)
        .map_err(|error| CliError::Failure(format!("bad reply from the service: {error}")))?;
    reply.body.into_data(name).map_err(|error| match error {
        ReplyError::Refused(reason) => BadInput(reason).into(),
        shape @ ReplyError::Shape { .. } => CliError::Failure(shape.to_string()),
    })
}
