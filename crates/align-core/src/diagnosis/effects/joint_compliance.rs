//! `joint_compliance`: joints that lean under gravity, each by its compliance times the gravity
//! torque on it at the touch.

use super::EffectModel;
use crate::diagnosis::model::{Extras, Problem};

pub(super) struct JointCompliance;

impl EffectModel for JointCompliance {
    fn name(&self) -> &'static str {
        "joint_compliance"
    }

    fn needs_joints(&self) -> bool {
        true
    }

    fn parameter_names(&self, dof: usize) -> Vec<String> {
        (1..=dof).map(|j| format!("joint_{j}_rad_per_nm")).collect()
    }

    fn separating_touches(&self) -> &'static str {
        "for joint compliance, touches with the arm folded and stretched (different gravity loads)"
    }

    fn bound(&self) -> f64 {
        5e-4
    }

    /// The joints some touch loads: a joint no gravity torque acts on cannot lean.
    fn active_parameters(&self, problem: &Problem) -> Vec<usize> {
        (0..problem.dof())
            .filter(|&j| {
                problem
                    .gravity_torques_nm
                    .iter()
                    .any(|torques| torques.get(j).is_some_and(|t| t.abs() > 1e-9))
            })
            .collect()
    }

    fn unavailable(&self, problem: &Problem) -> Option<String> {
        self.active_parameters(problem).is_empty().then(|| {
            "no joint carries a gravity torque: the URDF has no inertials and the tool no mass"
                .to_owned()
        })
    }

    fn implausible(&self, name: &str, value: f64, standard_error: f64) -> Option<String> {
        (value < 0.0).then(|| {
            let se = standard_error;
            format!(
                "{name} = {value:.3e} +- {se:.1e} is negative: a joint does not lean against gravity"
            )
        })
    }

    fn apply(&self, extras: &mut Extras, index: usize, value: f64) {
        extras.compliance_rad_per_nm[index] = value;
    }
}
