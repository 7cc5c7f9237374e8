//! A part's surface as a triangle mesh with the queries registration needs.
//!
//! Duplicate vertices (every STL repeats them per triangle) are merged and degenerate triangles
//! dropped, so that edges are shared and pseudo-normals exist. A closed, consistently oriented
//! mesh answers with signed distances (negative inside) and with the angle-weighted pseudo-normal
//! on edges and vertices (Baerentzen and Aanaes), which makes the sign right at convex and concave
//! features alike. A mesh that is not closed or not orientable still works with unsigned distances
//! and face normals; [`Mesh::is_watertight`] says which, and [`Mesh::notes`] why.

use std::sync::OnceLock;

use nalgebra::{Isometry3, Point3, Vector3};
use parry3d_f64::math::Vector as GlamVector;
use parry3d_f64::partitioning::TraversalAction;
use parry3d_f64::query::{PointQuery, PointQueryWithLocation, Ray, RayCast};
use parry3d_f64::shape::{TriMesh, TriMeshFlags, TrianglePointLocation};

use super::facing_tree::{Closest, FacingTree, Feature, NearbyTriangles};
use super::inside_grid::{InsideGrid, count_bodies};
use super::just_beyond;
use super::spread::{PrincipalSpread, human_length, implausible_size_warning};

/// A vertex spread (standard deviation) below this fraction of the largest one is no spread at
/// all: STL stores f32, whose rounding moves exactly collinear or coplanar vertices by about
/// 1e-7 of the part's size, while a real part's thinnest direction (a 0.5 mm sheet on a 2 m
/// panel) is above 1e-4.
const FLAT_SPREAD_RATIO: f64 = 1e-6;

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshError {
    #[error("the mesh has no triangles")]
    Empty,
    #[error("vertex {index} is not finite ({x}, {y}, {z})")]
    NonFiniteVertex {
        index: usize,
        x: f64,
        y: f64,
        z: f64,
    },
    #[error("triangle {triangle} uses vertex {vertex}, but the mesh has {count} vertices")]
    IndexOutOfRange {
        triangle: usize,
        vertex: u32,
        count: usize,
    },
    #[error("every triangle of the mesh is degenerate (zero area)")]
    AllDegenerate,
    #[error(
        "the mesh has no surface: its triangles have zero area (every vertex lies on one line through ({x:.4}, {y:.4}, {z:.4}) m along ({dx:.3}, {dy:.3}, {dz:.3})), so no alignment can fix the rotation about that line or the translation along it"
    )]
    Collinear {
        x: f64,
        y: f64,
        z: f64,
        dx: f64,
        dy: f64,
        dz: f64,
    },
    #[error("cannot build the mesh: {0}")]
    Build(String),
}

/// The closest point of a mesh to a query point, in the mesh's frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfacePoint {
    pub point: Point3<f64>,
    /// Unit outward normal: the face normal inside a face, the pseudo-normal on an edge or vertex.
    pub normal: Vector3<f64>,
    /// Distance from the query point, negative inside a watertight mesh.
    pub signed_distance: f64,
    pub triangle: u32,
    /// True when the closest point lies inside a triangle rather than on an edge or vertex.
    pub on_face: bool,
}

#[derive(Debug, Clone)]
pub struct Mesh {
    trimesh: TriMesh,
    watertight: bool,
    notes: Vec<String>,
    centroid: Point3<f64>,
    radius_m: f64,
    /// Axis-aligned bounds in the mesh frame (parry recomputes them on every call).
    bounds: (Point3<f64>, Point3<f64>),
    /// Which of `notes` warns that the size is implausible for a part (a unit mistake).
    size_note: Option<usize>,
    /// Unit normal of every triangle: the coherent searches test one per candidate triangle.
    face_normals: Vec<Vector3<f64>>,
    /// Built on the first facing query: registration of clouds never asks one.
    facing_tree: OnceLock<FacingTree>,
    /// Separate bodies (groups of triangles sharing vertices): closed bodies may overlap.
    bodies: usize,
    /// Built on the first inside test of a mesh that is not closed or not one body (see
    /// [`Mesh::is_inside_deeper_than`]).
    inside_grid: OnceLock<InsideGrid>,
}

