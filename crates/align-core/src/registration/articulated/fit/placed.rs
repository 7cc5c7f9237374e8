//! Link surfaces placed in the world and the point queries every stage scores and refines with.

use nalgebra::{Isometry3, Point3, Unit, Vector3};
use rayon::prelude::*;

use crate::geometry::Mesh;
use crate::registration::articulated::body::ArticulatedBody;

/// A keypoint matched to a link surface.
#[derive(Debug, Clone, Copy)]
pub(super) struct Match {
    pub(super) point: Point3<f64>,
    pub(super) surface: Point3<f64>,
    pub(super) normal: Vector3<f64>,
    pub(super) distance: f64,
    pub(super) weight: f64,
    pub(super) link: usize,
}

/// The link and triangle a keypoint's exact match lay on at a refinement's previous step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct SurfaceHint {
    link: u32,
    triangle: u32,
}

#[cfg(test)]
impl SurfaceHint {
    pub(super) fn of(link: u32, triangle: u32) -> Self {
        Self { link, triangle }
    }
}

/// No triangle remembered (yet, or the last match came from a distance grid).
pub(super) const NO_HINT: SurfaceHint = SurfaceHint {
    link: u32::MAX,
    triangle: u32::MAX,
};

/// Where [`Placed::closeness`] takes its distances from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Distances {
    /// The link meshes' exact closest points.
    Exact,
    /// The links' distance grids where they answer as far as the band (a millimetre of blur),
    /// the meshes elsewhere.
    Grids,
}

/// Link surfaces placed in the world, with their bounds, ready for point queries.
pub(super) struct Placed<'a> {
    pub(super) body: &'a ArticulatedBody,
    pub(super) poses: Vec<Isometry3<f64>>,
    pub(super) inverse: Vec<Isometry3<f64>>,
    /// False: [`Placed::nearest`] takes the surface point and normal from the links' distance
    /// grids (a millimetre of blur at edges, no edge rejection) where they answer the band.
    pub(super) exact: bool,
    /// Each link surface's bounding sphere in the world (centre, radius), for a quick "too far".
    pub(super) spheres: Vec<Option<(Point3<f64>, f64)>>,
}

impl<'a> Placed<'a> {
    pub(super) fn new(
        body: &'a ArticulatedBody,
        world_from_root: &Isometry3<f64>,
        q: &[f64],
    ) -> Self {
        let poses = body.link_poses(world_from_root, q);
        let inverse = poses.iter().map(|p| p.inverse()).collect();
        let spheres = body
            .links()
            .iter()
            .zip(&poses)
            .map(|(link, pose)| {
                let surface = link.surface.as_ref()?;
                Some((pose * surface.centroid(), surface.radius_m()))
            })
            .collect();
        Self {
            body,
            poses,
            inverse,
            exact: true,
            spheres,
        }
    }

    /// False when `point` is farther than `band` from every point of `link`'s surface.
    pub(super) fn within_reach(&self, point: &Point3<f64>, link: usize, band: f64) -> bool {
        self.spheres[link].is_some_and(|(centre, radius)| {
            (point - centre).norm_squared() <= (radius + band) * (radius + band)
        })
    }

    /// The nearest surface of `links` within `band` of `point`.
    pub(super) fn nearest(&self, point: &Point3<f64>, band: f64, links: &[usize]) -> Option<Match> {
        let mut none = NO_HINT;
        self.nearest_hinted(point, band, links, &mut none)
    }

