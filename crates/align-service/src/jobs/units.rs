//! Unit sanity checks shared by the jobs: a part or a tool whose size looks like a unit mistake
//! gets a warning in the report's notes, and where the numbers make the alignment meaningless
//! the job refuses with the same hint instead of returning a wrong answer.

use align_core::geometry::{Mesh, human_length, implausible_size_warning};
use align_core::tool::Tool;
use nalgebra::Point3;

use crate::BadInput;

/// A flange-to-TCP offset longer than this is not a cobot tool (probes and grippers are tens of
/// centimetres at most): more likely an offset in mm given as m.
const LONGEST_PLAUSIBLE_TCP_OFFSET_M: f64 = 1.0;

/// A part this many times larger or smaller than what was measured of it (the cloud's or the
/// touches' extent) cannot be aligned to it: a scan covering a thousandth of a part's size sees
/// a patch smaller than its features, and a part a thousandth of the scan's size is smaller
/// than the scan's spacing. Both are what a mm/m mix-up produces (factor 1000).
const MEANINGLESS_SIZE_RATIO: f64 = 1000.0;

/// The unit warnings alone (the mesh's size, the tool's offset): what a refusal appends.
pub fn unit_hints(mesh: &Mesh, mesh_scale: f64, tool: Option<&Tool>) -> Vec<String> {
    implausible_size_warning("the mesh", mesh.size_m(), Some(mesh_scale))
        .into_iter()
        .chain(tool.and_then(tool_warning))
        .collect()
}

/// The warning for a tool whose TCP is implausibly far from the flange, `None` otherwise.
pub fn tool_warning(tool: &Tool) -> Option<String> {
    let offset_m = tool.flange_from_tcp.translation.vector.norm();
    (offset_m > LONGEST_PLAUSIBLE_TCP_OFFSET_M).then(|| {
        format!(
            "the TCP is {} from the flange (over 1 m, longer than a cobot's tool): is the tool offset in mm where m are expected?",
            human_length(offset_m)
        )
    })
}

/// The diagonal of the points' axis-aligned bounds, m (0 for fewer than two distinct points).
pub fn extent_m(points: &[Point3<f64>]) -> f64 {
    let Some(first) = points.first() else {
        return 0.0;
    };
    let (low, high) = points
        .iter()
        .fold((*first, *first), |(low, high), p| (low.inf(p), high.sup(p)));
    (high - low).norm()
}

/// Refuses when the part's size is implausible (a unit hint exists) and differs from the
/// measured extent by a factor of 1000 or more: the alignment would be meaningless. A plausible
/// part is never refused here, whatever the ratio (a small part in a large scan is fine).
pub fn refuse_unit_mismatch(
    mesh: &Mesh,
    mesh_scale: f64,
    measured_m: f64,
    // What was measured with its verb: "the cloud spans".
    measured: &str,
) -> Result<(), BadInput> {
    let part_m = mesh.size_m();
    let Some(hint) = implausible_size_warning("the mesh", part_m, Some(mesh_scale)) else {
        return Ok(());
    };
    let mismatched = part_m > MEANINGLESS_SIZE_RATIO * measured_m
        || part_m * MEANINGLESS_SIZE_RATIO < measured_m;
    if mismatched {
        return Err(BadInput(format!(
            "cannot align: {hint} ({measured} {})",
            human_length(measured_m)
        )));
    }
    Ok(())
}

/// `message` with the unit warnings appended, so that a refusal caused by a unit mistake says so.
pub fn with_hints(message: String, hints: &[String]) -> String {
    if hints.is_empty() {
        message
    } else {
        format!("{message} (note: {})", hints.join("; "))
    }
}
