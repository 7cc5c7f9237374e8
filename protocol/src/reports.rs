//! The documents the alignment service replies and `ips ... --json` prints (DESIGN.md 6.4): an
//! alignment of touches, of a scanner cloud, and a diagnosis. Distances are in m unless a name
//! says otherwise.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::pose::Pose;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Residual {
    pub id: String,
    /// Signed distance of the touch from the aligned surface (ball radius removed), m.
    pub distance: f64,
    /// The ball centre in the robot base frame, m (what `--export csv` lists).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ball_centre: Option<[f64; 3]>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    pub pose: Pose,
    pub rms: f64,
}

/// The 95 % confidence region of the part origin's position, mm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Position95 {
    /// Semi-axes of the 3-dof 95 % ellipsoid, largest first.
    pub semi_axes: [f64; 3],
    /// Their unit directions, base frame.
    pub axes: [[f64; 3]; 3],
    /// 95 % half-widths (1.96 sd) of x, y, z alone.
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// The 95 % confidence region of the orientation (rotation vector, base frame), mrad.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Rotation95 {
    pub semi_axes: [f64; 3],
    pub axes: [[f64; 3]; 3],
    pub rx: f64,
    pub ry: f64,
    pub rz: f64,
}

/// The least constrained motion of the part.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WeakDirection {
    /// "translation", "rotation" or "screw".
    pub kind: String,
    /// Translation direction or rotation axis (unit, base frame).
    pub axis: [f64; 3],
    /// A point on the rotation axis (base frame, m); null for a translation.
    pub point: Option<[f64; 3]>,
    /// 95 % size (1.96 sd along this one motion) in `unit`.
    pub size_95: f64,
    /// "mm" for a translation, "mrad" for a rotation or screw.
    pub unit: String,
    /// Screws only: translation along the axis per rotation, m/rad (= mm/mrad).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pitch_m_per_rad: Option<f64>,
    pub text: String,
}

/// Pose covariance from the noise and the touch geometry (align_core::registration::uncertainty).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Uncertainty {
    /// Measurement noise the covariance assumes (of a touch, or of a scan point along its normal), m.
    pub sigma_m: f64,
    /// "declared" (the session's `noise_sigma`), "estimated" (from the residuals, N - 6 dof) or,
    /// for a cloud, "scan" (the robust spread of the last matches' residuals).
    pub sigma_source: String,
    /// The noise the residuals suggest, sqrt(RSS / (N - 6)), m; null with 6 touches or fewer. Far
    /// above a declared sigma, the model lacks an effect (`ips diagnose`) and the covariance,
    /// which assumes the declared noise, is optimistic.
    pub residual_sigma_m: Option<f64>,
    /// 6x6 rows in `covariance_order`: rotation vector of the part in the base frame (rad), then
    /// the part origin's position in the base frame (m).
    pub covariance: [[f64; 6]; 6],
    pub covariance_order: [String; 6],
    pub position_95_mm: Position95,
    pub rotation_95_mrad: Rotation95,
    pub weak_direction: WeakDirection,
    /// The part point (base frame, m) whose position is known best, if computable.
    pub least_uncertain_point: Option<[f64; 3]>,
    /// The thesis's pose distance from the truth (translation of the part's origin and rotation
    /// times the part's radius, as a hypotenuse) that 95 % of fits stay within, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose_distance_95_mm: Option<f64>,
}

/// The keys every alignment report starts with (DESIGN.md 6.4), written at the top level of
/// [`AlignReport`] and [`CloudReport`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlignmentSummary {
    /// `base_from_part`, with its matrix.
    pub pose: Pose,
    pub iterations: usize,
    pub converged: bool,
    /// RMS and largest distance of the measurements from the aligned surface, m.
    pub rms: f64,
    pub max: f64,
    pub time_s: f64,
    /// Each touch's signed distance from the aligned surface; empty for a cloud.
    pub residuals: Vec<Residual>,
}

/// DESIGN.md 6.4 keys, plus `ambiguous`, `candidates`, `starts`, `notes`, and from `ips align
/// SESSION` either `uncertainty` or `uncertainty_error` (why it could not be computed).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlignReport {
    #[serde(flatten)]
    pub alignment: AlignmentSummary,
    pub ambiguous: bool,
    pub candidates: Vec<Candidate>,
    pub starts: usize,
    pub notes: Vec<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<Uncertainty>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty_error: Option<String>,
    /// The robot base frame the pose is relative to (the session's `base_link`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base_frame: Option<String>,
}