    /// [`Placed::nearest`], with the triangle `hint` the same keypoint matched at the previous
    /// step of a refinement (and set to this one's). An exact query whose hinted triangle lies
    /// within [`EDGE_REJECTION_M`] bounds every link's search by its distance from the start:
    /// any closer surface point is accepted wherever it lies, so the answer is the one
    /// [`Placed::nearest`] gives, and links farther than the hint are ruled out by their
    /// bounds and grids instead of each opening its tree to the band (a centimetre).
    pub(super) fn nearest_hinted(
        &self,
        point: &Point3<f64>,
        band: f64,
        links: &[usize],
        hint: &mut SurfaceHint,
    ) -> Option<Match> {
        let hinted_m = self.hinted_distance_m(point, links, *hint);
        *hint = NO_HINT;
        let start_limit = hinted_m
            .filter(|&d| d <= EDGE_REJECTION_M)
            .map_or(band, |d| band.min(crate::geometry::just_beyond(d)));
        let mut best: Option<Match> = None;
        for &link in links {
            let body_link = &self.body.links()[link];
            let Some(surface) = &body_link.surface else {
                continue;
            };
            let limit = best.map_or(start_limit, |b| b.distance);
            if !self.within_reach(point, link, limit) {
                continue;
            }
            let local = self.inverse[link] * point;
            if let Some(grid) = &body_link.grid {
                let reliable = grid.reliable_m();
                if !self.exact {
                    match grid.distance_and_gradient(&local) {
                        Some((signed, gradient)) if signed.abs() < reliable => {
                            let distance = signed.abs();
                            if let (true, Some(normal)) =
                                (distance < limit, gradient.try_normalize(1e-9))
                            {
                                best = Some(Match {
                                    point: *point,
                                    surface: self.poses[link] * (local - normal * signed),
                                    normal: self.poses[link].rotation * normal,
                                    distance,
                                    weight: (distance / band * std::f64::consts::FRAC_PI_2).cos(),
                                    link,
                                });
                            }
                            continue;
                        }
                        // Beyond what the grid answers: farther than the band, or the exact
                        // query below for a band wider than the grid.
                        _ if limit <= reliable => continue,
                        _ => {}
                    }
                } else if limit <= reliable {
                    // A link the grid puts farther than the limit, without blur, is ruled out
                    // without the exact query (see `DistanceGrid::distance_lower_bound_m`;
                    // outside the grid it is farther than the margin).
                    if grid
                        .distance_lower_bound_m(&local)
                        .is_none_or(|lower| lower > limit)
                    {
                        continue;
                    }
                }
            }
            let (lower, upper) = surface.bounds();
            let inside_box =
                (0..3).all(|a| local[a] >= lower[a] - band && local[a] <= upper[a] + band);
            if !inside_box {
                continue;
            }
            let Some(closest) = surface.closest_point_within(&local, limit) else {
                continue;
            };
            let distance = closest.signed_distance.abs();
            // A point whose nearest feature is an edge, more than a millimetre away, lies beyond
            // the link (floor or a fixture meeting it) and would drag the edge towards it.
            if !closest.on_face && distance > EDGE_REJECTION_M {
                continue;
            }
            if best.is_none_or(|b| distance < b.distance) {
                best = Some(Match {
                    point: *point,
                    surface: self.poses[link] * closest.point,
                    normal: self.poses[link].rotation * closest.normal,
                    distance,
                    weight: (distance / band * std::f64::consts::FRAC_PI_2).cos(),
                    link,
                });
                *hint = SurfaceHint {
                    link: link as u32,
                    triangle: closest.triangle,
                };
            }
        }
        best
    }

    /// The distance from `point` to the triangle `hint` names, when it is an exact query's and
    /// its link is among `links`.
    fn hinted_distance_m(
        &self,
        point: &Point3<f64>,
        links: &[usize],
        hint: SurfaceHint,
    ) -> Option<f64> {
        let link = hint.link as usize;
        if !self.exact || hint == NO_HINT || !links.contains(&link) {
            return None;
        }
        let surface = self.body.links().get(link)?.surface.as_ref()?;
        surface.distance_to_triangle_m(&(self.inverse[link] * point), hint.triangle)
    }

    /// What `point` says about the links placed here: +1 when it lies on the surface of one of
    /// `links` (within `band` outside, within `inside_m` inside), -2 when it lies deeper inside
    /// one (a scanner cannot see into a solid: a link crossing the floor or a neighbour is
    /// wrong there), 0 otherwise.
    pub(super) fn evidence(
        &self,
        point: &Point3<f64>,
        band: f64,
        inside_m: f64,
        links: &[usize],
    ) -> i64 {
        self.evidence_seen_from(point, band, inside_m, links, None)
    }

