//! The polishing run after the schedule. The schedule ends in a band of `delta_min` (1 cm), wide
//! enough for the floor and the fixtures beside a part to pull it: from the true pose itself, a
//! fifth of the 50 mm CAD scans ended more than 1 mm off (docs/cad-scan-trials.md). The polish
//! measures the residuals' spread there and steps in a band fitted to it, as an M-estimator with
//! Tukey's biweight and a robust scale would, so that a noisier scanner keeps a wider band.

use nalgebra::{Isometry3, Point3};

use super::PcaOptions;
use super::matching::{Lookup, Match, NO_HINT, correspond};
use super::schedule::{FIXED_POINT_FRACTION, MATCHES_PER_STEP, kept_at_stride, thinning_to};
use super::step::step_for;
use crate::geometry::Mesh;
use crate::registration::convergence::pose_distance;

/// The polish's band is this many robust standard deviations of the residuals (Tukey's
/// biweight constant), each the median absolute residual times `MAD_TO_SIGMA`.
pub(super) use crate::registration::robust_scale::{BIWEIGHT_C as BAND_PER_SIGMA, MAD_TO_SIGMA};

/// The band stays between these fractions of the schedule's last band: the lower keeps a
/// noise-free scan from a band of nothing, the upper keeps clutter that fills the residuals out.
const BAND_FRACTION_RANGE: (f64, f64) = (0.1, 0.5);

/// The polish starts where the schedule converged: a handful of point-to-plane steps settle it.
const MAX_ITERATIONS: usize = 30;

/// The same keypoint set must agree this many times in a row that the pose stands still.
const STILL_STEPS: usize = 2;

/// Fewer matches than this measure no spread.
const MIN_MATCHES: usize = 12;

#[derive(Debug, Clone, Copy)]
pub(super) struct Polished {
    pub pose: Isometry3<f64>,
    pub iterations: usize,
    pub converged: bool,
    pub band_m: f64,
    /// The last step's matches more than a robust standard deviation off their surface, on each
    /// side of it (see `hop`).
    pub off_the_surface: Sides,
}

/// Whether a polish from the schedule's last band `schedule_band_m` ended in `band_m`, its
/// widest: the residuals near the part spread so much that the band never narrowed.
pub(super) fn stayed_at_widest(band_m: f64, schedule_band_m: f64) -> bool {
    band_m >= BAND_FRACTION_RANGE.1 * schedule_band_m * (1.0 - 1e-9)
}

/// Steps from `pose` in a band of [`BAND_PER_SIGMA`] robust standard deviations of the
/// residuals, starting from half of `band_m`, the schedule's last band. `None` when fewer than
/// [`MIN_MATCHES`] keypoints match, too few to measure a spread.
pub(super) fn polish(
    mesh: &Mesh,
    keypoints: &[Point3<f64>],
    pose: &Isometry3<f64>,
    band_m: f64,
    options: &PcaOptions,
) -> Option<Polished> {
    polish_in_steps(
        mesh,
        keypoints,
        pose,
        band_m,
        options,
        (MAX_ITERATIONS, MATCHES_PER_STEP),
    )
}

