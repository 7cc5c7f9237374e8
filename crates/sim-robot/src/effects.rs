//! What the simulated robot gets wrong that nobody declared: the difference between where its
//! joints really are and what its encoders report. The alignment side sees only the reported
//! angles. Set with the control socket's `effects` request; every field is optional and an
//! absent one is no effect:
//!
//! | field | effect | in the diagnosis library |
//! | --- | --- | --- |
//! | `joint_offsets: [rad]` | reported = true + offset (encoder zero off) | `joint_offsets` |
//! | `compliance_rad_per_nm: [..]` with `payload: {mass_kg, com_in_flange: [m]}` | gravity sag: the joints really sit c tau_g further than reported | `joint_compliance` |
//! | `cyclic_encoder: {joint, amplitude_rad, cycles_per_turn}` | reported += a sin(n q) on one joint (an eccentric encoder disc) | no: outside the library |
//! | `noise_sigma_rad` | Gaussian noise on every reported angle | the declared noise |
//! | `trigger_latency_s` | each sample carries the joints of that much later than its time stamp: a touch captured at its trigger time while moving shows the arm past the contact | `trigger_latency` |
//!
//! The noise is a deterministic function of the sample's time, so `truth_at` reproduces exactly
//! what was streamed.

use align_core::kinematics::{Chain, PointMass};
use align_core::rng::SplitMix64;
use nalgebra::Point3;

/// The effects in force: the `effects` request's fields, checked.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Effects(protocol::sim::Effects);

fn finite(values: &[f64]) -> bool {
    values.iter().all(|v| v.is_finite())
}

impl Effects {
    /// Checks an `effects` request for a robot with `dof` joints.
    pub(crate) fn checked(effects: protocol::sim::Effects, dof: usize) -> Result<Self, String> {
        let per_joint = [
            ("joint_offsets", &effects.joint_offsets, 0.1),
            (
                "compliance_rad_per_nm",
                &effects.compliance_rad_per_nm,
                1e-3,
            ),
        ];
        for (name, values, bound) in per_joint {
            if let Some(values) = values
                && (values.len() != dof
                    || !finite(values)
                    || values.iter().any(|v| v.abs() > bound))
            {
                return Err(format!(
                    "effects: '{name}' needs {dof} finite values within +-{bound}"
                ));
            }
        }
        if effects
            .compliance_rad_per_nm
            .as_ref()
            .is_some_and(|c| c.iter().any(|v| *v < 0.0))
        {
            return Err("effects: a compliance is never negative".to_owned());
        }
        if let Some(payload) = &effects.payload
            && !(payload.mass_kg.is_finite()
                && (0.0..=50.0).contains(&payload.mass_kg)
                && finite(&payload.com_in_flange))
        {
            return Err("effects: payload mass_kg must be within 0-50 and com finite".to_owned());
        }
        if let Some(cyclic) = &effects.cyclic_encoder
            && (cyclic.joint >= dof
                || !(cyclic.amplitude_rad.is_finite() && cyclic.amplitude_rad.abs() <= 0.01)
                || !(cyclic.cycles_per_turn.is_finite()
                    && (1.0..=1000.0).contains(&cyclic.cycles_per_turn)))
        {
            return Err(format!(
                "effects: cyclic_encoder needs joint < {dof}, |amplitude_rad| <= 0.01 and cycles_per_turn 1-1000"
            ));
        }
        if let Some(sigma) = effects.noise_sigma_rad
            && !(sigma.is_finite() && (0.0..=0.01).contains(&sigma))
        {
            return Err("effects: noise_sigma_rad must be within 0-0.01".to_owned());
        }
        if let Some(latency) = effects.trigger_latency_s
            && !(latency.is_finite() && (0.0..=0.5).contains(&latency))
        {
            return Err("effects: trigger_latency_s must be within 0-0.5 s".to_owned());
        }
        Ok(Self(effects))
    }

    /// How much later than its time stamp a sample's joints are, s.
    pub(crate) fn latency_s(&self) -> f64 {
        self.0.trigger_latency_s.unwrap_or(0.0)
    }

    /// What the encoders report for the true angles `q_true` at controller time `time_s`.
    pub(crate) fn reported(&self, chain: &Chain, q_true: &[f64], time_s: f64) -> Vec<f64> {
        let effects = &self.0;
        let mut q: Vec<f64> = q_true.to_vec();
        if let Some(offsets) = &effects.joint_offsets {
            for (value, offset) in q.iter_mut().zip(offsets) {
                *value += offset;
            }
        }
        if let Some(compliance) = &effects.compliance_rad_per_nm {
            let payload = effects.payload.as_ref().map(|p| PointMass {
                mass_kg: p.mass_kg,
                com_in_tip: Point3::from(p.com_in_flange),
            });
            // The joints sag by c tau beyond what the encoders (on the motor side) read.
            let torques = chain.gravity_torques_nm(q_true, payload.as_ref());
            for ((value, c), tau) in q.iter_mut().zip(compliance).zip(torques) {
                *value -= c * tau;
            }
        }
        if let Some(cyclic) = &effects.cyclic_encoder {
            q[cyclic.joint] +=
                cyclic.amplitude_rad * (cyclic.cycles_per_turn * q_true[cyclic.joint]).sin();
        }
        if let Some(sigma) = effects.noise_sigma_rad.filter(|s| *s > 0.0) {
            let mut rng = SplitMix64::new(time_s.to_bits());
            for value in &mut q {
                *value += sigma * rng.gaussian();
            }
        }
        q
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn from_request(request: serde_json::Value, dof: usize) -> Result<Effects, String> {
        let effects = serde_json::from_value(request).map_err(|error| error.to_string())?;
        Effects::checked(effects, dof)
    }

    #[test]
    fn requests_are_checked() {
        assert!(from_request(json!({}), 6).is_ok());
        let bad = [
            json!({"joint_offsets": vec![0.0; 5]}),
            json!({"joint_offsets": [0.2, 0, 0, 0, 0, 0]}),
            json!({"compliance_rad_per_nm": [-1e-5, 0, 0, 0, 0, 0]}),
            json!({"cyclic_encoder": {"joint": 6, "amplitude_rad": 0.001, "cycles_per_turn": 1}}),
            json!({"noise_sigma_rad": 0.5}),
            json!({"gravity": 1}),
        ];
        for request in bad {
            assert!(from_request(request.clone(), 6).is_err(), "{request}");
        }
    }

    #[test]
    fn noise_is_a_function_of_the_sample_time() {
        let chain = align_core::robots::ShippedRobot::Ur10
            .chain()
            .expect("model");
        let effects = from_request(json!({"noise_sigma_rad": 1e-4}), 6).expect("valid");
        let q = align_core::robots::ShippedRobot::Ur10.home();
        let a = effects.reported(&chain, &q, 1.25);
        assert_eq!(a, effects.reported(&chain, &q, 1.25));
        assert_ne!(a, effects.reported(&chain, &q, 1.26));
        assert!(a.iter().zip(&q).all(|(r, t)| (r - t).abs() < 1e-3));
    }
}
