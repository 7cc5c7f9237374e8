//! A bounding volume hierarchy over a mesh's triangles whose nodes also bound their triangles'
//! normals (a cone per node), so that "the closest surface facing this direction" is one
//! descent: a node is skipped when it is farther than the best triangle found so far or when
//! none of its normals can lie within the query's cone. The touch alignment asks this for every
//! touch at every step of hundreds of starts; a plain BVH must visit every near triangle turned
//! away from the probe, and the normal bins it replaced needed a descent per bin.
//!
//! Nodes split the triangles at the median of whichever of their six coordinates (centroid, and
//! normal scaled by half the part's size) spreads most, so that subtrees group triangles that are
//! near each other and face alike: a box's corner region splits by face before it splits by place.

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

/// Triangles a leaf holds at most.
const LEAF_SIZE: usize = 4;

/// Where on a triangle its closest point to a query lies, numbered as parry numbers them: vertex
/// 0, 1, 2 = a, b, c; edge 0 = ab, 1 = bc, 2 = ac.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Feature {
    Vertex(u32),
    Edge(u32),
    Face,
}

/// The closest facing triangle found by [`FacingTree::closest`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct Closest {
    pub triangle: u32,
    pub point: Point3<f64>,
    pub distance_m: f64,
    pub feature: Feature,
}

#[derive(Debug, Clone)]
struct Node {
    lower: Vector3<f64>,
    upper: Vector3<f64>,
    /// Mean direction of the node's normals and the largest angle of any of them from it.
    axis: Vector3<f64>,
    half_angle_rad: f64,
    /// Cosine and sine of `half_angle_rad`, so that a query needs no trigonometry per node.
    cos_half: f64,
    sin_half: f64,
    /// Inner node: index of the first child (the second follows it). Leaf: first triangle slot.
    first: u32,
    /// Triangles of a leaf; 0 for an inner node.
    count: u32,
}

#[derive(Debug, Clone)]
pub(crate) struct FacingTree {
    nodes: Vec<Node>,
    /// Triangle corners in leaf order.
    corners: Vec<[Vector3<f64>; 3]>,
    normals: Vec<Vector3<f64>>,
    /// The mesh's index of each slot's triangle, and the slot of each of the mesh's triangles.
    original: Vec<u32>,
    slot_of: Vec<u32>,
}

impl FacingTree {
    /// Builds the tree over `corners` (one triangle each) with their unit `normals`; `size_m`
    /// weighs normal spread against distance when choosing splits. `parallel`: on rayon's pool
    /// (the same tree); only from where no job the pool might take up while waiting can need
    /// this tree (see `Mesh::prepare_approximate_queries`).
    pub fn new(
        corners: &[[Vector3<f64>; 3]],
        normals: &[Vector3<f64>],
        size_m: f64,
        parallel: bool,
    ) -> Self {
        let keys = split_keys(corners, normals, size_m);
        let mut order: Vec<u32> = (0..corners.len() as u32).collect();
        if corners.is_empty() {
            return Self {
                nodes: Vec::new(),
                corners: Vec::new(),
                normals: Vec::new(),
                original: Vec::new(),
                slot_of: Vec::new(),
            };
        }
        // The triangles' order first (each node's members are a contiguous run of it, halved
        // at its median), then every node's bounds from its run of the ordered triangles
        // (contiguous in memory). A 26k-triangle link took 18 ms as the tree was built before,
        // depth first with each node's bounds gathered by index, on a local alignment's
        // critical path; 6 ms this way on two cores.
        partition(&mut order, &keys, parallel);
        let corners: Vec<[Vector3<f64>; 3]> = order.iter().map(|&t| corners[t as usize]).collect();
        let normals: Vec<Vector3<f64>> = order.iter().map(|&t| normals[t as usize]).collect();
        let node_of = |run: &NodeRun| {
            let members = run.start as usize..(run.start + run.len) as usize;
            let mut node = Self::bound(&corners[members.clone()], &normals[members]);
            (node.first, node.count) = match run.first_child {
                Some(child) => (child, 0),
                // A leaf's triangles are stored in the tree's order: its slots are its run.
                None => (run.start, run.len),
            };
            node
        };
        let runs = node_runs(corners.len());
        let nodes: Vec<Node> = if parallel {
            runs.par_iter().map(node_of).collect()
        } else {
            runs.iter().map(node_of).collect()
        };
        let mut slot_of = vec![0; corners.len()];
        for (slot, &triangle) in order.iter().enumerate() {
            slot_of[triangle as usize] = slot as u32;
        }
        Self {
            nodes,
            corners,
            normals,
            original: order,
            slot_of,
        }
    }

