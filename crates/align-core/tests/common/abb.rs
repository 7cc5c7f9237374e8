//! The ABB IRB 1600 (ROS-Industrial's support package, Apache-2.0), which the repository does
//! not ship: `$ABB_IRB1600_SUPPORT_DIR`, else the workspace's sibling `shared/data` folder.
//! Shared by the articulated tests, the `ppf_detection` bench and cad-scans' robot_scans tests.

use align_core::registration::articulated::ArticulatedBody;

// The includer declares `robot_package` (robot_package.rs) beside this module.
use super::robot_package::robot_from_package;

/// The joint values its trials scan it at (`ips trials --urdf ... --home 0,0.3,-0.2,0,0.6,0`).
pub const ABB_TRIAL_HOME: [f64; 6] = [0.0, 0.3, -0.2, 0.0, 0.6, 0.0];

/// The ABB IRB 1600 prepared for fitting, where its support package is; `None` (and a line on
/// stderr saying so) where it is not.
pub fn abb_irb1600() -> Option<ArticulatedBody> {
    robot_from_package(
        "ABB_IRB1600_SUPPORT_DIR",
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/data/abb_irb1600/abb_irb1600_support"),
        "urdf/irb1600_6_12.urdf",
        "abb_irb1600_support",
        "the ABB IRB 1600 support package",
    )
}
