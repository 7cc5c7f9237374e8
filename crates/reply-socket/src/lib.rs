//! The request socket of every cobot-align service (the bridge's instructions, the alignment
//! service, sim-robot's control): one request, one reply, and nothing a client sends stops it.
//!
//! A fault test found two ways a plain REP socket stops serving everyone: a two-frame request
//! leaves a REP loop that reads one frame owing a reply it cannot send, and raw TCP bytes, which
//! libzmq reads as an unversioned (ZMTP 1.0) peer's messages, leave libzmq's REP state machine
//! stuck so that no later client is answered. A [`ReplySocket`] is therefore a ROUTER that does
//! REP's part itself: it reads every frame of every message, answers a REQ client's request
//! through its envelope (the frames up to the empty delimiter), and drops what no REQ client
//! sends. REQ clients see no difference.

/// The most envelope frames (routing id and any proxies' hops) kept to address a reply; a
/// message with more before its delimiter is not from a REQ client and is dropped.
const MAX_ENVELOPE_FRAMES: usize = 16;

/// Frames larger than this make libzmq drop their peer unread: a bound on what one client can
/// make a service allocate. Requests between a service's own limit and this get a reason.
pub const MAX_FRAME_BYTES: i64 = 16 << 20;

/// A REQ client's request: where the reply goes and what came.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Request {
    /// The routing id, any hops, and the empty delimiter: sent back before the reply.
    envelope: Vec<Vec<u8>>,
    first_frame: Vec<u8>,
    frame_count: usize,
    total_bytes: usize,
}

impl Request {
    /// The request's one frame, or why it is not a request (`limit_bytes` the largest the
    /// service reads).
    pub fn single_frame(&self, limit_bytes: usize) -> Result<&[u8], String> {
        if self.frame_count == 0 {
            return Err(
                "an empty request: a request is one frame holding a JSON object".to_owned(),
            );
        }
        if self.frame_count > 1 {
            return Err(format!(
                "a multipart request of {} frames: a request is a single frame holding one JSON object",
                self.frame_count
            ));
        }
        if self.total_bytes > limit_bytes {
            return Err(format!(
                "request of {} bytes exceeds the {limit_bytes}-byte limit",
                self.total_bytes
            ));
        }
        Ok(&self.first_frame)
    }
}

/// What one wait on the socket gave.
#[derive(Debug)]
pub enum Wait {
    Request(Request),
    /// Nothing within the receive timeout, an interruption, or a message no REQ client sends
    /// (there is no one to answer): look at the shutdown flag again.
    Nothing,
    /// The context is gone: nothing can be received again.
    Closed,
}

/// A bound ROUTER socket serving REQ clients.
pub struct ReplySocket {
    socket: zmq::Socket,
}

impl std::fmt::Debug for ReplySocket {
    fn fmt(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        formatter.write_str("ReplySocket")
    }
}

impl ReplySocket {
    /// Binds to `endpoint` (`tcp://127.0.0.1:*` picks a port) and returns the socket and the
    /// endpoint it bound. Waits for a request at most `receive_timeout_ms` at a time, so the
    /// caller can look at its shutdown flag.
    pub fn bind(
        context: &zmq::Context,
        endpoint: &str,
        receive_timeout_ms: i32,
    ) -> Result<(Self, String), zmq::Error> {
        let socket = context.socket(zmq::ROUTER)?;
        socket.set_linger(0)?;
        socket.set_rcvtimeo(receive_timeout_ms)?;
        // A reply to a client that stopped reading must not hold up every other client; a
        // ROUTER drops such a reply rather than block, and the timeout bounds any other wait.
        socket.set_sndtimeo(1000)?;
        socket.set_maxmsgsize(MAX_FRAME_BYTES)?;
        socket.bind(endpoint)?;
        let bound = socket
            .get_last_endpoint()?
            .unwrap_or_else(|_| endpoint.to_owned());
        Ok((Self { socket }, bound))
    }

    /// Waits for one message and reads all its frames. Frames beyond the first body frame are
    /// counted and dropped, never kept.
    pub fn receive(&self) -> Wait {
        let socket = &self.socket;
        let routing_id = match socket.recv_bytes(0) {
            Ok(frame) => frame,
            Err(zmq::Error::ETERM | zmq::Error::ENOTSOCK) => return Wait::Closed,
            // EAGAIN (the receive timeout), EINTR and anything else are not the socket's end.
            Err(_) => return Wait::Nothing,
        };
        let mut envelope = vec![routing_id];
        let mut delimited = false;
        let mut first_frame = None;
        let (mut frame_count, mut total_bytes) = (0_usize, 0_usize);
        // libzmq delivers a message whole, so its remaining frames are already here.
        while socket.get_rcvmore().unwrap_or(false) {
            let Ok(frame) = socket.recv_bytes(0) else {
                break;
            };
            if !delimited {
                delimited = frame.is_empty();
                if envelope.len() < MAX_ENVELOPE_FRAMES {
                    envelope.push(frame);
                }
                continue;
            }
            frame_count += 1;
            total_bytes = total_bytes.saturating_add(frame.len());
            if first_frame.is_none() {
                first_frame = Some(frame);
            }
        }
        let envelope_complete = envelope.last().is_some_and(Vec::is_empty);
        if !delimited || !envelope_complete {
            // Not a REQ client's request (libzmq's REP drops these too).
            return Wait::Nothing;
        }
        Wait::Request(Request {
            envelope,
            first_frame: first_frame.unwrap_or_default(),
            frame_count,
            total_bytes,
        })
    }

    /// Sends `reply` to the client `request` came from. A ROUTER drops a reply to a peer that
    /// has gone; nothing is left owing, so the error is only for a log.
    pub fn reply(&self, request: &Request, reply: &[u8]) -> Result<(), zmq::Error> {
        let frames = request
            .envelope
            .iter()
            .map(Vec::as_slice)
            .chain(std::iter::once(reply));
        self.socket.send_multipart(frames, 0)
    }
}
