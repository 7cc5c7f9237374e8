//! The effects the diagnosis knows: names, parameters, plausibility bounds and what a session
//! needs to reveal each.

/// A small parameterised change of the model that may explain a residual.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    ProbeRadius,
    TcpOffset,
    JointOffsets,
    JointCompliance,
    PartScale,
    TriggerLatency,
}

impl Effect {
    pub const ALL: [Effect; 6] = [
        Effect::ProbeRadius,
        Effect::TcpOffset,
        Effect::JointOffsets,
        Effect::JointCompliance,
        Effect::PartScale,
        Effect::TriggerLatency,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Effect::ProbeRadius => "probe_radius",
            Effect::TcpOffset => "tcp_offset",
            Effect::JointOffsets => "joint_offsets",
            Effect::JointCompliance => "joint_compliance",
            Effect::PartScale => "part_scale",
            Effect::TriggerLatency => "trigger_latency",
        }
    }

    /// True when the effect acts through the joints, so touches given as flange poses cannot
    /// show it.
    pub fn needs_joints(self) -> bool {
        matches!(
            self,
            Effect::JointOffsets | Effect::JointCompliance | Effect::TriggerLatency
        )
    }

    /// Every parameter the effect can have on a robot with `dof` joints.
    pub(super) fn parameter_names(self, dof: usize) -> Vec<String> {
        match self {
            Effect::ProbeRadius => vec!["delta_radius_m".to_owned()],
            Effect::TcpOffset => ["dx_m", "dy_m", "dz_m"].map(str::to_owned).to_vec(),
            Effect::JointOffsets => (1..=dof).map(|j| format!("joint_{j}_rad")).collect(),
            Effect::JointCompliance => (1..=dof).map(|j| format!("joint_{j}_rad_per_nm")).collect(),
            Effect::PartScale => vec!["scale_minus_one".to_owned()],
            Effect::TriggerLatency => vec!["latency_s".to_owned()],
        }
    }

    /// What a session needs for this effect to stand out from the others and from the pose.
    pub(super) fn separating_touches(self) -> &'static str {
        match self {
            Effect::ProbeRadius | Effect::TcpOffset => {
                "for the ball radius and the TCP, each face touched head-on and tilted both ways"
            }
            Effect::JointOffsets => "for joint offsets, touches in different arm configurations",
            Effect::JointCompliance => {
                "for joint compliance, touches with the arm folded and stretched (different gravity loads)"
            }
            Effect::PartScale => {
                "for the part's scale, faces at different distances from the part origin"
            }
            Effect::TriggerLatency => "for latency, touches at different approach speeds",
        }
    }

    /// The largest plausible size of each parameter (m, rad, rad/(N m), 1 or s).
    pub(super) fn bound(self) -> f64 {
        match self {
            Effect::ProbeRadius => 0.005,
            Effect::TcpOffset => 0.02,
            Effect::JointOffsets => 0.05,
            Effect::JointCompliance => 5e-4,
            Effect::PartScale => 0.01,
            Effect::TriggerLatency => 0.5,
        }
    }
}
