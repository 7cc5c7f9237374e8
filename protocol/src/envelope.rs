//! The thesis's envelope `{"header": {"from", "to", "type"}, "body": {...}}`, shared by every
//! message, and what senders and receivers do with it whatever the body.

use serde::{Deserialize, Serialize};

/// Name of the IPS side in headers.
pub const IPS: &str = "ips";

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Header {
    pub from: String,
    pub to: String,
    #[serde(rename = "type")]
    pub kind: String,
}

/// `{"header": ..., "body": ...}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Envelope<B> {
    pub header: Header,
    pub body: B,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProtocolError {
    #[error("the message is not valid JSON: {0}")]
    Json(String),
    #[error("the message does not have the expected shape: {0}")]
    Shape(String),
    #[error("unknown message type '{0}' (expected 'instruction')")]
    UnknownType(String),
    #[error("unknown command '{0}' (expected start, stop or status)")]
    UnknownCommand(String),
    #[error("unknown content '{0}' (expected 'hwState')")]
    UnknownContent(String),
    #[error("field {0} is not a finite number")]
    NonFinite(String),
    #[error("request of {bytes} bytes exceeds the {limit}-byte limit")]
    TooLarge { bytes: usize, limit: usize },
    #[error(
        "unknown command '{0}' (expected status, start, stop, get, list, remove, reset, align, align-cloud, diagnose, save or load)"
    )]
    UnknownServiceCommand(String),
}

/// A message a sender can check before it goes on the wire.
pub trait Message: Serialize {
    /// Checks shapes and that every number is finite (serde_json would write NaN as null).
    fn validate(&self) -> Result<(), ProtocolError>;
}

/// Serialises a message after validating it.
pub fn to_json<T: Message>(message: &T) -> Result<String, ProtocolError> {
    message.validate()?;
    serde_json::to_string(message).map_err(|error| ProtocolError::Shape(error.to_string()))
}

/// Checks that a received message is an object whose `header` and `body` are objects before serde
/// reads it: serde's derived structs also accept arrays (`[["ips","ros","instruction"],
/// ["stop","hwState"]]` would read as a stop), which no sender of the thesis's messages writes.
pub(crate) fn check_envelope_shape(value: &serde_json::Value) -> Result<(), ProtocolError> {
    let object = value.as_object().ok_or_else(|| {
        ProtocolError::Shape(format!("expected a JSON object, got {}", kind_of(value)))
    })?;
    for part in ["header", "body"] {
        match object.get(part) {
            Some(inner) if inner.is_object() => {}
            Some(inner) => {
                return Err(ProtocolError::Shape(format!(
                    "'{part}' must be an object, got {}",
                    kind_of(inner)
                )));
            }
            None => return Err(ProtocolError::Shape(format!("missing field `{part}`"))),
        }
    }
    Ok(())
}

/// What a JSON value is, as error messages name it ("an array").
pub fn kind_of(value: &serde_json::Value) -> &'static str {
    match value {
        serde_json::Value::Null => "null",
        serde_json::Value::Bool(_) => "a boolean",
        serde_json::Value::Number(_) => "a number",
        serde_json::Value::String(_) => "a string",
        serde_json::Value::Array(_) => "an array",
        serde_json::Value::Object(_) => "an object",
    }
}
