//! The wire types of cobot-align's ZeroMQ links and files, and the only place they are defined.
//!
//! Every message is one JSON frame `{"header": {"from", "to", "type"}, "body": {...}}`, the
//! envelope of the thesis's messages (section 2.3.3). The instruction request and its ack are
//! byte-for-byte the thesis's (DESIGN.md 6.2); our additions are extra fields only (`reason` on
//! an error ack), and receivers ignore fields they do not know. The language-neutral contract
//! is in `protocol/schemas/` with golden examples in `protocol/examples/`.
//!
//! - [`envelope`]: the envelope, validation before sending, the errors.
//! - [`bridge`]: robot-bridge's instruction, ack, hardware state and status (6.2).
//! - [`service`]: the alignment service's requests and typed replies (6.4, 6.5).
//! - [`reports`]: the alignment and diagnosis documents the service replies and `ips` prints.
//! - [`session`], [`journal`]: the session file (6.3) and the service's journal lines.
//! - [`pose`]: the one pose type of all of them.
//! - [`io`]: the controller's digital inputs in the hardware state (a touch-trigger probe's).
//! - [`calibration`]: a UR controller's calibrated DH table and the calibration file.
//!
//! Senders validate before serialising: [`to_json`] refuses NaN or infinite numbers, which JSON
//! cannot carry and which would poison a twin downstream. Receivers parse with
//! [`parse_request`] and [`parse_service_request`], which refuse arrays where the envelope has
//! objects and name what is wrong.

pub mod bridge;
pub mod calibration;
pub mod envelope;
pub mod io;
pub mod journal;
pub mod pose;
pub mod reports;
pub mod service;
pub mod session;
pub mod sim;

pub use bridge::{
    Command, HwState, HwStateBody, Instruction, InstructionBody, Request, RobotSide, Status,
    StatusBody, ack_error, ack_ok, hw_state, instruction, parse_request, status,
};
pub use envelope::{Envelope, Header, IPS, Message, ProtocolError, to_json};
pub use io::{DigitalInput, InputBank, NotAnInput};
pub use journal::JournalEntry;
pub use pose::Pose;
pub use service::{
    AlignCloudRequest, BallPlace, GetReply, GetRequest, InspectionCountReply, InspectionsReply,
    LatestResult, MAX_SERVICE_REQUEST_BYTES, MirroringReply, NextTouchHint, PathRequest,
    RemoveRequest, ReplyError, ResultsReply, SERVICE, SavedReply, ServiceCommand, ServiceReply,
    ServiceReplyBody, ServiceRequest, StatusReply, parse_service_request, service_reply_error,
    service_reply_ok, service_request,
};
pub use session::{Inspection, SessionFile};
