//! How far a local run (no exploration) reaches: its first band and the scan points it can
//! match.

use nalgebra::{Isometry3, Point3};

use super::PcaOptions;
use crate::geometry::Mesh;

/// The first band of a local run (no exploration): delta0, but at most the part's radius (and
/// at least the last band). The peers' coarse-to-fine stages start at 0.3 m whatever the bound
/// (crates/cad-scans/peers); measured on the CAD scans (`replay` bench, two corpora of 200,
/// docs/cad-scan-trials.md): 72 -> 75 and 75 -> 80 successes, the 500 and 1000 mm medians
/// halved or better; a cap of 0.75 or 1.5 radii gave 73 and 72 on the first corpus.
pub(super) fn local_first_band(mesh: &Mesh, delta0_m: f64, options: &PcaOptions) -> f64 {
    delta0_m.min(mesh.radius_m().max(options.delta_min_m))
}

/// The points of `cloud` a local run from `start` can match: a run matches only keypoints within
/// its band of the part's box, and the box's centre moves by about delta0 on the way to the truth
/// (the user's bound). Points farther from the box's centre at the start than the schedule's
/// filter reaches from a centre moved by twice delta0 (1.25 (h + sqrt(3) delta0) + 2 delta0, h
/// the box's half diagonal) are left out before the voxel grid is built: binning the whole cell
/// was a fifth of a 50 mm local alignment on the CAD scans. A run whose part has wandered
/// farther than twice its bound has failed whatever it still sees.
pub(super) fn within_local_reach(
    mesh: &Mesh,
    cloud: &[Point3<f64>],
    start: &Isometry3<f64>,
    delta0_m: f64,
) -> Vec<Point3<f64>> {
    let (lower, upper) = mesh.bounds();
    let centre = start * Point3::from((lower.coords + upper.coords) / 2.0);
    let half_diagonal_m = ((upper - lower) / 2.0).norm();
    // The schedule's filter: half diagonal grown by delta0, and a quarter of it as margin.
    let reach_m = 1.25 * (half_diagonal_m + 3f64.sqrt() * delta0_m) + 2.0 * delta0_m;
    let reach_squared = reach_m * reach_m;
    cloud
        .iter()
        .filter(|p| (*p - centre).norm_squared() <= reach_squared)
        .copied()
        .collect()
}
