//! `trigger_latency`: Joint positions read a little after the touch: each joint behind by its velocity times
//! the latency.

use super::EffectModel;
use crate::diagnosis::model::{Extras, Problem};

pub(super) struct TriggerLatency;

impl EffectModel for TriggerLatency {
    fn name(&self) -> &'static str {
        "trigger_latency"
    }

    fn needs_joints(&self) -> bool {
        true
    }

    fn parameter_names(&self, _dof: usize) -> Vec<String> {
        vec!["latency_s".to_owned()]
    }

    fn separating_touches(&self) -> &'static str {
        "for latency, touches at different approach speeds"
    }

    fn bound(&self) -> f64 {
        0.5
    }

    fn active_parameters(&self, _problem: &Problem) -> Vec<usize> {
        vec![0]
    }

    fn unavailable(&self, problem: &Problem) -> Option<String> {
        let has_velocities = problem
            .touches
            .iter()
            .all(|t| t.qd.as_ref().is_some_and(|qd| qd.iter().any(|v| *v != 0.0)));
        (!has_velocities).then(|| "needs joint velocities at the touches".to_owned())
    }

    fn apply(&self, extras: &mut Extras, _index: usize, value: f64) {
        extras.latency_s = value;
    }
}