    /// The node bounding a run of triangles (`corners` and `normals` side by side), a leaf
    /// until given children.
    fn bound(corners: &[[Vector3<f64>; 3]], normals: &[Vector3<f64>]) -> Node {
        let mut lower = Vector3::repeat(f64::INFINITY);
        let mut upper = Vector3::repeat(f64::NEG_INFINITY);
        let mut sum = Vector3::zeros();
        for (triangle, normal) in corners.iter().zip(normals) {
            for corner in triangle {
                lower = lower.inf(corner);
                upper = upper.sup(corner);
            }
            sum += normal;
        }
        let axis = sum.try_normalize(1e-9).unwrap_or_else(Vector3::z);
        // The widest normal's angle: acos is decreasing, so one acos of the smallest cosine.
        let half_angle_rad = if sum.norm() < 1e-9 {
            std::f64::consts::PI
        } else {
            normals
                .iter()
                .map(|n| axis.dot(n).clamp(-1.0, 1.0))
                .fold(1.0, f64::min)
                .acos()
        };
        Node {
            lower,
            upper,
            axis,
            half_angle_rad,
            cos_half: half_angle_rad.cos(),
            sin_half: half_angle_rad.sin(),
            first: 0,
            count: corners.len() as u32,
        }
    }

    /// The closest triangle to `query` whose unit normal `n` lies within `cone_rad` of `facing`
    /// (any triangle when `facing` is `None`), if one lies within `max_distance_m`. `hint` is a
    /// triangle likely to be (near) the answer, the previous answer of a query that moved a
    /// little: its distance bounds the search from the start, which then opens only the nodes
    /// nearer than it.
    pub fn closest(
        &self,
        query: &Point3<f64>,
        facing: Option<(&Vector3<f64>, f64)>,
        max_distance_m: f64,
        hint: Option<u32>,
    ) -> Option<Closest> {
        self.closest_within_slack(query, facing, max_distance_m, hint, 1.0)
    }

