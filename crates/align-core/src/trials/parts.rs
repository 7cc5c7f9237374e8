//! The test parts the trials run on, with their touch plans. Built in code so that their geometry
//! is reviewable here; `ips trials` can also read touch sets from files.

use nalgebra::{Point3, Vector3};

use crate::geometry::shapes::extrude;
use crate::geometry::{Mesh, MeshError};
use crate::registration::psa::Face;

/// A planned touch on a part, in the part frame.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedTouch {
    pub point: Point3<f64>,
    /// Outward normal of the touched face.
    pub normal: Vector3<f64>,
    pub face: String,
}

/// A part with named faces and an ordered touch plan (the first six follow the 3-2-1 principle).
#[derive(Debug, Clone)]
pub struct TestPart {
    pub name: String,
    pub mesh: Mesh,
    pub faces: Vec<Face>,
    pub touches: Vec<PlannedTouch>,
}

fn touch(x: f64, y: f64, z: f64, normal: Vector3<f64>, face: &str) -> PlannedTouch {
    PlannedTouch {
        point: Point3::new(x, y, z),
        normal,
        face: face.to_owned(),
    }
}

fn face(name: &str, normal: Vector3<f64>, point: Point3<f64>) -> Face {
    Face {
        name: name.to_owned(),
        normal,
        point,
    }
}

/// A 300 x 200 x 150 mm block with a 100 x 80 mm step cut along one top edge, the thesis's
/// box-like part made asymmetric: 3-2-1 touches near the middle of the bottom, front and left
/// faces, then the top, the back and the step's riser (the asymmetric feature).
pub fn step_block() -> Result<TestPart, MeshError> {
    // The x-z profile is extruded along its own z and then mapped (u, v, w) -> (u, w, v) so
    // that the part stands with z up. The mapping mirrors the solid, which turns its winding
    // inside out; Mesh::new re-orients it from the signed volume.
    let outline = [
        [0.0, 0.0],
        [0.3, 0.0],
        [0.3, 0.07],
        [0.2, 0.07],
        [0.2, 0.15],
        [0.0, 0.15],
    ];
    let prism = extrude(&outline, 0.2)?;
    let vertices: Vec<Point3<f64>> = prism
        .vertices()
        .map(|p| Point3::new(p.x, p.z, p.y))
        .collect();
    let mesh = Mesh::new(&vertices, prism.triangles())?;
    let x = Vector3::x();
    let y = Vector3::y();
    let z = Vector3::z();
    Ok(TestPart {
        name: "step_block".to_owned(),
        mesh,
        faces: vec![
            face("bottom", -z, Point3::origin()),
            face("top", z, Point3::new(0.0, 0.0, 0.15)),
            face("front", -y, Point3::origin()),
            face("back", y, Point3::new(0.0, 0.2, 0.0)),
            face("left", -x, Point3::origin()),
            face("right", x, Point3::new(0.3, 0.0, 0.0)),
            face("step_riser", x, Point3::new(0.2, 0.0, 0.1)),
            face("step_tread", z, Point3::new(0.25, 0.0, 0.07)),
        ],
        touches: vec![
            touch(0.07, 0.06, 0.0, -z, "bottom"),
            touch(0.23, 0.07, 0.0, -z, "bottom"),
            touch(0.12, 0.15, 0.0, -z, "bottom"),
            touch(0.08, 0.0, 0.07, -y, "front"),
            touch(0.22, 0.0, 0.04, -y, "front"),
            touch(0.0, 0.1, 0.08, -x, "left"),
            touch(0.1, 0.1, 0.15, z, "top"),
            touch(0.15, 0.2, 0.08, y, "back"),
            touch(0.2, 0.12, 0.11, x, "step_riser"),
        ],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_planned_touch_lies_on_its_named_face_and_outside_normal() {
        let part = step_block().unwrap();
        assert!(part.mesh.is_watertight());
        for planned in &part.touches {
            let closest = part
                .mesh
                .closest_point(&(planned.point + planned.normal * 0.001));
            assert!(
                (closest.signed_distance - 0.001).abs() < 1e-12,
                "{planned:?}"
            );
            assert!(
                (closest.normal - planned.normal).norm() < 1e-12,
                "{planned:?}"
            );
            let face = part.faces.iter().find(|f| f.name == planned.face).unwrap();
            assert!((planned.point - face.point).dot(&face.normal).abs() < 1e-12);
        }
    }
}
