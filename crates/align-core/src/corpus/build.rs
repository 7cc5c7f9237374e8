//! The mesh-building kit the corpus parts are made with: a vertex-welding triangle collector,
//! strips between matching loops, and planar faces with holes (ear clipping after bridging each
//! hole to the outline). Every part is assembled from faces whose shared edges carry the same
//! vertices, so a closed part comes out as a closed, consistently oriented manifold.

use std::collections::HashMap;

use nalgebra::{Point3, Vector3};

use crate::geometry::{Mesh, MeshError};

/// Collects triangles; vertices at the same position (to 1 nm) are one vertex.
#[derive(Debug, Default)]
pub(crate) struct Builder {
    vertices: Vec<Point3<f64>>,
    index: HashMap<[i64; 3], u32>,
    triangles: Vec<[u32; 3]>,
}

impl Builder {
    pub(crate) fn new() -> Self {
        Self::default()
    }

    pub(crate) fn vertex(&mut self, p: &Point3<f64>) -> u32 {
        // Quantise to 1 nm: the loops of adjacent faces are computed by the same formulas, so
        // shared vertices are bit-identical and this only guards against -0.0 and the like.
        let key = [p.x, p.y, p.z].map(|c| (c * 1e9).round() as i64);
        let next = self.vertices.len() as u32;
        *self.index.entry(key).or_insert_with(|| {
            self.vertices.push(*p);
            next
        })
    }

    pub(crate) fn triangle(&mut self, a: &Point3<f64>, b: &Point3<f64>, c: &Point3<f64>) {
        let ids = [self.vertex(a), self.vertex(b), self.vertex(c)];
        if ids[0] != ids[1] && ids[1] != ids[2] && ids[0] != ids[2] {
            self.triangles.push(ids);
        }
    }

    /// Quads between two loops (or open polylines) of equal length, `a[i] a[i+1] b[i+1] b[i]`,
    /// all turned so that the first quad's normal has a positive component along `outward_hint`
    /// evaluated at that quad. Degenerate quads (a loop shrunk to a point) keep their one triangle.
    pub(crate) fn strip(
        &mut self,
        a: &[Point3<f64>],
        b: &[Point3<f64>],
        closed: bool,
        outward_hint: impl Fn(&Point3<f64>) -> Vector3<f64>,
    ) {
        debug_assert_eq!(a.len(), b.len());
        let n = a.len();
        let quads = if closed { n } else { n - 1 };
        // Decide the orientation on the quad with the largest area (robust to a shrunken end).
        let mut best = (0.0, 1.0);
        for i in 0..quads {
            let j = (i + 1) % n;
            let normal = (a[j] - a[i]).cross(&(b[i] - a[i])) + (b[j] - b[i]).cross(&(b[i] - a[j]));
            let area = normal.norm();
            if area > best.0 {
                let centre =
                    Point3::from((a[i].coords + a[j].coords + b[i].coords + b[j].coords) / 4.0);
                best = (area, normal.dot(&outward_hint(&centre)).signum());
            }
        }
        let flip = best.1 < 0.0;
        for i in 0..quads {
            let j = (i + 1) % n;
            let (p, q, r, s) = (a[i], a[j], b[j], b[i]);
            if flip {
                self.triangle(&p, &r, &q);
                self.triangle(&p, &s, &r);
            } else {
                self.triangle(&p, &q, &r);
                self.triangle(&p, &r, &s);
            }
        }
    }

