//! Reading part meshes (STL ASCII and binary, OBJ, PLY) and scanner clouds (PLY, PCD ASCII and
//! binary, XYZ/CSV/TXT), scaled to metres by a caller-given unit scale (0.001 for files in mm).
//!
//! Every error names the file and the problem, so a user with twenty files open knows which one
//! to fix and how.

pub mod export;
mod mesh_formats;
mod ply;
mod point_formats;

use std::path::{Path, PathBuf};

use nalgebra::Point3;

pub use mesh_formats::write_stl_binary;
pub use point_formats::write_xyz;

/// Indexed triangles exactly as read (after unit scaling): no merging or orientation fixes.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriangleSoup {
    pub vertices: Vec<Point3<f64>>,
    pub triangles: Vec<[u32; 3]>,
}

#[derive(Debug, thiserror::Error)]
pub enum FileError {
    #[error("'{path}': {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("'{path}': {message}")]
    Format { path: PathBuf, message: String },
    #[error("'{path}': unknown format (expected {expected})")]
    UnknownFormat {
        path: PathBuf,
        expected: &'static str,
    },
    #[error("'{path}': the file holds no {what}")]
    Empty { path: PathBuf, what: &'static str },
    #[error("'{path}': {what} {index} is not finite")]
    NonFinite {
        path: PathBuf,
        what: &'static str,
        index: usize,
    },
    #[error("unit scale {0} must be finite and > 0")]
    BadScale(f64),
}

pub(crate) fn format_error(path: &Path, message: impl Into<String>) -> FileError {
    FileError::Format {
        path: path.to_owned(),
        message: message.into(),
    }
}

fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

fn read_bytes(path: &Path) -> Result<Vec<u8>, FileError> {
    std::fs::read(path).map_err(|source| FileError::Io {
        path: path.to_owned(),
        source,
    })
}

fn check_scale(unit_scale: f64) -> Result<(), FileError> {
    if unit_scale.is_finite() && unit_scale > 0.0 {
        Ok(())
    } else {
        Err(FileError::BadScale(unit_scale))
    }
}

fn scale_and_check(
    path: &Path,
    points: &mut [Point3<f64>],
    unit_scale: f64,
    what: &'static str,
) -> Result<(), FileError> {
    for (index, point) in points.iter_mut().enumerate() {
        if !point.coords.iter().all(|c| c.is_finite()) {
            return Err(FileError::NonFinite {
                path: path.to_owned(),
                what,
                index,
            });
        }
        point.coords *= unit_scale;
    }
    Ok(())
}

/// Reads a triangle mesh (.stl, .obj, .ply), coordinates multiplied by `unit_scale`.
pub fn read_mesh(path: &Path, unit_scale: f64) -> Result<TriangleSoup, FileError> {
    check_scale(unit_scale)?;
    let bytes = read_bytes(path)?;
    let mut soup = match extension(path).as_str() {
        "stl" => mesh_formats::parse_stl(path, &bytes)?,
        "obj" => mesh_formats::parse_obj(path, &bytes)?,
        "ply" => ply::parse(path, &bytes)?.into_soup(path)?,
        _ => {
            return Err(FileError::UnknownFormat {
                path: path.to_owned(),
                expected: ".stl, .obj or .ply for a mesh",
            });
        }
    };
    if soup.triangles.is_empty() {
        return Err(FileError::Empty {
            path: path.to_owned(),
            what: "triangles",
        });
    }
    if let Some((index, &vertex)) = soup.triangles.iter().enumerate().find_map(|(i, t)| {
        t.iter()
            .find(|&&v| v as usize >= soup.vertices.len())
            .map(|v| (i, v))
    }) {
        return Err(format_error(
            path,
            format!(
                "triangle {index} uses vertex {vertex}, but the file has {} vertices",
                soup.vertices.len()
            ),
        ));
    }
    scale_and_check(path, &mut soup.vertices, unit_scale, "vertex")?;
    Ok(soup)
}

/// Reads a point cloud (.ply, .pcd, .xyz, .csv, .txt), coordinates multiplied by `unit_scale`.
pub fn read_cloud(path: &Path, unit_scale: f64) -> Result<Vec<Point3<f64>>, FileError> {
    check_scale(unit_scale)?;
    let bytes = read_bytes(path)?;
    let mut points = match extension(path).as_str() {
        "ply" => ply::parse(path, &bytes)?.vertices,
        "pcd" => point_formats::parse_pcd(path, &bytes)?,
        "xyz" | "csv" | "txt" => point_formats::parse_xyz(path, &bytes)?,
        _ => {
            return Err(FileError::UnknownFormat {
                path: path.to_owned(),
                expected: ".ply, .pcd, .xyz, .csv or .txt for a point cloud",
            });
        }
    };
    if points.is_empty() {
        return Err(FileError::Empty {
            path: path.to_owned(),
            what: "points",
        });
    }
    scale_and_check(path, &mut points, unit_scale, "point")?;
    Ok(points)
}
