//! The ABB IRB 1600 (ROS-Industrial's support package, Apache-2.0), which the repository does
//! not ship: `$ABB_IRB1600_SUPPORT_DIR`, else the workspace's sibling `shared/data` folder.
//! Shared by the articulated tests, the `ppf_detection` bench and cad-scans' robot_scans tests.

use align_core::kinematics::{PackageMap, RobotModel};
use align_core::registration::articulated::ArticulatedBody;

/// The joint values its trials scan it at (`ips trials --urdf ... --home 0,0.3,-0.2,0,0.6,0`).
pub const ABB_TRIAL_HOME: [f64; 6] = [0.0, 0.3, -0.2, 0.0, 0.6, 0.0];

/// The ABB IRB 1600 prepared for fitting, where its support package is; `None` (and a line on
/// stderr saying so) where it is not.
pub fn abb_irb1600() -> Option<ArticulatedBody> {
    let dir = std::env::var_os("ABB_IRB1600_SUPPORT_DIR")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../../shared/data/abb_irb1600/abb_irb1600_support")
        });
    let urdf = dir.join("urdf/irb1600_6_12.urdf");
    if !urdf.is_file() {
        eprintln!(
            "skipped: the ABB IRB 1600 support package is not here (ABB_IRB1600_SUPPORT_DIR)"
        );
        return None;
    }
    let mut packages = PackageMap::new();
    packages.insert("abb_irb1600_support".to_owned(), dir);
    let model = RobotModel::from_urdf_file(&urdf, &packages).expect("the ABB URDF loads");
    Some(ArticulatedBody::from_model(&model).expect("the ABB has surfaces"))
}
