//! `part_scale`: A part larger or smaller than its model, about the part origin.

use super::EffectModel;
use crate::diagnosis::model::{Extras, Problem};

pub(super) struct PartScale;

impl EffectModel for PartScale {
    fn name(&self) -> &'static str {
        "part_scale"
    }

    fn needs_joints(&self) -> bool {
        false
    }

    fn parameter_names(&self, _dof: usize) -> Vec<String> {
        vec!["scale_minus_one".to_owned()]
    }

    fn separating_touches(&self) -> &'static str {
        "for the part's scale, faces at different distances from the part origin"
    }

    fn bound(&self) -> f64 {
        0.01
    }

    fn active_parameters(&self, _problem: &Problem) -> Vec<usize> {
        vec![0]
    }

    fn apply(&self, extras: &mut Extras, _index: usize, value: f64) {
        extras.scale_minus_one = value;
    }
}