fn to_glam(p: &Point3<f64>) -> GlamVector {
    GlamVector::new(p.x, p.y, p.z)
}

fn from_glam(v: GlamVector) -> Vector3<f64> {
    Vector3::new(v.x, v.y, v.z)
}

impl Mesh {
    /// Builds a mesh from vertices (m) and triangles.
    pub fn new(vertices: &[Point3<f64>], triangles: &[[u32; 3]]) -> Result<Self, MeshError> {
        if triangles.is_empty() {
            return Err(MeshError::Empty);
        }
        if let Some((index, p)) = vertices
            .iter()
            .enumerate()
            .find(|(_, p)| !p.coords.iter().all(|c| c.is_finite()))
        {
            return Err(MeshError::NonFiniteVertex {
                index,
                x: p.x,
                y: p.y,
                z: p.z,
            });
        }
        for (triangle, indices) in triangles.iter().enumerate() {
            if let Some(&vertex) = indices.iter().find(|&&i| i as usize >= vertices.len()) {
                return Err(MeshError::IndexOutOfRange {
                    triangle,
                    vertex,
                    count: vertices.len(),
                });
            }
        }
        let mut indices: Vec<[u32; 3]> = triangles.to_vec();
        if signed_volume(vertices, &indices) < 0.0 {
            // Inward-facing winding (common in exports): flip so normals point out.
            for triangle in &mut indices {
                triangle.swap(1, 2);
            }
        }
        let points: Vec<GlamVector> = vertices.iter().map(to_glam).collect();
        let cleanup = TriMeshFlags::MERGE_DUPLICATE_VERTICES
            | TriMeshFlags::DELETE_DEGENERATE_TRIANGLES
            | TriMeshFlags::DELETE_DUPLICATE_TRIANGLES;
        let mut notes = Vec::new();
        let (trimesh, watertight) = match TriMesh::with_flags(
            points.clone(),
            indices.clone(),
            cleanup | TriMeshFlags::HALF_EDGE_TOPOLOGY | TriMeshFlags::ORIENTED,
        ) {
            Ok(mesh) => {
                let closed = mesh
                    .topology()
                    .is_some_and(|topology| topology.half_edges.iter().all(|h| h.twin != u32::MAX));
                if !closed {
                    notes.push(
                        "the mesh has boundary edges (not closed): distances are unsigned"
                            .to_owned(),
                    );
                }
                (mesh, closed)
            }
            Err(error) => {
                notes.push(format!(
                    "the mesh is not a consistently oriented manifold ({error}): distances are unsigned"
                ));
                let mesh = TriMesh::with_flags(points, indices, cleanup)
                    .map_err(|error| MeshError::Build(error.to_string()))?;
                (mesh, false)
            }
        };
        if trimesh.num_triangles() == 0 {
            return Err(MeshError::AllDegenerate);
        }
        check_spread(&trimesh, &mut notes)?;
        let vertices = trimesh.vertices();
        let centroid = vertices
            .iter()
            .fold(Vector3::zeros(), |sum, v| sum + from_glam(*v))
            / vertices.len() as f64;
        let centroid = Point3::from(centroid);
        let radius_m = vertices
            .iter()
            .map(|v| (from_glam(*v) - centroid.coords).norm())
            .fold(0.0, f64::max);
        let aabb = trimesh.local_aabb();
        let bounds = (
            Point3::from(from_glam(aabb.mins)),
            Point3::from(from_glam(aabb.maxs)),
        );
        let size_note = implausible_size_warning("the mesh", (bounds.1 - bounds.0).norm(), None)
            .map(|warning| {
                notes.push(warning);
                notes.len() - 1
            });
        let face_normals = face_normals_of(&trimesh);
        let bodies = count_bodies(trimesh.indices(), trimesh.vertices().len());
        Ok(Self {
            trimesh,
            watertight,
            notes,
            centroid,
            radius_m,
            bounds,
            size_note,
            face_normals,
            facing_tree: OnceLock::new(),
            bodies,
            inside_grid: OnceLock::new(),
        })
    }

