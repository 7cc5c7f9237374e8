//! The demo's conversation with the cell: typed requests to sim-robot's control socket and to
//! the alignment service, and the capture of each planned touch once the simulator says the
//! ball rests on it.

use std::time::{Duration, Instant};

use cell::ChildProcess;
use protocol::session::Inspection;
use protocol::sim::{self, ProbePlan, SimCommand, SimStatus};
use protocol::{GetRequest, MirroringReply, ServiceCommand};
use serde::de::DeserializeOwned;

use crate::CliError;

/// How long a touch rests in contact before it is captured: a few controller sample periods
/// (8 ms at 125 Hz), so that the stream has caught up with the arm at rest.
const SETTLE_S: f64 = 0.05;

fn socket(
    context: &zmq::Context,
    kind: zmq::SocketType,
    endpoint: &str,
) -> Result<zmq::Socket, CliError> {
    let failure = |error: zmq::Error| CliError::Failure(format!("{endpoint}: {error}"));
    let socket = context.socket(kind).map_err(failure)?;
    socket.set_linger(0).map_err(failure)?;
    socket.set_rcvtimeo(10_000).map_err(failure)?;
    socket.connect(endpoint).map_err(failure)?;
    Ok(socket)
}

/// The REQ sockets to sim-robot's control and to the service.
pub struct Links {
    control: zmq::Socket,
    service: zmq::Socket,
}

impl std::fmt::Debug for Links {
    fn fmt(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        formatter.write_str("Links")
    }
}

impl Links {
    pub fn connect(
        context: &zmq::Context,
        control_endpoint: &str,
        service_endpoint: &str,
    ) -> Result<Self, CliError> {
        Ok(Self {
            control: socket(context, zmq::REQ, control_endpoint)?,
            service: socket(context, zmq::REQ, service_endpoint)?,
        })
    }

    /// One request to sim-robot's control socket; a refusal is a failure of the demo.
    pub fn control<T: DeserializeOwned>(
        &self,
        command: &SimCommand,
        timeout: Duration,
    ) -> Result<T, CliError> {
        let failure = |reason: String| CliError::Failure(format!("sim-robot control: {reason}"));
        let text = serde_json::to_string(command).map_err(|e| failure(e.to_string()))?;
        let timeout_ms = i32::try_from(timeout.as_millis()).unwrap_or(i32::MAX);
        self.control
            .set_rcvtimeo(timeout_ms)
            .map_err(|e| failure(e.to_string()))?;
        self.control
            .send(text.as_bytes(), 0)
            .map_err(|e| failure(e.to_string()))?;
        let reply = self
            .control
            .recv_bytes(0)
            .map_err(|_| failure(format!("no reply within {timeout:?}")))?;
        sim::parse_reply(&reply).map_err(|error| failure(error.to_string()))
    }

    /// One request to the service: `Ok(Err(reason))` when the service refused it.
    pub fn service<T: DeserializeOwned>(
        &self,
        command: ServiceCommand,
    ) -> Result<Result<T, String>, CliError> {
        let name = command.name();
        let text = protocol::to_json(&protocol::service_request(command))
            .map_err(|e| CliError::Failure(e.to_string()))?;
        self.service
            .send(text.as_bytes(), 0)
            .map_err(|e| CliError::Failure(format!("{name}: {e}")))?;
        let reply = self
            .service
            .recv_bytes(0)
            .map_err(|_| CliError::Failure(format!("{name}: no reply within the timeout")))?;
        let reply: protocol::ServiceReply = serde_json::from_slice(&reply)
            .map_err(|error| CliError::Failure(format!("{name}: bad reply: {error}")))?;
        match reply.body.into_data(name) {
            Ok(data) => Ok(Ok(data)),
            Err(protocol::ReplyError::Refused(reason)) => Ok(Err(reason)),
            Err(shape) => Err(CliError::Failure(shape.to_string())),
        }
    }
}

/// An error when a child has exited.
pub fn check_alive(children: &mut [&mut ChildProcess]) -> Result<(), CliError> {
    for child in children.iter_mut() {
        child
            .check_alive()
            .map_err(|error| CliError::Failure(error.to_string()))?;
    }
    Ok(())
}

/// Asks the service to start mirroring until the bridge has its controller (20 s at most).
pub fn start_mirroring(links: &Links, children: &mut [&mut ChildProcess]) -> Result<(), CliError> {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let reason = match links.service::<MirroringReply>(ServiceCommand::Start)? {
            Ok(_) => return Ok(()),
            Err(reason) => reason,
        };
        check_alive(children)?;
        if Instant::now() > deadline {
            return Err(CliError::Failure(format!(
                "the service could not start mirroring: {reason}"
            )));
        }
        // The bridge connects to its controller on its own schedule; ask again shortly.
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Waits until touch `index` of `plan` can be captured: the ball at rest on it (settled for a
/// few sample periods), or on the fly just past its trigger time.
fn wait_for_touch(
    links: &Links,
    children: &mut [&mut ChildProcess],
    plan: &ProbePlan,
    index: usize,
    on_the_fly: bool,
) -> Result<(), CliError> {
    let contact = plan.contacts.get(index).ok_or_else(|| {
        CliError::Failure(format!(
            "sim-robot planned no contact for touch {}",
            index + 1
        ))
    })?;
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let status: SimStatus = links.control(&SimCommand::Status, Duration::from_secs(10))?;
        let probe = status.probe.as_ref();
        let ready = if on_the_fly {
            // Past the contact far enough for the stream to hold the trigger's sample.
            status.time >= contact.at_s + SETTLE_S
        } else {
            // At rest by the simulator's clock; the bridge's newest sample may be one period
            // older, so let the contact settle for a few sample periods first.
            probe.is_some_and(|p| p.active_touch == Some(index))
                && status.at_rest
                && status.time >= contact.from_s + SETTLE_S
        };
        if ready {
            return Ok(());
        }
        if probe.is_some_and(|p| p.done) {
            return Err(CliError::Failure(format!(
                "sim-robot finished probing before touch {} was captured",
                index + 1
            )));
        }
        check_alive(children)?;
        if Instant::now() > deadline {
            return Err(CliError::Failure(format!(
                "touch {} did not come to rest within 60 s",
                index + 1
            )));
        }
        // Polls the simulator's clock, which has no event to wait on.
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Captures every touch of `plan` through the service's `get`.
pub fn capture_touches(
    links: &Links,
    children: &mut [&mut ChildProcess],
    plan: &ProbePlan,
    on_the_fly: bool,
    mut progress: impl FnMut(&str),
) -> Result<(), CliError> {
    for index in 0..plan.touches {
        wait_for_touch(links, children, plan, index, on_the_fly)?;
        // On the fly, the touch is the sample at the trigger's time stamp, as a touch-trigger
        // probe wired to the controller would give it.
        let time_s = on_the_fly.then(|| plan.contacts[index].at_s);
        let got = links.service::<Inspection>(ServiceCommand::Get(GetRequest { time_s }))?;
        if let Err(reason) = got {
            return Err(CliError::Failure(format!(
                "get refused at touch {}: {reason}",
                index + 1
            )));
        }
        progress(&format!("touch {} of {} captured", index + 1, plan.touches));
    }
    Ok(())
}
