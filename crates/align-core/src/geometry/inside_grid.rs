//! Which points lie inside a mesh that is not closed, for the scores that count a scan point in
//! a part's material against a pose. A closed mesh answers by the side of its closest feature
//! (signed distances), but many robot meshes people publish are not closed: 20 of the 50 links
//! of `scripts/unseen-parts.sh` and all six of the ABB IRB 1600's visual links have boundary
//! edges, or edges more than two triangles share (`cargo bench -p align-core --bench
//! inside_grid`). Most of them still enclose their material but for seams and small openings,
//! and some are several closed bodies that overlap. Their inside is decided here along rays: a
//! ray from a point whose crossings of the surface, counted by the side each triangle faces,
//! do not cancel (a winding number along the ray) votes the point inside, and a point five of
//! whose six axis-aligned rays (both ways along x, y and z) vote so is inside. A seam does not
//! change a ray's count; an opening, or a triangle facing the wrong way, changes the count of
//! the rays through it only; a point inside two overlapping bodies leaves both (where parity
//! would call it outside); a sheet without thickness gets three votes at most, and nothing
//! about it is called inside.
//!
//! A closed mesh made of several bodies (each closed) that overlap is not answered rightly by
//! the side of its closest feature either: in the common part of two bodies the closest feature
//! is often the other body's face, seen from outside that body. Six of the unseen links' closed
//! meshes are such (UR5's forearm, shoulder and upper arm, Cassie's pelvis, G1's knee, Bolt's
//! body), and their signed distances call 1-11 % of the points of their box outside that are
//! inside by the exact winding number, where this grid agrees with it on all (`cargo bench -p
//! align-core --bench inside_grid`). [`count_bodies`] tells which meshes may be such.

use nalgebra::{Point3, Vector3};

/// Cells along the longest side of the mesh's box: 3.7 mm cells for a 470 mm link, so that the
/// band the scores count the surface in (10 mm or more) is wider than a cell's half diagonal.
const CELLS_ALONG_LONGEST: usize = 64;

/// Of the six rays from a point, how many must vote it inside for it to be inside: one ray may
/// pass through an opening.
const INSIDE_VOTES: u8 = 4;

/// The inside of a mesh sampled at the centres of a grid of cubic cells over its box.
#[derive(Debug, Clone)]
pub struct InsideGrid {
    /// The corner of the first cell, in the mesh's frame.
    origin: Point3<f64>,
    cell_m: f64,
    counts: [usize; 3],
    /// Per cell (x fastest), the rays from its centre that vote it inside (0-6).
    votes: Vec<u8>,
}

impl InsideGrid {
    /// Samples the inside of the triangles `corners` (in metres) whose box is `lower`-`upper`.
    pub fn new(corners: &[[Vector3<f64>; 3]], lower: &Point3<f64>, upper: &Point3<f64>) -> Self {
        let extent = upper - lower;
        let cell_m = (extent.max() / (CELLS_ALONG_LONGEST - 2) as f64).max(1e-6);
        // One cell of margin each side: the rays start and end outside the mesh.
        let origin = lower - Vector3::repeat(cell_m);
        let counts = [0, 1, 2].map(|axis| (extent[axis] / cell_m).ceil() as usize + 2);
        let mut grid = Self {
            origin,
            cell_m,
            counts,
            votes: vec![0; counts[0] * counts[1] * counts[2]],
        };
        for axis in 0..3 {
            grid.count_rays_along(axis, corners);
        }
        grid
    }

    /// True when `point` (in the mesh's frame) is inside the mesh, as its cell's centre is. Off
    /// the grid, it is outside.
    pub fn contains(&self, point: &Point3<f64>) -> bool {
        let mut index = [0usize; 3];
        for axis in 0..3 {
            let cell = ((point[axis] - self.origin[axis]) / self.cell_m).floor();
            if !(cell >= 0.0 && cell < self.counts[axis] as f64) {
                return false;
            }
            index[axis] = cell as usize;
        }
        self.votes[self.flat(index)] >= INSIDE_VOTES
    }

    /// Half the diagonal of a cell: a point farther than this from the surface is on the side
    /// its cell's centre is on.
    pub fn cell_half_diagonal_m(&self) -> f64 {
        self.cell_m * 3f64.sqrt() / 2.0
    }

    fn flat(&self, index: [usize; 3]) -> usize {
        index[0] + self.counts[0] * (index[1] + self.counts[1] * index[2])
    }

