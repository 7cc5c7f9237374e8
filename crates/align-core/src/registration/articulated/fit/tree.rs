//! The kinematic tree as the searches see it: which joint comes first, which links a joint
//! decides, where it turns and how far its window reaches.

use nalgebra::{Isometry3, Point3};

use super::RobotFitOptions;
use super::placed::{Placed, reach_m};
use crate::registration::articulated::body::{ArticulatedBody, JointAxis};

/// Parameters from the root outwards (the order their links appear in the tree).
pub(super) fn search_order(body: &ArticulatedBody) -> Vec<usize> {
    let mut order = Vec::new();
    for &link in body.order() {
        for &parameter in body.movers(link) {
            if !order.contains(&parameter) {
                order.push(parameter);
            }
        }
    }
    order
}

/// How far a parameter may move its links from the current value: the search window.
pub(super) struct Window {
    pub(super) parameter: usize,
    pub(super) half: f64,
    /// Largest distance of its links from its axis (1 for prismatic joints: windows in m).
    pub(super) reach_m: f64,
}

impl Window {
    pub(super) fn new(
        body: &ArticulatedBody,
        placed: &Placed,
        parameter: usize,
        delta_m: f64,
        voxel_m: f64,
    ) -> Option<(Self, Point3<f64>)> {
        let axis = axis_of(body, &placed.poses, parameter)?;
        let reach = reach_m(placed, &body.moved_by(parameter), &axis.origin).max(voxel_m);
        // The joint moves its farthest point by reach * dq: a window twice delta at that point
        // leaves room for the base's own error.
        let (half, reach_m) = if body.parameters()[parameter].prismatic {
            (2.0 * delta_m, 1.0)
        } else {
            ((2.0 * delta_m / reach).min(std::f64::consts::PI), reach)
        };
        Some((
            Self {
                parameter,
                half,
                reach_m,
            },
            axis.origin,
        ))
    }

    /// A revolute parameter's whole turn: half a turn each way ([`Self::slid_grid`] keeps it
    /// inside the limits). None for a prismatic joint or one whose axis is not placed.
    pub(super) fn whole_turn(
        body: &ArticulatedBody,
        placed: &Placed,
        parameter: usize,
        voxel_m: f64,
    ) -> Option<Self> {
        if body.parameters()[parameter].prismatic {
            return None;
        }
        let (window, _) = Self::new(body, placed, parameter, 0.0, voxel_m)?;
        Some(Self {
            half: std::f64::consts::PI,
            ..window
        })
    }

    pub(super) fn sweep_m(&self) -> f64 {
        self.half * self.reach_m
    }

    /// `steps + 1` values across `centre +- half`, inside the joint's limits.
    pub(super) fn grid(
        &self,
        body: &ArticulatedBody,
        centre: f64,
        half: f64,
        steps: usize,
    ) -> Vec<f64> {
        let info = &body.parameters()[self.parameter];
        let step = 2.0 * half / steps as f64;
        (0..=steps)
            .map(|i| (centre - half + i as f64 * step).clamp(info.lower, info.upper))
            .collect()
    }

    /// `steps + 1` values over [`Self::slid_span`] about `centre`.
    pub(super) fn slid_grid(&self, body: &ArticulatedBody, centre: f64, steps: usize) -> Vec<f64> {
        let (lower, upper) = self.slid_span(body, centre);
        let step = (upper - lower) / steps as f64;
        (0..=steps).map(|i| lower + i as f64 * step).collect()
    }

    /// A span of twice `half` about `centre`, slid inside the joint's limits rather than
    /// clamped to them (no longer than the limits allow): a whole turn (`half` = pi) from a
    /// wrist near its limit still covers every angle the joint can reach once (the UR10's wrist
    /// joints turn +-2 pi; from -6.28, centre +- pi clamped would miss -1.57).
    pub(super) fn slid_span(&self, body: &ArticulatedBody, centre: f64) -> (f64, f64) {
        let info = &body.parameters()[self.parameter];
        let (mut lower, mut upper) = (centre - self.half, centre + self.half);
        if lower < info.lower {
            upper = (upper + info.lower - lower).min(info.upper);
            lower = info.lower;
        }
        if upper > info.upper {
            lower = (lower - (upper - info.upper)).max(info.lower);
            upper = info.upper;
        }
        (lower, upper)
    }
}

