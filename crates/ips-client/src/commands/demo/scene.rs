//! The demo's cell as it physically is and as the session declares it: the step block at a
//! pose only the simulator knows, a nominal pose 42 mm / 6 degrees off, a probe with a 3 mm ball
//! 150 mm from the flange, and the effect the cell has that the session does not declare.

use std::path::Path;

use align_core::diagnosis::Effect;
use align_core::io::{TriangleSoup, write_stl_binary};
use align_core::pose::{isometry_from_xyz_rpy, xyz_rpy};
use align_core::robots::ShippedRobot;
use align_core::trials::parts::step_block;
use clap::ValueEnum;
use clap::builder::PossibleValue;
use nalgebra::{Isometry3, Vector3};
use protocol::Pose;
use protocol::session::{FORMAT, PartSection, RobotSection, SessionFile, ToolSection};
use protocol::sim::{CyclicEncoder, Effects, Payload, ProbeRequest};

use crate::BadInput;

/// An effect the simulated cell may have: every effect the diagnosis knows, no effect, or one
/// outside its library. The list follows `align_core::diagnosis::Effect::ALL`, so a new effect
/// there is a new `--effect` value here (and [`Scene::new`] will not compile until the
/// simulator is told how to show it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimulatedEffect {
    None,
    Modelled(Effect),
    /// An eccentric encoder disc on the shoulder: outside the diagnosis library.
    CyclicEncoder,
}

const EFFECT_COUNT: usize = Effect::ALL.len() + 2;

const SIMULATED_EFFECTS: [SimulatedEffect; EFFECT_COUNT] = {
    let mut all = [SimulatedEffect::None; EFFECT_COUNT];
    let mut index = 0;
    while index < Effect::ALL.len() {
        all[index + 1] = SimulatedEffect::Modelled(Effect::ALL[index]);
        index += 1;
    }
    all[EFFECT_COUNT - 1] = SimulatedEffect::CyclicEncoder;
    all
};

impl SimulatedEffect {
    pub fn name(self) -> &'static str {
        match self {
            SimulatedEffect::None => "none",
            SimulatedEffect::Modelled(effect) => effect.name(),
            SimulatedEffect::CyclicEncoder => "cyclic_encoder",
        }
    }
}

impl ValueEnum for SimulatedEffect {
    fn value_variants<'a>() -> &'a [Self] {
        &SIMULATED_EFFECTS
    }

    fn to_possible_value(&self) -> Option<PossibleValue> {
        Some(PossibleValue::new(self.name()))
    }
}

/// The cell the demo simulates and the session it declares.
#[derive(Debug)]
pub struct Scene {
    /// Where the part really is.
    pub base_from_part_truth: Isometry3<f64>,
    /// Where the session says it is.
    pub base_from_part_nominal: Isometry3<f64>,
    /// The session: robot, declared tool and part, no inspections yet.
    pub session: SessionFile,
    /// What sim-robot's encoders get wrong (its `effects` request); `None` for nothing.
    pub encoder_effects: Option<Effects>,
    /// The touches sim-robot is asked to plan and run.
    pub probe: ProbeRequest,
}

fn pose(pose: &Isometry3<f64>) -> Pose {
    let (xyz, rpy) = xyz_rpy(pose);
    Pose::new(xyz, rpy)
}

