//! A ray-casting range scanner (a structured-light camera or a lidar seen as a range image): an
//! angular grid of rays from one origin, each returning the first surface of the whole scene it
//! meets, so that whatever stands in front of the part hides it.
//!
//! It shares nothing with `align_core::trials::clouds`, which samples the part's surface and keeps
//! the facing samples: that generator knows the part, this one only knows triangles and rays.
//! What a real scanner adds on top of geometry, as measured on such devices:
//! - range noise along the ray (Gaussian, 0.5 mm by default), not isotropic noise;
//! - mixed pixels: where a beam's footprint straddles a depth edge the sensor averages the two
//!   returns, and the point lands on the ray between the foreground and the background;
//! - spurious returns anywhere along a ray (multi-path, ambient light).

use nalgebra::{Isometry3, Point3, Vector3};
use parry3d_f64::math::Vector as GlamVector;
use parry3d_f64::query::{Ray, RayCast};
use parry3d_f64::shape::TriMesh;

use align_core::rng::SplitMix64;

/// What a scene triangle belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Surface {
    Part,
    Floor,
    Clutter,
}

/// Where a returned point came from: a surface (with range noise), or one of the scanner's
/// artefacts. Kept with every point so tests and statistics know the truth; the files the
/// aligners read carry only the coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Origin {
    Surface(Surface),
    MixedPixel,
    Outlier,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanPoint {
    pub point: Point3<f64>,
    pub origin: Origin,
}

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("the scene has no triangles")]
    Empty,
    #[error("the scene's triangles cannot be indexed for ray casting: {0}")]
    Index(String),
}

/// One object of a scene: its vertices (world frame) and triangles.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneObject {
    pub surface: Surface,
    pub vertices: Vec<Point3<f64>>,
    pub triangles: Vec<[u32; 3]>,
}

/// Every surface of a scene, in the world frame, in one BVH (parry's `TriMesh`), and which
/// object each triangle belongs to.
#[derive(Debug, Clone)]
pub struct SceneMesh {
    trimesh: TriMesh,
    surfaces: Vec<Surface>,
}

impl SceneMesh {
    pub fn new(objects: &[SceneObject]) -> Result<Self, SceneError> {
        let mut vertices = Vec::new();
        let mut triangles = Vec::new();
        let mut surfaces = Vec::new();
        for object in objects {
            let offset = u32::try_from(vertices.len())
                .map_err(|_| SceneError::Index("more than 2^32 vertices".to_owned()))?;
            vertices.extend(
                object
                    .vertices
                    .iter()
                    .map(|p| GlamVector::new(p.x, p.y, p.z)),
            );
            triangles.extend(object.triangles.iter().map(|t| t.map(|i| i + offset)));
            surfaces.extend(std::iter::repeat_n(object.surface, object.triangles.len()));
        }
        if triangles.is_empty() {
            return Err(SceneError::Empty);
        }
        // No cleanup flags: merging or dropping triangles would renumber them, and the triangle
        // index is how a hit finds its object.
        let trimesh =
            TriMesh::new(vertices, triangles).map_err(|e| SceneError::Index(format!("{e:?}")))?;
        Ok(Self { trimesh, surfaces })
    }

    /// The first surface along the ray (unit `direction`) within `max_range_m`, and its range.
    pub fn first_hit(
        &self,
        origin: &Point3<f64>,
        direction: &Vector3<f64>,
        max_range_m: f64,
    ) -> Option<(f64, Surface)> {
        let ray = Ray::new(
            GlamVector::new(origin.x, origin.y, origin.z),
            GlamVector::new(direction.x, direction.y, direction.z),
        );
        let hit = self
            .trimesh
            .cast_local_ray_and_get_normal(&ray, max_range_m, false)?;
        let surface = *self.surfaces.get(hit.subshape as usize)?;
        Some((hit.time_of_impact, surface))
    }
}

