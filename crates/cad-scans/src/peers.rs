//! The peers (Open3D's point-to-plane ICP, small_gicp's GICP) run by `peers/cad_scan_peers.py`
//! in the project's venv (`scripts/peer-env.sh` installs them) on the files the runner wrote.
//! The script prints one JSON line per scene; the runner scores the poses exactly as its own.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use serde::Deserialize;

use crate::files::isometry_from_rows;
use crate::trials::Outcome;

/// The peers' names as the script's JSON and the table use them.
pub const PEERS: [&str; 2] = ["open3d", "small_gicp"];

/// The peer script shipped with this crate.
pub fn default_script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("peers/cad_scan_peers.py")
}

#[derive(Debug, thiserror::Error)]
pub enum PeerError {
    #[error(
        "cannot start '{python}': {source} (run scripts/peer-env.sh to make the venv with Open3D and small_gicp, or pass --no-peers)"
    )]
    Start {
        python: PathBuf,
        source: std::io::Error,
    },
    #[error("the peer script failed ({status}); its messages are above")]
    Failed { status: std::process::ExitStatus },
    #[error("the peer script printed a line that is not a scene's result: {line:?}: {source}")]
    Parse {
        line: String,
        source: serde_json::Error,
    },
}

#[derive(Debug, Deserialize)]
struct PeerLine {
    id: usize,
    #[serde(flatten)]
    methods: HashMap<String, PeerResult>,
}

#[derive(Debug, Deserialize)]
struct PeerResult {
    pose: Option<[[f64; 4]; 4]>,
    #[serde(default)]
    time_s: f64,
    error: Option<String>,
}

/// Every peer's outcome per trial id: `results[id][peer]`.
pub type PeerOutcomes = HashMap<usize, HashMap<String, Outcome>>;

/// Runs the script on the scenes the manifest lists; its progress goes to our stderr.
pub fn run_peers(
    python: &Path,
    script: &Path,
    manifest: &Path,
    threads: usize,
) -> Result<PeerOutcomes, PeerError> {
    let output = Command::new(python)
        .arg(script)
        .arg("--manifest")
        .arg(manifest)
        .arg("--threads")
        .arg(threads.to_string())
        .stdin(Stdio::null())
        .stderr(Stdio::inherit())
        .output()
        .map_err(|source| PeerError::Start {
            python: python.to_owned(),
            source,
        })?;
    if !output.status.success() {
        return Err(PeerError::Failed {
            status: output.status,
        });
    }
    parse_peer_lines(&String::from_utf8_lossy(&output.stdout))
}

fn parse_peer_lines(text: &str) -> Result<PeerOutcomes, PeerError> {
    let mut outcomes = PeerOutcomes::new();
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let parsed: PeerLine = serde_json::from_str(line).map_err(|source| PeerError::Parse {
            line: line.to_owned(),
            source,
        })?;
        let methods = parsed
            .methods
            .into_iter()
            .map(|(name, result)| {
                let outcome = match (result.pose, result.error) {
                    (Some(rows), None) => Outcome {
                        pose: Some(isometry_from_rows(&rows)),
                        time_s: result.time_s,
                        ambiguous: false,
                        refused: None,
                        miss_scores: None,
                    },
                    (_, error) => Outcome {
                        time_s: result.time_s,
                        ..Outcome::refused(error.unwrap_or_else(|| "no pose".to_owned()))
                    },
                };
                (name, outcome)
            })
            .collect();
        outcomes.insert(parsed.id, methods);
    }
    Ok(outcomes)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

    #[test]
    fn a_peer_line_gives_each_method_its_pose_or_its_error() {
        let line = r#"{"id": 3, "open3d": {"pose": [[1,0,0,0.5],[0,1,0,0],[0,0,1,0],[0,0,0,1]], "time_s": 0.25}, "small_gicp": {"error": "too few points", "time_s": 0.01}}"#;
        let outcomes = super::parse_peer_lines(line).unwrap();
        let open3d = &outcomes[&3]["open3d"];
        assert_eq!(open3d.pose.unwrap().translation.vector.x, 0.5);
        assert_eq!(open3d.time_s, 0.25);
        let gicp = &outcomes[&3]["small_gicp"];
        assert!(gicp.pose.is_none());
        assert_eq!(gicp.refused.as_deref(), Some("too few points"));
    }
}
