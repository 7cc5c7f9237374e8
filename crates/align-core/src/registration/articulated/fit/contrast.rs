//! Two states of the robot compared where they differ: the links one puts elsewhere than the
//! other, scored on the fine keypoints near them in a narrow band.
//!
//! Scoring each state on every link and counting the difference lets the large links decide:
//! two refinements of the same arm differ by a few tenths of a millimetre, which in a band of a
//! centimetre moves tens of coarse keypoints in or out, as many as a wrist's asymmetric feature
//! 20 mm off holds. On the ABB IRB 1600 at 500 mm the half-turn check kept the wrong wrist twin
//! that way in two of ten trials (link_4 21 mm off), where on the fine keypoints near the wrist
//! the true state explains about 500 more.

use nalgebra::{Isometry3, Point3};
use rayon::prelude::*;

use super::context::FitContext;
use super::placed::Placed;
use crate::geometry::Mesh;

/// A link is placed elsewhere by two states when some point of its surface moves more than this:
/// the trials' success threshold.
pub(super) const DISTINCT_M: f64 = 1e-3;

/// Vertices of a link compared for [`DISTINCT_M`]: enough to see a surface move by a
/// millimetre, few enough to cost nothing beside the fit.
pub(super) const SAMPLES_PER_LINK: usize = 400;

/// A state of the robot: the root's pose in the world and the joint values.
pub(super) type State<'s> = (&'s Isometry3<f64>, &'s [f64]);

/// A state held by value.
pub(super) type OwnedState = (Isometry3<f64>, Vec<f64>);

/// Whether `mesh` placed at `a` lies more than `beyond_m` from itself placed at `b`, one way or
/// the other, at some of at most [`SAMPLES_PER_LINK`] of its vertices: [`Mesh::deviation_m`]
/// sampled, against a bound.
///
/// A vertex lies on the surface, so the surface is never farther from where a move takes the
/// vertex than the move itself: a vertex moved no more than the bound is within it without a
/// query. Two states a refinement apart move most links by tenths of a millimetre, and the
/// closest-point queries of every vertex of every link were most of [`FitContext::twin`]'s
/// time (about 4 ms of a 100 mm fit of the UR10, on one core).
pub(super) fn placed_apart(
    mesh: &Mesh,
    a: &Isometry3<f64>,
    b: &Isometry3<f64>,
    beyond_m: f64,
) -> bool {
    let b_from_a = b.inverse() * a;
    let a_from_b = b_from_a.inverse();
    let count = mesh.vertices().count();
    let stride = count.div_ceil(SAMPLES_PER_LINK).max(1);
    let off = |moved: Point3<f64>, vertex: Point3<f64>| {
        (moved - vertex).norm() > beyond_m
            && mesh.closest_point(&moved).signed_distance.abs() > beyond_m
    };
    mesh.vertices()
        .step_by(stride)
        .any(|v| off(b_from_a * v, v) || off(a_from_b * v, v))
}

impl FitContext<'_> {
    /// Those of `among` with a surface that `a` and `b` place more than [`DISTINCT_M`] apart.
    pub(super) fn differing_links(&self, a: State, b: State, among: &[usize]) -> Vec<usize> {
        self.links_apart(a, b, among, DISTINCT_M)
    }

    /// Those of `links` with a surface that `a` and `b` place more than `beyond_m` apart
    /// somewhere ([`placed_apart`]).
    pub(super) fn links_apart(
        &self,
        a: State,
        b: State,
        links: &[usize],
        beyond_m: f64,
    ) -> Vec<usize> {
        let at_a = self.body.link_poses(a.0, a.1);
        let at_b = self.body.link_poses(b.0, b.1);
        links
            .iter()
            .copied()
            .filter(|&link| {
                self.body.links()[link]
                    .surface
                    .as_ref()
                    .is_some_and(|mesh| placed_apart(mesh, &at_a[link], &at_b[link], beyond_m))
            })
            .collect()
    }

    /// Whether `b` puts every vertex of every link within `within_m` of where `a` puts it: the
    /// same configuration, not only the same surfaces (a round link turned half a turn covers
    /// its own surface with every vertex moved).
    pub(super) fn vertices_within(&self, a: State, b: State, within_m: f64) -> bool {
        let at_a = self.body.link_poses(a.0, a.1);
        let at_b = self.body.link_poses(b.0, b.1);
        self.body
            .links()
            .iter()
            .zip(at_a.iter().zip(&at_b))
            .all(|(link, (pose_a, pose_b))| {
                let Some(mesh) = &link.surface else {
                    return true;
                };
                let b_from_a = pose_b.inverse() * pose_a;
                mesh.vertices()
                    .all(|v| (b_from_a * v - v).norm_squared() <= within_m * within_m)
            })
    }

    /// How many fine keypoints each state explains where the two differ, `(a's, b's)`; `None`
    /// when they place every link alike. The points are those near a link the two place apart
    /// (in either state) that no other link explains; each counts as [`Placed::evidence`] says
    /// (+1 on one of those links, within half a keypoint voxel; -2 buried deeper in one).
    pub(super) fn contrast(&self, a: State, b: State) -> Option<(i64, i64)> {
        let all: Vec<usize> = (0..self.body.links().len()).collect();
        self.contrast_among(a, b, &all)
    }

    /// [`Self::contrast`] on those of `among` the two states place apart: what a joint's move
    /// changed, without what the refinement after it changed elsewhere (a base settling into
    /// place as a wrist flips would otherwise carry the flip).
    pub(super) fn contrast_among(&self, a: State, b: State, among: &[usize]) -> Option<(i64, i64)> {
        let FitContext {
            body,
            scan,
            options,
            ..
        } = *self;
        let differing = self.differing_links(a, b, among);
        if differing.is_empty() {
            return None;
        }
        let shared: Vec<usize> = (0..body.links().len())
            .filter(|link| body.links()[*link].surface.is_some() && !differing.contains(link))
            .collect();
        let band = 0.5 * options.voxel_m;
        let placed_a = Placed::new(body, a.0, a.1);
        let placed_b = Placed::new(body, b.0, b.1);
        let one = |p: &Point3<f64>| -> (i64, i64) {
            let near = |placed: &Placed| {
                differing
                    .iter()
                    .any(|&link| placed.within_reach(p, link, band))
            };
            if !(near(&placed_a) || near(&placed_b)) {
                return (0, 0);
            }
            if placed_a.supports(p, band, &shared) || placed_b.supports(p, band, &shared) {
                return (0, 0);
            }
            (
                placed_a.evidence(p, band, band, &differing),
                placed_b.evidence(p, band, band, &differing),
            )
        };
        let add = |x: (i64, i64), y: (i64, i64)| (x.0 + y.0, x.1 + y.1);
        Some(if options.parallel {
            scan.fine.par_iter().map(one).reduce(|| (0, 0), add)
        } else {
            scan.fine.iter().map(one).fold((0, 0), add)
        })
    }
}