/// One scanner placement and its ray grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Scanner {
    /// The scanner looks along its +z; its grid's columns run along +x, rows along +y.
    pub world_from_scanner: Isometry3<f64>,
    pub columns: usize,
    pub rows: usize,
    /// Angle between neighbouring rays, rad.
    pub step_rad: f64,
    pub max_range_m: f64,
}

impl Scanner {
    /// A scanner at `origin` aimed at `target`, whose grid spans a cone of half-angle
    /// `half_angle_rad` with rays `step_rad` apart.
    pub fn aimed(
        origin: Point3<f64>,
        target: Point3<f64>,
        half_angle_rad: f64,
        step_rad: f64,
        max_range_m: f64,
    ) -> Self {
        let forward = (target - origin).normalize();
        // Any "up" not parallel to the line of sight: the grid's roll does not matter.
        let up = if forward.z.abs() < 0.9 {
            Vector3::z()
        } else {
            Vector3::x()
        };
        // face_towards maps the local +z onto the line of sight.
        let world_from_scanner = Isometry3::face_towards(&origin, &target, &up);
        let side = (2.0 * half_angle_rad / step_rad).ceil() as usize + 1;
        Self {
            world_from_scanner,
            columns: side,
            rows: side,
            step_rad,
            max_range_m,
        }
    }

    pub fn origin(&self) -> Point3<f64> {
        Point3::from(self.world_from_scanner.translation.vector)
    }

    /// The unit direction (world frame) of the ray at `column`, `row`: equal angular steps in
    /// azimuth and elevation, as a scanning mirror pair or a camera's pixel grid (near enough).
    pub fn ray(&self, column: usize, row: usize) -> Vector3<f64> {
        let azimuth = (column as f64 - (self.columns as f64 - 1.0) / 2.0) * self.step_rad;
        let elevation = (row as f64 - (self.rows as f64 - 1.0) / 2.0) * self.step_rad;
        let local = Vector3::new(
            azimuth.sin() * elevation.cos(),
            elevation.sin(),
            azimuth.cos() * elevation.cos(),
        );
        self.world_from_scanner.rotation * local
    }
}

/// The scanner's artefacts.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanNoise {
    /// Standard deviation of the range along the ray, m.
    pub range_sigma_m: f64,
    /// A pixel whose 4-neighbour's range differs by more than this straddles a depth edge, m.
    pub edge_jump_m: f64,
    /// The chance that a pixel at a depth edge returns a mixed pixel instead of its surface.
    pub mixed_pixel_chance: f64,
    /// Outliers (mixed pixels included) as a fraction of all returned points: spurious returns
    /// make up whatever the mixed pixels leave of it.
    pub outlier_fraction: f64,
}

impl Default for ScanNoise {
    fn default() -> Self {
        Self {
            range_sigma_m: 0.0005,
            // Well above the range change between neighbouring rays on a steep face (a 5 mm step
            // on a face at 80 degrees to the ray is under 3 cm), well below the step from a part
            // to the floor or the box behind it.
            edge_jump_m: 0.03,
            mixed_pixel_chance: 0.5,
            outlier_fraction: 0.1,
        }
    }
}

