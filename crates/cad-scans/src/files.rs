//! The files a trial leaves for whoever aligns it: the cloud (binary PLY, world frame, m), the
//! part's mesh (binary STL, m) and `scene.json` (the start pose and delta; never the truth, which
//! stays with the runner and goes to `truth.json` for a reader after the fact).

use std::io::Write;
use std::path::{Path, PathBuf};

use align_core::io::{TriangleSoup, write_stl_binary};
use align_core::pose::matrix_rows;
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    #[error("'{path}': {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(transparent)]
    Mesh(#[from] align_core::io::FileError),
    #[error("'{path}': {source}")]
    Json {
        path: PathBuf,
        source: serde_json::Error,
    },
}

/// What a peer reads (`peers/cad_scan_peers.py`): paths relative to the scene's folder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneFile {
    pub id: usize,
    pub part: String,
    pub cloud: String,
    pub mesh: String,
    pub delta_m: f64,
    /// `world_from_part` at the start, 4x4 row-major.
    pub start: [[f64; 4]; 4],
}

/// The paths one trial's files were written to.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialFiles {
    pub dir: PathBuf,
    pub cloud: PathBuf,
    pub mesh: PathBuf,
}

/// Writes `dir/cloud.ply`, `dir/part.stl`, `dir/scene.json` and `dir/truth.json`.
pub fn write_trial(
    dir: &Path,
    scene: &SceneFile,
    cloud: &[Point3<f64>],
    soup: &TriangleSoup,
    truth: &Isometry3<f64>,
) -> Result<TrialFiles, WriteError> {
    let io = |path: &Path| {
        let path = path.to_owned();
        move |source| WriteError::Io { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let files = TrialFiles {
        dir: dir.to_owned(),
        cloud: dir.join(&scene.cloud),
        mesh: dir.join(&scene.mesh),
    };
    write_ply(&files.cloud, cloud).map_err(io(&files.cloud))?;
    write_stl_binary(&files.mesh, soup)?;
    write_json(&dir.join("scene.json"), scene)?;
    write_json(&dir.join("truth.json"), &matrix_rows(truth))?;
    Ok(files)
}

fn write_json(path: &Path, value: &impl Serialize) -> Result<(), WriteError> {
    let text = serde_json::to_string_pretty(value).map_err(|source| WriteError::Json {
        path: path.to_owned(),
        source,
    })?;
    std::fs::write(path, text).map_err(|source| WriteError::Io {
        path: path.to_owned(),
        source,
    })
}

/// Binary little-endian PLY with float x, y, z: a 100k-point scan in 1.2 MB instead of 4 MB of
/// text; float32 rounds a coordinate within a few metres by under a micrometre.
pub fn write_ply(path: &Path, points: &[Point3<f64>]) -> std::io::Result<()> {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
        points.len()
    )?;
    for p in points {
        for c in [p.x, p.y, p.z] {
            out.write_all(&(c as f32).to_le_bytes())?;
        }
    }
    out.flush()
}

/// A 4x4 row-major pose (as reports and peers print it) to an isometry; the rotation block is
/// re-orthonormalised, since printed digits leave it a little off.
pub fn isometry_from_rows(rows: &[[f64; 4]; 4]) -> Isometry3<f64> {
    let rotation = Matrix3::from_fn(|r, c| rows[r][c]);
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_eps(
        &rotation,
        1e-12,
        100,
        Rotation3::identity(),
    ));
    Isometry3::from_parts(
        Translation3::from(Vector3::new(rows[0][3], rows[1][3], rows[2][3])),
        rotation,
    )
}
