//! A third-party robot description the repository does not ship, prepared for fitting where it
//! is: shared by `abb.rs` and `ur10_cad.rs`, whose includers declare it beside them.

use std::path::PathBuf;

use align_core::kinematics::{PackageMap, RobotModel};
use align_core::registration::articulated::ArticulatedBody;

/// The robot of `urdf` (a path inside the description's folder), with the ROS package
/// `package` at that folder: `$env_var`, else `default_dir`. `None`, and a line on stderr
/// saying how to get it (`how`), where the URDF is not there.
pub fn robot_from_package(
    env_var: &str,
    default_dir: PathBuf,
    urdf: &str,
    package: &str,
    how: &str,
) -> Option<ArticulatedBody> {
    let dir = std::env::var_os(env_var).map_or(default_dir, PathBuf::from);
    let urdf = dir.join(urdf);
    if !urdf.is_file() {
        eprintln!("skipped: {} is not here ({how}, {env_var})", urdf.display());
        return None;
    }
    let mut packages = PackageMap::new();
    packages.insert(package.to_owned(), dir);
    let model = RobotModel::from_urdf_file(&urdf, &packages)
        .unwrap_or_else(|error| panic!("{} loads: {error}", urdf.display()));
    Some(ArticulatedBody::from_model(&model).expect("the robot has surfaces"))
}
