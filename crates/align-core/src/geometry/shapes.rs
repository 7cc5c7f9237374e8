//! Simple solids built in code: prisms extruded from a planar outline. Tests and the shipped test
//! parts use them; real parts come from CAD files.

use nalgebra::Point3;

use super::mesh::{Mesh, MeshError};

/// A prism: the simple polygon `outline` (counter-clockwise, in the xy-plane, m) extruded from
/// z = 0 to z = `height_m`, as a closed outward-oriented mesh.
pub fn extrude(outline: &[[f64; 2]], height_m: f64) -> Result<Mesh, MeshError> {
    let count = outline.len();
    if count < 3 || !(height_m.is_finite() && height_m > 0.0) {
        return Err(MeshError::Empty);
    }
    let mut vertices: Vec<Point3<f64>> = outline
        .iter()
        .map(|&[x, y]| Point3::new(x, y, 0.0))
        .collect();
    vertices.extend(outline.iter().map(|&[x, y]| Point3::new(x, y, height_m)));
    let cap = ear_clip(outline);
    let mut triangles = Vec::with_capacity(2 * cap.len() + 2 * count);
    for &[a, b, c] in &cap {
        // Bottom faces down (reversed), top faces up.
        triangles.push([a, c, b]);
        triangles.push([a + count as u32, b + count as u32, c + count as u32]);
    }
    for i in 0..count as u32 {
        let j = (i + 1) % count as u32;
        let (top_i, top_j) = (i + count as u32, j + count as u32);
        triangles.push([i, j, top_j]);
        triangles.push([i, top_j, top_i]);
    }
    Mesh::new(&vertices, &triangles)
}

/// Triangulates a simple counter-clockwise polygon by ear clipping (O(n^2), fine for outlines).
fn ear_clip(outline: &[[f64; 2]]) -> Vec<[u32; 3]> {
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut remaining: Vec<usize> = (0..outline.len()).collect();
    let mut triangles = Vec::new();
    while remaining.len() > 3 {
        let n = remaining.len();
        let ear = (0..n).find(|&k| {
            let (prev, here, next) = (
                remaining[(k + n - 1) % n],
                remaining[k],
                remaining[(k + 1) % n],
            );
            let (a, b, c) = (outline[prev], outline[here], outline[next]);
            if cross(a, b, c) <= 0.0 {
                return false;
            }
            remaining.iter().all(|&other| {
                if other == prev || other == here || other == next {
                    return true;
                }
                let p = outline[other];
                !(cross(a, b, p) >= 0.0 && cross(b, c, p) >= 0.0 && cross(c, a, p) >= 0.0)
            })
        });
        let Some(k) = ear else {
            break;
        };
        let n = remaining.len();
        triangles.push([
            remaining[(k + n - 1) % n] as u32,
            remaining[k] as u32,
            remaining[(k + 1) % n] as u32,
        ]);
        remaining.remove(k);
    }
    if remaining.len() == 3 {
        triangles.push([
            remaining[0] as u32,
            remaining[1] as u32,
            remaining[2] as u32,
        ]);
    }
    triangles
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn l_prism_is_closed_with_the_right_volume_signs() {
        let outline = [
            [0.0, 0.0],
            [0.2, 0.0],
            [0.2, 0.06],
            [0.14, 0.06],
            [0.14, 0.1],
            [0.0, 0.1],
        ];
        let mesh = extrude(&outline, 0.15).unwrap();
        assert!(mesh.is_watertight(), "{:?}", mesh.notes());
        // Inside the notch (x > 0.14, y > 0.06) is outside the part.
        assert!(
            mesh.closest_point(&Point3::new(0.17, 0.08, 0.07))
                .signed_distance
                > 0.0
        );
        assert!(
            mesh.closest_point(&Point3::new(0.1, 0.05, 0.07))
                .signed_distance
                < 0.0
        );
    }
}
