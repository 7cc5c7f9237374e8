//! Universal Robots' UR10 with its CAD collision meshes (ROS-Industrial's ur_description, BSD,
//! from the PyPI wheel example-robot-data), which the repository does not ship:
//! `scripts/robot-descriptions.sh` writes it, and `$EXAMPLE_ROBOT_DATA_DIR` (else
//! `target/robot-descriptions/example-robot-data` in the workspace) says where. The shipped
//! UR10 is drawn from primitives; this one's links are the manufacturer's shapes.

use align_core::kinematics::{PackageMap, RobotModel};
use align_core::registration::articulated::ArticulatedBody;

/// The UR10 with CAD links prepared for fitting, where the description is; `None` (and a line
/// on stderr saying so) where it is not.
pub fn ur10_cad() -> Option<ArticulatedBody> {
    let dir = std::env::var_os("EXAMPLE_ROBOT_DATA_DIR")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../target/robot-descriptions/example-robot-data")
        });
    let urdf = dir.join("robots/ur_description/urdf/ur10_collision.urdf");
    if !urdf.is_file() {
        eprintln!(
            "skipped: the UR10's CAD description is not here (scripts/robot-descriptions.sh, \
             EXAMPLE_ROBOT_DATA_DIR)"
        );
        return None;
    }
    let mut packages = PackageMap::new();
    packages.insert("example-robot-data".to_owned(), dir);
    let model = RobotModel::from_urdf_file(&urdf, &packages).expect("the UR10 URDF loads");
    Some(ArticulatedBody::from_model(&model).expect("the UR10 has surfaces"))
}