    /// An axis-aligned box centred on the origin, outward-oriented.
    pub fn cuboid(size_m: [f64; 3]) -> Result<Self, MeshError> {
        let [hx, hy, hz] = size_m.map(|s| s / 2.0);
        let vertices: Vec<Point3<f64>> = (0..8)
            .map(|i| {
                Point3::new(
                    if i & 1 == 0 { -hx } else { hx },
                    if i & 2 == 0 { -hy } else { hy },
                    if i & 4 == 0 { -hz } else { hz },
                )
            })
            .collect();
        let triangles = [
            [0, 2, 1],
            [1, 2, 3], // z-
            [4, 5, 6],
            [5, 7, 6], // z+
            [0, 1, 4],
            [1, 5, 4], // y-
            [2, 6, 3],
            [3, 6, 7], // y+
            [0, 4, 2],
            [2, 4, 6], // x-
            [1, 3, 5],
            [3, 7, 5], // x+
        ];
        Self::new(&vertices, &triangles)
    }

    /// True when distances are signed (closed, consistently oriented mesh).
    pub fn is_watertight(&self) -> bool {
        self.watertight
    }

    /// How many separate bodies (groups of triangles sharing vertices) the mesh is.
    pub fn bodies(&self) -> usize {
        self.bodies
    }

    /// Remarks on how the mesh was interpreted (e.g. why distances are unsigned, that it is flat,
    /// that its size looks like a unit mistake).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// The notes, with the size warning (if any) naming the unit scale the file was read with
    /// and the scale that would make the part's size plausible.
    pub fn notes_with_unit_scale(&self, unit_scale: f64) -> Vec<String> {
        let mut notes = self.notes.clone();
        if let Some(index) = self.size_note
            && let Some(warning) =
                implausible_size_warning("the mesh", self.size_m(), Some(unit_scale))
        {
            notes[index] = warning;
        }
        notes
    }

    /// The diagonal of the axis-aligned bounds, m: how large the part is across.
    pub fn size_m(&self) -> f64 {
        (self.bounds.1 - self.bounds.0).norm()
    }

    pub fn num_triangles(&self) -> usize {
        self.trimesh.num_triangles()
    }

