//! Mesh and cloud files: round trips through every supported format, unit scaling, and a clear
//! message naming the file for every kind of bad file.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::path::{Path, PathBuf};

use align_core::geometry::Mesh;
use align_core::io::{TriangleSoup, read_cloud, read_mesh, write_stl_binary, write_xyz};
use nalgebra::Point3;

struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        let dir =
            std::env::temp_dir().join(format!("cobot-align-io-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Self(dir)
    }

    fn write(&self, name: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
        let path = self.0.join(name);
        std::fs::write(&path, bytes).unwrap();
        path
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn cube_soup() -> TriangleSoup {
    let cube = Mesh::cuboid([20.0, 30.0, 40.0]).unwrap();
    TriangleSoup {
        vertices: cube.vertices().collect(),
        triangles: cube.triangles().to_vec(),
    }
}

fn error(result: Result<impl std::fmt::Debug, align_core::io::FileError>) -> String {
    result.unwrap_err().to_string()
}

#[test]
fn binary_stl_round_trips_and_scales_from_mm() {
    let scratch = Scratch::new("stl");
    let path = scratch.0.join("cube.stl");
    write_stl_binary(&path, &cube_soup()).unwrap();
    let soup = read_mesh(&path, 0.001).unwrap();
    assert_eq!(soup.triangles.len(), 12);
    let mesh = Mesh::new(&soup.vertices, &soup.triangles).unwrap();
    assert!(
        mesh.is_watertight(),
        "merged vertices close the cube: {:?}",
        mesh.notes()
    );
    let (min, max) = mesh.bounds();
    assert!(((max - min) - nalgebra::Vector3::new(0.02, 0.03, 0.04)).norm() < 1e-9);
}

#[test]
fn binary_stl_whose_header_starts_with_solid_is_still_binary() {
    let scratch = Scratch::new("solid");
    let path = scratch.0.join("cube.stl");
    write_stl_binary(&path, &cube_soup()).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[..5].copy_from_slice(b"solid");
    let path = scratch.write("solid.stl", bytes);
    assert_eq!(read_mesh(&path, 1.0).unwrap().triangles.len(), 12);
}

#[test]
fn ascii_stl_obj_and_ply_read_the_same_square() {
    let scratch = Scratch::new("text");
    let stl = scratch.write(
        "square.STL",
        "solid sq\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 1 1 0\nendloop\nendfacet\n\
         facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 1 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid sq\n",
    );
    let obj = scratch.write(
        "square.obj",
        "# quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 -1//1\n",
    );
    let ply = scratch.write(
        "square.ply",
        "ply\nformat ascii 1.0\ncomment quad\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\n\
         element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0 255\n1 0 0 255\n1 1 0 255\n0 1 0 255\n4 0 1 2 3\n",
    );
    for path in [stl, obj, ply] {
        let soup = read_mesh(&path, 2.0).unwrap();
        assert_eq!(soup.triangles.len(), 2, "{}", path.display());
        let area: f64 = soup
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| soup.vertices[i as usize]);
                (b - a).cross(&(c - a)).norm() / 2.0
            })
            .sum();
        assert!(
            (area - 4.0).abs() < 1e-12,
            "{}: area {area}",
            path.display()
        );
    }
}

fn binary_ply(big_endian: bool) -> Vec<u8> {
    let format = if big_endian {
        "binary_big_endian"
    } else {
        "binary_little_endian"
    };
    let mut bytes = format!(
        "ply\nformat {format} 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\nproperty float intensity\n\
         element face 1\nproperty list uchar uint vertex_indices\nend_header\n"
    )
    .into_bytes();
    let put_f64 = |bytes: &mut Vec<u8>, v: f64| {
        bytes.extend_from_slice(&if big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        })
    };
    for (x, y, z) in [(0.0, 0.0, 0.0), (3.0, 0.0, 0.0), (0.0, 4.0, 0.5)] {
        put_f64(&mut bytes, x);
        put_f64(&mut bytes, y);
        put_f64(&mut bytes, z);
        bytes.extend_from_slice(&if big_endian {
            1.0f32.to_be_bytes()
        } else {
            1.0f32.to_le_bytes()
        });
    }
    bytes.push(3);
    for index in [0u32, 1, 2] {
        bytes.extend_from_slice(&if big_endian {
            index.to_be_bytes()
        } else {
            index.to_le_bytes()
        });
    }
    bytes
}

