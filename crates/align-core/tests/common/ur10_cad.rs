//! Universal Robots' UR10 with its CAD collision meshes (ROS-Industrial's ur_description, BSD,
//! from the PyPI wheel example-robot-data), which the repository does not ship:
//! `scripts/robot-descriptions.sh` writes it, and `$EXAMPLE_ROBOT_DATA_DIR` (else
//! `target/robot-descriptions/example-robot-data` in the workspace) says where. The shipped
//! UR10 is drawn from primitives; this one's links are the manufacturer's shapes.

use align_core::registration::articulated::ArticulatedBody;

// The includer declares `robot_package` (robot_package.rs) beside this module.
use super::robot_package::robot_from_package;

/// The UR10 with CAD links prepared for fitting, where the description is; `None` (and a line
/// on stderr saying so) where it is not.
pub fn ur10_cad() -> Option<ArticulatedBody> {
    robot_from_package(
        "EXAMPLE_ROBOT_DATA_DIR",
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../target/robot-descriptions/example-robot-data"),
        "robots/ur_description/urdf/ur10_collision.urdf",
        "example-robot-data",
        "scripts/robot-descriptions.sh writes it",
    )
}