    pub fn vertices(&self) -> impl ExactSizeIterator<Item = Point3<f64>> + '_ {
        self.trimesh
            .vertices()
            .iter()
            .map(|v| Point3::from(from_glam(*v)))
    }

    pub fn triangles(&self) -> &[[u32; 3]] {
        self.trimesh.indices()
    }

    /// Unit normal of a triangle.
    pub fn triangle_normal(&self, triangle: u32) -> Vector3<f64> {
        self.face_normals[triangle as usize]
    }

    /// Area of a triangle, m^2.
    pub fn triangle_area(&self, triangle: u32) -> f64 {
        self.trimesh.triangle(triangle).area()
    }

    /// Area of the whole surface, m^2.
    pub fn area_m2(&self) -> f64 {
        (0..self.num_triangles() as u32)
            .map(|t| self.triangle_area(t))
            .sum()
    }

    /// Mean of the vertices.
    pub fn centroid(&self) -> Point3<f64> {
        self.centroid
    }

    /// Largest vertex distance from the centroid: the object radius r of the thesis's pose
    /// distance d = sqrt(|dt|^2 + (r da)^2).
    pub fn radius_m(&self) -> f64 {
        self.radius_m
    }

    /// Axis-aligned bounds (min, max) in the mesh frame.
    pub fn bounds(&self) -> (Point3<f64>, Point3<f64>) {
        self.bounds
    }

    /// Largest distance between the surface placed at `a` and placed at `b` (both
    /// world_from_mesh), both ways, over vertices, edge midpoints and triangle centroids. Zero
    /// for a cylinder turned about its own axis: it measures where the surface is, not how the
    /// mesh is labelled.
    pub fn deviation_m(&self, a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
        let b_from_a = b.inverse() * a;
        let a_from_b = b_from_a.inverse();
        let vertices: Vec<Point3<f64>> = self.vertices().collect();
        let samples = self.triangles().iter().flat_map(|triangle| {
            let [p, q, r] = triangle.map(|i| vertices[i as usize]);
            [
                Point3::from((p.coords + q.coords + r.coords) / 3.0),
                Point3::from((p.coords + q.coords) / 2.0),
            ]
        });
        vertices
            .iter()
            .copied()
            .chain(samples)
            .map(|s| {
                let there = self.closest_point(&(b_from_a * s)).signed_distance.abs();
                let back = self.closest_point(&(a_from_b * s)).signed_distance.abs();
                there.max(back)
            })
            .fold(0.0, f64::max)
    }

    /// The closest surface point to `query` (mesh frame), its outward normal and signed distance.
    pub fn closest_point(&self, query: &Point3<f64>) -> SurfacePoint {
        self.closest_point_within(query, f64::MAX)
            .unwrap_or(SurfacePoint {
                point: *query,
                normal: Vector3::z(),
                signed_distance: f64::INFINITY,
                triangle: 0,
                on_face: false,
            })
    }

    /// Distance along the ray from `origin` in the unit direction `direction` to the first
    /// surface it meets within `max_distance_m` (scanner line-of-sight tests).
    pub fn ray_hit_m(
        &self,
        origin: &Point3<f64>,
        direction: &Vector3<f64>,
        max_distance_m: f64,
    ) -> Option<f64> {
        let ray = Ray::new(to_glam(origin), to_glam(&Point3::from(*direction)));
        self.trimesh.cast_local_ray(&ray, max_distance_m, false)
    }

    /// Like [`Mesh::closest_point`], but `None` when no surface point lies within `max_distance_m`
    /// (the BVH prunes the search, which makes far queries cheap).
    pub fn closest_point_within(
        &self,
        query: &Point3<f64>,
        max_distance_m: f64,
    ) -> Option<SurfacePoint> {
        let query_glam = to_glam(query);
        let (projection, (triangle, location)) = self
            .trimesh
            .project_local_point_and_get_location_with_max_dist(
                query_glam,
                false,
                max_distance_m,
            )?;
        let feature = match location {
            TrianglePointLocation::OnVertex(i) => Feature::Vertex(i),
            TrianglePointLocation::OnEdge(i, _) => Feature::Edge(i),
            TrianglePointLocation::OnFace(..) | TrianglePointLocation::OnSolid => Feature::Face,
        };
        Some(self.surface_point(query, triangle, &from_glam(projection.point), feature))
    }

    /// [`Mesh::closest_point_within`], exact, with the search bounded from the start by the
    /// distance to triangle `hint` (the answer to a nearby query: the same point at the
    /// previous step of a run), so that the descent opens only the nodes nearer than it.
    pub fn closest_point_within_hinted(
        &self,
        query: &Point3<f64>,
        max_distance_m: f64,
        hint: Option<u32>,
    ) -> Option<SurfacePoint> {
        let bound_m = hint
            .and_then(|t| self.distance_to_triangle_m(query, t))
            .map_or(max_distance_m, |d| max_distance_m.min(just_beyond(d)));
        self.closest_point_within(query, bound_m)
    }

    /// The distance from `query` (mesh frame) to triangle `triangle`, or `None` when the mesh
    /// has no such triangle: an upper bound on the distance to the surface, from one projection.
    pub fn distance_to_triangle_m(&self, query: &Point3<f64>, triangle: u32) -> Option<f64> {
        ((triangle as usize) < self.trimesh.indices().len()).then(|| {
            let projection = self
                .trimesh
                .triangle(triangle)
                .project_local_point(to_glam(query), false);
            (from_glam(projection.point) - query.coords).norm()
        })
    }

    /// [`Mesh::closest_point_within`], approximate by at most a factor `slack` (>= 1): the point
    /// found is no farther than `slack` times the closest one. For searches whose queries lie
    /// mostly far off the part (a coarse exploration in a band of half a metre), where an exact
    /// answer must open every node the sphere through the best triangle meets. `hint` is the
    /// answer to a nearby query (the same point at the previous step of a run): with a slack,
    /// a far query near its hint's triangle is answered without opening the tree at all.
    pub fn closest_point_within_slack(
        &self,
        query: &Point3<f64>,
        max_distance_m: f64,
        slack: f64,
        hint: Option<u32>,
    ) -> Option<SurfacePoint> {
        let found = self.facing_tree().closest_within_slack(
            query,
            None,
            max_distance_m,
            hint,
            slack.max(1.0),
        )?;
        Some(self.surface_point(query, found.triangle, &found.point.coords, found.feature))
    }

    /// Whether some surface point lies within `max_distance_m` of `query` (mesh frame; inside
    /// a solid counts only near its surface): a descent of the mesh's tree that stops at the
    /// first triangle within it. parry's ball test projects onto the whole mesh and counts a
    /// point inside as touching; the facing tree would have to be built first (a few ms per
    /// part, which a 50 mm local alignment otherwise never needs).
    pub fn has_surface_within(&self, query: &Point3<f64>, max_distance_m: f64) -> bool {
        if max_distance_m.is_nan() || max_distance_m < 0.0 {
            return false;
        }
        let q = to_glam(query);
        let limit_squared = max_distance_m * max_distance_m;
        let mut found = false;
        self.trimesh.bvh().traverse(|node| {
            let gap = (node.mins() - q).max(q - node.maxs()).max(GlamVector::ZERO);
            if gap.length_squared() > limit_squared {
                return TraversalAction::Prune;
            }
            if let Some(triangle) = node.leaf_data() {
                let on = self
                    .trimesh
                    .triangle(triangle)
                    .project_local_point(q, false);
                if (on.point - q).length_squared() <= limit_squared {
                    found = true;
                    return TraversalAction::EarlyExit;
                }
            }
            TraversalAction::Continue
        });
        found
    }

    /// The closest surface point to `query` among the triangles whose unit normal lies within
    /// `cone_rad` of `facing` (the faces a probe approaching along `-facing` could touch), or
    /// `None` when the part has no such triangle. One descent of a tree that bounds normals as
    /// well as places. `normal` is the triangle's own normal, the one that constrains a touch
    /// matched to it. `hint` is the answer to a nearby query; with `slack` > 1 the answer may be
    /// up to `slack` times farther than the closest (1: exact).
    pub fn closest_point_facing(
        &self,
        query: &Point3<f64>,
        facing: &Vector3<f64>,
        cone_rad: f64,
        hint: Option<u32>,
        slack: f64,
    ) -> Option<SurfacePoint> {
        let found = self.facing_tree().closest_within_slack(
            query,
            Some((facing, cone_rad)),
            f64::INFINITY,
            hint,
            slack,
        )?;
        let mut surface =
            self.surface_point(query, found.triangle, &found.point.coords, found.feature);
        surface.normal = self.face_normals[found.triangle as usize];
        Some(surface)
    }

    /// Builds the tree the approximate and facing queries descend now, on rayon's pool, so
    /// that a caller can build it while a core is idle. Left to the first such query, it is
    /// built on one core inside that query's parallel loop, whose other queries wait for it.
    ///
    /// The tree is built outside the cell that keeps it. Built inside, a thread waiting for
    /// its share of the build could take up a query of the same mesh from the pool and wait
    /// for the very cell it is filling. A query that comes while this runs builds its own copy
    /// on one core (the same tree); the copy stored first is kept.
    pub fn prepare_approximate_queries(&self) {
        if self.facing_tree.get().is_none() {
            let _ = self.facing_tree.set(self.build_facing_tree(true));
        }
    }

    fn facing_tree(&self) -> &FacingTree {
        // One core: this runs inside the cell's initialisation, often from a parallel loop's
        // query (see `prepare_approximate_queries`).
        self.facing_tree
            .get_or_init(|| self.build_facing_tree(false))
    }

    fn build_facing_tree(&self, parallel: bool) -> FacingTree {
        FacingTree::new(
            &self.triangle_corners(),
            &self.face_normals,
            self.size_m(),
            parallel,
        )
    }

    fn triangle_corners(&self) -> Vec<[Vector3<f64>; 3]> {
        (0..self.trimesh.num_triangles() as u32)
            .map(|i| {
                let triangle = self.trimesh.triangle(i);
                [triangle.a, triangle.b, triangle.c].map(from_glam)
            })
            .collect()
    }

    /// True when `query` lies in the part's material, deeper than `depth_m`, `closest` being
    /// its closest point ([`Mesh::closest_point`]). A closed mesh answers by its signed
    /// distance. One that is not (open seams, small openings, shells sharing edges) answers by
    /// winding numbers along rays (see [`InsideGrid`]), for a query farther from its surface
    /// than `depth_m` and than the grid's half cell diagonal; a sheet without thickness has no
    /// inside. A closed mesh of several bodies asks the grid too where its signed distance says
    /// outside: that is wrong where the bodies overlap, and never wrong the other way.
    pub fn is_inside_deeper_than(
        &self,
        query: &Point3<f64>,
        closest: &SurfacePoint,
        depth_m: f64,
    ) -> bool {
        if self.watertight && closest.signed_distance < -depth_m {
            return true;
        }
        if self.watertight && self.bodies == 1 {
            return false;
        }
        // Built on one core: the first test often comes from a parallel loop's query, and a
        // thread waiting here for its share of a parallel build could take up another query
        // of this mesh and wait for the very cell it is filling (as `facing_tree`).
        let grid = self.inside_grid.get_or_init(|| {
            let (lower, upper) = self.bounds;
            InsideGrid::new(&self.triangle_corners(), &lower, &upper)
        });
        closest.signed_distance.abs() > depth_m.max(grid.cell_half_diagonal_m())
            && grid.contains(query)
    }

    /// A projection onto `triangle` as a [`SurfacePoint`]: the pseudo-normal on edges and
    /// vertices of an oriented mesh, and the side it gives (a point behind it is inside).
    fn surface_point(
        &self,
        query: &Point3<f64>,
        triangle: u32,
        point: &Vector3<f64>,
        feature: Feature,
    ) -> SurfacePoint {
        let point = *point;
        let face_normal = self.triangle_normal(triangle);
        let (normal, on_face) = match (feature, self.trimesh.pseudo_normals_if_oriented()) {
            (Feature::Edge(edge), Some(pseudo)) => (
                from_glam(pseudo.edges_pseudo_normal[triangle as usize][edge as usize]),
                false,
            ),
            (Feature::Vertex(corner), Some(pseudo)) => {
                let vertex = self.trimesh.indices()[triangle as usize][corner as usize];
                (
                    from_glam(pseudo.vertices_pseudo_normal[vertex as usize]),
                    false,
                )
            }
            (Feature::Face, _) => (face_normal, true),
            _ => (face_normal, false),
        };
        // parry's pseudo-normals are NaN next to a zero-area triangle (see `face_normals_of`).
        let normal = normal
            .try_normalize(1e-15)
            .filter(|n| n.iter().all(|c| c.is_finite()))
            .unwrap_or(face_normal);
        let offset = query.coords - point;
        let distance = offset.norm();
        // parry's inside test for a trimesh: behind the pseudo-normal of the closest feature
        // (the face normal inside a face). Redone here because single-triangle projections, as
        // the coherent search makes them, do not know the mesh's pseudo-normals.
        let inside = self.watertight && offset.dot(&normal) <= 0.0;
        SurfacePoint {
            point: Point3::from(point),
            normal,
            signed_distance: if inside { -distance } else { distance },
            triangle,
            on_face,
        }
    }
}

