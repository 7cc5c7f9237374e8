//! `probe_radius`: A ball larger or smaller than declared: every touch lands that much farther from the surface.

use super::EffectModel;
use crate::diagnosis::model::{Extras, Problem};

pub(super) struct ProbeRadius;

impl EffectModel for ProbeRadius {
    fn name(&self) -> &'static str {
        "probe_radius"
    }

    fn needs_joints(&self) -> bool {
        false
    }

    fn parameter_names(&self, _dof: usize) -> Vec<String> {
        vec!["delta_radius_m".to_owned()]
    }

    fn separating_touches(&self) -> &'static str {
        "for the ball radius and the TCP, each face touched head-on and tilted both ways"
    }

    fn bound(&self) -> f64 {
        0.005
    }

    fn active_parameters(&self, _problem: &Problem) -> Vec<usize> {
        vec![0]
    }

    fn apply(&self, extras: &mut Extras, _index: usize, value: f64) {
        extras.delta_radius_m = value;
    }
}
