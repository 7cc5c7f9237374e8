//! Rigid registration of a part's mesh to measurements: weighted SVD ([`svd`]), the thesis's
//! stopping criterion and pose distance ([`convergence`]), Point Set Alignment of touch
//! inspections ([`psa`]) and Point Cloud Alignment of scans ([`pca`]).
//!
//! Every algorithm moves the part: it estimates `base_from_part` such that the part's surface
//! passes through the measurements given in the base frame.

pub mod convergence;
pub mod pca;
pub mod psa;
pub mod sampling;
pub mod svd;

pub use convergence::{StopCriterion, pose_distance};
pub use svd::{RegistrationError, weighted_svd};
