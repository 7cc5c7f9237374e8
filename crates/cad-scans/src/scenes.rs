//! Parts and the seeded scenes that show them: one part standing or lying on a floor beside a
//! box, seen by two or three scanners placed around it.

use std::path::{Path, PathBuf};

use align_core::geometry::Mesh;
use align_core::io::{TriangleSoup, read_mesh};
use align_core::rng::SplitMix64;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::scanner::{
    Origin, ScanNoise, ScanPoint, Scanner, SceneMesh, SceneObject, Surface, scan,
};

/// Where the ABB IRB 1600 link meshes are when no option or `CAD_SCANS_ABB_DIR` names a folder
/// (relative to the working directory: a checkout's root, beside the workplace's shared data).
pub const DEFAULT_ABB_DIR: &str =
    "../shared/data/abb_irb1600/abb_irb1600_support/meshes/irb1600/visual";

/// The meshes shipped with this crate (license notes in `meshes/LICENSE.md`), in metres.
pub const SHIPPED_MESHES: [&str; 5] = [
    "xarm7_link2.stl",
    "xarm7_link4.stl",
    "xarm7_link_base.stl",
    "so100_upper_arm.stl",
    "so100_lower_arm.stl",
];

pub fn shipped_mesh_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("meshes")
}

#[derive(Debug, thiserror::Error)]
pub enum PartError {
    #[error(transparent)]
    File(#[from] align_core::io::FileError),
    #[error("'{path}': {source}")]
    Mesh {
        path: PathBuf,
        source: align_core::geometry::MeshError,
    },
    #[error(
        "part '{name}' is {radius_m:.0} m in radius: meshes are read in metres, and one drawn in millimetres comes out 1000 times too large"
    )]
    NotMetres { name: String, radius_m: f64 },
    #[error("'{path}': no .stl, .obj or .ply file in the folder")]
    NoMeshes { path: PathBuf },
    #[error("'{path}': cannot list the folder: {source}")]
    Folder {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// A part: its triangles as read (metres) for the scene and the files, and the project's mesh of
/// them for the alignment and the pose distance's radius.
#[derive(Debug, Clone)]
pub struct Part {
    pub name: String,
    pub soup: TriangleSoup,
    pub mesh: Mesh,
}

impl Part {
    pub fn from_soup(name: impl Into<String>, soup: TriangleSoup) -> Result<Self, PartError> {
        let name = name.into();
        let mesh =
            Mesh::new(&soup.vertices, &soup.triangles).map_err(|source| PartError::Mesh {
                path: PathBuf::from(&name),
                source,
            })?;
        Ok(Self { name, soup, mesh })
    }

    /// An STL, OBJ or PLY file in metres, named after its file stem with `prefix`.
    pub fn read(path: &Path, prefix: &str) -> Result<Self, PartError> {
        let soup = read_mesh(path, 1.0)?;
        let stem = path
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
        Self::from_soup(format!("{prefix}{stem}"), soup)
    }
}

/// A part read in metres with a radius beyond this was drawn in other units (the largest here,
/// the ABB IRB 1600's base, is 0.4 m; a 200 mm link drawn in millimetres reads as 100 m).
const MAX_PART_RADIUS_M: f64 = 5.0;

/// Refuses a part too large to have been read in the right units (see [`MAX_PART_RADIUS_M`]).
pub fn check_metres(part: &Part) -> Result<(), PartError> {
    let radius_m = part.mesh.radius_m();
    if radius_m > MAX_PART_RADIUS_M {
        return Err(PartError::NotMetres {
            name: part.name.clone(),
            radius_m,
        });
    }
    Ok(())
}

/// The shipped meshes.
pub fn shipped_parts() -> Result<Vec<Part>, PartError> {
    SHIPPED_MESHES
        .iter()
        .map(|file| Part::read(&shipped_mesh_dir().join(file), ""))
        .collect()
}

/// The mesh files a part can be read from (`read_mesh`'s formats), by extension.
const MESH_EXTENSIONS: [&str; 3] = ["stl", "obj", "ply"];

/// Every STL, OBJ or PLY file in `dir` (in metres, as the ABB IRB 1600's visual meshes are),
/// sorted by name, each named after its file stem with `prefix`.
pub fn parts_in(dir: &Path, prefix: &str) -> Result<Vec<Part>, PartError> {
    let entries = std::fs::read_dir(dir).map_err(|source| PartError::Folder {
        path: dir.to_owned(),
        source,
    })?;
    let mut paths: Vec<PathBuf> = entries
        .filter_map(Result::ok)
        .map(|entry| entry.path())
        .filter(|path| {
            path.extension().is_some_and(|e| {
                MESH_EXTENSIONS
                    .iter()
                    .any(|known| e.eq_ignore_ascii_case(known))
            })
        })
        .collect();
    paths.sort();
    if paths.is_empty() {
        return Err(PartError::NoMeshes {
            path: dir.to_owned(),
        });
    }
    paths.iter().map(|path| Part::read(path, prefix)).collect()
}

/// How the part rests on the floor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Posture {
    /// As its CAD frame has it (z up, as a robot link stands at zero joints).
    Standing,
    /// Turned a quarter about x or y, then laid down.
    Lying,
}

