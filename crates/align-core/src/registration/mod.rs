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
pub mod sampling;
pub mod svd;
pub mod uncertainty;

pub use convergence::{StopCriterion, pose_distance};
pub use svd::{RegistrationError, weighted_svd};
