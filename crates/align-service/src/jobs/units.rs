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

/// A flange-to-TCP offset longer than this is a unit mistake, not a tool: it is several times
/// the reach of the largest cobot arm (UR20: 1.75 m), so touches computed with it are metres off
/// the part and any pose fitted to them is wrong.
const LONGEST_POSSIBLE_TCP_OFFSET_M: f64 = 10.0;

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

/// Refuses a tool whose TCP offset can only be a unit mistake, with the same words as the warning.
pub fn refuse_impossible_tool(tool: &Tool) -> Result<(), BadInput> {
    let offset_m = tool.flange_from_tcp.translation.vector.norm();
    match tool_warning(tool) {
        Some(warning) if offset_m > LONGEST_POSSIBLE_TCP_OFFSET_M => {
            Err(BadInput(format!("cannot align: {warning}")))
        }
        _ => Ok(()),
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Vector3};

    fn tool_with_offset(offset_m: f64) -> Tool {
        let flange_from_tcp = Isometry3::translation(0.0, 0.0, offset_m);
        Tool::new(flange_from_tcp, 0.003, 0.4).unwrap()
    }

    #[test]
    fn tcp_offsets_over_1_m_warn_and_over_10_m_are_refused() {
        assert_eq!(tool_warning(&tool_with_offset(0.15)), None);
        assert!(refuse_impossible_tool(&tool_with_offset(0.15)).is_ok());
        let long = tool_warning(&tool_with_offset(1.5)).unwrap();
        assert!(
            long.contains("1.50 m from the flange") && long.contains("in mm"),
            "{long}"
        );
        assert!(refuse_impossible_tool(&tool_with_offset(1.5)).is_ok());
        let BadInput(refusal) = refuse_impossible_tool(&tool_with_offset(150.0)).unwrap_err();
        assert!(refusal.contains("150.00 m from the flange"), "{refusal}");
    }

    #[test]
    fn a_part_1000_times_the_measured_extent_is_refused_only_when_implausible() {
        let km = Mesh::cuboid([300e3, 200e3, 100e3]).unwrap();
        let BadInput(refusal) =
            refuse_unit_mismatch(&km, 1000.0, 1.7, "the cloud spans").unwrap_err();
        assert!(
            refusal.contains("its scale is 0.001, not 1000")
                && refusal.contains("the cloud spans 1.70 m"),
            "{refusal}"
        );
        // A plausible 5 mm part in a 10 m scan is fine.
        let small = Mesh::cuboid([0.005, 0.005, 0.005]).unwrap();
        assert!(refuse_unit_mismatch(&small, 0.001, 10.0, "the cloud spans").is_ok());
        let points = [Point3::origin(), Point3::from(Vector3::new(3.0, 4.0, 0.0))];
        assert!((extent_m(&points) - 5.0).abs() < 1e-12);
        assert_eq!(extent_m(&[]), 0.0);
    }
}

/// The unit a person reads an effect parameter in, from the unit its name ends in: the factor
/// from the SI value, the unit's name and the decimals worth printing (m -> mm, rad -> mrad,
/// rad/(N m) -> urad/(N m), s -> ms, a scale's deviation from one -> %).
pub fn person_unit(parameter: &str) -> (f64, &'static str, usize) {
    if parameter.ends_with("_rad_per_nm") {
        (1e6, "urad/(N m)", 3)
    } else if parameter.ends_with("_rad") {
        (1e3, "mrad", 4)
    } else if parameter.ends_with("_m") {
        (1e3, "mm", 4)
    } else if parameter.ends_with("_s") {
        (1e3, "ms", 3)
    } else if parameter == "scale_minus_one" {
        (1e2, "%", 4)
    } else {
        (1.0, "", 9)
    }
}

/// `value` of `parameter` in the unit a person reads it in, e.g. `+0.4000 mm`.
pub fn in_person_units(parameter: &str, value: f64) -> String {
    let (factor, unit, decimals) = person_unit(parameter);
    format!("{:+.decimals$} {unit}", value * factor)
}

#[cfg(test)]
mod person_unit_tests {
    use super::in_person_units;

    #[test]
    fn effect_parameters_read_in_the_units_people_use() {
        assert_eq!(in_person_units("delta_radius_m", 0.0004), "+0.4000 mm");
        assert_eq!(in_person_units("joint_3_rad", -0.0015), "-1.5000 mrad");
        assert_eq!(
            in_person_units("joint_2_rad_per_nm", 2e-6),
            "+2.000 urad/(N m)"
        );
        assert_eq!(in_person_units("latency_s", 0.008), "+8.000 ms");
        assert_eq!(in_person_units("scale_minus_one", 0.0012), "+0.1200 %");
    }
}