/// One scene's scan and its truth.
#[derive(Debug, Clone)]
pub struct Scene {
    pub part: String,
    pub posture: Posture,
    pub world_from_part: Isometry3<f64>,
    pub points: Vec<ScanPoint>,
    pub scanners: Vec<Scanner>,
    /// The ray spacing each scanner was set up for at the part's centre, m.
    pub spacing_m: Vec<f64>,
}

impl Scene {
    pub fn cloud(&self) -> Vec<Point3<f64>> {
        self.points.iter().map(|p| p.point).collect()
    }

    pub fn count(&self, origin: Origin) -> usize {
        self.points.iter().filter(|p| p.origin == origin).count()
    }
}

/// Largest grid side: caps a large part's rays (the spacing then grows within its bounds).
const MAX_GRID_SIDE: usize = 301;
/// The spacing on the part the issue asks for, m.
const SPACING_RANGE_M: (f64, f64) = (0.003, 0.010);

/// The seeded scene `seed` of `part`: its posture, place, the box and the scanners all follow
/// from the seed.
pub fn make_scene(part: &Part, seed: u64, noise: &ScanNoise) -> Result<Scene, crate::SceneError> {
    let mut rng = SplitMix64::new(seed);
    let posture = if rng.uniform() < 0.5 {
        Posture::Standing
    } else {
        Posture::Lying
    };
    let world_from_part = place_on_floor(part, posture, &mut rng);
    let part_vertices: Vec<Point3<f64>> = part
        .soup
        .vertices
        .iter()
        .map(|v| world_from_part * v)
        .collect();
    let centre = bounds_centre(&part_vertices);
    let radius_m = part_vertices
        .iter()
        .map(|v| (v - centre).norm())
        .fold(0.0, f64::max);
    let footprint_m = part_vertices
        .iter()
        .map(|v| (v.xy() - centre.xy()).norm())
        .fold(0.0, f64::max);
    let (box_vertices, box_triangles) = clutter_box(&centre, footprint_m, &mut rng);
    let (floor_vertices, floor_triangles) = floor(&centre, 4.0);
    let scene = SceneMesh::new(&[
        SceneObject {
            surface: Surface::Part,
            vertices: part_vertices,
            triangles: part.soup.triangles.clone(),
        },
        SceneObject {
            surface: Surface::Floor,
            vertices: floor_vertices,
            triangles: floor_triangles,
        },
        SceneObject {
            surface: Surface::Clutter,
            vertices: box_vertices,
            triangles: box_triangles,
        },
    ])?;
    let (points, scanners, spacing_m) =
        scan_around(&scene, &centre, radius_m, MAX_GRID_SIDE, noise, &mut rng);
    Ok(Scene {
        part: part.name.clone(),
        posture,
        world_from_part,
        points,
        scanners,
        spacing_m,
    })
}

