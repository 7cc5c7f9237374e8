//! The inspection journal: every change to the inspection list is appended as one
//! [`JournalEntry`] line and forced to disk before the request is acknowledged, so an
//! acknowledged inspection survives a crash; a restarted service replays the journal.

use std::fs::{File, OpenOptions};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};

use protocol::JournalEntry;
use protocol::session::Inspection;

use super::ServiceError;

#[derive(Debug)]
pub(crate) struct Journal {
    file: File,
}

/// The inspection list a journal leaves, and the highest numeric id it ever held.
#[derive(Debug, Default)]
pub(crate) struct Replayed {
    pub inspections: Vec<Inspection>,
    pub highest_id: u64,
}

fn numeric_id(inspection: &Inspection) -> Option<u64> {
    inspection.id.parse().ok()
}

/// The highest numeric id among `inspections` (ids are numbers the service counts up from).
pub(crate) fn highest_id(inspections: &[Inspection]) -> u64 {
    inspections.iter().filter_map(numeric_id).max().unwrap_or(0)
}

impl Replayed {
    fn apply(&mut self, entry: JournalEntry) {
        match entry {
            JournalEntry::Add { inspection } => {
                self.highest_id = self.highest_id.max(numeric_id(&inspection).unwrap_or(0));
                self.inspections.push(inspection);
            }
            JournalEntry::Remove { ids } => self.inspections.retain(|i| !ids.contains(&i.id)),
            JournalEntry::Reset => self.inspections.clear(),
            JournalEntry::Load { inspections } => {
                self.highest_id = self.highest_id.max(highest_id(&inspections));
                self.inspections = inspections;
            }
        }
    }
}

/// Replays the journal at `path`, `None` when there is none yet. A line that is not an entry
/// (a torn last line: a crash mid-write, never acknowledged) is skipped.
pub(crate) fn replay(path: &Path) -> Result<Option<Replayed>, ServiceError> {
    let Ok(file) = File::open(path) else {
        return Ok(None);
    };
    let mut replayed = Replayed::default();
    for line in BufReader::new(file).lines() {
        let line = line.map_err(|source| ServiceError::Journal {
            path: path.to_owned(),
            source,
        })?;
        if let Some(entry) = JournalEntry::from_line(&line) {
            replayed.apply(entry);
        }
    }
    Ok(Some(replayed))
}

impl Journal {
    /// Opens the journal at `path` for appending, creating it.
    pub(crate) fn open(path: &Path) -> Result<Self, ServiceError> {
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .map_err(|source| ServiceError::Journal {
                path: PathBuf::from(path),
                source,
            })?;
        Ok(Self { file })
    }

    /// Appends one entry and forces it to disk.
    pub(crate) fn append(&mut self, entry: &JournalEntry) -> Result<(), String> {
        let line = entry
            .to_line()
            .map_err(|e| format!("cannot write the journal: {e}"))?;
        self.file
            .write_all(line.as_bytes())
            .and_then(|()| self.file.sync_data())
            .map_err(|e| format!("cannot write the journal: {e}"))
    }
}
