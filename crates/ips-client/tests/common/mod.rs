//! What the `ips` integration tests share: a scratch file or folder in the temp folder that is
//! removed when the test ends, passed or not.

// Each test file compiles this module on its own and uses only some of it.
#![allow(dead_code)]
#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::ops::Deref;
use std::path::{Path, PathBuf};

/// A file or folder in the temp folder, removed when this is dropped: also when an assertion
/// fails and the test unwinds, so that runs leave nothing behind. It derefs to `path`.
#[derive(Debug)]
pub struct Scratch {
    /// What is removed: a folder with everything in it, or a single file.
    root: PathBuf,
    /// What the test uses: `root` itself or a file in it.
    path: PathBuf,
}

impl Scratch {
    /// The folder `folder`, created (with its parents) if it is not there yet.
    pub fn folder(folder: PathBuf) -> Self {
        std::fs::create_dir_all(&folder).unwrap();
        Self {
            path: folder.clone(),
            root: folder,
        }
    }

    /// The file `file` in the folder `folder`, which is created; the file is not. The whole
    /// folder is removed, so that whatever the test writes next to the file goes too.
    pub fn in_folder(folder: PathBuf, file: &str) -> Self {
        std::fs::create_dir_all(&folder).unwrap();
        Self {
            path: folder.join(file),
            root: folder,
        }
    }

    /// The single file `file`, not created: the test writes it.
    pub fn file(file: PathBuf) -> Self {
        Self {
            root: file.clone(),
            path: file,
        }
    }
}

impl Deref for Scratch {
    type Target = Path;

    fn deref(&self) -> &Path {
        &self.path
    }
}

/// So that a `Scratch` can be handed to `std::fs` functions as it is.
impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.path
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        // Best effort: it may be gone already, and a leftover is no reason to fail a test (nor
        // to panic a second time while unwinding).
        if self.root.is_dir() {
            let _ = std::fs::remove_dir_all(&self.root);
        } else {
            let _ = std::fs::remove_file(&self.root);
        }
    }
}
