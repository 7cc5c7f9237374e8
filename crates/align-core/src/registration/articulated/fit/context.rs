//! What every stage of one fit reads, carried in one place instead of long argument lists.

use nalgebra::{Point3, Vector3};

use super::RobotFitOptions;
use crate::registration::articulated::body::ArticulatedBody;

/// The scan's keypoints at two densities.
#[derive(Debug, Clone, Copy)]
pub(super) struct Keypoints<'a> {
    /// One per voxel three keypoint voxels wide: what the refinements before the last, the
    /// beam and the checks after it score on.
    pub(super) coarse: &'a [Point3<f64>],
    /// One per keypoint voxel: what a local joint search samples near the links it moves (a
    /// wrist holds a handful of coarse keypoints, no more than the outliers around it).
    pub(super) fine: &'a [Point3<f64>],
}

/// One fit's fixed inputs: the robot, the scan's keypoints, how far the start may be off and
/// the options. The stages (base candidates, joint searches, checks) are its methods.
#[derive(Clone, Copy)]
pub(super) struct FitContext<'a> {
    pub(super) body: &'a ArticulatedBody,
    pub(super) scan: Keypoints<'a>,
    /// How far any point of the robot may be from where the start puts it, m.
    pub(super) delta_m: f64,
    /// The start is not local (see [`super::searches_globally`]): the proximal links are
    /// detected and each joint is searched with its child over its whole window.
    pub(super) global: bool,
    /// The start is near (delta at most 0.18 of the robot's radius, see
    /// `NEAR_DELTA_PER_RADIUS`): the searches from it settle every joint in its basin, the
    /// beam search keeps fewer states, and a joint that spins its own links in place keeps its
    /// value.
    pub(super) near: bool,
    /// The floor under the scan (a point on it and its unit normal, up), found when the start
    /// is neither near nor global: its points never count for the base in the beam's scores
    /// (see [`super::placed::coverage_beside_floor`]).
    pub(super) floor: Option<(Point3<f64>, Vector3<f64>)>,
    /// The floor the base is stood on for more hypotheses (`FitContext::standing_candidates`):
    /// [`Self::floor`], and from a global start too.
    pub(super) stand_on: Option<(Point3<f64>, Vector3<f64>)>,
    pub(super) options: &'a RobotFitOptions,
}
