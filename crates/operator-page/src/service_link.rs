//! The page's one connection to the alignment service: a ZeroMQ REQ socket owned by a thread of
//! its own (a socket is `!Sync` and blocks), fed through a channel. Every request from the page
//! is a typed [`ServiceCommand`] in the thesis's envelope, exactly what `ips` sends, so the
//! service validates it as any other client's.

use std::sync::mpsc;
use std::thread;
use std::time::Duration;

use protocol::{ServiceCommand, ServiceReply, ServiceReplyBody};
use tokio::sync::oneshot;

/// Why a request got no reply (a refusal is a reply: `ok: false` with the service's reason).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LinkError {
    #[error("no reply from the alignment service at {endpoint} within {timeout_s:.1} s")]
    NoReply { endpoint: String, timeout_s: f64 },
    #[error("alignment service at {endpoint}: {reason}")]
    Socket { endpoint: String, reason: String },
    #[error("the page's service link has stopped")]
    Stopped,
}

struct Call {
    command: ServiceCommand,
    reply: oneshot::Sender<Result<ServiceReplyBody, LinkError>>,
}

/// A handle to the link's thread; cloning it shares the one socket, whose requests then go out
/// in turn (the service answers in turn anyway).
#[derive(Debug, Clone)]
pub struct ServiceLink {
    calls: mpsc::Sender<Call>,
}

impl ServiceLink {
    /// Starts the link's thread; it connects on the first request and ends when every handle is
    /// dropped. `timeout` bounds each wait for a reply: a diagnose takes about 0.3 s.
    pub fn connect(endpoint: &str, timeout: Duration) -> Self {
        let (calls, receiver) = mpsc::channel::<Call>();
        let endpoint = endpoint.to_owned();
        thread::spawn(move || serve_calls(&endpoint, timeout, &receiver));
        Self { calls }
    }

    /// Sends `command` and waits for the service's reply body.
    pub async fn call(&self, command: ServiceCommand) -> Result<ServiceReplyBody, LinkError> {
        let (reply, answer) = oneshot::channel();
        self.calls
            .send(Call { command, reply })
            .map_err(|_| LinkError::Stopped)?;
        answer.await.map_err(|_| LinkError::Stopped)?
    }
}

fn serve_calls(endpoint: &str, timeout: Duration, calls: &mpsc::Receiver<Call>) {
    let context = zmq::Context::new();
    let mut socket: Option<zmq::Socket> = None;
    while let Ok(call) = calls.recv() {
        let result = request(&context, &mut socket, endpoint, timeout, &call.command);
        // A REQ socket that got no reply cannot send again: the next call connects afresh.
        if result.is_err() {
            socket = None;
        }
        let _ = call.reply.send(result);
    }
}

fn request(
    context: &zmq::Context,
    socket: &mut Option<zmq::Socket>,
    endpoint: &str,
    timeout: Duration,
    command: &ServiceCommand,
) -> Result<ServiceReplyBody, LinkError> {
    let failed = |error: zmq::Error| LinkError::Socket {
        endpoint: endpoint.to_owned(),
        reason: error.to_string(),
    };
    let req = match socket {
        Some(req) => req,
        None => {
            let req = context.socket(zmq::REQ).map_err(failed)?;
            req.set_linger(0).map_err(failed)?;
            let timeout_ms = i32::try_from(timeout.as_millis()).unwrap_or(i32::MAX);
            req.set_rcvtimeo(timeout_ms).map_err(failed)?;
            req.set_sndtimeo(timeout_ms).map_err(failed)?;
            req.connect(endpoint).map_err(failed)?;
            socket.insert(req)
        }
    };
    let text = protocol::to_json(&protocol::service_request(command.clone())).map_err(|e| {
        LinkError::Socket {
            endpoint: endpoint.to_owned(),
            reason: e.to_string(),
        }
    })?;
    req.send(text.as_bytes(), 0).map_err(failed)?;
    let bytes = req.recv_bytes(0).map_err(|_| LinkError::NoReply {
        endpoint: endpoint.to_owned(),
        timeout_s: timeout.as_secs_f64(),
    })?;
    let reply: ServiceReply = serde_json::from_slice(&bytes).map_err(|e| LinkError::Socket {
        endpoint: endpoint.to_owned(),
        reason: format!("a reply that is not the service's: {e}"),
    })?;
    Ok(reply.body)
}

/// The endpoint a client on this machine connects to for a service bound at `bound`: a
/// wildcard address (`tcp://0.0.0.0:4000`, `tcp://*:4000`, `tcp://[::]:4000`) is reached on
/// loopback.
pub fn local_endpoint(bound: &str) -> String {
    for wildcard in ["tcp://0.0.0.0:", "tcp://*:", "tcp://[::]:"] {
        if let Some(port) = bound.strip_prefix(wildcard) {
            return format!("tcp://127.0.0.1:{port}");
        }
    }
    bound.to_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_service_bound_on_every_interface_is_reached_on_loopback() {
        assert_eq!(local_endpoint("tcp://0.0.0.0:4000"), "tcp://127.0.0.1:4000");
        assert_eq!(local_endpoint("tcp://*:4000"), "tcp://127.0.0.1:4000");
        assert_eq!(local_endpoint("tcp://[::]:4000"), "tcp://127.0.0.1:4000");
        assert_eq!(
            local_endpoint("tcp://192.168.1.10:4000"),
            "tcp://192.168.1.10:4000"
        );
    }

    #[tokio::test]
    async fn a_service_that_does_not_answer_is_a_timeout_and_the_next_call_tries_again() {
        // A bound ROUTER that never replies: the REQ's send succeeds, its receive times out.
        let context = zmq::Context::new();
        let silent = context.socket(zmq::ROUTER).unwrap();
        silent.set_linger(0).unwrap();
        silent.bind("tcp://127.0.0.1:*").unwrap();
        let endpoint = silent.get_last_endpoint().unwrap().unwrap();
        let link = ServiceLink::connect(&endpoint, Duration::from_millis(100));
        for _ in 0..2 {
            let error = link.call(ServiceCommand::Status).await.unwrap_err();
            assert!(matches!(error, LinkError::NoReply { .. }), "{error}");
        }
    }
}
