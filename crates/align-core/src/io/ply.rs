//! PLY (ASCII, binary little- and big-endian): the vertex element's x, y, z and the face
//! element's vertex index lists; other elements and properties are skipped.

use std::path::Path;

use nalgebra::Point3;

use super::{FileError, TriangleSoup, format_error};

#[derive(Debug, Clone, Copy, PartialEq)]
enum Encoding {
    Ascii,
    LittleEndian,
    BigEndian,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Debug, Clone)]
enum Property {
    Scalar(String, Scalar),
    List(String, Scalar, Scalar),
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

/// What a PLY file holds that the project uses.
#[derive(Debug, Default)]
pub(super) struct PlyData {
    pub vertices: Vec<Point3<f64>>,
    pub faces: Vec<Vec<u32>>,
}

impl PlyData {
    pub fn into_soup(self, path: &Path) -> Result<TriangleSoup, FileError> {
        let mut triangles = Vec::new();
        for (index, face) in self.faces.iter().enumerate() {
            if face.len() < 3 {
                return Err(format_error(
                    path,
                    format!("face {index} has {} vertices", face.len()),
                ));
            }
            for k in 1..face.len() - 1 {
                triangles.push([face[0], face[k], face[k + 1]]);
            }
        }
        Ok(TriangleSoup {
            vertices: self.vertices,
            triangles,
        })
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
    encoding: Encoding,
    words: std::str::SplitAsciiWhitespace<'a>,
}

impl Reader<'_> {
    fn read(&mut self, scalar: Scalar) -> Option<f64> {
        if self.encoding == Encoding::Ascii {
            return self.words.next()?.parse().ok();
        }
        let size = scalar.size();
        let raw = self.bytes.get(self.at..self.at + size)?;
        self.at += size;
        let mut buffer = [0u8; 8];
        buffer[..size].copy_from_slice(raw);
        if self.encoding == Encoding::BigEndian {
            buffer[..size].reverse();
        }
        Some(match scalar {
            Scalar::I8 => buffer[0] as i8 as f64,
            Scalar::U8 => buffer[0] as f64,
            Scalar::I16 => i16::from_le_bytes([buffer[0], buffer[1]]) as f64,
            Scalar::U16 => u16::from_le_bytes([buffer[0], buffer[1]]) as f64,
            Scalar::I32 => i32::from_le_bytes([buffer[0], buffer[1], buffer[2], buffer[3]]) as f64,
            Scalar::U32 => u32::from_le_bytes([buffer[0], buffer[1], buffer[2], buffer[3]]) as f64,
            Scalar::F32 => f32::from_le_bytes([buffer[0], buffer[1], buffer[2], buffer[3]]) as f64,
            Scalar::F64 => f64::from_le_bytes(buffer),
        })
    }
}

pub(super) fn parse(path: &Path, bytes: &[u8]) -> Result<PlyData, FileError> {
    let header_end = find(bytes, b"end_header")
        .ok_or_else(|| format_error(path, "not a PLY file (no 'end_header' line)"))?;
    let header = std::str::from_utf8(&bytes[..header_end])
        .map_err(|_| format_error(path, "the PLY header is not text"))?;
    if !header.starts_with("ply") {
        return Err(format_error(
            path,
            "not a PLY file (it does not start with 'ply')",
        ));
    }
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    for line in header.lines().skip(1) {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["format", "ascii", ..] => encoding = Some(Encoding::Ascii),
            ["format", "binary_little_endian", ..] => encoding = Some(Encoding::LittleEndian),
            ["format", "binary_big_endian", ..] => encoding = Some(Encoding::BigEndian),
            ["element", name, count] => elements.push(Element {
                name: (*name).to_owned(),
                count: count.parse().map_err(|_| {
                    format_error(path, format!("element '{name}' has a bad count '{count}'"))
                })?,
                properties: Vec::new(),
            }),
            ["property", "list", count_type, item_type, name] => {
                let scalar = |t: &str| {
                    Scalar::parse(t)
                        .ok_or_else(|| format_error(path, format!("unknown PLY type '{t}'")))
                };
                let property =
                    Property::List((*name).to_owned(), scalar(count_type)?, scalar(item_type)?);
                elements
                    .last_mut()
                    .ok_or_else(|| format_error(path, "a property before any element"))?
                    .properties
                    .push(property);
            }
            ["property", kind, name] => {
                let scalar = Scalar::parse(kind)
                    .ok_or_else(|| format_error(path, format!("unknown PLY type '{kind}'")))?;
                elements
                    .last_mut()
                    .ok_or_else(|| format_error(path, "a property before any element"))?
                    .properties
                    .push(Property::Scalar((*name).to_owned(), scalar));
            }
            _ => {}
        }
    }
    let encoding =
        encoding.ok_or_else(|| format_error(path, "the PLY header has no 'format' line"))?;
    // The body starts after the newline that ends "end_header".
    let mut body_start = header_end + b"end_header".len();
    while bytes
        .get(body_start)
        .is_some_and(|b| *b == b'\r' || *b == b'\n')
    {
        body_start += 1;
        if bytes[body_start - 1] == b'\n' {
            break;
        }
    }
    let body = &bytes[body_start..];
    let text = if encoding == Encoding::Ascii {
        std::str::from_utf8(body)
            .map_err(|_| format_error(path, "an ASCII PLY body that is not text"))?
    } else {
        ""
    };
    let mut reader = Reader {
        bytes: body,
        at: 0,
        encoding,
        words: text.split_ascii_whitespace(),
    };
    let truncated = |element: &str, index: usize| {
        format_error(
            path,
            format!("truncated PLY: element '{element}' ends at item {index}"),
        )
    };
    let mut data = PlyData::default();
    for element in &elements {
        let position = |axis: &str| {
            element
                .properties
                .iter()
                .position(|p| matches!(p, Property::Scalar(name, _) if name == axis))
        };
        let xyz = (position("x"), position("y"), position("z"));
        for index in 0..element.count {
            let mut coordinates = [0.0; 3];
            for (slot, property) in element.properties.iter().enumerate() {
                match property {
                    Property::Scalar(_, scalar) => {
                        let value = reader
                            .read(*scalar)
                            .ok_or_else(|| truncated(&element.name, index))?;
                        for (axis, found) in [xyz.0, xyz.1, xyz.2].into_iter().enumerate() {
                            if found == Some(slot) {
                                coordinates[axis] = value;
                            }
                        }
                    }
                    Property::List(name, count_type, item_type) => {
                        let count = reader
                            .read(*count_type)
                            .ok_or_else(|| truncated(&element.name, index))?;
                        let mut items = Vec::with_capacity(count as usize);
                        for _ in 0..count as usize {
                            items.push(
                                reader
                                    .read(*item_type)
                                    .ok_or_else(|| truncated(&element.name, index))?,
                            );
                        }
                        if element.name == "face"
                            && (name == "vertex_indices" || name == "vertex_index")
                        {
                            if items.iter().any(|&i| i < 0.0) {
                                return Err(format_error(
                                    path,
                                    format!("face {index} has a negative index"),
                                ));
                            }
                            data.faces.push(items.iter().map(|&i| i as u32).collect());
                        }
                    }
                }
            }
            if element.name == "vertex" {
                if let (Some(_), Some(_), Some(_)) = xyz {
                    data.vertices.push(Point3::from(coordinates));
                } else {
                    return Err(format_error(path, "the vertex element lacks x, y or z"));
                }
            }
        }
    }
    Ok(data)
}

fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack
        .windows(needle.len())
        .position(|window| window == needle)
}