/// A ball centre's closest surface point with its signed distance and the distance's gradient.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignedClosest {
    pub point: Point3<f64>,
    /// Unit gradient of the signed distance at the query: exact at edges and corners too, where
    /// the pseudo-normal only says which side is outside.
    pub gradient: Vector3<f64>,
    /// Negative on the inside (or, on an open mesh, on the side away from the probe).
    pub signed_distance_m: f64,
    /// The closest triangle's own unit normal.
    pub face_normal: Vector3<f64>,
    /// The closest triangle: a hint for the next query near this one.
    pub triangle: u32,
}

impl Mesh {
    /// The closest point to `query` with a signed distance on every mesh. A closed mesh has an
    /// inside; on an open one the face normal's side is outside, and closest to an edge or a
    /// corner of an open mesh the distance is unsigned (past an opening's rim either side is
    /// outside). Flipping the side towards the probe was tried and lost the part: a side contact
    /// at 90 degrees meets the face with its normal square to the probe, and noise then flips it.
    pub fn signed_closest(&self, query: &Point3<f64>) -> SignedClosest {
        let found = self.facing_tree().closest(query, None, f64::INFINITY, None);
        self.signed_from(query, found)
    }

    /// [`Mesh::signed_closest`] with `hint`, the triangle a nearby query found (the same touch
    /// at the previous step of a search): the descent then opens only nodes nearer than it.
    pub fn signed_closest_near(&self, query: &Point3<f64>, hint: Option<u32>) -> SignedClosest {
        let found = self.facing_tree().closest(query, None, f64::INFINITY, hint);
        self.signed_from(query, found)
    }