    /// [`Self::evidence`] of a point seen from the side `up` points to (a unit vector in the
    /// world; the floor's points, which a scanner sees from above): it lies on a link's surface
    /// only where that surface faces that side. A link lying on the floor touches it with its
    /// underside, which faces the floor: the floor's points there are not its own, though they
    /// lie within the band of it, and a scanner above cannot see that underside at all. `None`
    /// accepts every side, as [`Self::evidence`] does.
    pub(super) fn evidence_seen_from(
        &self,
        point: &Point3<f64>,
        band: f64,
        inside_m: f64,
        links: &[usize],
        up: Option<&Vector3<f64>>,
    ) -> i64 {
        let mut buried = false;
        for &link in links {
            let body_link = &self.body.links()[link];
            let Some(surface) = &body_link.surface else {
                continue;
            };
            // Nothing beyond the band outside the bounding sphere is near or inside the link.
            if !self.within_reach(point, link, band) {
                continue;
            }
            let local = self.inverse[link] * point;
            let up_local = up.map(|up| self.inverse[link].rotation * up);
            let faces = |outward: &Vector3<f64>| up_local.is_none_or(|up| outward.dot(&up) > 0.0);
            if let Some(grid) = body_link
                .grid
                .as_ref()
                .filter(|g| band.max(inside_m) <= g.reliable_m())
            {
                match grid.signed_distance_m(&local) {
                    Some(distance) if distance > band => {}
                    Some(distance) if distance >= -inside_m => {
                        // The interpolant's gradient points outward, away from the surface.
                        let outward = || grid.distance_and_gradient(&local).map(|(_, g)| g);
                        if up_local.is_none() || outward().is_some_and(|g| faces(&g)) {
                            return 1;
                        }
                    }
                    Some(_) => buried = true,
                    None => {}
                }
                continue;
            }
            let (lower, upper) = surface.bounds();
            if !(0..3).all(|a| local[a] >= lower[a] - band && local[a] <= upper[a] + band) {
                continue;
            }
            match surface.closest_point_within(&local, band) {
                Some(closest) if closest.signed_distance >= -inside_m => {
                    if faces(&closest.normal) {
                        return 1;
                    }
                }
                Some(_) => buried = true,
                None => buried |= deep_inside(surface, &local, inside_m),
            }
        }
        if buried { -2 } else { 0 }
    }

    /// [`Self::evidence`] graded by distance: `1 - (d / r)^2` for a point `d` from the nearest
    /// surface of `links` (within `band` outside, `inside_m` inside; `r` the larger of the
    /// two), -2 for a point buried deeper in one, 0 otherwise. A count within the band cannot
    /// tell a wrist on its scan from one a few millimetres off that keeps most of its points
    /// within the band (the ABB IRB 1600's joint 5 in ray-cast scans: 57 points against 52-54,
    /// at 0.4 mm and 1.6 mm rms); the grade can. The distance grid blurs a millimetre, so in
    /// a narrow band the distances come from the meshes ([`Distances::Exact`]); for a band of a
    /// centimetre or more, where the blur is a tenth of it, the grids answer in tens of
    /// nanoseconds instead of a tree's descent ([`Distances::Grids`], where they reach).
    pub(super) fn closeness(
        &self,
        point: &Point3<f64>,
        band: f64,
        inside_m: f64,
        links: &[usize],
        distances: Distances,
    ) -> f64 {
        let mut best: Option<f64> = None;
        let mut buried = false;
        let reach = band.max(inside_m);
        for &link in links {
            let body_link = &self.body.links()[link];
            let Some(surface) = &body_link.surface else {
                continue;
            };
            if !self.within_reach(point, link, reach) {
                continue;
            }
            let local = self.inverse[link] * point;
            let grid = body_link
                .grid
                .as_ref()
                .filter(|g| distances == Distances::Grids && reach <= g.reliable_m());
            let signed = if let Some(grid) = grid {
                // Outside the grid: farther than its margin, and outside the solid.
                let Some(signed) = grid.signed_distance_m(&local) else {
                    continue;
                };
                signed
            } else {
                let (lower, upper) = surface.bounds();
                if !(0..3).all(|a| local[a] >= lower[a] - reach && local[a] <= upper[a] + reach) {
                    continue;
                }
                match surface.closest_point_within(&local, reach) {
                    Some(closest) => closest.signed_distance,
                    None => {
                        buried |= deep_inside(surface, &local, inside_m);
                        continue;
                    }
                }
            };
            if (-inside_m..=band).contains(&signed) {
                let off = signed.abs() / reach;
                let grade = 1.0 - off * off;
                best = Some(best.map_or(grade, |b: f64| b.max(grade)));
            } else if signed < -inside_m {
                buried = true;
            }
        }
        match best {
            Some(grade) => grade,
            None if buried => -2.0,
            None => 0.0,
        }
    }

    /// [`Self::evidence`] of a point another link's surface is `claimed_m` from (infinite when
    /// none is near): such a point counts for `links` only where they come nearer to it, and
    /// never against them (links meet at their joints).
    pub(super) fn evidence_nearer(
        &self,
        point: &Point3<f64>,
        band: f64,
        inside_m: f64,
        claimed_m: f64,
        links: &[usize],
    ) -> i64 {
        if claimed_m.is_finite() {
            self.evidence(point, band.min(claimed_m), inside_m.min(claimed_m), links)
                .max(0)
        } else {
            self.evidence(point, band, inside_m, links)
        }
    }

    /// Whether `point` lies within `band` of the surface of one of `links`.
    pub(super) fn supports(&self, point: &Point3<f64>, band: f64, links: &[usize]) -> bool {
        links
            .iter()
            .any(|&link| self.link_distance(point, band, band, link).is_some())
    }