/// Where the (first) joint driven by `parameter` turns or slides, with the links at `poses`.
pub(super) fn axis_of(
    body: &ArticulatedBody,
    poses: &[Isometry3<f64>],
    parameter: usize,
) -> Option<JointAxis> {
    body.axes(poses)
        .into_iter()
        .flatten()
        .find(|(_, p, _)| *p == parameter)
        .map(|(axis, _, _)| axis)
}

/// True when turning `parameter` does not move its own links (those no deeper joint moves)
/// along their normals: a cylinder spinning about its axis. Its value then shows only through
/// the links beyond the next joint.
pub(super) fn spins_in_place(
    body: &ArticulatedBody,
    placed: &Placed,
    parameter: usize,
    min_ratio: f64,
) -> bool {
    if body.parameters()[parameter].prismatic {
        return false;
    }
    let Some(axis) = axis_of(body, &placed.poses, parameter) else {
        return false;
    };
    turns_in_place(
        body,
        &placed.poses,
        &own_links(body, parameter),
        &axis,
        min_ratio,
    )
}

/// True when turning `links` (placed at `poses`) about `axis` does not move their surfaces
/// along their normals: RMS normal motion per radian below `min_ratio` of their reach.
pub(super) fn turns_in_place(
    body: &ArticulatedBody,
    poses: &[Isometry3<f64>],
    links: &[usize],
    axis: &JointAxis,
    min_ratio: f64,
) -> bool {
    let (mut sum, mut area, mut reach) = (0.0, 0.0, 0.0f64);
    for &link in links {
        let Some(mesh) = &body.links()[link].surface else {
            continue;
        };
        let vertices: Vec<Point3<f64>> = mesh.vertices().map(|v| poses[link] * v).collect();
        for (index, triangle) in mesh.triangles().iter().enumerate() {
            let [a, b, c] = triangle.map(|i| vertices[i as usize]);
            let centre = Point3::from((a.coords + b.coords + c.coords) / 3.0);
            let normal = poses[link].rotation * mesh.triangle_normal(index as u32);
            let arm = centre - axis.origin;
            let motion = axis.axis.cross(&arm).dot(&normal);
            let weight = mesh.triangle_area(index as u32);
            sum += weight * motion * motion;
            area += weight;
            reach = reach.max(axis.axis.cross(&arm).norm());
        }
    }
    area > 0.0 && (sum / area).sqrt() < min_ratio * reach.max(1e-9)
}

/// The parameter of the joint right after `parameter` down the tree (the one moving the most
/// of its links), if any.
pub(super) fn child_parameter(body: &ArticulatedBody, parameter: usize) -> Option<usize> {
    let moved = body.moved_by(parameter);
    (0..body.parameters().len())
        .filter(|&other| other != parameter)
        .map(|other| (other, body.moved_by(other)))
        .filter(|(_, links)| !links.is_empty() && links.iter().all(|l| moved.contains(l)))
        .max_by_key(|(_, links)| links.len())
        .map(|(other, _)| other)
}

/// Links whose pose `parameter` decides once the joints above are known: those it is the
/// last joint of.
pub(super) fn own_links(body: &ArticulatedBody, parameter: usize) -> Vec<usize> {
    body.moved_by(parameter)
        .into_iter()
        .filter(|&link| body.movers(link).last() == Some(&parameter))
        .collect()
}

/// The links with geometry whose pose `parameter` decides last.
pub(super) fn own_surfaces(body: &ArticulatedBody, parameter: usize) -> Vec<usize> {
    own_links(body, parameter)
        .into_iter()
        .filter(|&l| body.links()[l].surface.is_some())
        .collect()
}

/// The window of the revolute joint right after `parameter`, with its axis origin.
pub(super) fn revolute_child(
    body: &ArticulatedBody,
    placed: &Placed,
    parameter: usize,
    delta_m: f64,
    options: &RobotFitOptions,
) -> Option<(Window, Point3<f64>)> {
    child_parameter(body, parameter)
        .filter(|&c| !body.parameters()[c].prismatic)
        .and_then(|c| Window::new(body, placed, c, delta_m, options.voxel_m))
}