    /// A planar face bounded by `outline` with `holes` (3-D loops on one plane, either winding),
    /// triangulated with its normal along `normal`.
    pub(crate) fn face(
        &mut self,
        outline: &[Point3<f64>],
        holes: &[Vec<Point3<f64>>],
        normal: &Vector3<f64>,
    ) -> Result<(), MeshError> {
        let n = normal.normalize();
        let helper = if n.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        let u = helper.cross(&n).normalize();
        let v = n.cross(&u);
        let flat = |p: &Point3<f64>| [p.coords.dot(&u), p.coords.dot(&v)];
        let mut points: Vec<Point3<f64>> = outline.to_vec();
        let mut outline_2d: Vec<[f64; 2]> = outline.iter().map(flat).collect();
        if signed_area(&outline_2d) < 0.0 {
            outline_2d.reverse();
            points.reverse();
        }
        let mut holes_2d = Vec::with_capacity(holes.len());
        for hole in holes {
            let mut hole_points = hole.clone();
            let mut hole_2d: Vec<[f64; 2]> = hole.iter().map(flat).collect();
            if signed_area(&hole_2d) > 0.0 {
                hole_2d.reverse();
                hole_points.reverse();
            }
            holes_2d.push(hole_2d);
            points.extend(hole_points);
        }
        let triangles = triangulate(&outline_2d, &holes_2d).ok_or_else(|| {
            MeshError::Build(format!(
                "cannot triangulate a face with {} outline points and {} holes",
                outline.len(),
                holes.len()
            ))
        })?;
        for [a, b, c] in triangles {
            self.triangle(&points[a], &points[b], &points[c]);
        }
        Ok(())
    }

    pub(crate) fn finish(self) -> Result<Mesh, MeshError> {
        Mesh::new(&self.vertices, &self.triangles)
    }
}

pub(crate) fn signed_area(polygon: &[[f64; 2]]) -> f64 {
    let n = polygon.len();
    (0..n)
        .map(|i| {
            let (p, q) = (polygon[i], polygon[(i + 1) % n]);
            p[0] * q[1] - q[0] * p[1]
        })
        .sum::<f64>()
        / 2.0
}

fn cross(o: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// True when the segments p-q and r-s share any point.
fn segments_touch(p: [f64; 2], q: [f64; 2], r: [f64; 2], s: [f64; 2]) -> bool {
    let (d1, d2) = (cross(p, q, r), cross(p, q, s));
    let (d3, d4) = (cross(r, s, p), cross(r, s, q));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    let within = |a: [f64; 2], b: [f64; 2], x: [f64; 2]| {
        x[0] >= a[0].min(b[0])
            && x[0] <= a[0].max(b[0])
            && x[1] >= a[1].min(b[1])
            && x[1] <= a[1].max(b[1])
    };
    (d1 == 0.0 && within(p, q, r))
        || (d2 == 0.0 && within(p, q, s))
        || (d3 == 0.0 && within(r, s, p))
        || (d4 == 0.0 && within(r, s, q))
}

/// True when direction `towards` from the polygon vertex at `here` (neighbours `prev`, `next`,
/// interior on the left of a counter-clockwise walk) points into the polygon's interior.
fn in_cone(prev: [f64; 2], here: [f64; 2], next: [f64; 2], towards: [f64; 2]) -> bool {
    if cross(prev, here, next) >= 0.0 {
        // Convex corner: strictly left of both edges.
        cross(here, next, towards) > 0.0 && cross(prev, here, towards) > 0.0
    } else {
        !(cross(here, next, towards) <= 0.0 && cross(prev, here, towards) <= 0.0)
    }
}

/// Triangulates a counter-clockwise outline with clockwise holes. Indices refer to the outline's
/// points followed by each hole's, in order. `None` if the polygon defeats the ear clipper.
pub(crate) fn triangulate(
    outline: &[[f64; 2]],
    holes: &[Vec<[f64; 2]>],
) -> Option<Vec<[usize; 3]>> {
    let mut coords: Vec<[f64; 2]> = outline.to_vec();
    let mut hole_ranges = Vec::with_capacity(holes.len());
    for hole in holes {
        hole_ranges.push(coords.len()..coords.len() + hole.len());
        coords.extend_from_slice(hole);
    }
    let mut polygon: Vec<usize> = (0..outline.len()).collect();
    // Bridge the holes in order of their rightmost point, from the right: every hole still to be
    // bridged lies left of the one being bridged, which keeps the bridges short and free.
    let mut order: Vec<usize> = (0..holes.len()).collect();
    let rightmost = |h: usize| {
        hole_ranges[h]
            .clone()
            .max_by(|&a, &b| coords[a][0].total_cmp(&coords[b][0]))
            .unwrap_or(hole_ranges[h].start)
    };
    order.sort_by(|&a, &b| coords[rightmost(b)][0].total_cmp(&coords[rightmost(a)][0]));
    for (k, &h) in order.iter().enumerate() {
        let range = hole_ranges[h].clone();
        let m = rightmost(h);
        let pm = coords[m];
        let hole_len = range.len();
        let hole_at = |i: usize| range.start + (i + hole_len) % hole_len;
        let m_local = m - range.start;
        let (m_prev, m_next) = (
            coords[hole_at(m_local + hole_len - 1)],
            coords[hole_at(m_local + 1)],
        );
        // Edges that a bridge must not cross: the polygon so far and the holes not yet bridged.
        let mut edges: Vec<(usize, usize)> = (0..polygon.len())
            .map(|i| (polygon[i], polygon[(i + 1) % polygon.len()]))
            .collect();
        for &other in &order[k..] {
            let r = hole_ranges[other].clone();
            let len = r.len();
            edges.extend((0..len).map(|i| (r.start + i, r.start + (i + 1) % len)));
        }
        let mut candidates: Vec<usize> = (0..polygon.len()).collect();
        candidates.sort_by(|&a, &b| {
            let da = dist2(coords[polygon[a]], pm);
            let db = dist2(coords[polygon[b]], pm);
            da.total_cmp(&db)
        });
        let n = polygon.len();
        let bridge = candidates.into_iter().find(|&slot| {
            let p = coords[polygon[slot]];
            let (prev, next) = (
                coords[polygon[(slot + n - 1) % n]],
                coords[polygon[(slot + 1) % n]],
            );
            if !in_cone(prev, p, next, pm) || !in_cone(m_prev, pm, m_next, p) {
                return false;
            }
            edges.iter().all(|&(a, b)| {
                let (ca, cb) = (coords[a], coords[b]);
                ca == p || cb == p || ca == pm || cb == pm || !segments_touch(p, pm, ca, cb)
            })
        })?;
        // Walk: ... P, M, around the hole back to M, P, ...
        let mut splice = Vec::with_capacity(hole_len + 2);
        for i in 0..=hole_len {
            splice.push(hole_at(m_local + i));
        }
        splice.push(polygon[bridge]);
        polygon.splice(bridge + 1..bridge + 1, splice);
    }
    ear_clip(&coords, polygon)
}

fn dist2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}

