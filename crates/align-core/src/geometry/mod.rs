//! Geometry the alignment works on: triangle meshes with closest-point, normal and signed-distance
//! queries ([`Mesh`]), built on parry3d's BVH (glam types stay inside this module).

mod distance_grid;
mod facing_tree;
mod inside_grid;
mod mesh;
pub mod shapes;
mod spread;

pub use distance_grid::DistanceGrid;
pub use facing_tree::NearbyTriangles;
pub use inside_grid::InsideGrid;
pub use mesh::{Mesh, MeshError, SignedClosest, SurfacePoint};
pub use spread::{
    PLAUSIBLE_PART_SIZE_M, PrincipalSpread, human_length, implausible_size_warning, plane_through,
};

/// Two unit vectors completing the unit vector `n` to a right-handed frame (`n` their cross
/// product): a plane's axes along it, for the plane whose normal is `n`.
pub(crate) fn tangents(
    n: &nalgebra::Vector3<f64>,
) -> (nalgebra::Vector3<f64>, nalgebra::Vector3<f64>) {
    let helper = if n.x.abs() < 0.8 {
        nalgebra::Vector3::x()
    } else {
        nalgebra::Vector3::y()
    };
    let e1 = n.cross(&helper).normalize();
    (e1, n.cross(&e1))
}

/// A search bound a hair beyond `distance_m`, so that the triangle at that distance is still
/// found despite rounding.
pub(crate) fn just_beyond(distance_m: f64) -> f64 {
    distance_m * (1.0 + 1e-9) + 1e-12
}
