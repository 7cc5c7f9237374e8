//! The service's journal: one JSON object per line, appended and flushed to disk before a
//! change to the inspection list is acknowledged, replayed in order at start.

use serde::{Deserialize, Serialize};

use crate::session::Inspection;

/// One change to the inspection list. Lines written before the entries were typed
/// (`{"inspection": .., "op": "add"}`, keys in any order) read the same.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "op", rename_all = "lowercase")]
pub enum JournalEntry {
    /// An inspection taken (`get`) or present in the session file the journal started from.
    Add {
        inspection: Inspection,
    },
    Remove {
        ids: Vec<String>,
    },
    Reset,
    /// The whole list replaced by a session file's inspections, in one entry so that a crash
    /// leaves either the old list or the new one.
    Load {
        inspections: Vec<Inspection>,
    },
}

impl JournalEntry {
    /// The entry as one journal line, newline included.
    pub fn to_line(&self) -> Result<String, crate::ProtocolError> {
        let mut line = serde_json::to_string(self)
            .map_err(|error| crate::ProtocolError::Shape(error.to_string()))?;
        line.push('\n');
        Ok(line)
    }

    /// Reads one journal line; `None` for a line that is not an entry (a torn write).
    pub fn from_line(line: &str) -> Option<Self> {
        serde_json::from_str(line).ok()
    }
}