fn ear_clip(coords: &[[f64; 2]], mut polygon: Vec<usize>) -> Option<Vec<[usize; 3]>> {
    let mut triangles = Vec::with_capacity(polygon.len());
    let mut start = 0;
    while polygon.len() > 3 {
        let n = polygon.len();
        let is_ear = |k: usize| {
            let (ia, ib, ic) = (polygon[(k + n - 1) % n], polygon[k], polygon[(k + 1) % n]);
            let (a, b, c) = (coords[ia], coords[ib], coords[ic]);
            if cross(a, b, c) <= 0.0 {
                return false;
            }
            // No other vertex on or inside the triangle (bridge duplicates share a position
            // with a corner and do not count).
            polygon.iter().all(|&other| {
                let p = coords[other];
                if p == a || p == b || p == c {
                    return true;
                }
                !(cross(a, b, p) >= 0.0 && cross(b, c, p) >= 0.0 && cross(c, a, p) >= 0.0)
            })
        };
        let ear = (0..n).map(|i| (start + i) % n).find(|&k| is_ear(k))?;
        triangles.push([
            polygon[(ear + n - 1) % n],
            polygon[ear],
            polygon[(ear + 1) % n],
        ]);
        polygon.remove(ear);
        start = ear.saturating_sub(1);
    }
    if polygon.len() == 3 {
        let [a, b, c] = [polygon[0], polygon[1], polygon[2]];
        if cross(coords[a], coords[b], coords[c]) > 0.0 {
            triangles.push([a, b, c]);
        }
    }
    Some(triangles)
}

