//! Simple solids built in code: prisms extruded from a planar outline (tests and the shipped test
//! parts), and the URDF primitives (box, cylinder, sphere, capsule) as closed, outward-oriented
//! triangle soups that a robot link's surface is assembled from.

use nalgebra::Point3;

use super::mesh::{Mesh, MeshError};
use crate::io::TriangleSoup;

/// Segments around a tessellated circle: the facets deviate from the true circle by
/// r (1 - cos(pi / n)), 0.06 mm for a 50 mm radius, well under a scanner's noise.
pub const CIRCLE_SEGMENTS: usize = 64;

/// A URDF box: centred on the origin, edges `size_m` along x, y, z.
pub fn box_soup(size_m: [f64; 3]) -> TriangleSoup {
    let [hx, hy, hz] = size_m.map(|s| s / 2.0);
    let vertices = (0..8)
        .map(|i| {
            Point3::new(
                if i & 1 == 0 { -hx } else { hx },
                if i & 2 == 0 { -hy } else { hy },
                if i & 4 == 0 { -hz } else { hz },
            )
        })
        .collect();
    let triangles = vec![
        [0, 2, 1],
        [1, 2, 3],
        [4, 5, 6],
        [5, 7, 6],
        [0, 1, 4],
        [1, 5, 4],
        [2, 6, 3],
        [3, 6, 7],
        [0, 4, 2],
        [2, 4, 6],
        [1, 3, 5],
        [3, 7, 5],
    ];
    TriangleSoup {
        vertices,
        triangles,
    }
}

/// A solid of revolution about z: `profile` lists (radius, z) from the bottom pole to the top
/// pole (radius 0 at both ends), swept in `segments` steps.
fn revolve(profile: &[(f64, f64)], segments: usize) -> TriangleSoup {
    let rings = profile.len();
    let mut vertices = vec![Point3::new(0.0, 0.0, profile[0].1)];
    for &(radius, z) in &profile[1..rings - 1] {
        for k in 0..segments {
            let angle = k as f64 / segments as f64 * std::f64::consts::TAU;
            vertices.push(Point3::new(radius * angle.cos(), radius * angle.sin(), z));
        }
    }
    let top = vertices.len() as u32;
    vertices.push(Point3::new(0.0, 0.0, profile[rings - 1].1));
    let ring = |r: usize, k: usize| (1 + (r - 1) * segments + k % segments) as u32;
    let mut triangles = Vec::new();
    for k in 0..segments {
        triangles.push([0, ring(1, k + 1), ring(1, k)]);
        for r in 1..rings - 2 {
            let (a, b, c, d) = (
                ring(r, k),
                ring(r, k + 1),
                ring(r + 1, k),
                ring(r + 1, k + 1),
            );
            triangles.push([a, b, d]);
            triangles.push([a, d, c]);
        }
        triangles.push([ring(rings - 2, k), ring(rings - 2, k + 1), top]);
    }
    TriangleSoup {
        vertices,
        triangles,
    }
}

/// A URDF cylinder: axis z, centred on the origin.
pub fn cylinder_soup(radius_m: f64, length_m: f64) -> TriangleSoup {
    let h = length_m / 2.0;
    revolve(
        &[(0.0, -h), (radius_m, -h), (radius_m, h), (0.0, h)],
        CIRCLE_SEGMENTS,
    )
}

/// A URDF capsule: a cylinder of `length_m` along z with hemispherical caps.
pub fn capsule_soup(radius_m: f64, length_m: f64) -> TriangleSoup {
    let h = length_m / 2.0;
    let steps = CIRCLE_SEGMENTS / 4;
    let mut profile = Vec::new();
    for i in 0..=steps {
        let angle =
            -std::f64::consts::FRAC_PI_2 + i as f64 / steps as f64 * std::f64::consts::FRAC_PI_2;
        profile.push((radius_m * angle.cos(), -h + radius_m * angle.sin()));
    }
    for i in 0..=steps {
        let angle = i as f64 / steps as f64 * std::f64::consts::FRAC_PI_2;
        profile.push((radius_m * angle.cos(), h + radius_m * angle.sin()));
    }
    profile[0].0 = 0.0;
    let last = profile.len() - 1;
    profile[last].0 = 0.0;
    revolve(&profile, CIRCLE_SEGMENTS)
}

/// A URDF sphere centred on the origin.
pub fn sphere_soup(radius_m: f64) -> TriangleSoup {
    capsule_soup(radius_m, 0.0)
}

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