    /// [`FacingTree::closest`], approximate by at most a factor `slack` (>= 1): the triangle
    /// found is no farther than `slack` times the closest one. A search that only needs to know
    /// which way the surface lies (the global search's exploration, whose queries are mostly
    /// tens of millimetres off a part at a wrong orientation) opens far fewer nodes: the exact
    /// answer must rule out every node the sphere through the best triangle touches.
    pub fn closest_within_slack(
        &self,
        query: &Point3<f64>,
        facing: Option<(&Vector3<f64>, f64)>,
        max_distance_m: f64,
        hint: Option<u32>,
        slack: f64,
    ) -> Option<Closest> {
        if self.nodes.is_empty() {
            return None;
        }
        let q = query.coords;
        let min_cos = facing.map(|(_, cone)| cone.cos());
        let sin_cone = facing.map_or(0.0, |(_, cone)| cone.sin());
        // A node can hold a facing normal when its axis is within half-angle + cone of
        // `facing`: cos(half + cone) expanded, since the sum's cosine per node would dominate.
        let may_face = |node: &Node| match (facing, min_cos) {
            (Some((direction, cone)), Some(cos_cone)) => {
                node.half_angle_rad + cone >= std::f64::consts::PI
                    || node.axis.dot(direction)
                        >= node.cos_half * cos_cone - node.sin_half * sin_cone
            }
            _ => true,
        };
        let mut best: Option<Closest> = None;
        let mut best_squared = if max_distance_m.is_finite() {
            max_distance_m * max_distance_m
        } else {
            f64::INFINITY
        };
        let accepts = |slot: usize| match (facing, min_cos) {
            (Some((direction, _)), Some(min_cos)) => self.normals[slot].dot(direction) >= min_cos,
            _ => true,
        };
        if let Some(slot) = hint
            .and_then(|t| self.slot_of.get(t as usize))
            .map(|&s| s as usize)
            && accepts(slot)
        {
            let [a, b, c] = &self.corners[slot];
            let (point, feature) = closest_on_triangle(&q, a, b, c);
            let squared = (point - q).norm_squared();
            if squared < best_squared {
                // The descent replaces it only with a strictly nearer triangle: a tie (the
                // other side of a shared edge) keeps the hint, so answers do not flip between
                // calls.
                best_squared = squared;
                best = Some(Closest {
                    triangle: self.original[slot],
                    point: Point3::from(point),
                    distance_m: 0.0,
                    feature,
                });
            }
        }
        let mut stack: Vec<(u32, f64)> = Vec::with_capacity(64);
        stack.push((0, box_distance_squared(&self.nodes[0], &q)));
        // A node is opened only if it could hold a triangle nearer than the best by the slack.
        let slack_squared = slack * slack;
        while let Some((index, lower_bound)) = stack.pop() {
            let lower_bound = lower_bound * slack_squared;
            if lower_bound >= best_squared {
                continue;
            }
            let node = &self.nodes[index as usize];
            if !may_face(node) {
                continue;
            }
            if node.count > 0 {
                let slots = node.first as usize..(node.first + node.count) as usize;
                for slot in slots {
                    if !accepts(slot) {
                        continue;
                    }
                    let [a, b, c] = &self.corners[slot];
                    let (point, feature) = closest_on_triangle(&q, a, b, c);
                    let squared = (point - q).norm_squared();
                    if squared < best_squared {
                        best_squared = squared;
                        best = Some(Closest {
                            triangle: self.original[slot],
                            point: Point3::from(point),
                            distance_m: 0.0,
                            feature,
                        });
                    }
                }
                continue;
            }
            let (left, right) = (node.first, node.first + 1);
            let left_bound = box_distance_squared(&self.nodes[left as usize], &q);
            let right_bound = box_distance_squared(&self.nodes[right as usize], &q);
            // The nearer child is popped first, so its triangles tighten the bound early.
            if left_bound <= right_bound {
                stack.push((right, right_bound));
                stack.push((left, left_bound));
            } else {
                stack.push((left, left_bound));
                stack.push((right, right_bound));
            }
        }
        best.map(|mut found| {
            found.distance_m = best_squared.sqrt();
            found
        })
    }
}

/// Each triangle's place for the splits: its centroid, and its normal scaled by a quarter of
/// `size_m` (see the module's documentation).
fn split_keys(
    corners: &[[Vector3<f64>; 3]],
    normals: &[Vector3<f64>],
    size_m: f64,
) -> Vec<[f64; 6]> {
    let normal_weight = 0.25 * size_m.max(1e-9);
    corners
        .iter()
        .zip(normals)
        .map(|(c, n)| {
            let centroid = (c[0] + c[1] + c[2]) / 3.0;
            let n = n * normal_weight;
            [centroid.x, centroid.y, centroid.z, n.x, n.y, n.z]
        })
        .collect()
}

/// A node's run of the tree's triangle order and, for an inner node, its first child's index.
struct NodeRun {
    start: u32,
    len: u32,
    first_child: Option<u32>,
}

/// Runs of more triangles than this have their halves ordered in parallel.
const PARALLEL_RUN: usize = 2048;