    /// [`Mesh::signed_closest`] for a query that moves a little from call to call (a touch at
    /// successive steps of a fit): `cache` remembers the triangles near the last one, and a
    /// query within their reach scans only those. The answer is the same as without it.
    pub fn signed_closest_cached(
        &self,
        query: &Point3<f64>,
        cache: &mut NearbyTriangles,
    ) -> SignedClosest {
        let found = self
            .facing_tree()
            .closest_cached(query, cache, self.size_m());
        self.signed_from(query, found)
    }

    fn signed_from(&self, query: &Point3<f64>, found: Option<Closest>) -> SignedClosest {
        let found = match found {
            Some(found) => {
                self.surface_point(query, found.triangle, &found.point.coords, found.feature)
            }
            // Only a query that is not finite finds nothing.
            None => self.closest_point(query),
        };
        let face_normal = self.triangle_normal(found.triangle);
        let offset = query - found.point;
        let distance = offset.norm();
        let signed_distance_m = if self.is_watertight() {
            found.signed_distance
        } else if !found.on_face {
            // Past a free edge of an open skin (an opening's rim) either side is outside: a
            // ball touching the rim sideways sits behind the face's plane.
            distance
        } else {
            if offset.dot(&face_normal) < 0.0 {
                -distance
            } else {
                distance
            }
        };
        let gradient = if distance > 1e-12 {
            offset / distance * signed_distance_m.signum()
        } else {
            found.normal
        };
        SignedClosest {
            point: found.point,
            gradient,
            signed_distance_m,
            face_normal,
            triangle: found.triangle,
        }
    }
}