/// As `ips align` (DESIGN.md 6.4); for clouds `residuals` is empty (thousands of points) and the
/// point counts are given instead.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CloudReport {
    #[serde(flatten)]
    pub alignment: AlignmentSummary,
    pub cloud_points: usize,
    pub keypoints: usize,
    pub kept_points: usize,
    pub final_delta: f64,
    pub starts: usize,
    pub notes: Vec<String>,
    /// True when another pose fits the scan as well (a symmetric part, or too little seen).
    #[serde(default)]
    pub ambiguous: bool,
    /// How clearly the pose beats the best different pose the search found; absent for a
    /// local alignment or when no other pose was found.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uniqueness: Option<CloudUniqueness>,
    /// The pose's covariance from its last matches, the noise measured on them (`sigma_source`
    /// "scan"); absent with `uncertainty_error` saying why when it cannot be computed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<Uncertainty>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty_error: Option<String>,
}

/// The pose's consensus score (keypoints on the part's surface, less those inside it) against
/// the runner-up's, a different pose.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CloudUniqueness {
    pub score: f64,
    pub runner_up_score: f64,
    /// (score - runner-up's) / score.
    pub margin: f64,
    pub runner_up: Pose,
}

/// The diagnosis of a session's residual (DESIGN.md 6.4).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiagnoseReport {
    /// "effect", "noise", "ambiguous" or "not_attributable".
    pub verdict: String,
    /// The effect applied, when the verdict is "effect".
    pub effect: Option<EffectFit>,
    /// Every other effect tried, with why it lost.
    pub alternatives: Vec<Alternative>,
    pub before: FitSummary,
    pub after: FitSummary,
    pub pose_before: Pose,
    pub pose_after: Pose,
    pub inspections: Vec<InspectionResidual>,
    pub explanation: String,
    /// Chi-square of the residual before and after, against the declared noise.
    pub chi_square: [f64; 2],
    /// The picture of the residuals, written next to the session file (none from the service:
    /// its session is in memory).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plot: Option<String>,
    /// The same as a page for a browser (verdict, plot, candidates, touches), written next to
    /// the session file by `ips diagnose SESSION`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub page: Option<String>,
    /// The robot base frame the poses are relative to (the session's `base_link`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base_frame: Option<String>,
    /// The touch noise the diagnosis tested against (the session's `noise_sigma`), m: the
    /// pictures draw its +-2 sigma band.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_sigma_m: Option<f64>,
}

/// A fitted effect: its parameters and their standard errors, by parameter name (units in the
/// names). Fields in alphabetical order, as the documents have always been written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EffectFit {
    pub bic: f64,
    pub name: String,
    pub params: BTreeMap<String, f64>,
    pub stderr: BTreeMap<String, f64>,
}

/// An effect that was not applied. `bic` and `loo_rms` are null when it could not be fitted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Alternative {
    pub bic: Option<f64>,
    pub loo_rms: Option<f64>,
    pub name: String,
    pub reason: String,
}

/// The residual of a fit: leave-one-out rms (how well it predicts a touch it did not see), max
/// and rms, m.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitSummary {
    pub loo_rms: f64,
    pub max: f64,
    pub rms: f64,
}

/// One touch's signed residual before and after the effect, m.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InspectionResidual {
    pub id: String,
    pub residual_after: f64,
    pub residual_before: f64,
    /// The ball centre in the robot base frame after the effect is applied, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ball_centre_after: Option<[f64; 3]>,
}

/// One value `ips diagnose --apply` changed in the session, in the file's unit (`unit`: m, rad,
/// rad/(N m), s, or empty for the unitless mesh scale), with a line for people.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AppliedChange {
    /// Where in the session file, e.g. `tool.tcp.xyz[2]` or `robot.joint_offsets[1]`.
    pub key: String,
    pub before: f64,
    pub after: f64,
    pub unit: String,
    pub text: String,
}

/// What `ips diagnose SESSION --apply OUT --json` prints: the corrected session written, the
/// effect applied and each change.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AppliedReport {
    pub path: String,
    pub effect: String,
    pub changes: Vec<AppliedChange>,
    /// The diagnosis's residual rms before and after the effect, m.
    pub rms_before: f64,
    pub rms_after: f64,
}