/// Orders `members` so that every node's are contiguous: a run of more than [`LEAF_SIZE`] is
/// split at its median along whichever of the six coordinates of [`split_keys`] spreads most,
/// and each half ordered the same way (the halves of long runs in parallel if `parallel`).
fn partition(members: &mut [u32], keys: &[[f64; 6]], parallel: bool) {
    if members.len() <= LEAF_SIZE {
        return;
    }
    let mut lowest = [f64::MAX; 6];
    let mut highest = [f64::MIN; 6];
    for &t in members.iter() {
        for (d, &value) in keys[t as usize].iter().enumerate() {
            lowest[d] = lowest[d].min(value);
            highest[d] = highest[d].max(value);
        }
    }
    let spread: [f64; 6] = std::array::from_fn(|d| highest[d] - lowest[d]);
    let dimension = (0..6)
        .max_by(|&a, &b| spread[a].total_cmp(&spread[b]))
        .unwrap_or(0);
    let middle = members.len() / 2;
    members.select_nth_unstable_by(middle, |&a, &b| {
        keys[a as usize][dimension].total_cmp(&keys[b as usize][dimension])
    });
    let in_parallel = parallel && members.len() > PARALLEL_RUN;
    let (left, right) = members.split_at_mut(middle);
    if in_parallel {
        rayon::join(
            || partition(left, keys, parallel),
            || partition(right, keys, parallel),
        );
    } else {
        partition(left, keys, parallel);
        partition(right, keys, parallel);
    }
}

/// The nodes of a tree over `count` triangles ordered by [`partition`], indexed depth first
/// with each node's two children side by side (the layout [`FacingTree::closest`] descends).
fn node_runs(count: usize) -> Vec<NodeRun> {
    fn split(index: usize, runs: &mut Vec<NodeRun>) {
        let (start, len) = (runs[index].start, runs[index].len);
        if len as usize <= LEAF_SIZE {
            return;
        }
        let middle = len / 2;
        let first_child = runs.len();
        runs.push(NodeRun {
            start,
            len: middle,
            first_child: None,
        });
        runs.push(NodeRun {
            start: start + middle,
            len: len - middle,
            first_child: None,
        });
        runs[index].first_child = Some(first_child as u32);
        split(first_child, runs);
        split(first_child + 1, runs);
    }
    let mut runs = Vec::with_capacity(2 * count / LEAF_SIZE + 1);
    runs.push(NodeRun {
        start: 0,
        len: count as u32,
        first_child: None,
    });
    split(0, &mut runs);
    runs
}

/// The triangles near one query point, remembered so that the next queries close to it (the same
/// touch at the next step of a fit) scan a handful of triangles instead of descending the tree.
///
/// Exact: with `d` the closest distance at the anchor `a`, every query `q` with |q - a| <= r has
/// its closest triangle among those within `d + 2 r` of `a` (that triangle is within
/// `d + r` of `q`, so within `d + 2 r` of `a`).
#[derive(Debug, Clone, Default)]
pub struct NearbyTriangles {
    anchor: Vector3<f64>,
    reach_m: f64,
    /// Tree slots within `d + 2 reach` of the anchor; filled on the first query that lands
    /// within reach, so that a run of far-apart queries pays for none.
    slots: Vec<u32>,
    filled: bool,
    /// Squared distance up to which `slots` were collected.
    collected_squared: f64,
    /// The last answer, a hint for the next descent.
    last_triangle: Option<u32>,
}

/// A query within this fraction of the closest distance of the anchor (at most
/// [`MAX_REACH_FRACTION`] of the part's size, at least [`MIN_REACH_FRACTION`] of it) reuses its
/// triangles. The triangles kept are those on the patch of radius about sqrt(4 d r) around the
/// closest point: the cap keeps the patch small for a query far from the part.
const REACH_OF_DISTANCE: f64 = 0.5;
const MIN_REACH_FRACTION: f64 = 1e-3;
const MAX_REACH_FRACTION: f64 = 1e-2;

