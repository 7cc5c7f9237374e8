//! The effects the diagnosis knows, one file each: name, parameters, plausibility bound, what a
//! session needs to reveal it and how it enters the measurement model. Adding an effect takes a
//! file implementing [`EffectModel`] and its line in the `effects!` list below.

mod joint_compliance;
mod joint_offsets;
mod part_scale;
mod probe_radius;
mod tcp_offset;
mod trigger_latency;

use std::str::FromStr;

use super::model::{Extras, Problem};

/// Everything that sets one effect apart from the others.
pub(super) trait EffectModel: Sync {
    /// The effect's name in reports and on the command line.
    fn name(&self) -> &'static str;

    /// True when the effect acts through the joints, so touches given as flange poses cannot
    /// show it.
    fn needs_joints(&self) -> bool;

    /// Every parameter the effect can have on a robot with `dof` joints.
    fn parameter_names(&self, dof: usize) -> Vec<String>;

    /// What a session needs for this effect to stand out from the others and from the pose.
    fn separating_touches(&self) -> &'static str;

    /// The largest plausible size of each parameter (m, rad, rad/(N m), 1 or s).
    fn bound(&self) -> f64;

    /// Indices (into [`Self::parameter_names`]) of the parameters that could act on
    /// `problem`'s touches.
    fn active_parameters(&self, problem: &Problem) -> Vec<usize>;

    /// Why `problem`'s touches cannot show the effect at all (beyond needing joint values, which
    /// [`Self::needs_joints`] covers), if they cannot.
    fn unavailable(&self, _problem: &Problem) -> Option<String> {
        None
    }

    /// Why a fitted value no real cell has, within the plausibility bound, is implausible (a
    /// joint leaning against gravity), if it is; `name` and `standard_error` for the message.
    fn implausible(&self, _name: &str, _value: f64, _standard_error: f64) -> Option<String> {
        None
    }

    /// Sets parameter `index` to `value` in the model's `extras`: how the effect changes the
    /// predicted touches, and so its columns of the Jacobian.
    fn apply(&self, extras: &mut Extras, index: usize, value: f64);
}

/// The registry: one line per effect, `Variant => module::Model`, in the order of
/// [`Effect::ALL`] (which is also the enum's order for sorting).
macro_rules! effects {
    ($($variant:ident => $module:ident :: $model:ident,)*) => {
        /// A small parameterised change of the model that may explain a residual.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum Effect {
            $($variant,)*
        }

        impl Effect {
            pub const ALL: [Effect; [$(stringify!($variant)),*].len()] = [$(Effect::$variant,)*];

            /// What is specific to this effect.
            fn model(self) -> &'static dyn EffectModel {
                match self {
                    $(Effect::$variant => &$module::$model,)*
                }
            }
        }
    };
}

effects! {
    ProbeRadius => probe_radius::ProbeRadius,
    TcpOffset => tcp_offset::TcpOffset,
    JointOffsets => joint_offsets::JointOffsets,
    JointCompliance => joint_compliance::JointCompliance,
    PartScale => part_scale::PartScale,
    TriggerLatency => trigger_latency::TriggerLatency,
}

impl Effect {
    pub fn name(self) -> &'static str {
        self.model().name()
    }

    /// The effect named `name` (as [`Effect::name`] spells it), if any.
    pub fn from_name(name: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|effect| effect.name() == name)
    }

    /// True when the effect acts through the joints, so touches given as flange poses cannot
    /// show it.
    pub fn needs_joints(self) -> bool {
        self.model().needs_joints()
    }

    /// Every parameter the effect can have on a robot with `dof` joints.
    pub(super) fn parameter_names(self, dof: usize) -> Vec<String> {
        self.model().parameter_names(dof)
    }

    /// What a session needs for this effect to stand out from the others and from the pose.
    pub(super) fn separating_touches(self) -> &'static str {
        self.model().separating_touches()
    }

    /// The largest plausible size of each parameter (m, rad, rad/(N m), 1 or s).
    pub(super) fn bound(self) -> f64 {
        self.model().bound()
    }

    /// Indices of the parameters that could act on `problem`'s touches.
    pub(super) fn active_parameters(self, problem: &Problem) -> Vec<usize> {
        self.model().active_parameters(problem)
    }

    /// Why `problem`'s touches cannot show the effect at all, if they cannot.
    pub(super) fn unavailable(self, problem: &Problem) -> Option<String> {
        self.model().unavailable(problem)
    }

    /// Why a fitted value within the bound is still implausible, if it is.
    pub(super) fn implausible(self, name: &str, value: f64, standard_error: f64) -> Option<String> {
        self.model().implausible(name, value, standard_error)
    }

    /// Sets parameter `index` to `value` in the model's `extras`.
    pub(super) fn apply(self, extras: &mut Extras, index: usize, value: f64) {
        self.model().apply(extras, index, value);
    }
}

/// A name no effect has (see [`Effect::from_name`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown effect '{name}' (known: {known})")]
pub struct UnknownEffect {
    pub name: String,
    /// The known names, comma-separated.
    pub known: String,
}

impl FromStr for Effect {
    type Err = UnknownEffect;

    fn from_str(name: &str) -> Result<Self, Self::Err> {
        Effect::from_name(name).ok_or_else(|| UnknownEffect {
            name: name.to_owned(),
            known: Effect::ALL.map(Effect::name).join(", "),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::Effect;

    #[test]
    fn every_effect_is_found_by_its_name_and_no_other() {
        for effect in Effect::ALL {
            assert_eq!(Effect::from_name(effect.name()), Some(effect));
            assert_eq!(effect.name().parse::<Effect>(), Ok(effect));
        }
        assert_eq!(Effect::from_name("gravity"), None);
        let error = "gravity".parse::<Effect>().unwrap_err();
        assert!(
            error.to_string().contains("probe_radius, tcp_offset"),
            "{error}"
        );
    }
}