/// Two or three scanners placed around `centre` (25-65 degrees above the floor, 0.8-1.6 m plus
/// `radius_m` from it, 70-140 degrees apart), each aimed at the centre with a view of the radius
/// plus 25 cm and a ray spacing at the centre of 3-10 mm (drawn per scanner; a grid side capped
/// at `max_grid_side` may push it up, never above 10 mm): every point they return, the
/// scanners, and the spacing each was set up for.
pub(crate) fn scan_around(
    scene: &SceneMesh,
    centre: &Point3<f64>,
    radius_m: f64,
    max_grid_side: usize,
    noise: &ScanNoise,
    rng: &mut SplitMix64,
) -> (Vec<ScanPoint>, Vec<Scanner>, Vec<f64>) {
    let count = if rng.uniform() < 0.5 { 2 } else { 3 };
    let mut azimuth = rng.uniform() * std::f64::consts::TAU;
    let (mut points, mut scanners, mut spacing_m) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..count {
        let elevation = (25.0 + 40.0 * rng.uniform()).to_radians();
        let distance_m = radius_m + 0.8 + 0.8 * rng.uniform();
        let origin = centre
            + distance_m
                * Vector3::new(
                    elevation.cos() * azimuth.cos(),
                    elevation.cos() * azimuth.sin(),
                    elevation.sin(),
                );
        let aim = centre + 0.02 * (2.0 * rng.uniform() - 1.0) * Vector3::new(1.0, 1.0, 1.0);
        // Enough of the view to take in the floor and the box around the part.
        let half_angle_rad = ((radius_m + 0.25) / distance_m).atan();
        let wanted_m = SPACING_RANGE_M.0 + (SPACING_RANGE_M.1 - SPACING_RANGE_M.0) * rng.uniform();
        let capped_m = 2.0 * half_angle_rad * distance_m / (max_grid_side - 1) as f64;
        let spacing = wanted_m.max(capped_m).min(SPACING_RANGE_M.1);
        let scanner = Scanner::aimed(origin, aim, half_angle_rad, spacing / distance_m, 10.0);
        points.extend(scan(scene, &scanner, noise, rng));
        scanners.push(scanner);
        spacing_m.push(spacing);
        azimuth += (70.0 + 70.0 * rng.uniform()).to_radians();
    }
    (points, scanners, spacing_m)
}

/// The part turned to its posture, spun about the vertical and set down on z = 0 near the
/// cell's usual part position (0.6, 0, 0).
fn place_on_floor(part: &Part, posture: Posture, rng: &mut SplitMix64) -> Isometry3<f64> {
    let tilt = match posture {
        Posture::Standing => UnitQuaternion::identity(),
        Posture::Lying => {
            let axis = if rng.uniform() < 0.5 {
                Vector3::x_axis()
            } else {
                Vector3::y_axis()
            };
            let sign = if rng.uniform() < 0.5 { 1.0 } else { -1.0 };
            UnitQuaternion::from_axis_angle(&axis, sign * std::f64::consts::FRAC_PI_2)
        }
    };
    let spin =
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rng.uniform() * std::f64::consts::TAU);
    let rotation = spin * tilt;
    let turned: Vec<Point3<f64>> = part.soup.vertices.iter().map(|v| rotation * v).collect();
    let centre = bounds_centre(&turned);
    let lowest = turned.iter().map(|v| v.z).fold(f64::INFINITY, f64::min);
    let target = Vector3::new(
        0.6 + 0.2 * (rng.uniform() - 0.5),
        0.2 * (rng.uniform() - 0.5),
        0.0,
    );
    let shift = target - Vector3::new(centre.x, centre.y, lowest);
    Isometry3::from_parts(Translation3::from(shift), rotation)
}