    /// The distance of `point` from the nearest surface of `links`, when within `band`.
    pub(super) fn distance_within(
        &self,
        point: &Point3<f64>,
        band: f64,
        links: &[usize],
    ) -> Option<f64> {
        links.iter().fold(None, |nearest, &link| {
            self.link_distance(point, band, nearest.unwrap_or(band), link)
                .or(nearest)
        })
    }

    /// The distance of `point` from `link`'s surface when within `limit` (no more than `band`):
    /// from its distance grid when that answers as far as `band`, else exactly.
    fn link_distance(
        &self,
        point: &Point3<f64>,
        band: f64,
        limit: f64,
        link: usize,
    ) -> Option<f64> {
        let body_link = &self.body.links()[link];
        let surface = body_link.surface.as_ref()?;
        if !self.within_reach(point, link, limit) {
            return None;
        }
        let local = self.inverse[link] * point;
        let distance =
            if let Some(grid) = body_link.grid.as_ref().filter(|g| band <= g.reliable_m()) {
                grid.signed_distance_m(&local)?.abs()
            } else {
                let (lower, upper) = surface.bounds();
                if !(0..3).all(|a| local[a] >= lower[a] - limit && local[a] <= upper[a] + limit) {
                    return None;
                }
                surface
                    .closest_point_within(&local, limit)?
                    .signed_distance
                    .abs()
            };
        (distance <= limit).then_some(distance)
    }
}

/// Whether `local` (mesh frame), farther than any band from `surface`, lies more than
/// `inside_m` inside it: only a watertight mesh has an inside, and only a point within its
/// bounds can be in it.
fn deep_inside(surface: &Mesh, local: &Point3<f64>, inside_m: f64) -> bool {
    let (lower, upper) = surface.bounds();
    (0..3).all(|a| local[a] >= lower[a] && local[a] <= upper[a])
        && surface.is_watertight()
        && surface.closest_point(local).signed_distance < -inside_m
}

const EDGE_REJECTION_M: f64 = 1e-3;

pub(super) fn correspond(
    placed: &Placed,
    keypoints: &[Point3<f64>],
    band: f64,
    links: &[usize],
    parallel: bool,
) -> Vec<Match> {
    correspond_hinted(placed, keypoints, band, links, parallel, &mut [])
}

/// [`correspond`], with each keypoint's triangle remembered in `hints` (one per keypoint, or
/// empty for none) between the steps of a refinement: see [`Placed::nearest_hinted`].
pub(super) fn correspond_hinted(
    placed: &Placed,
    keypoints: &[Point3<f64>],
    band: f64,
    links: &[usize],
    parallel: bool,
    hints: &mut [SurfaceHint],
) -> Vec<Match> {
    let one = |p: &Point3<f64>, hint: &mut SurfaceHint| {
        placed
            .nearest_hinted(p, band, links, hint)
            .filter(|m| m.weight > 0.0)
    };
    let unhinted = |p: &Point3<f64>| placed.nearest(p, band, links).filter(|m| m.weight > 0.0);
    match (parallel, hints.len() == keypoints.len()) {
        (true, true) => keypoints
            .par_iter()
            .zip(hints.par_iter_mut())
            .filter_map(|(p, hint)| one(p, hint))
            .collect(),
        (true, false) => keypoints.par_iter().filter_map(unhinted).collect(),
        (false, true) => keypoints
            .iter()
            .zip(hints.iter_mut())
            .filter_map(|(p, hint)| one(p, hint))
            .collect(),
        (false, false) => keypoints.iter().filter_map(unhinted).collect(),
    }
}

/// Largest distance of the surfaces of `links` from `origin`, m.
pub(super) fn reach_m(placed: &Placed, links: &[usize], origin: &Point3<f64>) -> f64 {
    links
        .iter()
        .filter_map(|&link| {
            let surface = placed.body.links()[link].surface.as_ref()?;
            let centre = placed.poses[link] * surface.centroid();
            Some((centre - origin).norm() + surface.radius_m())
        })
        .fold(0.0, f64::max)
}

