//! STL (binary and ASCII) and Wavefront OBJ.

use std::path::Path;

use nalgebra::Point3;

use super::{FileError, TriangleSoup, format_error};

const STL_HEADER_BYTES: usize = 80;
const STL_TRIANGLE_BYTES: usize = 50;

/// Binary STL is recognised by its size (84 + 50 n bytes for the n it declares), not by the
/// "solid" keyword, which many binary exporters also write into the header.
pub(super) fn parse_stl(path: &Path, bytes: &[u8]) -> Result<TriangleSoup, FileError> {
    if bytes.len() >= STL_HEADER_BYTES + 4 {
        let declared = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        let expected = STL_HEADER_BYTES + 4 + declared * STL_TRIANGLE_BYTES;
        if bytes.len() == expected {
            return Ok(parse_binary_stl(bytes, declared));
        }
        let looks_ascii =
            bytes.trim_ascii_start().starts_with(b"solid") && std::str::from_utf8(bytes).is_ok();
        if !looks_ascii {
            return Err(format_error(
                path,
                format!(
                    "truncated or corrupt binary STL: the header declares {declared} triangles ({expected} bytes) but the file has {} bytes",
                    bytes.len()
                ),
            ));
        }
    }
    let text = std::str::from_utf8(bytes).map_err(|_| {
        format_error(
            path,
            "neither a binary STL (size does not match) nor ASCII STL text",
        )
    })?;
    parse_ascii_stl(path, text)
}

fn parse_binary_stl(bytes: &[u8], count: usize) -> TriangleSoup {
    let mut soup = TriangleSoup {
        vertices: Vec::with_capacity(count * 3),
        triangles: Vec::with_capacity(count),
    };
    let float = |offset: usize| {
        f32::from_le_bytes([
            bytes[offset],
            bytes[offset + 1],
            bytes[offset + 2],
            bytes[offset + 3],
        ]) as f64
    };
    for triangle in 0..count {
        // 12 bytes of normal (ignored: recomputed from the winding), 3 vertices, 2 attribute bytes.
        let base = STL_HEADER_BYTES + 4 + triangle * STL_TRIANGLE_BYTES + 12;
        let first = soup.vertices.len() as u32;
        for corner in 0..3 {
            let at = base + corner * 12;
            soup.vertices
                .push(Point3::new(float(at), float(at + 4), float(at + 8)));
        }
        soup.triangles.push([first, first + 1, first + 2]);
    }
    soup
}

fn parse_ascii_stl(path: &Path, text: &str) -> Result<TriangleSoup, FileError> {
    let mut soup = TriangleSoup::default();
    let mut corners = 0;
    for (number, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("vertex") => {
                let values: Vec<f64> =
                    words
                        .map(str::parse)
                        .collect::<Result<_, _>>()
                        .map_err(|_| {
                            format_error(
                                path,
                                format!("line {}: a vertex needs three numbers", number + 1),
                            )
                        })?;
                if values.len() != 3 {
                    return Err(format_error(
                        path,
                        format!("line {}: a vertex needs three numbers", number + 1),
                    ));
                }
                soup.vertices
                    .push(Point3::new(values[0], values[1], values[2]));
                corners += 1;
            }
            Some("endfacet") => {
                if corners != 3 {
                    return Err(format_error(
                        path,
                        format!("line {}: a facet has {corners} vertices, not 3", number + 1),
                    ));
                }
                let first = soup.vertices.len() as u32 - 3;
                soup.triangles.push([first, first + 1, first + 2]);
                corners = 0;
            }
            _ => {}
        }
    }
    if soup.triangles.is_empty() && !text.trim_start().starts_with("solid") {
        return Err(format_error(
            path,
            "not an STL file (no 'solid' header, size not binary STL)",
        ));
    }
    Ok(soup)
}

/// OBJ: `v x y z` and `f a b c ...` (1-based or negative indices, `a/t/n` forms), polygons
/// triangulated as fans; everything else (normals, texture coordinates, groups) ignored.
pub(super) fn parse_obj(path: &Path, bytes: &[u8]) -> Result<TriangleSoup, FileError> {
    let text = std::str::from_utf8(bytes)
        .map_err(|_| format_error(path, "OBJ files are text, this is not"))?;
    let mut soup = TriangleSoup::default();
    for (number, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let bad = |what: &str| format_error(path, format!("line {}: {what}", number + 1));
        match words.next() {
            Some("v") => {
                let values: Vec<f64> = words
                    .take(3)
                    .map(str::parse)
                    .collect::<Result<_, _>>()
                    .map_err(|_| bad("a vertex needs three numbers"))?;
                if values.len() != 3 {
                    return Err(bad("a vertex needs three numbers"));
                }
                soup.vertices
                    .push(Point3::new(values[0], values[1], values[2]));
            }
            Some("f") => {
                let count = soup.vertices.len() as i64;
                let indices: Vec<u32> = words
                    .map(|word| {
                        let index: i64 = word
                            .split('/')
                            .next()
                            .and_then(|i| i.parse().ok())
                            .ok_or_else(|| bad(&format!("face index '{word}' is not a number")))?;
                        let resolved = if index < 0 { count + index } else { index - 1 };
                        if resolved < 0 || resolved >= count {
                            return Err(bad(&format!(
                                "face index {index} is out of range ({count} vertices so far)"
                            )));
                        }
                        Ok(resolved as u32)
                    })
                    .collect::<Result<_, _>>()?;
                if indices.len() < 3 {
                    return Err(bad("a face needs at least 3 vertices"));
                }
                for k in 1..indices.len() - 1 {
                    soup.triangles
                        .push([indices[0], indices[k], indices[k + 1]]);
                }
            }
            _ => {}
        }
    }
    Ok(soup)
}

/// Writes a binary STL (f32 coordinates, normals from the winding).
pub fn write_stl_binary(path: &Path, soup: &TriangleSoup) -> Result<(), FileError> {
    let mut bytes = Vec::with_capacity(84 + soup.triangles.len() * 50);
    let mut header = [b' '; 80];
    let label = b"binary STL written by cobot-align";
    header[..label.len()].copy_from_slice(label);
    bytes.extend_from_slice(&header);
    bytes.extend_from_slice(&(soup.triangles.len() as u32).to_le_bytes());
    for triangle in &soup.triangles {
        let [a, b, c] = triangle.map(|i| soup.vertices[i as usize]);
        let normal = (b - a)
            .cross(&(c - a))
            .try_normalize(0.0)
            .unwrap_or_default();
        for value in normal
            .iter()
            .chain(a.coords.iter())
            .chain(b.coords.iter())
            .chain(c.coords.iter())
        {
            bytes.extend_from_slice(&(*value as f32).to_le_bytes());
        }
        bytes.extend_from_slice(&[0, 0]);
    }
    std::fs::write(path, bytes).map_err(|source| FileError::Io {
        path: path.to_owned(),
        source,
    })
}