/// Refuses a mesh whose vertices all lie on a line or in a point (its triangles have no area,
/// whatever parry kept), and notes a flat one: touches or a scan of a plane fix only the motion
/// out of it.
fn check_spread(trimesh: &TriMesh, notes: &mut Vec<String>) -> Result<(), MeshError> {
    let spread = PrincipalSpread::of(
        trimesh
            .vertices()
            .iter()
            .map(|v| Point3::from(from_glam(*v))),
    );
    let Some(spread) = spread else {
        return Err(MeshError::Empty);
    };
    let [widest_m, middle_m, thinnest_m] = spread.sigma_m;
    if widest_m == 0.0 {
        return Err(MeshError::AllDegenerate);
    }
    if middle_m <= FLAT_SPREAD_RATIO * widest_m {
        let (at, along) = (spread.centroid, spread.axes[0]);
        return Err(MeshError::Collinear {
            x: at.x,
            y: at.y,
            z: at.z,
            dx: along.x,
            dy: along.y,
            dz: along.z,
        });
    }
    if thinnest_m <= FLAT_SPREAD_RATIO * widest_m {
        let normal = spread.axes[2];
        let aabb = trimesh.local_aabb();
        notes.push(format!(
            "the mesh is flat (every vertex in one plane, normal ({:.3}, {:.3}, {:.3}) in the part frame, {} across): touching or scanning its face fixes only the motion out of the plane; the translation within the plane and the rotation about its normal are free unless its edges are touched",
            normal.x,
            normal.y,
            normal.z,
            human_length(from_glam(aabb.maxs - aabb.mins).norm())
        ));
    }
    Ok(())
}

