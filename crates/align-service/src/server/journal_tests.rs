use super::*;

fn inspection(id: u64) -> Inspection {
    Inspection {
        id: id.to_string(),
        q: Some(vec![0.1 * id as f64, -1.2, 1.4, -1.8, -1.57, 0.0]),
        flange_pose: None,
        qd: Some(vec![0.0; 6]),
        stamp: Some(id as f64),
        face: None,
        trigger: None,
    }
}

/// A journal's path in a scratch folder that is removed when this is dropped, also when an
/// assertion fails and the test unwinds, so that runs leave nothing in the temp folder. It
/// derefs to the journal's path.
struct Scratch {
    folder: PathBuf,
    path: PathBuf,
}

impl std::ops::Deref for Scratch {
    type Target = Path;

    fn deref(&self) -> &Path {
        &self.path
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.path
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        // Best effort: a leftover folder is no reason to fail a test.
        let _ = std::fs::remove_dir_all(&self.folder);
    }
}

fn scratch(name: &str) -> Scratch {
    let folder =
        std::env::temp_dir().join(format!("cobot-align-journal-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&folder);
    let scratch = Scratch {
        path: folder.join("inspections.journal"),
        folder,
    };
    std::fs::create_dir_all(&scratch.folder).unwrap();
    scratch
}

/// A journal of `count` added inspections, and the byte offset where each line ends.
fn journal_of(path: &Path, count: u64) -> Vec<usize> {
    let mut journal = Journal::open(path).unwrap();
    let mut ends = Vec::new();
    for id in 1..=count {
        journal
            .append(&JournalEntry::Add {
                inspection: inspection(id),
            })
            .unwrap();
        ends.push(std::fs::metadata(path).unwrap().len() as usize);
    }
    ends
}

fn ids(inspections: &[Inspection]) -> Vec<String> {
    inspections.iter().map(|i| i.id.clone()).collect()
}

#[test]
fn a_crash_at_any_byte_of_the_last_writes_loses_only_the_unacknowledged_entry() {
    let original = scratch("torn");
    let ends = journal_of(&original, 5);
    let bytes = std::fs::read(&original).unwrap();
    let torn = original.with_file_name("torn.journal");
    // Every offset from the start of the fourth line to the end of the file.
    for cut in ends[2]..=bytes.len() {
        std::fs::write(&torn, &bytes[..cut]).unwrap();
        let acknowledged = ends.iter().filter(|end| **end <= cut).count() as u64;
        let replayed = replay(&torn).unwrap().unwrap();
        let expected: Vec<String> = (1..=acknowledged).map(|id| id.to_string()).collect();
        assert_eq!(ids(&replayed.inspections), expected, "cut at byte {cut}");
        assert!(replayed.report.skipped.is_empty(), "cut at {cut}");
        let torn_bytes = cut - ends[..acknowledged as usize].last().copied().unwrap_or(0);
        assert_eq!(replayed.report.torn_tail_bytes, torn_bytes, "cut at {cut}");
        // The next acknowledged entry after a restart is kept too: it starts on a line of its
        // own, not glued to the torn one.
        Journal::open(&torn)
            .unwrap()
            .append(&JournalEntry::Add {
                inspection: inspection(99),
            })
            .unwrap();
        let again = replay(&torn).unwrap().unwrap();
        let mut with_next = expected.clone();
        with_next.push("99".to_owned());
        assert_eq!(ids(&again.inspections), with_next, "cut at byte {cut}");
        assert!(again.report.skipped.is_empty() && again.report.torn_tail_bytes == 0);
    }
}

#[test]
fn corrupt_lines_are_reported_quarantined_and_the_good_ones_replayed() {
    let path = scratch("corrupt");
    journal_of(&path, 6);
    let text = std::fs::read(&path).unwrap();
    let mut lines: Vec<Vec<u8>> = text
        .split(|b| *b == b'\n')
        .filter(|l| !l.is_empty())
        .map(<[u8]>::to_vec)
        .collect();
    // A digit flipped inside q on line 2, a 0xFF byte on line 4, a comment line inserted
    // before line 6.
    let q_digit = lines[1].windows(3).position(|w| w == b"-1.").unwrap() + 1;
    lines[1][q_digit] = b'7';
    lines[3][20] = 0xFF;
    lines.insert(5, b"# edited by hand".to_vec());
    let mut corrupted = lines.join(&b'\n');
    corrupted.push(b'\n');
    std::fs::write(&path, &corrupted).unwrap();
    let replayed = replay(&path).unwrap().unwrap();
    assert_eq!(ids(&replayed.inspections), ["1", "3", "5", "6"]);
    let skipped: Vec<usize> = replayed
        .report
        .skipped
        .iter()
        .map(|(line, _)| *line)
        .collect();
    assert_eq!(skipped, [2, 4, 6]);
    assert!(
        replayed.report.skipped[0].1.contains("checksum"),
        "{:?}",
        replayed.report
    );
    let quarantine = replayed.report.quarantine.clone().unwrap();
    let kept = std::fs::read(&quarantine).unwrap();
    assert_eq!(
        kept.split(|b| *b == b'\n')
            .filter(|l| !l.is_empty())
            .count(),
        3
    );
    assert_eq!(replayed.report.warnings().len(), 4);
}

#[test]
fn a_journal_that_does_not_exist_yet_is_none_and_one_unreadable_is_an_error() {
    let path = scratch("missing");
    assert!(replay(&path).unwrap().is_none());
    // A directory where the journal should be: an error naming it, not an empty list.
    std::fs::create_dir_all(&path).unwrap();
    let error = replay(&path).unwrap_err().to_string();
    assert!(error.contains("inspections.journal"), "{error}");
}

#[test]
fn damaged_journals_never_fail_the_start_and_never_invent_an_inspection() {
    let path = scratch("fuzz");
    journal_of(&path, 8);
    let original = std::fs::read(&path).unwrap();
    let damaged = path.with_file_name("damaged.journal");
    let mut state = 0x1234_5678_9ABC_DEF1u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    for _ in 0..2_000 {
        let mut bytes = original.clone();
        for _ in 0..1 + next() % 4 {
            let at = (next() as usize) % bytes.len();
            match next() % 4 {
                0 => bytes[at] ^= 1 << (next() % 8),
                1 => bytes.insert(at, (next() >> 24) as u8),
                2 => {
                    bytes.remove(at);
                }
                _ => bytes.truncate(at.max(1)),
            }
        }
        std::fs::write(&damaged, &bytes).unwrap();
        let replayed = replay(&damaged).unwrap().unwrap();
        // Every entry that survives its checksum is one that was written.
        for inspection in &replayed.inspections {
            let id: u64 = inspection.id.parse().unwrap();
            assert_eq!(*inspection, self::inspection(id));
        }
        let _ = std::fs::remove_file(quarantine_path(&damaged));
    }
}