/// A rounded rectangle in the xy-plane, counter-clockwise, centre `centre`, full size `size`,
/// corner radius `radius` with `corner_segments` per quarter, straight sides split into pieces of
/// at most `side_step` (so that walls and caps share their vertices). Starts at the +x side.
pub(crate) fn rounded_rect(
    centre: [f64; 2],
    size: [f64; 2],
    radius: f64,
    corner_segments: usize,
    side_step: f64,
) -> Vec<[f64; 2]> {
    let (hx, hy) = (size[0] / 2.0 - radius, size[1] / 2.0 - radius);
    let corners = [[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]];
    let mut out = Vec::new();
    for (k, corner) in corners.iter().enumerate() {
        let start_angle = k as f64 * std::f64::consts::FRAC_PI_2;
        for s in 0..=corner_segments {
            let angle =
                start_angle + s as f64 / corner_segments as f64 * std::f64::consts::FRAC_PI_2;
            out.push([
                centre[0] + corner[0] + radius * angle.cos(),
                centre[1] + corner[1] + radius * angle.sin(),
            ]);
        }
        // The straight side to the next corner.
        let next = corners[(k + 1) % 4];
        let end_angle = start_angle + std::f64::consts::FRAC_PI_2;
        let from = [
            corner[0] + radius * end_angle.cos(),
            corner[1] + radius * end_angle.sin(),
        ];
        let to = [
            next[0] + radius * end_angle.cos(),
            next[1] + radius * end_angle.sin(),
        ];
        let length = ((to[0] - from[0]).powi(2) + (to[1] - from[1]).powi(2)).sqrt();
        let pieces = (length / side_step - 1e-6).ceil().max(1.0) as usize;
        for s in 1..pieces {
            let t = s as f64 / pieces as f64;
            out.push([
                centre[0] + from[0] + t * (to[0] - from[0]),
                centre[1] + from[1] + t * (to[1] - from[1]),
            ]);
        }
    }
    out
}

/// A circle in the xy-plane, counter-clockwise, starting at angle `phase`.
pub(crate) fn circle(centre: [f64; 2], radius: f64, segments: usize, phase: f64) -> Vec<[f64; 2]> {
    (0..segments)
        .map(|k| {
            let angle = phase + k as f64 / segments as f64 * std::f64::consts::TAU;
            [
                centre[0] + radius * angle.cos(),
                centre[1] + radius * angle.sin(),
            ]
        })
        .collect()
}

/// A 2-D outline rotated by `angle` about `pivot`.
pub(crate) fn rotate_2d(outline: &[[f64; 2]], pivot: [f64; 2], angle: f64) -> Vec<[f64; 2]> {
    let (s, c) = angle.sin_cos();
    outline
        .iter()
        .map(|p| {
            let (dx, dy) = (p[0] - pivot[0], p[1] - pivot[1]);
            [pivot[0] + c * dx - s * dy, pivot[1] + s * dx + c * dy]
        })
        .collect()
}

/// A 2-D outline lifted to height `z` (m).
pub(crate) fn at_z(outline: &[[f64; 2]], z: f64) -> Vec<Point3<f64>> {
    outline.iter().map(|p| Point3::new(p[0], p[1], z)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn area_of(coords: &[[f64; 2]], triangles: &[[usize; 3]]) -> f64 {
        triangles
            .iter()
            .map(|&[a, b, c]| {
                let area = cross(coords[a], coords[b], coords[c]) / 2.0;
                assert!(area > 0.0, "a clipped triangle is not counter-clockwise");
                area
            })
            .sum()
    }

    #[test]
    fn plate_with_holes_is_covered_exactly_once() {
        let outline = rounded_rect([0.0, 0.0], [0.18, 0.12], 0.012, 8, 0.01);
        let mut holes: Vec<Vec<[f64; 2]>> = vec![
            circle([0.05, 0.03], 0.004, 32, 0.0),
            circle([-0.05, 0.03], 0.004, 32, 0.0),
            circle([0.05, -0.03], 0.004, 32, 0.0),
            rounded_rect([-0.03, -0.02], [0.05, 0.03], 0.005, 6, 0.01),
        ];
        for hole in &mut holes {
            hole.reverse();
        }
        let triangles = triangulate(&outline, &holes).expect("triangulates");
        let mut coords = outline.clone();
        for hole in &holes {
            coords.extend_from_slice(hole);
        }
        let expected = signed_area(&outline) + holes.iter().map(|h| signed_area(h)).sum::<f64>();
        let got = area_of(&coords, &triangles);
        assert!((got - expected).abs() < 1e-12, "{got} vs {expected}");
    }
}
