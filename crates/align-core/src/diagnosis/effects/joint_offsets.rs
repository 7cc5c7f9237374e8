//! `joint_offsets`: A constant offset of each joint's reading (calibration).

use super::EffectModel;
use crate::diagnosis::model::{Extras, Problem};

pub(super) struct JointOffsets;

impl EffectModel for JointOffsets {
    fn name(&self) -> &'static str {
        "joint_offsets"
    }

    fn needs_joints(&self) -> bool {
        true
    }

    fn parameter_names(&self, dof: usize) -> Vec<String> {
        (1..=dof).map(|j| format!("joint_{j}_rad")).collect()
    }

    fn separating_touches(&self) -> &'static str {
        "for joint offsets, touches in different arm configurations"
    }

    fn bound(&self) -> f64 {
        0.05
    }

    fn active_parameters(&self, problem: &Problem) -> Vec<usize> {
        (0..problem.dof()).collect()
    }

    fn apply(&self, extras: &mut Extras, index: usize, value: f64) {
        extras.joint_offsets_rad[index] = value;
    }
}
