//! A second look when a full alignment from a small delta ends without a fit.
//!
//! The exploration turns the start by the spread set's rotations within the delta's reach, and
//! the nearest of its 48 is 36 degrees off: from 50 mm a part of more than about 95 mm radius
//! gets no turn at all, and the alignment is the local stage's run and the hop (at 50 mm, 32-36
//! of each unseen set's 40 scans). On the unseen set B, scan 1 (a UR5 shoulder, 50 mm) the local
//! stage settled 16 degrees tilted and 45 mm off, where the polish's band stayed at its widest
//! (robust deviation over a millimetre; the truth fits at 0.34 mm rms), and it was reported
//! with no uniqueness tested. Every other 50 mm scan of the four sets ended its polish in a band
//! of 1.2-1.8 mm.
//!
//! Such an end is aligned again with the exploration turning the start by half the reach each
//! way about the part's three axes through its centre (six short runs), whose best end competes
//! with the local stage's as usual (docs/cad-scan-trials.md, thirty-eighth session).

use nalgebra::{Isometry3, Point3};

use super::polish::stayed_at_widest;
use super::schedule::ScheduleRun;
use super::{PcaError, PcaOptions, Uniqueness, locate};
use crate::geometry::Mesh;

/// What [`locate`] found: the run that ended at the pose, the keypoints, the starts tried and
/// the uniqueness.
pub(super) struct Located {
    pub(super) run: ScheduleRun,
    pub(super) keypoints: Vec<Point3<f64>>,
    pub(super) starts: usize,
    pub(super) uniqueness: Option<Uniqueness>,
}

/// [`locate`], and again with the small turns when a full alignment's exploration had no turn
/// to run and the polish ended in its widest band (see the module's notes).
pub(super) fn locate_looking_again(
    mesh: &Mesh,
    cloud: &[Point3<f64>],
    base_from_part_start: &Isometry3<f64>,
    delta0_m: f64,
    options: &PcaOptions,
) -> Result<Located, PcaError> {
    let located = locate(mesh, cloud, base_from_part_start, delta0_m, options)?;
    let unfit = options.look_again_when_unfit
        && !options.small_turns
        && options.starts > 0
        && options.polish
        && located.starts == 1
        && stayed_at_widest(located.run.delta, options.delta_min_m.min(delta0_m));
    if !unfit {
        return Ok(located);
    }
    let turning = PcaOptions {
        small_turns: true,
        ..options.clone()
    };
    locate(mesh, cloud, base_from_part_start, delta0_m, &turning)
}

/// The pose [`super::align_cloud`] finds, without the residuals it reports (every keypoint matched
/// once more, exactly: about a twentieth of a 100 mm robot fit, for figures its rigid stage
/// never reads). No second look here: the robot fit's rigid stage was not measured with it.
pub(crate) fn align_cloud_pose(
    mesh: &Mesh,
    cloud: &[Point3<f64>],
    base_from_part_start: &Isometry3<f64>,
    delta0_m: f64,
    options: &PcaOptions,
) -> Result<Isometry3<f64>, PcaError> {
    Ok(
        locate(mesh, cloud, base_from_part_start, delta0_m, options)?
            .run
            .pose,
    )
}