    /// Casts one line along `axis` through every column of cell centres, and adds to each cell
    /// the votes of its rays towards both ends.
    fn count_rays_along(&mut self, axis: usize, corners: &[[Vector3<f64>; 3]]) {
        let (across_a, across_b) = ((axis + 1) % 3, (axis + 2) % 3);
        let (columns_a, columns_b) = (self.counts[across_a], self.counts[across_b]);
        let mut crossings: Vec<Vec<(f64, i32)>> = vec![Vec::new(); columns_a * columns_b];
        // The lines run a little off the cells' centres, so that a line meeting an edge or a
        // vertex exactly (a grid's centres often line up with a CAD part's faces) is unlikely.
        let nudge = [0.5 + 1.3e-4, 0.5 - 2.9e-4];
        let column_position = |column: usize, across: usize, nudge: f64| {
            self.origin[across] + (column as f64 + nudge) * self.cell_m
        };
        for triangle in corners {
            let projected = triangle.map(|v| [v[across_a], v[across_b]]);
            let (lower_a, upper_a) = span(projected.map(|p| p[0]));
            let (lower_b, upper_b) = span(projected.map(|p| p[1]));
            let first_a = self.column_at(lower_a, across_a, nudge[0]);
            let last_a = self.column_at(upper_a, across_a, nudge[0]);
            let first_b = self.column_at(lower_b, across_b, nudge[1]);
            let last_b = self.column_at(upper_b, across_b, nudge[1]);
            for column_a in first_a..=last_a.min(columns_a - 1) {
                let a = column_position(column_a, across_a, nudge[0]);
                for column_b in first_b..=last_b.min(columns_b - 1) {
                    let b = column_position(column_b, across_b, nudge[1]);
                    if let Some((weights, facing)) = barycentric(&projected, [a, b]) {
                        let along = weights[0] * triangle[0][axis]
                            + weights[1] * triangle[1][axis]
                            + weights[2] * triangle[2][axis];
                        crossings[column_a + columns_a * column_b].push((along, facing));
                    }
                }
            }
        }
        let cells_along = self.counts[axis];
        for (column, column_crossings) in crossings.iter_mut().enumerate() {
            if column_crossings.is_empty() {
                continue;
            }
            column_crossings.sort_by(|a, b| a.0.total_cmp(&b.0));
            // Leaving a body along +axis crosses a triangle facing +axis: the sum of the
            // facings past a point is the bodies the ray leaves, less those it enters.
            let total: i32 = column_crossings.iter().map(|(_, facing)| facing).sum();
            let mut passed = 0;
            let mut behind = 0;
            let mut index = [0usize; 3];
            index[across_a] = column % columns_a;
            index[across_b] = column / columns_a;
            for cell in 0..cells_along {
                let centre = self.origin[axis] + (cell as f64 + 0.5) * self.cell_m;
                while passed < column_crossings.len() && column_crossings[passed].0 < centre {
                    behind += column_crossings[passed].1;
                    passed += 1;
                }
                index[axis] = cell;
                let flat = self.flat(index);
                // Towards -axis the ray leaves through triangles facing -axis; a body whose
                // triangles all face inwards counts the other way, and still votes.
                self.votes[flat] += u8::from(total - behind != 0) + u8::from(behind != 0);
            }
        }
    }

    /// The first column whose line lies at or past `position` across the grid (the grid's
    /// columns when past its end).
    fn column_at(&self, position: f64, across: usize, nudge: f64) -> usize {
        let column = ((position - self.origin[across]) / self.cell_m - nudge).ceil();
        column.max(0.0) as usize
    }
}

/// How many separate bodies `triangles` make: groups of triangles connected through shared
/// vertices.
pub(crate) fn count_bodies(triangles: &[[u32; 3]], vertex_count: usize) -> usize {
    let mut parent: Vec<u32> = (0..vertex_count as u32).collect();
    fn root(parent: &mut [u32], mut vertex: u32) -> u32 {
        while parent[vertex as usize] != vertex {
            let grandparent = parent[parent[vertex as usize] as usize];
            parent[vertex as usize] = grandparent;
            vertex = grandparent;
        }
        vertex
    }
    for triangle in triangles {
        let first = root(&mut parent, triangle[0]);
        for &vertex in &triangle[1..] {
            let other = root(&mut parent, vertex);
            parent[other as usize] = first;
        }
    }
    let mut used = vec![false; vertex_count];
    for &vertex in triangles.iter().flatten() {
        used[vertex as usize] = true;
    }
    (0..vertex_count as u32)
        .filter(|&vertex| used[vertex as usize] && root(&mut parent, vertex) == vertex)
        .count()
}

fn span(values: [f64; 3]) -> (f64, f64) {
    (
        values[0].min(values[1]).min(values[2]),
        values[0].max(values[1]).max(values[2]),
    )
}

/// The barycentric weights of `point` in the 2-D triangle `corners` and the side the triangle
/// faces (1 when its corners turn counter-clockwise, towards the axis the plane's two span,
/// -1 when clockwise), when `point` lies inside it (`None` outside it and for a triangle seen
/// edge-on).
fn barycentric(corners: &[[f64; 2]; 3], point: [f64; 2]) -> Option<([f64; 3], i32)> {
    let edge = |from: [f64; 2], to: [f64; 2]| {
        (to[0] - from[0]) * (point[1] - from[1]) - (to[1] - from[1]) * (point[0] - from[0])
    };
    let w0 = edge(corners[1], corners[2]);
    let w1 = edge(corners[2], corners[0]);
    let w2 = edge(corners[0], corners[1]);
    let area = w0 + w1 + w2;
    let same_side = (w0 >= 0.0 && w1 >= 0.0 && w2 >= 0.0) || (w0 <= 0.0 && w1 <= 0.0 && w2 <= 0.0);
    let facing = if area > 0.0 { 1 } else { -1 };
    (same_side && area.abs() > 0.0).then(|| ([w0 / area, w1 / area, w2 / area], facing))
}
