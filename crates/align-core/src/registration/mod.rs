//! Rigid registration of a part's mesh to measurements: weighted SVD ([`svd`]), the thesis's
//! stopping criterion and pose distance ([`convergence`]), Point Set Alignment of touch
//! inspections ([`psa`]), Point Cloud Alignment of scans ([`pca`]) and hierarchical alignment of
//! robots in scans ([`articulated`]).
//!
//! Every algorithm moves the part: it estimates `base_from_part` such that the part's surface
//! passes through the measurements given in the base frame.

pub mod articulated;
pub mod convergence;
pub mod pca;
pub mod ppf;
pub mod psa;
pub(crate) mod robust_scale;
pub mod sampling;
pub mod svd;
pub mod uncertainty;

pub use convergence::{StopCriterion, pose_distance};

use nalgebra::Isometry3;

/// What every rigid alignment reports, whatever it aligned to: the pose, how the search went
/// and how well the part fits. [`psa::PsaResult`] and [`pca::PcaResult`] add what is particular
/// to touches and to clouds.
#[derive(Debug, Clone, PartialEq)]
pub struct Alignment {
    pub base_from_part: Isometry3<f64>,
    pub iterations: usize,
    pub converged: bool,
    /// RMS and largest distance of the measurements from the aligned surface, m.
    pub rms_m: f64,
    pub max_m: f64,
    /// Local alignments run (1 for a local search).
    pub starts: usize,
    pub time_s: f64,
}
pub use svd::{RegistrationError, weighted_svd};
