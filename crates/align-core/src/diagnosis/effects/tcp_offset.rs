//! `tcp_offset`: A TCP shifted from the declared one, in the flange frame.

use super::EffectModel;
use crate::diagnosis::model::{Extras, Problem};

pub(super) struct TcpOffset;

impl EffectModel for TcpOffset {
    fn name(&self) -> &'static str {
        "tcp_offset"
    }

    fn needs_joints(&self) -> bool {
        false
    }

    fn parameter_names(&self, _dof: usize) -> Vec<String> {
        ["dx_m", "dy_m", "dz_m"].map(str::to_owned).to_vec()
    }

    fn separating_touches(&self) -> &'static str {
        "for the ball radius and the TCP, each face touched head-on and tilted both ways"
    }

    fn bound(&self) -> f64 {
        0.02
    }

    fn active_parameters(&self, _problem: &Problem) -> Vec<usize> {
        vec![0, 1, 2]
    }

    fn apply(&self, extras: &mut Extras, index: usize, value: f64) {
        extras.tcp_shift_m[index] = value;
    }
}