/// [`polish`] in at most `max_steps` steps, matching about `matches_per_step` keypoints a step
/// at most (one in every n of them, see [`thinning_to`]).
pub(super) fn polish_in_steps(
    mesh: &Mesh,
    keypoints: &[Point3<f64>],
    pose: &Isometry3<f64>,
    band_m: f64,
    options: &PcaOptions,
    (max_steps, matches_per_step): (usize, f64),
) -> Option<Polished> {
    let (lower, upper) = mesh.bounds();
    // The polish moves the part by millimetres: the keypoints within the schedule's band of the
    // part's box are all it can reach, a few percent of a cell's scan.
    let part_from_base = pose.inverse();
    let near: Vec<Point3<f64>> = keypoints
        .iter()
        .filter(|p| {
            let in_part = part_from_base * *p;
            (0..3).all(|axis| {
                in_part[axis] >= lower[axis] - band_m && in_part[axis] <= upper[axis] + band_m
            })
        })
        .copied()
        .collect();
    let stride = thinning_to(near.len() as f64, matches_per_step);
    let near: Vec<Point3<f64>> = near
        .into_iter()
        .enumerate()
        .filter(|(i, _)| kept_at_stride(*i, stride))
        .map(|(_, p)| p)
        .collect();
    let exact = Lookup::exact(options.parallel);
    let (least, most) = BAND_FRACTION_RANGE;
    let radius_m = mesh.radius_m();
    let mut band = most * band_m;
    let mut polished = *pose;
    let mut still = 0;
    let mut iterations = 0;
    let mut hints = vec![NO_HINT; near.len()];
    let mut off_the_surface = Sides::default();
    while iterations < max_steps {
        let mut matches = correspond(
            mesh,
            &near,
            &polished,
            band,
            (&lower, &upper),
            exact,
            &mut hints,
        );
        if matches.len() < MIN_MATCHES {
            break;
        }
        // The scale is measured again on each step's matches and the band only shrinks: clutter
        // that widened the first spread falls out of the band, and the spread with it.
        band = band.min(robust_band(&mut matches).max(least * band_m));
        matches.retain(|m| m.distance <= band);
        if matches.len() < MIN_MATCHES {
            break;
        }
        for m in &mut matches {
            m.weight = (m.distance / band * std::f64::consts::FRAC_PI_2).cos();
        }
        off_the_surface = Sides::of(&matches, band / BAND_PER_SIGMA);
        iterations += 1;
        let Some(step) = step_for(&matches, options.step, radius_m) else {
            break;
        };
        let previous = polished;
        polished = step * polished;
        let moved_m = pose_distance(&previous, &polished, radius_m);
        // A fixed point (see `FIXED_POINT_FRACTION`). The band may still shrink with the
        // spread, but [`STILL_STEPS`] steps this still would end the polish anyway.
        if moved_m <= FIXED_POINT_FRACTION * options.tolerance_m {
            still = STILL_STEPS;
            break;
        }
        still = if moved_m <= options.tolerance_m {
            still + 1
        } else {
            0
        };
        if still >= STILL_STEPS {
            break;
        }
    }
    if iterations == 0 {
        return None;
    }
    Some(Polished {
        pose: polished,
        iterations,
        converged: still >= STILL_STEPS,
        band_m: band,
        off_the_surface,
    })
}

/// Matches counted by the side of their surface they lie on (by its normal).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(super) struct Sides {
    /// Behind the surface: inside the part's material.
    pub behind: usize,
    pub in_front: usize,
}

impl Sides {
    /// `matches` more than `sigma_m` off their surface, by side.
    fn of(matches: &[Match], sigma_m: f64) -> Self {
        let mut sides = Self::default();
        for m in matches {
            let signed_m = m.normal.dot(&(m.point - m.surface));
            if signed_m < -sigma_m {
                sides.behind += 1;
            } else if signed_m > sigma_m {
                sides.in_front += 1;
            }
        }
        sides
    }

    /// Clearly more behind than in front: by more than twice the square root of their total,
    /// the spread of a count's difference when each side were as likely (the scanner's noise).
    pub(super) fn mostly_behind(&self) -> bool {
        let (behind, in_front) = (self.behind as f64, self.in_front as f64);
        behind - in_front > 2.0 * (behind + in_front).sqrt()
    }
}

/// [`BAND_PER_SIGMA`] times the robust standard deviation ([`MAD_TO_SIGMA`] times the median) of the
/// matches' distances.
fn robust_band(matches: &mut [Match]) -> f64 {
    let middle = matches.len() / 2;
    let (_, median, _) =
        matches.select_nth_unstable_by(middle, |a, b| a.distance.total_cmp(&b.distance));
    BAND_PER_SIGMA * MAD_TO_SIGMA * median.distance
}
