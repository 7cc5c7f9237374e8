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

/// Why a journal line was not read as an entry.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum JournalLineError {
    #[error("not a journal line (expected 'CRC32 LENGTH JSON')")]
    Format,
    #[error("length {declared} bytes declared, {actual} found")]
    Length { declared: usize, actual: usize },
    #[error("checksum {declared:08x} declared, {actual:08x} computed: the line was altered")]
    Checksum { declared: u32, actual: u32 },
    #[error("the entry is not valid: {0}")]
    Entry(String),
}

impl JournalEntry {
    /// The entry as one journal line, newline included: `CRC32 LENGTH JSON`, the CRC-32 (IEEE,
    /// 8 hex digits) and the byte length of the JSON, so that a reader tells a torn or altered
    /// line from a good one.
    pub fn to_line(&self) -> Result<String, crate::ProtocolError> {
        let json = serde_json::to_string(self)
            .map_err(|error| crate::ProtocolError::Shape(error.to_string()))?;
        Ok(format!(
            "{:08x} {} {json}\n",
            crc32(json.as_bytes()),
            json.len()
        ))
    }

    /// Reads one journal line (without its newline). A line of bare JSON, as journals were
    /// written before entries carried a checksum, is read as it is.
    pub fn from_line(line: &[u8]) -> Result<Self, JournalLineError> {
        let json = if line.first() == Some(&b'{') {
            line
        } else {
            let mut fields = line.splitn(3, |byte| *byte == b' ');
            let (Some(crc), Some(length), Some(json)) =
                (fields.next(), fields.next(), fields.next())
            else {
                return Err(JournalLineError::Format);
            };
            let parse = |field: &[u8], radix| {
                std::str::from_utf8(field)
                    .ok()
                    .and_then(|text| u64::from_str_radix(text, radix).ok())
                    .ok_or(JournalLineError::Format)
            };
            let declared_crc = parse(crc, 16)?;
            let declared_length = parse(length, 10)?;
            if usize::try_from(declared_length).ok() != Some(json.len()) {
                return Err(JournalLineError::Length {
                    declared: usize::try_from(declared_length).unwrap_or(usize::MAX),
                    actual: json.len(),
                });
            }
            let actual = crc32(json);
            if u64::from(actual) != declared_crc {
                return Err(JournalLineError::Checksum {
                    declared: u32::try_from(declared_crc).unwrap_or(u32::MAX),
                    actual,
                });
            }
            json
        };
        serde_json::from_slice(json).map_err(|error| JournalLineError::Entry(error.to_string()))
    }
}

/// CRC-32 (IEEE 802.3, the polynomial of zlib and PNG), bit by bit: journal lines are short
/// and written once per acknowledged change, so a table buys nothing.
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &byte in bytes {
        crc ^= u32::from(byte);
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !crc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_is_the_ieee_checksum() {
        // The standard check value of CRC-32/ISO-HDLC.
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
    }

    #[test]
    fn lines_round_trip_and_any_altered_byte_is_caught() {
        let entry = JournalEntry::Remove {
            ids: vec!["3".to_owned(), "14".to_owned()],
        };
        let line = entry.to_line().unwrap();
        assert!(line.ends_with('\n'));
        let body = line.trim_end().as_bytes();
        assert_eq!(JournalEntry::from_line(body), Ok(entry));
        for index in 0..body.len() {
            let mut altered = body.to_vec();
            altered[index] ^= 0x01;
            assert!(
                JournalEntry::from_line(&altered).is_err(),
                "byte {index} flipped: {}",
                String::from_utf8_lossy(&altered)
            );
        }
        for cut in 0..body.len() {
            assert!(
                JournalEntry::from_line(&body[..cut]).is_err(),
                "cut at {cut}"
            );
        }
    }

    #[test]
    fn lines_written_before_checksums_still_read() {
        let old = br#"{"inspection":{"id":"4","q":[0.1,0.2]},"op":"add"}"#;
        assert!(matches!(
            JournalEntry::from_line(old),
            Ok(JournalEntry::Add { inspection }) if inspection.id == "4"
        ));
    }
}
