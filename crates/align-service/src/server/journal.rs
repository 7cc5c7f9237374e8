//! The inspection journal: every change to the inspection list is appended as one
//! [`JournalEntry`] line (`CRC32 LENGTH JSON`) and forced to disk before the request is
//! acknowledged, so an acknowledged inspection survives a crash; a restarted service replays the
//! journal.
//!
//! What a crash or a disk can leave, and what replay does with it:
//! - a torn last line (a crash mid-write, never acknowledged): cut off before anything is
//!   appended, so the next entry starts on a line of its own;
//! - a line that fails its length or checksum, or is not an entry (an edited or corrupted
//!   line): reported by line number and copied to `<journal>.quarantine`; every good entry is
//!   still replayed.

use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use protocol::JournalEntry;
use protocol::session::Inspection;

use super::ServiceError;

#[derive(Debug)]
pub(crate) struct Journal {
    file: File,
}

/// What replaying a journal found besides its entries.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct JournalReport {
    /// Entries replayed.
    pub entries: usize,
    /// 1-based line numbers of lines skipped as corrupt, with why.
    pub skipped: Vec<(usize, String)>,
    /// Where the skipped lines were copied, if any were.
    pub quarantine: Option<PathBuf>,
    /// Bytes of a torn last line cut off.
    pub torn_tail_bytes: usize,
}

impl JournalReport {
    /// One line per thing worth a warning, for the service's log.
    pub fn warnings(&self) -> Vec<String> {
        let mut warnings = Vec::new();
        if self.torn_tail_bytes > 0 {
            warnings.push(format!(
                "journal: cut off a torn last line of {} bytes (a write interrupted before it was acknowledged)",
                self.torn_tail_bytes
            ));
        }
        for (line, why) in &self.skipped {
            warnings.push(format!("journal: skipped line {line}: {why}"));
        }
        if let Some(quarantine) = &self.quarantine {
            warnings.push(format!(
                "journal: {} corrupt line(s) copied to {}; {} good entries replayed",
                self.skipped.len(),
                quarantine.display(),
                self.entries
            ));
        }
        warnings
    }
}

/// The inspection list a journal leaves, the highest numeric id it ever held, and the report.
#[derive(Debug, Default)]
pub(crate) struct Replayed {
    pub inspections: Vec<Inspection>,
    pub highest_id: u64,
    pub report: JournalReport,
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
        self.report.entries += 1;
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

fn journal_error(path: &Path) -> impl Fn(std::io::Error) -> ServiceError + '_ {
    move |source| ServiceError::Journal {
        path: path.to_owned(),
        source,
    }
}

/// The quarantine file beside the journal at `path`.
pub(crate) fn quarantine_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".quarantine");
    path.with_file_name(name)
}

/// Replays the journal at `path`, `None` when there is none yet. A torn last line is cut off
/// the file and corrupt lines are copied to the quarantine file (see the module docs).
pub(crate) fn replay(path: &Path) -> Result<Option<Replayed>, ServiceError> {
    let mut file = match File::open(path) {
        Ok(file) => file,
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => return Err(journal_error(path)(source)),
    };
    let mut bytes = Vec::new();
    file.read_to_end(&mut bytes).map_err(journal_error(path))?;
    let mut replayed = Replayed::default();
    // Everything after the last newline was never acknowledged: the reply waits for the whole
    // line, newline included, to reach the disk.
    let complete = bytes.iter().rposition(|b| *b == b'\n').map_or(0, |i| i + 1);
    if complete < bytes.len() {
        replayed.report.torn_tail_bytes = bytes.len() - complete;
        OpenOptions::new()
            .write(true)
            .open(path)
            .and_then(|file| {
                file.set_len(complete as u64)?;
                file.sync_all()
            })
            .map_err(journal_error(path))?;
    }
    let mut quarantined = Vec::new();
    for (index, line) in bytes[..complete].split(|b| *b == b'\n').enumerate() {
        if line.is_empty() {
            continue;
        }
        match JournalEntry::from_line(line) {
            Ok(entry) => replayed.apply(entry),
            Err(why) => {
                replayed.report.skipped.push((index + 1, why.to_string()));
                quarantined.extend_from_slice(line);
                quarantined.push(b'\n');
            }
        }
    }
    if !quarantined.is_empty() {
        let quarantine = quarantine_path(path);
        OpenOptions::new()
            .create(true)
            .append(true)
            .open(&quarantine)
            .and_then(|mut file| {
                file.write_all(&quarantined)?;
                file.sync_data()
            })
            .map_err(journal_error(&quarantine))?;
        replayed.report.quarantine = Some(quarantine);
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
            .map_err(journal_error(path))?;
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

#[cfg(test)]
#[path = "journal_tests.rs"]
mod tests;
