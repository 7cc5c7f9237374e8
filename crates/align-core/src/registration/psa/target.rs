//! The part as the alignment sees it: its mesh, named datum faces, triangles binned by normal
//! direction for coherent searches, and the contact of a touch with the surface.

use std::collections::HashMap;

use nalgebra::{Point3, Vector3};

use super::Touch;
use crate::geometry::Mesh;
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
    /// The triangle matched: the next query of this touch starts from it.
    pub triangle: u32,
}

impl<'a> PsaTarget<'a> {
    pub fn new(mesh: &'a Mesh) -> Self {
        Self {
            mesh,
            faces: HashMap::new(),
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
    /// outside ([`Mesh::signed_closest`]). `hint` is the touch's previous triangle.
    pub(super) fn plain_contact(
        &self,
        surface: &Mesh,
        in_part: &Point3<f64>,
        facing: Option<&Vector3<f64>>,
        cone_rad: f64,
        hint: Option<u32>,
    ) -> Contact {
        // A hint, not a cache of nearby triangles: a search's steps and line searches move a
        // touch too far and back too often for one to pay (measured slower on the bench).
        let found = surface.signed_closest_near(in_part, hint);
        let coherent = facing.is_none_or(|f| found.face_normal.dot(f) >= cone_rad.cos());
        Contact {
            point: found.point,
            normal: found.gradient,
            signed_distance_m: found.signed_distance_m,
            coherent,
            triangle: found.triangle,
        }
    }

    /// The touch's guided contact: the closest surface point whose face turns towards the probe
    /// (within `cone_rad` of `facing`), so that a touch pushed through the part by a wrong pose
    /// still finds the face it touched, not the back of the wall. `None` when no such surface
    /// exists. `facing` is unit, in the part frame; `hint` is the touch's previous triangle;
    /// `slack` >= 1 allows a contact up to that factor farther than the closest (1: exact).
    pub(super) fn guided_contact(
        &self,
        in_part: &Point3<f64>,
        facing: &Vector3<f64>,
        cone_rad: f64,
        hint: Option<u32>,
        slack: f64,
    ) -> Option<Contact> {
        let found = self
            .mesh
            .closest_point_facing(in_part, facing, cone_rad, hint, slack)?;
        Some(Contact {
            point: found.point,
            normal: found.normal,
            signed_distance_m: found.signed_distance,
            coherent: true,
            triangle: found.triangle,
        })
    }
}