impl FacingTree {
    /// Like [`FacingTree::closest`] without a cone, answered from `cache` when the query lies
    /// within its reach and by a descent (which re-anchors the cache) otherwise.
    pub fn closest_cached(
        &self,
        query: &Point3<f64>,
        cache: &mut NearbyTriangles,
        size_m: f64,
    ) -> Option<Closest> {
        let q = query.coords;
        if cache.reach_m > 0.0 && (q - cache.anchor).norm() <= cache.reach_m {
            if !cache.filled {
                cache.slots.clear();
                self.collect_within(&cache.anchor, cache.collected_squared, &mut cache.slots);
                cache.filled = true;
            }
            let mut best: Option<Closest> = None;
            let mut best_squared = f64::INFINITY;
            for &slot in &cache.slots {
                let [a, b, c] = &self.corners[slot as usize];
                let (point, feature) = closest_on_triangle(&q, a, b, c);
                let squared = (point - q).norm_squared();
                if squared < best_squared {
                    best_squared = squared;
                    best = Some(Closest {
                        triangle: self.original[slot as usize],
                        point: Point3::from(point),
                        distance_m: 0.0,
                        feature,
                    });
                }
            }
            if let Some(mut found) = best {
                found.distance_m = best_squared.sqrt();
                cache.last_triangle = Some(found.triangle);
                return Some(found);
            }
        }
        let found = self.closest(query, None, f64::INFINITY, cache.last_triangle)?;
        let reach = (REACH_OF_DISTANCE * found.distance_m)
            .clamp(MIN_REACH_FRACTION * size_m, MAX_REACH_FRACTION * size_m);
        let collect = found.distance_m + 2.0 * reach;
        *cache = NearbyTriangles {
            anchor: q,
            reach_m: reach,
            slots: std::mem::take(&mut cache.slots),
            filled: false,
            collected_squared: collect * collect,
            last_triangle: Some(found.triangle),
        };
        Some(found)
    }

    /// Appends the slots of every triangle within `sqrt(limit_squared)` of `centre`.
    fn collect_within(&self, centre: &Vector3<f64>, limit_squared: f64, out: &mut Vec<u32>) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        stack.push(0);
        while let Some(index) = stack.pop() {
            let node = &self.nodes[index as usize];
            if box_distance_squared(node, centre) > limit_squared {
                continue;
            }
            if node.count > 0 {
                for slot in node.first..node.first + node.count {
                    let [a, b, c] = &self.corners[slot as usize];
                    let (point, _) = closest_on_triangle(centre, a, b, c);
                    if (point - centre).norm_squared() <= limit_squared {
                        out.push(slot);
                    }
                }
            } else {
                stack.push(node.first);
                stack.push(node.first + 1);
            }
        }
    }
}

fn box_distance_squared(node: &Node, q: &Vector3<f64>) -> f64 {
    let below = node.lower - q;
    let above = q - node.upper;
    (0..3)
        .map(|i| {
            let gap = below[i].max(above[i]).max(0.0);
            gap * gap
        })
        .sum()
}

/// The point of triangle abc closest to `p` and the feature it lies on, by the triangle's
/// Voronoi regions (vertices, then edges, then the face).
fn closest_on_triangle(
    p: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> (Vector3<f64>, Feature) {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (*a, Feature::Vertex(0));
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (*b, Feature::Vertex(1));
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab * v, Feature::Edge(0));
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (*c, Feature::Vertex(2));
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, Feature::Edge(2));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, Feature::Edge(1));
    }
    let denominator = 1.0 / (va + vb + vc);
    let v = vb * denominator;
    let w = vc * denominator;
    (a + ab * v + ac * w, Feature::Face)
}

#[cfg(test)]
#[path = "facing_tree_tests.rs"]
mod tests;