/// The points of `sample` that some surface of `links`, as `placed`, reaches within `band` when
/// turned by any angle about the axis through `origin` along `direction`: those within `band`
/// of the ring each link's bounding sphere sweeps. Every other point is beyond the band of
/// those links' spheres at every turn ([`Placed::within_reach`]) and counts 0 for them, so a
/// score of turns over these points is the score over `sample`, to the point.
pub(super) fn within_swept_reach(
    placed: &Placed,
    sample: &[Point3<f64>],
    links: &[usize],
    origin: &Point3<f64>,
    direction: &Unit<Vector3<f64>>,
    band: f64,
) -> Vec<Point3<f64>> {
    // Each sphere's centre as (height along the axis, distance from it), with its reach.
    let rings: Vec<(f64, f64, f64)> = links
        .iter()
        .filter_map(|&link| {
            let (centre, radius) = placed.spheres[link]?;
            let (height, distance) = axial_and_radial(&(centre - origin), direction);
            // A nanometre over: the turned states' spheres are placed by their own rounding.
            Some((height, distance, radius + band + 1e-9))
        })
        .collect();
    sample
        .iter()
        .filter(|p| {
            let (height, distance) = axial_and_radial(&(*p - origin), direction);
            rings.iter().any(|&(ring_height, ring_distance, reach)| {
                let (dh, dr) = (height - ring_height, distance - ring_distance);
                dh * dh + dr * dr <= reach * reach
            })
        })
        .copied()
        .collect()
}

/// `offset`'s component along `direction` and its distance from the line along it.
fn axial_and_radial(offset: &Vector3<f64>, direction: &Unit<Vector3<f64>>) -> (f64, f64) {
    let along = offset.dot(direction);
    (along, (offset - direction.as_ref() * along).norm())
}

/// How well `links` explain `sample`: points within `band` of their surfaces count +1, points
/// buried deeper than `band` inside one count -2 (see [`Placed::evidence`]).
pub(super) fn coverage(
    body: &ArticulatedBody,
    sample: &[Point3<f64>],
    world_from_root: &Isometry3<f64>,
    q: &[f64],
    links: &[usize],
    band: f64,
    parallel: bool,
) -> i64 {
    let placed = Placed::new(body, world_from_root, q);
    coverage_beside_floor(&placed, sample, None, links, band, parallel)
}

/// The floor in a sample of scan points: which of them lie on it (by index into the sample;
/// unmarked beyond its length), and its unit normal pointing up, to the side the scanner and
/// the robot are on.
#[derive(Clone, Copy)]
pub(super) struct FloorMarks<'a> {
    pub(super) on_floor: &'a [bool],
    pub(super) up: Vector3<f64>,
}

/// [`coverage`] of the robot as `placed`, where the points `floor` marks never count for the
/// base (the links no joint moves: the root link, and the links fixed to it, as a URDF's
/// base_link fixed to a `world` link without geometry), only against it. A base stands on the
/// floor and hides the floor under it; set down on the floor beside its place, its underside
/// explains the floor there as well as it explains its own points: the ABB IRB 1600's base set
/// down 0.33 m from its place, turned, covered 87 floor keypoints of a beam's 3000 and 27
/// others, against 97 others (and 9 of the floor) where it stands, and the beam kept the wrong
/// place (`robot-scans` seed 91 scene 0 at 500 mm, docs/articulated-trials.md).
///
/// The other links count the floor's points only where their surface faces up
/// ([`Placed::evidence_seen_from`]): the top of a wrist held low, not the underside of an arm
/// lying on the floor. Counted on any side, an arm lying on the floor explained more floor
/// points than the robot's own: the CAD UR10 in a ray-cast scan that is mostly floor (2 658 of
/// the beam's 2 802 keypoints) ranked only states lying on their side, 58-83 floor keypoints
/// counting for each, more than its whole score. Counted by no link, an own-scan UR10 trial at
/// 500 mm lost its wrist.
pub(super) fn coverage_beside_floor(
    placed: &Placed,
    sample: &[Point3<f64>],
    floor: Option<FloorMarks>,
    links: &[usize],
    band: f64,
    parallel: bool,
) -> i64 {
    let (base, above_base): (Vec<usize>, Vec<usize>) = links
        .iter()
        .partition(|&&l| placed.body.movers(l).is_empty());
    let one = |(index, p): (usize, &Point3<f64>)| match floor {
        Some(FloorMarks { on_floor, up }) if on_floor.get(index).copied().unwrap_or(false) => {
            match placed.evidence_seen_from(p, band, band, &above_base, Some(&up)) {
                0 if !base.is_empty() => placed.evidence(p, band, band, &base).min(0),
                evidence => evidence,
            }
        }
        _ => placed.evidence(p, band, band, links),
    };
    if parallel {
        sample.par_iter().enumerate().map(one).sum()
    } else {
        sample.iter().enumerate().map(one).sum()
    }
}

pub(super) fn placed_radius(placed: &Placed) -> f64 {
    let root = placed.poses[placed.body.root()] * Point3::origin();
    reach_m(
        placed,
        &(0..placed.body.links().len()).collect::<Vec<_>>(),
        &root,
    )
    .max(0.01)
}