pub(crate) fn bounds_centre(points: &[Point3<f64>]) -> Point3<f64> {
    let mut low = Point3::from(Vector3::repeat(f64::INFINITY));
    let mut high = Point3::from(Vector3::repeat(f64::NEG_INFINITY));
    for p in points {
        low = low.inf(p);
        high = high.sup(p);
    }
    nalgebra::center(&low, &high)
}

/// A box 8-30 cm a side on the floor beside the part, clear of its footprint.
pub(crate) fn clutter_box(
    centre: &Point3<f64>,
    footprint_m: f64,
    rng: &mut SplitMix64,
) -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
    let size = Vector3::from_fn(|_, _| 0.08 + 0.22 * rng.uniform());
    let half_diagonal_m = 0.5 * size.xy().norm();
    let azimuth = rng.uniform() * std::f64::consts::TAU;
    let distance_m = footprint_m + half_diagonal_m + 0.02 + 0.06 * rng.uniform();
    let position = Vector3::new(
        centre.x + distance_m * azimuth.cos(),
        centre.y + distance_m * azimuth.sin(),
        0.5 * size.z,
    );
    let pose = Isometry3::from_parts(
        Translation3::from(position),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rng.uniform() * std::f64::consts::TAU),
    );
    let soup = align_core::geometry::shapes::box_soup([size.x, size.y, size.z]);
    let vertices = soup.vertices.iter().map(|v| pose * v).collect();
    (vertices, soup.triangles)
}

/// A square floor of `side_m` at z = 0 under the part.
pub(crate) fn floor(centre: &Point3<f64>, side_m: f64) -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
    let h = side_m / 2.0;
    let corners = [(-h, -h), (h, -h), (h, h), (-h, h)]
        .map(|(x, y)| Point3::new(centre.x + x, centre.y + y, 0.0));
    (corners.to_vec(), vec![[0, 1, 2], [0, 2, 3]])
}

#[cfg(test)]
mod tests {
    use super::{Part, PartError, check_metres, parts_in};
    use align_core::io::{TriangleSoup, write_stl_binary};
    use nalgebra::Point3;

    fn tetrahedron() -> TriangleSoup {
        TriangleSoup {
            vertices: vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(0.1, 0.0, 0.0),
                Point3::new(0.0, 0.1, 0.0),
                Point3::new(0.0, 0.0, 0.1),
            ],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        }
    }

    #[test]
    fn a_folder_gives_its_stl_and_obj_files_as_parts_named_after_them_and_nothing_else() {
        let dir = std::env::temp_dir().join(format!("cad-scans-parts-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("scratch folder");
        write_stl_binary(&dir.join("b_link.STL"), &tetrahedron()).expect("stl");
        let obj = "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
        std::fs::write(dir.join("a_link.obj"), obj).expect("obj");
        std::fs::write(dir.join("notes.txt"), "not a mesh").expect("txt");
        let parts = parts_in(&dir, "robot_");
        let empty = dir.join("empty");
        std::fs::create_dir_all(&empty).expect("empty folder");
        let refused = parts_in(&empty, "robot_");
        std::fs::remove_dir_all(&dir).expect("clean up");
        let names: Vec<String> = parts
            .expect("two parts")
            .into_iter()
            .map(|p| p.name)
            .collect();
        assert_eq!(names, ["robot_a_link", "robot_b_link"]);
        assert!(
            matches!(refused, Err(PartError::NoMeshes { .. })),
            "{refused:?}"
        );
    }

    #[test]
    fn a_part_drawn_in_millimetres_is_refused_naming_the_units() {
        let in_metres = Part::from_soup("link", tetrahedron()).expect("a part");
        assert!(check_metres(&in_metres).is_ok());
        let mut soup = tetrahedron();
        for vertex in &mut soup.vertices {
            *vertex *= 1000.0;
        }
        let in_millimetres = Part::from_soup("link", soup).expect("a part");
        let refused = check_metres(&in_millimetres).expect_err("100 m across");
        assert!(refused.to_string().contains("millimetres"), "{refused}");
    }
}
