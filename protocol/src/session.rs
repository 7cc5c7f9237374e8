//! The session file (DESIGN.md 6.3, `cobot-align/session@1`): robot, tool, part and the
//! inspections taken, with paths relative to the file. An inspection is also what the service's
//! `get` replies and what its journal records.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::pose::Pose;

/// The value of [`SessionFile::format`].
pub const FORMAT: &str = "cobot-align/session@1";

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SessionFile {
    pub format: String,
    /// Optional when every inspection gives its `flange_pose` (DESIGN.md 6.3).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot: Option<RobotSection>,
    pub tool: ToolSection,
    pub part: PartSection,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_sigma: Option<f64>,
    pub inspections: Vec<Inspection>,
    /// What the service last found for these inspections, as `ips save` wrote it: kept with the
    /// touches it came from, never read back as an input.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub results: Option<SessionResults>,
}

/// The last alignment and diagnosis a service computed, each with the inspections it used.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SessionResults {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alignment: Option<SavedResult<crate::reports::AlignReport>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diagnosis: Option<SavedResult<crate::reports::DiagnoseReport>>,
}

/// A report and the ids of the inspections it was computed from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SavedResult<T> {
    pub inspections: Vec<String>,
    pub report: T,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RobotSection {
    pub urdf: String,
    pub base_link: String,
    pub tip_link: String,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub package_dirs: BTreeMap<String, String>,
    /// The controller's calibrated DH table (a UR's factory calibration, as `ips serve` learnt
    /// it from the bridge): joints become flange poses with it instead of the description's
    /// geometry. Optional; a saved session keeps it so that offline tools agree with the service.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kinematics: Option<crate::calibration::ControllerKinematics>,
    /// Joint zero offsets, rad, one per joint: added to every inspection's joints before forward
    /// kinematics (what `ips diagnose --apply` writes for `joint_offsets`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_offsets: Option<Vec<f64>>,
    /// Joint compliance, rad/(N m), one per joint: each joint deflects by this times the gravity
    /// torque on it (the links' inertials and the tool's mass) at the inspection.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_compliance: Option<Vec<f64>>,
    /// Capture latency, s: the joints were read this long after the touch, so they are taken
    /// back along their velocity (q - qd * latency); inspections without `qd` are unchanged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trigger_latency_s: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ToolSection {
    pub tcp: Pose,
    #[serde(default)]
    pub tip_radius: f64,
    #[serde(default)]
    pub mass: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartSection {
    pub mesh: String,
    #[serde(default = "unit_scale")]
    pub mesh_scale: f64,
    pub nominal_pose: Pose,
    /// Named planar faces (datum features) inspections may refer to; an extension of 6.3.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub faces: Vec<FaceSection>,
}

fn unit_scale() -> f64 {
    1.0
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FaceSection {
    pub name: String,
    /// Outward normal in the part frame.
    pub normal: [f64; 3],
    /// A point of the face's plane in the part frame, m.
    pub point: [f64; 3],
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Inspection {
    pub id: String,
    /// Joint positions, rad (or m for prismatic joints).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub q: Option<Vec<f64>>,
    /// `base_from_flange` as the controller reports it instead of joints: x, y, z (m) and a
    /// rotation vector (rad), as a UR's `actual_TCP_pose` with a zero TCP offset.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub flange_pose: Option<[f64; 6]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub qd: Option<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stamp: Option<f64>,
    /// The part face this touch was meant for (a face hint); an extension of 6.3.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub face: Option<String>,
    /// The digital input whose rising edge captured this touch (`"DI0"`, a touch-trigger
    /// probe's), absent for touches taken by request; an extension of 6.3.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trigger: Option<String>,
}