impl Scene {
    /// Writes the part's mesh and the robot's URDF into `folder` and sets the scene up.
    pub fn new(
        robot: ShippedRobot,
        effect: SimulatedEffect,
        noise: bool,
        folder: &Path,
    ) -> Result<Self, BadInput> {
        let part = step_block().map_err(BadInput::new)?;
        let soup = TriangleSoup {
            vertices: part.mesh.vertices().collect(),
            triangles: part.mesh.triangles().to_vec(),
        };
        let mesh_path = folder.join("part.stl");
        write_stl_binary(&mesh_path, &soup).map_err(BadInput::new)?;
        std::fs::write(folder.join("robot.urdf"), robot.urdf()).map_err(BadInput::new)?;
        // The iiwa's reach is shorter than the UR10's: its table stands closer.
        let (truth, nominal) = match robot {
            ShippedRobot::Iiwa14 => (
                isometry_from_xyz_rpy([0.5, -0.2, 0.02], [0.0, 0.0, 0.35]),
                isometry_from_xyz_rpy([0.53, -0.17, 0.02], [0.0, 0.0, 0.25]),
            ),
            _ => (
                isometry_from_xyz_rpy([0.62, -0.25, 0.02], [0.0, 0.0, 0.35]),
                isometry_from_xyz_rpy([0.65, -0.22, 0.02], [0.0, 0.0, 0.25]),
            ),
        };
        let tcp = isometry_from_xyz_rpy([0.0, 0.0, 0.15], [0.0; 3]);
        let tip_radius = 0.003;
        let session = SessionFile {
            format: FORMAT.to_owned(),
            robot: Some(RobotSection {
                urdf: "robot.urdf".to_owned(),
                base_link: robot.base_link().to_owned(),
                tip_link: robot.flange_link().to_owned(),
                package_dirs: Default::default(),
                kinematics: None,
                joint_offsets: None,
                joint_compliance: None,
                trigger_latency_s: None,
            }),
            tool: ToolSection {
                tcp: pose(&tcp),
                tip_radius,
                mass: 0.4,
            },
            part: PartSection {
                mesh: "part.stl".to_owned(),
                mesh_scale: 1.0,
                nominal_pose: pose(&nominal),
                faces: Vec::new(),
            },
            noise_sigma: Some(0.00005),
            inspections: Vec::new(),
            results: None,
        };
        // The cell as it physically is; the session above declares the nominal tool and part.
        let mut true_tcp = tcp;
        let (mut true_radius, mut true_scale) = (tip_radius, 1.0);
        let mut encoders = Effects {
            noise_sigma_rad: noise.then_some(2e-5),
            ..Effects::default()
        };
        let dof = robot.home().len();
        let shoulder_and_elbow = |values: [f64; 2]| -> Vec<f64> {
            let mut per_joint = vec![0.0; dof];
            // UR: shoulder lift and elbow (joints 2 and 3); iiwa: joints 2 and 4.
            let elbow = if robot == ShippedRobot::Iiwa14 { 3 } else { 2 };
            per_joint[1] = values[0];
            per_joint[elbow] = values[1];
            per_joint
        };
        match effect {
            SimulatedEffect::None => {}
            SimulatedEffect::Modelled(Effect::ProbeRadius) => true_radius = 0.0034,
            SimulatedEffect::Modelled(Effect::TcpOffset) => {
                true_tcp.translation.vector += Vector3::new(0.0015, -0.001, 0.0015)
            }
            SimulatedEffect::Modelled(Effect::PartScale) => true_scale = 1.004,
            SimulatedEffect::Modelled(Effect::JointOffsets) => {
                encoders.joint_offsets = Some(match robot {
                    ShippedRobot::Iiwa14 => vec![0.0, 0.0015, 0.0, -0.002, 0.0, 0.001, 0.0],
                    _ => vec![0.0, 0.0015, -0.002, 0.001, 0.0, 0.0],
                });
            }
            SimulatedEffect::Modelled(Effect::JointCompliance) => {
                encoders.compliance_rad_per_nm = Some(shoulder_and_elbow([3e-5, 4e-5]));
                // The tool the session declares: its mass at the TCP.
                encoders.payload = Some(Payload {
                    mass_kg: 0.4,
                    com_in_flange: tcp.translation.vector.into(),
                });
            }
            SimulatedEffect::Modelled(Effect::TriggerLatency) => {
                encoders.trigger_latency_s = Some(0.05);
            }
            SimulatedEffect::CyclicEncoder => {
                encoders.cyclic_encoder = Some(CyclicEncoder {
                    joint: 1,
                    amplitude_rad: 0.001,
                    cycles_per_turn: 2.0,
                });
            }
        }
        // Nine touches align; a diagnosis needs more, at varied tilts (a ball-radius change and
        // a TCP shift look alike on head-on touches).
        let with_effect = effect != SimulatedEffect::None;
        let probe = ProbeRequest {
            mesh: mesh_path,
            mesh_scale: 1.0,
            base_from_part: pose(&truth),
            tcp: pose(&true_tcp),
            tip_radius: true_radius,
            part_scale: true_scale,
            touches: if with_effect { 16 } else { 9 },
            max_tilt_rad: 0.6,
            dwell_s: 0.3,
            vary_tilt: with_effect,
            // A latency shows only on touches taken while moving, at different speeds (at rest a
            // late sample is the same sample; at one speed it looks like a larger ball).
            on_the_fly_speeds_m_s: (effect == SimulatedEffect::Modelled(Effect::TriggerLatency))
                .then(|| vec![0.001, 0.0025, 0.004]),
            trigger_input: protocol::DigitalInput::DI0,
        };
        Ok(Self {
            base_from_part_truth: truth,
            base_from_part_nominal: nominal,
            session,
            encoder_effects: (encoders != Effects::default()).then_some(encoders),
            probe,
        })
    }

    /// True when touches are captured on the fly at the trigger's time stamp.
    pub fn on_the_fly(&self) -> bool {
        self.probe.on_the_fly_speeds_m_s.is_some()
    }

    pub fn truth_pose(&self) -> Pose {
        pose(&self.base_from_part_truth)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_effect_the_diagnosis_knows_is_an_effect_value() {
        for effect in Effect::ALL {
            let value = SimulatedEffect::from_str(effect.name(), false);
            assert_eq!(value, Ok(SimulatedEffect::Modelled(effect)));
        }
        let names: Vec<&str> = SIMULATED_EFFECTS.iter().map(|e| e.name()).collect();
        assert_eq!(names.first(), Some(&"none"));
        assert_eq!(names.last(), Some(&"cyclic_encoder"));
        assert_eq!(names.len(), Effect::ALL.len() + 2);
    }
}