/// Six times the signed volume enclosed by the triangles (positive for outward winding).
/// Every triangle's unit normal. A triangle of zero area whose corners differ (on a line: parry
/// keeps it, as it closes the mesh at a T-junction) has none, and its normalised zero would be
/// NaN in every fit that matched it (a third-party pelvis's mesh has three): it takes the
/// area-weighted mean of the normals of the triangles that share its corners.
fn face_normals_of(trimesh: &TriMesh) -> Vec<Vector3<f64>> {
    let scaled: Vec<Vector3<f64>> = (0..trimesh.num_triangles() as u32)
        .map(|i| from_glam(trimesh.triangle(i).scaled_normal()))
        .collect();
    let unit = |v: &Vector3<f64>| {
        v.try_normalize(0.0)
            .filter(|n| n.iter().all(|c| c.is_finite()))
    };
    let mut normals: Vec<Option<Vector3<f64>>> = scaled.iter().map(unit).collect();
    if normals.iter().all(Option::is_some) {
        return normals.into_iter().flatten().collect();
    }
    let mut around_vertex = vec![Vector3::zeros(); trimesh.vertices().len()];
    for (triangle, normal) in trimesh.indices().iter().zip(&scaled) {
        if normal.iter().all(|c| c.is_finite()) {
            for &vertex in triangle {
                around_vertex[vertex as usize] += normal;
            }
        }
    }
    for (triangle, normal) in trimesh.indices().iter().zip(&mut normals) {
        if normal.is_none() {
            let around: Vector3<f64> = triangle.iter().map(|&v| around_vertex[v as usize]).sum();
            *normal = Some(unit(&around).unwrap_or_else(Vector3::z));
        }
    }
    normals.into_iter().flatten().collect()
}

fn signed_volume(vertices: &[Point3<f64>], triangles: &[[u32; 3]]) -> f64 {
    triangles
        .iter()
        .map(|&[a, b, c]| {
            let (a, b, c) = (
                vertices[a as usize].coords,
                vertices[b as usize].coords,
                vertices[c as usize].coords,
            );
            a.dot(&b.cross(&c))
        })
        .sum()
}

#[cfg(test)]
#[path = "mesh_tests.rs"]
mod tests;
