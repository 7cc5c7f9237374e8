//! Which files a request may name. `load`, `save` and `align-cloud` name files on the service's
//! machine; a client on the network must not read or write anything else there, nor stall the
//! request thread on a FIFO or a device. Requests therefore reach only regular files under the
//! directories the service was started with (`--data-dir`, by default the session file's
//! folder), up to a size per kind of file.

use std::path::{Path, PathBuf};

use crate::BadInput;

/// Largest session file `load` reads, bytes: a session of 100,000 inspections is about 30 MB.
pub(crate) const SESSION_FILE_LIMIT_BYTES: u64 = 64 << 20;
/// Largest scanner cloud `align-cloud` reads, bytes (about 50 million points as text).
pub(crate) const CLOUD_FILE_LIMIT_BYTES: u64 = 2 << 30;
/// Largest mesh `align-cloud` reads, bytes (about 20 million triangles as binary STL).
pub(crate) const MESH_FILE_LIMIT_BYTES: u64 = 1 << 30;

#[derive(Debug, Clone)]
pub(crate) struct FileAccess {
    /// Canonical paths of the allowed directories.
    dirs: Vec<PathBuf>,
}

impl FileAccess {
    /// `dirs` as configured; each must exist and be a directory.
    pub(crate) fn new(dirs: &[PathBuf]) -> Result<Self, BadInput> {
        let dirs = dirs
            .iter()
            .map(|dir| {
                let canonical = dir
                    .canonicalize()
                    .map_err(|e| BadInput(format!("data directory '{}': {e}", dir.display())))?;
                if canonical.is_dir() {
                    Ok(canonical)
                } else {
                    Err(BadInput(format!(
                        "data directory '{}' is not a directory",
                        dir.display()
                    )))
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { dirs })
    }

    fn check_inside(&self, requested: &str, canonical: &Path) -> Result<(), String> {
        if self.dirs.iter().any(|dir| canonical.starts_with(dir)) {
            return Ok(());
        }
        let dirs: Vec<String> = self.dirs.iter().map(|d| d.display().to_string()).collect();
        Err(format!(
            "'{requested}' is outside the service's data directories ({}): start ips serve with --data-dir to allow another",
            dirs.join(", ")
        ))
    }

    /// The path of an existing regular file under a data directory, at most `limit_bytes`
    /// long; `what` names the kind of file in errors.
    pub(crate) fn readable(
        &self,
        requested: &str,
        limit_bytes: u64,
        what: &str,
    ) -> Result<PathBuf, String> {
        let canonical = Path::new(requested)
            .canonicalize()
            .map_err(|e| format!("cannot read '{requested}': {e}"))?;
        self.check_inside(requested, &canonical)?;
        let metadata = canonical
            .metadata()
            .map_err(|e| format!("'{requested}': {e}"))?;
        if !metadata.is_file() {
            return Err(format!(
                "'{requested}' is not a regular file (a {what} must be one)"
            ));
        }
        if metadata.len() > limit_bytes {
            return Err(format!(
                "'{requested}' is {} bytes, over the {limit_bytes}-byte limit for a {what}",
                metadata.len()
            ));
        }
        Ok(canonical)
    }

    /// The path a new or replaced regular file may be written at, under a data directory.
    pub(crate) fn writable(&self, requested: &str) -> Result<PathBuf, String> {
        let path = Path::new(requested);
        let name = path
            .file_name()
            .ok_or_else(|| format!("'{requested}' does not name a file"))?;
        let parent = match path.parent() {
            Some(parent) if !parent.as_os_str().is_empty() => parent,
            _ => Path::new("."),
        };
        let folder = parent
            .canonicalize()
            .map_err(|e| format!("'{}': {e}", parent.display()))?;
        let target = folder.join(name);
        self.check_inside(requested, &target)?;
        // An existing entry is replaced only if it is a regular file: never a device, a FIFO or
        // a link to somewhere else.
        if let Ok(metadata) = target.symlink_metadata()
            && !metadata.is_file()
        {
            return Err(format!(
                "'{requested}' exists and is not a regular file: not replaced"
            ));
        }
        Ok(target)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_regular_files_under_the_data_directories_are_reachable() {
        let root = std::env::temp_dir().join(format!("cobot-align-files-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let inside = root.join("data");
        let outside = root.join("elsewhere");
        std::fs::create_dir_all(&inside).unwrap();
        std::fs::create_dir_all(&outside).unwrap();
        std::fs::write(inside.join("s.json"), "{}").unwrap();
        std::fs::write(outside.join("s.json"), "{}").unwrap();
        let access = FileAccess::new(std::slice::from_ref(&inside)).unwrap();
        let text = |p: &Path| p.display().to_string();
        assert!(
            access
                .readable(&text(&inside.join("s.json")), 10, "session")
                .is_ok()
        );
        let escaped = text(&inside.join("../elsewhere/s.json"));
        assert!(
            access
                .readable(&escaped, 10, "session")
                .unwrap_err()
                .contains("outside")
        );
        assert!(access.writable(&escaped).unwrap_err().contains("outside"));
        let too_big = access.readable(&text(&inside.join("s.json")), 1, "session");
        assert!(too_big.unwrap_err().contains("over the 1-byte limit"));
        assert!(
            access
                .readable(&text(&inside), 10, "session")
                .unwrap_err()
                .contains("not a regular file")
        );
        assert!(access.readable("/dev/zero", 10, "cloud").is_err());
        assert!(access.writable(&text(&inside.join("new.json"))).is_ok());
        assert!(
            access
                .writable(&text(&inside))
                .unwrap_err()
                .contains("not a regular file")
        );
        assert!(FileAccess::new(&[root.join("missing")]).is_err());
        let _ = std::fs::remove_dir_all(&root);
    }
}