/// One range image of `scene`, as points in the world frame with where each came from.
pub fn scan(
    scene: &SceneMesh,
    scanner: &Scanner,
    noise: &ScanNoise,
    rng: &mut SplitMix64,
) -> Vec<ScanPoint> {
    let origin = scanner.origin();
    let (columns, rows) = (scanner.columns, scanner.rows);
    let ranges: Vec<Option<(f64, Surface)>> = (0..rows)
        .flat_map(|row| (0..columns).map(move |column| (column, row)))
        .map(|(column, row)| {
            scene.first_hit(&origin, &scanner.ray(column, row), scanner.max_range_m)
        })
        .collect();
    let range_at = |column: usize, row: usize| ranges[row * columns + column].map(|(r, _)| r);
    let mut points = Vec::with_capacity(ranges.len());
    for row in 0..rows {
        for column in 0..columns {
            let Some((range, surface)) = ranges[row * columns + column] else {
                continue;
            };
            let direction = scanner.ray(column, row);
            let background = background_across_edge(&range_at, column, row, columns, rows, noise);
            let (range, origin_kind) = match background {
                Some(far) if rng.uniform() < noise.mixed_pixel_chance => {
                    // The averaged return: anywhere between the two, weighted by how much of the
                    // footprint each surface covers.
                    let share = 0.1 + 0.8 * rng.uniform();
                    (range + share * (far - range), Origin::MixedPixel)
                }
                _ => (range, Origin::Surface(surface)),
            };
            let noisy = range + noise.range_sigma_m * rng.gaussian();
            points.push(ScanPoint {
                point: origin + direction * noisy,
                origin: origin_kind,
            });
        }
    }
    add_spurious_returns(&mut points, scanner, &ranges, noise, rng);
    points
}

/// The range of the farthest 4-neighbour across a depth edge from the pixel at `column`, `row`,
/// if any: the background this beam's footprint may share. A jump is an edge when it exceeds
/// `noise.edge_jump_m` and three times the range step on the opposite side, which is the
/// surface's own slope: a floor seen at a grazing angle has large steps between rays, but
/// the same on both sides.
fn background_across_edge(
    range_at: &impl Fn(usize, usize) -> Option<f64>,
    column: usize,
    row: usize,
    columns: usize,
    rows: usize,
    noise: &ScanNoise,
) -> Option<f64> {
    let range = range_at(column, row)?;
    let at = |c: usize, r: usize| (c < columns && r < rows).then(|| range_at(c, r)).flatten();
    let (left, right) = (at(column.wrapping_sub(1), row), at(column + 1, row));
    let (up, down) = (at(column, row.wrapping_sub(1)), at(column, row + 1));
    [(left, right), (right, left), (up, down), (down, up)]
        .into_iter()
        .filter_map(|(side, opposite)| {
            let jump = side? - range;
            let slope = opposite.map_or(0.0, |o| (range - o).abs());
            (jump > noise.edge_jump_m && jump > 3.0 * slope).then_some(side?)
        })
        .fold(None, |far: Option<f64>, other| {
            Some(far.map_or(other, |f| f.max(other)))
        })
}

/// Tops the outliers up to `noise.outlier_fraction` of all points with returns at a uniform
/// range along random rays of the grid, short of whatever the ray hits (a spurious return comes
/// back before the surface; none comes from behind it).
fn add_spurious_returns(
    points: &mut Vec<ScanPoint>,
    scanner: &Scanner,
    ranges: &[Option<(f64, Surface)>],
    noise: &ScanNoise,
    rng: &mut SplitMix64,
) {
    let fraction = noise.outlier_fraction.clamp(0.0, 0.9);
    let mixed = points
        .iter()
        .filter(|p| p.origin == Origin::MixedPixel)
        .count();
    let good = points.len() - mixed;
    // outliers / (good + outliers) = fraction.
    let wanted = (fraction * good as f64 / (1.0 - fraction)).round() as usize;
    let origin = scanner.origin();
    let hits: Vec<usize> = (0..ranges.len()).filter(|&i| ranges[i].is_some()).collect();
    if hits.is_empty() {
        return;
    }
    for _ in mixed..wanted.max(mixed) {
        let index = hits[(rng.uniform() * hits.len() as f64) as usize % hits.len()];
        let Some((range, _)) = ranges[index] else {
            continue;
        };
        let direction = scanner.ray(index % scanner.columns, index / scanner.columns);
        // Never nearer than 10 % of the way: the scanner's own housing returns nothing.
        let spurious = range * (0.1 + 0.9 * rng.uniform());
        points.push(ScanPoint {
            point: origin + direction * spurious,
            origin: Origin::Outlier,
        });
    }
}
