//! The part as the alignment sees it: its mesh, named datum faces, triangles binned by normal
//! direction for coherent searches, and the contact of a touch with the surface.

use std::collections::HashMap;

use nalgebra::{Point3, Vector3};

use super::Touch;
use crate::geometry::{Mesh, SurfacePoint};
use crate::registration::RegistrationError;

/// A named planar face of a part (a datum feature), in the part frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Face {
    pub name: String,
    /// Outward unit normal.
    pub normal: Vector3<f64>,
    /// Any point of the face's plane.
    pub point: Point3<f64>,
}

/// The part's mesh with what the alignment precomputes: one sub-mesh per named face.
#[derive(Debug)]
pub struct PsaTarget<'a> {
    mesh: &'a Mesh,
    faces: HashMap<String, Mesh>,
    /// The mesh's triangles grouped by normal direction, for coherent searches.
    normal_bins: Vec<NormalBin>,
}

#[derive(Debug)]
struct NormalBin {
    direction: Vector3<f64>,
    mesh: Mesh,
}

/// Bin directions: the 26 neighbours of a cube's centre (faces, edges, corners), about 27 degrees
/// apart, so a triangle's normal is never more than about 35 degrees from its bin's direction.
const BIN_RADIUS_RAD: f64 = 0.62;

fn bin_directions() -> Vec<Vector3<f64>> {
    let mut directions = Vec::with_capacity(26);
    for x in -1..=1 {
        for y in -1..=1 {
            for z in -1..=1 {
                if (x, y, z) != (0, 0, 0) {
                    directions.push(Vector3::new(x as f64, y as f64, z as f64).normalize());
                }
            }
        }
    }
    directions
}

/// Where a touch meets the surface, in the part frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Contact {
    /// The surface point the ball centre is matched to.
    pub point: Point3<f64>,
    /// Unit direction along which the ball centre's distance grows: the gradient of the signed
    /// distance for a plain contact, the face normal for a guided one.
    pub normal: Vector3<f64>,
    /// Distance of the ball centre from the surface along `normal`, m (ball radius not removed).
    pub signed_distance_m: f64,
    /// False when the touched face turns away from the probe by more than the coherence cone:
    /// the ball could not have touched it with its front.
    pub coherent: bool,
}

impl<'a> PsaTarget<'a> {
    pub fn new(mesh: &'a Mesh) -> Self {
        let vertices: Vec<Point3<f64>> = mesh.vertices().collect();
        let directions = bin_directions();
        let mut members: Vec<Vec<[u32; 3]>> = vec![Vec::new(); directions.len()];
        for (index, triangle) in mesh.triangles().iter().enumerate() {
            let normal = mesh.triangle_normal(index as u32);
            let nearest = directions
                .iter()
                .enumerate()
                .max_by(|a, b| normal.dot(a.1).total_cmp(&normal.dot(b.1)))
                .map_or(0, |(bin, _)| bin);
            members[nearest].push(*triangle);
        }
        let normal_bins = directions
            .into_iter()
            .zip(members)
            .filter_map(|(direction, triangles)| {
                Mesh::new(&vertices, &triangles)
                    .ok()
                    .map(|mesh| NormalBin { direction, mesh })
            })
            .collect();
        Self {
            mesh,
            faces: HashMap::new(),
            normal_bins,
        }
    }

    /// Adds named faces: each becomes the triangles whose normal is within 1 degree of the face
    /// normal and whose vertices lie within 0.01 mm of its plane.
    pub fn with_faces(mut self, faces: &[Face]) -> Result<Self, RegistrationError> {
        let vertices: Vec<Point3<f64>> = self.mesh.vertices().collect();
        for face in faces {
            let normal = face.normal.try_normalize(1e-12).ok_or_else(|| {
                RegistrationError::Underconstrained {
                    dof: format!("face '{}' has a zero normal", face.name),
                }
            })?;
            let triangles: Vec<[u32; 3]> = self
                .mesh
                .triangles()
                .iter()
                .enumerate()
                .filter(|&(index, triangle)| {
                    self.mesh.triangle_normal(index as u32).dot(&normal) > 1f64.to_radians().cos()
                        && triangle
                            .iter()
                            .all(|&v| (vertices[v as usize] - face.point).dot(&normal).abs() < 1e-5)
                })
                .map(|(_, triangle)| *triangle)
                .collect();
            let sub_mesh = Mesh::new(&vertices, &triangles).map_err(|_| {
                RegistrationError::Underconstrained {
                    dof: format!("face '{}' matches no triangle of the part", face.name),
                }
            })?;
            self.faces.insert(face.name.clone(), sub_mesh);
        }
        Ok(self)
    }

