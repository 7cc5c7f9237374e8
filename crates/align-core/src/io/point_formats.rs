//! Point Cloud Library's PCD (ASCII and binary) and plain XYZ / CSV / TXT columns.

use std::path::Path;

use nalgebra::Point3;

use super::{FileError, format_error};

/// PCD v0.7: FIELDS / SIZE / TYPE / COUNT describe each point; x, y and z are read, other
/// fields skipped. `binary_compressed` (LZF) is refused with a clear message.
pub(super) fn parse_pcd(path: &Path, bytes: &[u8]) -> Result<Vec<Point3<f64>>, FileError> {
    let mut fields: Vec<String> = Vec::new();
    let mut sizes: Vec<usize> = Vec::new();
    let mut types: Vec<char> = Vec::new();
    let mut counts: Vec<usize> = Vec::new();
    let mut points = None;
    let mut at = 0;
    let mut data_kind = None;
    while at < bytes.len() {
        let end = bytes[at..]
            .iter()
            .position(|b| *b == b'\n')
            .map_or(bytes.len(), |p| at + p);
        let line = std::str::from_utf8(&bytes[at..end])
            .map_err(|_| format_error(path, "the PCD header is not text"))?
            .trim();
        at = end + 1;
        let mut words = line.split_whitespace();
        let Some(key) = words.next() else { continue };
        let rest: Vec<&str> = words.collect();
        let numbers = |what: &str| {
            rest.iter()
                .map(|w| w.parse::<usize>())
                .collect::<Result<Vec<_>, _>>()
                .map_err(|_| format_error(path, format!("PCD {what} line has a non-number")))
        };
        match key.to_ascii_uppercase().as_str() {
            "FIELDS" => fields = rest.iter().map(|w| w.to_string()).collect(),
            "SIZE" => sizes = numbers("SIZE")?,
            "TYPE" => types = rest.iter().filter_map(|w| w.chars().next()).collect(),
            "COUNT" => counts = numbers("COUNT")?,
            "POINTS" => points = numbers("POINTS")?.first().copied(),
            "DATA" => {
                data_kind = rest.first().map(|w| w.to_ascii_lowercase());
                break;
            }
            _ => {}
        }
    }
    let data_kind = data_kind.ok_or_else(|| format_error(path, "not a PCD file (no DATA line)"))?;
    if counts.is_empty() {
        counts = vec![1; fields.len()];
    }
    if fields.is_empty()
        || sizes.len() != fields.len()
        || types.len() != fields.len()
        || counts.len() != fields.len()
    {
        return Err(format_error(
            path,
            "PCD FIELDS, SIZE, TYPE and COUNT disagree in length",
        ));
    }
    let column = |name: &str| {
        fields
            .iter()
            .position(|f| f == name)
            .ok_or_else(|| format_error(path, format!("PCD has no '{name}' field")))
    };
    let (x, y, z) = (column("x")?, column("y")?, column("z")?);
    let point_count = points.ok_or_else(|| format_error(path, "PCD header has no POINTS line"))?;
    match data_kind.as_str() {
        "ascii" => {
            let text = std::str::from_utf8(&bytes[at.min(bytes.len())..])
                .map_err(|_| format_error(path, "ASCII PCD data is not text"))?;
            // Value offsets of x, y, z within a line, counting multi-count fields.
            let offset = |field: usize| counts[..field].iter().sum::<usize>();
            let mut cloud = Vec::with_capacity(point_count);
            for (index, line) in text.lines().filter(|l| !l.trim().is_empty()).enumerate() {
                let values: Vec<&str> = line.split_whitespace().collect();
                let get = |field: usize| {
                    values
                        .get(offset(field))
                        .and_then(|v| v.parse::<f64>().ok())
                        .ok_or_else(|| {
                            format_error(path, format!("PCD point {index} is malformed"))
                        })
                };
                cloud.push(Point3::new(get(x)?, get(y)?, get(z)?));
            }
            Ok(cloud)
        }
        "binary" => {
            let stride: usize = sizes.iter().zip(&counts).map(|(s, c)| s * c).sum();
            let offset = |field: usize| {
                sizes[..field]
                    .iter()
                    .zip(&counts[..field])
                    .map(|(s, c)| s * c)
                    .sum::<usize>()
            };
            let data = &bytes[at.min(bytes.len())..];
            if data.len() < stride * point_count {
                return Err(format_error(
                    path,
                    format!(
                        "truncated binary PCD: {point_count} points of {stride} bytes need {} bytes, the file has {}",
                        stride * point_count,
                        data.len()
                    ),
                ));
            }
            let value = |record: &[u8], field: usize| -> Result<f64, FileError> {
                let start = offset(field);
                let raw = &record[start..start + sizes[field]];
                match (types[field], sizes[field]) {
                    ('F', 4) => Ok(f32::from_le_bytes([raw[0], raw[1], raw[2], raw[3]]) as f64),
                    ('F', 8) => Ok(f64::from_le_bytes(
                        raw.try_into()
                            .map_err(|_| format_error(path, "bad PCD record"))?,
                    )),
                    (kind, size) => Err(format_error(
                        path,
                        format!("PCD coordinate type {kind}{size} is not supported (F4 or F8)"),
                    )),
                }
            };
            (0..point_count)
                .map(|index| {
                    let record = &data[index * stride..(index + 1) * stride];
                    Ok(Point3::new(
                        value(record, x)?,
                        value(record, y)?,
                        value(record, z)?,
                    ))
                })
                .collect()
        }
        "binary_compressed" => Err(format_error(
            path,
            "binary_compressed PCD is not supported; convert it with pcl_convert_pcd_ascii_binary <in> <out> 1",
        )),
        other => Err(format_error(
            path,
            format!("unknown PCD DATA kind '{other}'"),
        )),
    }
}

/// Text columns: the first three numbers of each line are x, y, z; separators are whitespace,
/// commas or semicolons; a non-numeric first line is a header; '#' starts a comment.
pub(super) fn parse_xyz(path: &Path, bytes: &[u8]) -> Result<Vec<Point3<f64>>, FileError> {
    let text = std::str::from_utf8(bytes)
        .map_err(|_| format_error(path, "a text point file that is not text"))?;
    let mut cloud = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let content = line.split('#').next().unwrap_or("").trim();
        if content.is_empty() {
            continue;
        }
        let values: Vec<&str> = content
            .split(|c: char| c == ',' || c == ';' || c.is_whitespace())
            .filter(|w| !w.is_empty())
            .collect();
        let parsed: Option<Vec<f64>> = values.iter().take(3).map(|w| w.parse().ok()).collect();
        match parsed {
            Some(xyz) if xyz.len() == 3 => cloud.push(Point3::new(xyz[0], xyz[1], xyz[2])),
            _ if cloud.is_empty() && number == 0 => {} // header line
            _ => {
                return Err(format_error(
                    path,
                    format!(
                        "line {}: expected three numbers x y z, got '{content}'",
                        number + 1
                    ),
                ));
            }
        }
    }
    Ok(cloud)
}

/// Writes points as "x y z" lines.
pub fn write_xyz(path: &Path, points: &[Point3<f64>]) -> Result<(), FileError> {
    let text: String = points
        .iter()
        .map(|p| format!("{} {} {}\n", p.x, p.y, p.z))
        .collect();
    std::fs::write(path, text).map_err(|source| FileError::Io {
        path: path.to_owned(),
        source,
    })
}
