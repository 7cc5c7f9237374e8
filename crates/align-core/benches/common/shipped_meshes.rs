//! The meshes shipped with crates/cad-scans (xArm7 and SO-ARM100 links), the default of the
//! benches that time something per mesh.

use std::path::{Path, PathBuf};

/// The STL files in crates/cad-scans/meshes, sorted.
pub fn shipped_meshes() -> Result<Vec<PathBuf>, String> {
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../cad-scans/meshes");
    let mut found: Vec<PathBuf> = std::fs::read_dir(&shipped)
        .map_err(|error| format!("{}: {error}", shipped.display()))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "stl"))
        .collect();
    found.sort();
    Ok(found)
}