#[test]
fn binary_ply_in_both_byte_orders() {
    let scratch = Scratch::new("ply");
    for big_endian in [false, true] {
        let path = scratch.write(&format!("t{big_endian}.ply"), binary_ply(big_endian));
        let soup = read_mesh(&path, 1.0).unwrap();
        assert_eq!(soup.triangles, vec![[0, 1, 2]]);
        assert_eq!(soup.vertices[2], Point3::new(0.0, 4.0, 0.5));
        assert_eq!(read_cloud(&path, 1.0).unwrap().len(), 3);
    }
}

#[test]
fn pcd_ascii_and_binary_and_xyz_columns() {
    let scratch = Scratch::new("pcd");
    let ascii = scratch.write(
        "a.pcd",
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n1 2 3 0\n4 5 6 0\n",
    );
    let mut binary = b"VERSION 0.7\nFIELDS intensity x y z\nSIZE 4 4 4 8\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA binary\n".to_vec();
    for (x, y, z) in [(1.0f32, 2.0f32, 3.0f64), (4.0, 5.0, 6.0)] {
        binary.extend_from_slice(&9.0f32.to_le_bytes());
        binary.extend_from_slice(&x.to_le_bytes());
        binary.extend_from_slice(&y.to_le_bytes());
        binary.extend_from_slice(&z.to_le_bytes());
    }
    let binary = scratch.write("b.pcd", binary);
    let csv = scratch.write("c.csv", "x,y,z,intensity\n1,2,3,0.5\n# a comment\n4;5;6\n");
    for path in [ascii, binary, csv] {
        let cloud = read_cloud(&path, 0.001).unwrap();
        assert_eq!(
            cloud,
            vec![
                Point3::new(0.001, 0.002, 0.003),
                Point3::new(0.004, 0.005, 0.006)
            ],
            "{}",
            path.display()
        );
    }
    let points = vec![Point3::new(0.5, -1.25, 3.0)];
    let xyz = scratch.0.join("w.xyz");
    write_xyz(&xyz, &points).unwrap();
    assert_eq!(read_cloud(&xyz, 1.0).unwrap(), points);
}

#[test]
fn bad_files_are_refused_naming_the_file_and_the_problem() {
    let scratch = Scratch::new("bad");
    let good = scratch.0.join("good.stl");
    write_stl_binary(&good, &cube_soup()).unwrap();
    let mut truncated = std::fs::read(&good).unwrap();
    truncated.truncate(300);
    let truncated = scratch.write("truncated.stl", truncated);
    let message = error(read_mesh(&truncated, 1.0));
    assert!(message.contains("truncated.stl': truncated or corrupt binary STL: the header declares 12 triangles (684 bytes) but the file has 300 bytes"), "{message}");

    let nan = scratch.write("nan.obj", "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n");
    assert!(error(read_mesh(&nan, 1.0)).ends_with("nan.obj': vertex 2 is not finite"));

    let empty = scratch.write("empty.obj", "# nothing\n");
    assert!(error(read_mesh(&empty, 1.0)).ends_with("empty.obj': the file holds no triangles"));
    let empty_cloud = scratch.write("empty.xyz", "");
    assert!(error(read_cloud(&empty_cloud, 1.0)).ends_with("empty.xyz': the file holds no points"));

    let png = scratch.write("image.stl", b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR not a mesh at all, just bytes padding padding padding padding padding padding padding");
    assert!(error(read_mesh(&png, 1.0)).contains("image.stl': truncated or corrupt binary STL"));

    let unknown = scratch.write("part.step", "ISO-10303-21;");
    assert!(
        error(read_mesh(&unknown, 1.0))
            .ends_with("part.step': unknown format (expected .stl, .obj or .ply for a mesh)")
    );
    assert!(error(read_cloud(&unknown, 1.0)).contains("unknown format"));

    let missing = Path::new("/no/such/part.stl");
    assert!(error(read_mesh(missing, 1.0)).starts_with("'/no/such/part.stl': No such file"));

    let out_of_range = scratch.write("range.obj", "v 0 0 0\nv 1 0 0\nf 1 2 7\n");
    assert!(
        error(read_mesh(&out_of_range, 1.0))
            .contains("line 3: face index 7 is out of range (2 vertices so far)")
    );

    let bad_xyz = scratch.write("bad.xyz", "1 2 3\n4 five 6\n");
    assert!(error(read_cloud(&bad_xyz, 1.0)).contains("bad.xyz': line 2: expected three numbers"));

    let compressed = scratch.write(
        "c.pcd",
        "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nDATA binary_compressed\n....",
    );
    assert!(error(read_cloud(&compressed, 1.0)).contains("binary_compressed PCD is not supported"));

    assert_eq!(
        error(read_mesh(&good, 0.0)),
        "unit scale 0 must be finite and > 0"
    );
}