    pub fn mesh(&self) -> &Mesh {
        self.mesh
    }

    pub(super) fn surface_for(&self, touch: &Touch) -> Result<&Mesh, RegistrationError> {
        match &touch.face {
            None => Ok(self.mesh),
            Some(name) => self
                .faces
                .get(name)
                .ok_or_else(|| RegistrationError::Underconstrained {
                    dof: format!(
                        "touch '{}' names face '{name}', which the part does not define",
                        touch.id
                    ),
                }),
        }
    }

    /// The touch's plain contact: the closest point of `surface` to the ball centre `in_part`,
    /// which is what the least-squares alignment matches it to. `facing` is the reversed approach
    /// direction in the part frame, when known.
    ///
    /// The ball meets a surface with any point of its front hemisphere, so a contact is coherent
    /// while the face's normal lies within `cone_rad` of `facing` (90 degrees plus a margin for
    /// stylus and normal errors). On a mesh that is not closed, the face normal's side is
    /// outside ([`Mesh::signed_closest`]).
    pub(super) fn plain_contact(
        &self,
        surface: &Mesh,
        in_part: &Point3<f64>,
        facing: Option<&Vector3<f64>>,
        cone_rad: f64,
    ) -> Contact {
        let found = surface.signed_closest(in_part);
        let coherent = facing.is_none_or(|f| found.face_normal.dot(f) >= cone_rad.cos());
        Contact {
            point: found.point,
            normal: found.gradient,
            signed_distance_m: found.signed_distance_m,
            coherent,
        }
    }

    /// The touch's guided contact: the closest surface point whose face turns towards the probe
    /// (within `cone_rad` of `facing`), so that a touch pushed through the part by a wrong pose
    /// still finds the face it touched, not the back of the wall. `None` when no such surface
    /// exists.
    pub(super) fn guided_contact(
        &self,
        in_part: &Point3<f64>,
        facing: &Vector3<f64>,
        cone_rad: f64,
    ) -> Option<Contact> {
        let found = self.closest_coherent(in_part, facing, cone_rad)?;
        Some(Contact {
            point: found.point,
            normal: found.normal,
            signed_distance_m: found.signed_distance,
            coherent: true,
        })
    }

    /// The closest surface point whose face normal lies within `cone_rad` of `facing` (unit,
    /// part frame), or `None` when no such surface exists.
    fn closest_coherent(
        &self,
        query: &Point3<f64>,
        facing: &Vector3<f64>,
        cone_rad: f64,
    ) -> Option<SurfacePoint> {
        let cos_cone = cone_rad.cos();
        // Usually the plain closest point is coherent, and then it is also the closest coherent
        // one: one BVH query instead of one per bin.
        let mut plain = self.mesh.closest_point(query);
        let face_normal = self.mesh.triangle_normal(plain.triangle);
        if face_normal.dot(facing) >= cos_cone {
            // On an edge the pseudo-normal blends in the incoherent neighbour; the touched face's
            // own normal is the one that constrains this touch.
            plain.normal = face_normal;
            return Some(plain);
        }
        let bin_reach = (cone_rad + BIN_RADIUS_RAD).min(std::f64::consts::PI).cos();
        let mut best: Option<SurfacePoint> = None;
        for bin in &self.normal_bins {
            if bin.direction.dot(facing) < bin_reach {
                continue;
            }
            let limit = best.map_or(f64::MAX, |b| b.signed_distance.abs());
            let Some(found) = bin.mesh.closest_point_within(query, limit) else {
                continue;
            };
            let normal = bin.mesh.triangle_normal(found.triangle);
            if normal.dot(facing) < cos_cone {
                continue;
            }
            if best.is_none_or(|b| found.signed_distance.abs() < b.signed_distance.abs()) {
                best = Some(SurfacePoint { normal, ..found });
            }
        }
        best.map(|mut found| {
            // Bins are open sub-meshes: recover the side from the face normal.
            let side = (query - found.point).dot(&found.normal);
            found.signed_distance = if side < 0.0 && self.mesh.is_watertight() {
                -found.signed_distance.abs()
            } else {
                found.signed_distance.abs()
            };
            found
        })
    }
}
