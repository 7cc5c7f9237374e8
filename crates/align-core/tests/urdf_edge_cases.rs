//! URDF as real descriptions write it: prismatic joints, runs of fixed joints, unnormalised axes,
//! gimbal-lock origins, chains across branches, package:// meshes, ROS-Industrial extras; and every
//! malformed description refused with a message naming the element at fault.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::path::PathBuf;

use align_core::kinematics::{ModelError, PackageMap, RobotModel};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

fn model(body: &str) -> Result<RobotModel, ModelError> {
    RobotModel::from_urdf_str(
        &format!("<robot name=\"test\">{body}</robot>"),
        &PackageMap::new(),
    )
}

fn links(names: &[&str]) -> String {
    names
        .iter()
        .map(|name| format!("<link name=\"{name}\"/>"))
        .collect()
}

fn joint(name: &str, kind: &str, parent: &str, child: &str, extra: &str) -> String {
    format!(
        "<joint name=\"{name}\" type=\"{kind}\"><parent link=\"{parent}\"/><child link=\"{child}\"/>{extra}</joint>"
    )
}

const LIMIT: &str = "<limit lower=\"-3\" upper=\"3\" effort=\"10\" velocity=\"1\"/>";

fn error_text(body: &str) -> String {
    model(body)
        .expect_err("the description is invalid")
        .to_string()
}

fn error_text_for_chain(body: &str, base: &str, tip: &str) -> String {
    model(body)
        .expect("model loads")
        .chain(base, tip)
        .expect_err("the chain is invalid")
        .to_string()
}

/// A unique scratch folder under the system temp dir, removed on drop.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("cobot-align-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("scratch dir");
        Self(dir)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[test]
fn prismatic_joint_moves_along_its_normalised_axis() {
    let body = links(&["base", "slider"])
        + &joint(
            "slide",
            "prismatic",
            "base",
            "slider",
            "<origin xyz=\"0.1 0 0\"/><axis xyz=\"0 3 4\"/><limit lower=\"0\" upper=\"1\" effort=\"1\" velocity=\"1\"/>",
        );
    let chain = model(&body).unwrap().chain("base", "slider").unwrap();
    let tip = chain.forward(&[0.5]).unwrap().translation.vector;
    assert!(
        (tip - Vector3::new(0.1, 0.3, 0.4)).norm() < 1e-15,
        "{tip:?}"
    );
    let jacobian = chain.jacobian(&[0.5]).unwrap();
    let column: Vec<f64> = jacobian.column(0).iter().copied().collect();
    assert!(
        column
            .iter()
            .zip([0.0, 0.6, 0.8, 0.0, 0.0, 0.0])
            .all(|(a, b)| (a - b).abs() < 1e-15)
    );
}

#[test]
fn consecutive_fixed_joints_compose() {
    let body = links(&["a", "b", "c", "d"])
        + &joint(
            "ab",
            "fixed",
            "a",
            "b",
            "<origin xyz=\"1 0 0\" rpy=\"0 0 1.5707963267948966\"/>",
        )
        + &joint("bc", "fixed", "b", "c", "<origin xyz=\"1 0 0\"/>")
        + &joint(
            "cd",
            "fixed",
            "c",
            "d",
            "<origin xyz=\"0 0 2\" rpy=\"0.5 0 0\"/>",
        );
    let chain = model(&body).unwrap().chain("a", "d").unwrap();
    assert_eq!(chain.dof(), 0);
    let pose = chain.forward(&[]).unwrap();
    assert!((pose.translation.vector - Vector3::new(1.0, 1.0, 2.0)).norm() < 1e-12);
}

#[test]
fn non_normalised_axis_behaves_like_the_unit_axis() {
    let make = |axis: &str| {
        let body = links(&["a", "b"])
            + &joint(
                "j",
                "revolute",
                "a",
                "b",
                &format!("<origin xyz=\"0 0 0\"/><axis xyz=\"{axis}\"/>{LIMIT}"),
            );
        model(&body)
            .unwrap()
            .chain("a", "b")
            .unwrap()
            .forward(&[0.7])
            .unwrap()
    };
    assert!(make("0 0 5").rotation.angle_to(&make("0 0 1").rotation) < 1e-15);
    assert!(
        make("0 0 5")
            .rotation
            .angle_to(&UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.7))
            < 1e-15
    );
}

#[test]
fn origins_at_pitch_plus_and_minus_half_pi_follow_fixed_axis_xyz() {
    for pitch in [std::f64::consts::FRAC_PI_2, -std::f64::consts::FRAC_PI_2] {
        let (roll, yaw) = (0.3, -1.1);
        let body = links(&["a", "b"])
            + &joint(
                "j",
                "fixed",
                "a",
                "b",
                &format!("<origin xyz=\"0 0 0\" rpy=\"{roll} {pitch} {yaw}\"/>"),
            );
        let pose = model(&body)
            .unwrap()
            .chain("a", "b")
            .unwrap()
            .forward(&[])
            .unwrap();
        let expected = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw)
            * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), pitch)
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), roll);
        assert!(pose.rotation.angle_to(&expected) < 1e-14, "pitch {pitch}");
    }
}

/// root -> arm1 -> hand1 and root -> arm2 -> hand2: a chain from one hand to the other crosses
/// the tree upwards and then down.
fn two_arms() -> RobotModel {
    let body = links(&["root", "arm1", "hand1", "arm2", "hand2"])
        + &joint(
            "s1",
            "revolute",
            "root",
            "arm1",
            &format!("<origin xyz=\"0 0.2 0.1\" rpy=\"0.1 0 0\"/><axis xyz=\"0 0 1\"/>{LIMIT}"),
        )
        + &joint(
            "e1",
            "revolute",
            "arm1",
            "hand1",
            &format!("<origin xyz=\"0.3 0 0\"/><axis xyz=\"0 1 0\"/>{LIMIT}"),
        )
        + &joint(
            "s2",
            "continuous",
            "root",
            "arm2",
            "<origin xyz=\"0 -0.2 0.1\" rpy=\"0 0.2 0\"/><axis xyz=\"1 0 1\"/>",
        )
        + &joint(
            "e2",
            "prismatic",
            "arm2",
            "hand2",
            "<origin xyz=\"0.25 0 0\"/><axis xyz=\"1 0 0\"/><limit lower=\"0\" upper=\"0.1\" effort=\"1\" velocity=\"1\"/>",
        );
    model(&body).unwrap()
}

#[test]
fn chain_across_branches_equals_the_composition_through_the_root() {
    let robot = two_arms();
    let across = robot.chain("hand1", "hand2").unwrap();
    assert_eq!(across.joint_names(), ["e1", "s1", "s2", "e2"]);
    let to_hand1 = robot.chain("root", "hand1").unwrap();
    let to_hand2 = robot.chain("root", "hand2").unwrap();
    let q = [0.4, -0.7, 1.3, 0.05];
    // The across chain orders joints from hand1 upwards: e1, s1, then s2, e2.
    let expected = to_hand1.forward(&[q[1], q[0]]).unwrap().inverse()
        * to_hand2.forward(&[q[2], q[3]]).unwrap();
    let got = across.forward(&q).unwrap();
    assert!((got.translation.vector - expected.translation.vector).norm() < 1e-14);
    assert!(got.rotation.angle_to(&expected.rotation) < 1e-14);
    assert!(across.joints()[0].reversed && !across.joints()[3].reversed);

    // Its Jacobian against central differences.
    let jacobian = across.jacobian(&q).unwrap();
    let step = 1e-6;
    for column in 0..4 {
        let (mut plus, mut minus) = (q, q);
        plus[column] += step;
        minus[column] -= step;
        let (a, b) = (
            across.forward(&plus).unwrap(),
            across.forward(&minus).unwrap(),
        );
        let linear = (a.translation.vector - b.translation.vector) / (2.0 * step);
        let angular = (a.rotation * b.rotation.inverse()).scaled_axis() / (2.0 * step);
        for row in 0..3 {
            assert!((jacobian[(row, column)] - linear[row]).abs() < 1e-8);
            assert!((jacobian[(row + 3, column)] - angular[row]).abs() < 1e-8);
        }
    }
}

#[test]
fn chain_from_a_link_to_itself_is_the_identity() {
    let chain = two_arms().chain("arm1", "arm1").unwrap();
    assert_eq!(chain.dof(), 0);
    assert_eq!(chain.forward(&[]).unwrap(), Isometry3::identity());
}

#[test]
fn continuous_joints_have_no_position_limits() {
    let robot = two_arms();
    let joint = robot.joint("s2").unwrap();
    assert_eq!(
        (joint.limits.lower, joint.limits.upper),
        (f64::NEG_INFINITY, f64::INFINITY)
    );
    assert!(robot.chain("root", "arm2").unwrap().within_limits(&[100.0]));
}

const ROS_INDUSTRIAL_STYLE: &str = r#"<?xml version="1.0"?>
<robot name="scanner_arm" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <material name="yellow"><color rgba="1 0.8 0 1"/></material>
  <link name="base_link">
    <visual><origin xyz="0 0 0" rpy="0 0 0"/><geometry><mesh filename="package://arm_support/meshes/visual/base_link.stl"/></geometry><material name="yellow"/></visual>
    <collision><geometry><mesh filename="package://arm_support/meshes/collision/base_link.stl" scale="0.001 0.001 0.001"/></geometry></collision>
  </link>
  <link name="link_1">
    <inertial><origin xyz="0 0 0.1"/><mass value="3.5"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.05"/></inertial>
    <visual><geometry><mesh filename="meshes/link_1.stl"/></geometry></visual>
    <collision><geometry><cylinder radius="0.05" length="0.2"/></geometry></collision>
  </link>
  <link name="link_2"><visual><geometry><mesh filename="FILE_URI"/></geometry></visual></link>
  <link name="tool0"/>
  <link name="gripper_finger"/>
  <joint name="joint_1" type="revolute">
    <origin xyz="0 0 0.4865" rpy="0 0 0"/><parent link="base_link"/><child link="link_1"/><axis xyz="0 0 1"/>
    <limit lower="-3.1416" upper="3.1416" effort="0" velocity="2.618"/>
    <safety_controller soft_lower_limit="-3.1" soft_upper_limit="3.1" k_position="100" k_velocity="2"/>
    <calibration rising="0.0"/>
    <dynamics damping="0.5" friction="0.1"/>
  </joint>
  <joint name="joint_2" type="revolute">
    <origin xyz="0.15 0 0" rpy="0 0 0"/><parent link="link_1"/><child link="link_2"/><axis xyz="0 1 0"/>
    <limit lower="-1.0995" upper="1.9198" effort="0" velocity="2.7925"/>
  </joint>
  <joint name="joint_2-tool0" type="fixed"><origin xyz="0.7 0 0" rpy="0 1.5707963267948966 0"/><parent link="link_2"/><child link="tool0"/></joint>
  <joint name="finger_joint" type="prismatic">
    <parent link="tool0"/><child link="gripper_finger"/><axis xyz="0 1 0"/>
    <limit lower="0" upper="0.04" effort="10" velocity="0.1"/>
    <mimic joint="joint_2" multiplier="0.01" offset="0"/>
  </joint>
  <transmission name="trans_1">
    <type>transmission_interface/SimpleTransmission</type>
    <joint name="joint_1"><hardwareInterface>hardware_interface/PositionJointInterface</hardwareInterface></joint>
    <actuator name="motor_1"><mechanicalReduction>1</mechanicalReduction></actuator>
  </transmission>
  <gazebo reference="link_1"><material>Gazebo/Orange</material><selfCollide>true</selfCollide></gazebo>
  <gazebo><plugin name="ros_control" filename="libgazebo_ros_control.so"/></gazebo>
</robot>
"#;

#[test]
fn ros_industrial_style_description_loads_and_resolves_its_meshes() {
    // Layout of a ROS package: arm_support/{urdf/arm.urdf, meshes/...}.
    let scratch = Scratch::new("rosi");
    let package = scratch.0.join("arm_support");
    for file in [
        "meshes/visual/base_link.stl",
        "meshes/collision/base_link.stl",
        "urdf/meshes/link_1.stl",
        "elsewhere/link_2.stl",
    ] {
        let path = package.join(file);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, b"solid x\nendsolid x\n").unwrap();
    }
    let file_uri = format!("file://{}", package.join("elsewhere/link_2.stl").display());
    let urdf_path = package.join("urdf/arm.urdf");
    std::fs::write(
        &urdf_path,
        ROS_INDUSTRIAL_STYLE.replace("FILE_URI", &file_uri),
    )
    .unwrap();

    // Found through the parent folder named like the package, with no map at all.
    let robot = RobotModel::from_urdf_file(&urdf_path, &PackageMap::new()).unwrap();
    assert!(
        robot.mesh_problems().is_empty(),
        "{:?}",
        robot.mesh_problems()
    );
    assert_eq!(
        robot
            .link("link_1")
            .unwrap()
            .inertial
            .as_ref()
            .unwrap()
            .mass_kg,
        3.5
    );
    // The mimic joint lies outside the base -> tool0 chain: tolerated.
    let chain = robot.chain("base_link", "tool0").unwrap();
    let pose = chain.forward(&[0.0, 0.0]).unwrap();
    assert!((pose.translation.vector - Vector3::new(0.85, 0.0, 0.4865)).norm() < 1e-12);

    // Through an explicit map to a copy elsewhere.
    let copy = scratch.0.join("copy");
    std::fs::create_dir_all(copy.join("meshes/visual")).unwrap();
    std::fs::create_dir_all(copy.join("meshes/collision")).unwrap();
    std::fs::write(copy.join("meshes/visual/base_link.stl"), b"x").unwrap();
    std::fs::write(copy.join("meshes/collision/base_link.stl"), b"x").unwrap();
    let mut packages = PackageMap::new();
    packages.insert("arm_support", &copy);
    let robot = RobotModel::from_urdf_file(&urdf_path, &packages).unwrap();
    assert!(
        robot.mesh_problems().is_empty(),
        "{:?}",
        robot.mesh_problems()
    );

    // A map to a folder without the meshes: reported, never fatal.
    let mut packages = PackageMap::new();
    packages.insert("arm_support", scratch.0.join("nowhere"));
    let robot = RobotModel::from_urdf_file(&urdf_path, &packages).unwrap();
    let problems = robot.mesh_problems();
    assert_eq!(problems.len(), 2, "{problems:?}");
    assert!(
        problems[0].starts_with(
            "link 'base_link': mesh 'package://arm_support/meshes/visual/base_link.stl' resolves to"
        ),
        "{}",
        problems[0]
    );
    assert!(problems[0].ends_with("which does not exist"));
}

#[test]
fn mimic_joint_inside_the_chain_is_refused() {
    let robot = RobotModel::from_urdf_str(
        &ROS_INDUSTRIAL_STYLE.replace("FILE_URI", "/x.stl"),
        &PackageMap::new(),
    )
    .unwrap();
    let message = robot
        .chain("base_link", "gripper_finger")
        .unwrap_err()
        .to_string();
    assert_eq!(
        message,
        "joint 'finger_joint' on the chain base_link -> gripper_finger mimics joint 'joint_2'; mimic joints inside a chain are not supported"
    );
}

#[test]
fn missing_links_named_by_joints_are_reported() {
    let body = links(&["a"]) + &joint("j", "fixed", "a", "ghost", "");
    assert_eq!(
        error_text(&body),
        "joint 'j' names child link 'ghost', which is not defined"
    );
    let body = links(&["b"]) + &joint("j", "fixed", "ghost", "b", "");
    assert_eq!(
        error_text(&body),
        "joint 'j' names parent link 'ghost', which is not defined"
    );
}

#[test]
fn unknown_base_or_tip_lists_the_links() {
    let body = links(&["a", "b"]) + &joint("j", "fixed", "a", "b", "");
    assert_eq!(
        error_text_for_chain(&body, "a", "tool0"),
        "no link named 'tool0' in robot 'test' (links: a, b)"
    );
    assert_eq!(
        error_text_for_chain(&body, "world", "b"),
        "no link named 'world' in robot 'test' (links: a, b)"
    );
}

#[test]
fn links_of_separate_trees_are_not_connected() {
    let body = links(&["a", "b", "c", "d"])
        + &joint("ab", "fixed", "a", "b", "")
        + &joint("cd", "fixed", "c", "d", "");
    assert_eq!(
        error_text_for_chain(&body, "b", "d"),
        "links 'b' and 'd' are not connected by any chain of joints"
    );
}

#[test]
fn kinematic_loops_are_refused() {
    let body = links(&["a", "b", "c"])
        + &joint("ab", "fixed", "a", "b", "")
        + &joint("ac", "fixed", "a", "c", "")
        + &joint("cb", "fixed", "c", "b", "");
    assert_eq!(
        error_text(&body),
        "kinematic loop: link 'b' is the child of both joint 'ab' and joint 'cb'"
    );
    let body = links(&["a", "b", "c"])
        + &joint("ab", "fixed", "a", "b", "")
        + &joint("bc", "fixed", "b", "c", "")
        + &joint("ca", "fixed", "c", "a", "");
    let message = error_text(&body);
    assert!(
        message.starts_with("kinematic loop: the joints"),
        "{message}"
    );
    assert!(
        message.contains("'ab'") && message.contains("'bc'") && message.contains("'ca'"),
        "{message}"
    );
}

#[test]
fn zero_axis_is_refused() {
    let body = links(&["a", "b"])
        + &joint(
            "j",
            "revolute",
            "a",
            "b",
            &format!("<axis xyz=\"0 0 0\"/>{LIMIT}"),
        );
    assert_eq!(error_text(&body), "joint 'j' has a zero-length axis");
}

#[test]
fn nan_in_origin_or_axis_names_the_joint() {
    let body = links(&["a", "b"])
        + &joint(
            "j",
            "revolute",
            "a",
            "b",
            &format!("<origin xyz=\"0 nan 0\"/>{LIMIT}"),
        );
    assert_eq!(
        error_text(&body),
        "joint 'j' has a non-finite origin xyz (0 NaN 0)"
    );
    let body = links(&["a", "b"])
        + &joint(
            "j",
            "revolute",
            "a",
            "b",
            &format!("<axis xyz=\"NaN 0 1\"/>{LIMIT}"),
        );
    assert_eq!(
        error_text(&body),
        "joint 'j' has a non-finite axis (NaN 0 1)"
    );
    let body = links(&["a", "b"])
        + &joint(
            "j",
            "revolute",
            "a",
            "b",
            "<limit lower=\"nan\" upper=\"1\" effort=\"1\" velocity=\"1\"/>",
        );
    assert_eq!(
        error_text(&body),
        "joint 'j' has a non-finite limit lower (NaN)"
    );
}

#[test]
fn inverted_limits_are_refused() {
    let body = links(&["a", "b"])
        + &joint(
            "j",
            "revolute",
            "a",
            "b",
            "<limit lower=\"1\" upper=\"-1\" effort=\"1\" velocity=\"1\"/>",
        );
    assert_eq!(
        error_text(&body),
        "joint 'j' has lower limit 1 above upper limit -1"
    );
}

#[test]
fn duplicate_names_are_refused() {
    assert_eq!(error_text(&links(&["a", "a"])), "link 'a' is defined twice");
    let body = links(&["a", "b", "c"])
        + &joint("j", "fixed", "a", "b", "")
        + &joint("j", "fixed", "b", "c", "");
    assert_eq!(error_text(&body), "joint 'j' is defined twice");
}

#[test]
fn floating_joint_inside_a_chain_is_refused() {
    let body = links(&["world", "base"]) + &joint("float", "floating", "world", "base", "");
    assert_eq!(
        error_text_for_chain(&body, "world", "base"),
        "joint 'float' on the chain world -> base is floating; chains support revolute, continuous, prismatic and fixed joints"
    );
}

#[test]
fn empty_robot_is_refused() {
    assert_eq!(error_text(""), "robot 'test' has no links");
}

#[test]
fn xacro_missing_and_malformed_files_are_refused_clearly() {
    let message = RobotModel::from_urdf_str("<robot name=\"x\" xmlns:xacro=\"http://www.ros.org/wiki/xacro\"><xacro:include filename=\"a.xacro\"/></robot>", &PackageMap::new())
        .unwrap_err()
        .to_string();
    assert!(
        message.contains("uses xacro macros; expand it first"),
        "{message}"
    );
    let message = RobotModel::from_urdf_file(
        std::path::Path::new("/nonexistent/robot.urdf"),
        &PackageMap::new(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        message.starts_with("cannot read URDF '/nonexistent/robot.urdf'"),
        "{message}"
    );
    let message = RobotModel::from_urdf_str(
        "<robot name=\"x\"><link name=\"a\"></robot>",
        &PackageMap::new(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        message.starts_with("cannot parse URDF '<string>'"),
        "{message}"
    );
}

#[test]
fn translation_only_chains_report_positions_in_the_base_frame() {
    // A base offset and a rotated intermediate frame: the tip position must include both.
    let body = links(&["a", "b", "c"])
        + &joint(
            "ab",
            "fixed",
            "a",
            "b",
            "<origin xyz=\"0 0 1\" rpy=\"0 0 1.5707963267948966\"/>",
        )
        + &joint(
            "bc",
            "prismatic",
            "b",
            "c",
            "<axis xyz=\"1 0 0\"/><limit lower=\"0\" upper=\"2\" effort=\"1\" velocity=\"1\"/>",
        );
    let pose = model(&body)
        .unwrap()
        .chain("a", "c")
        .unwrap()
        .forward(&[0.5])
        .unwrap();
    let expected = Isometry3::from_parts(
        Translation3::new(0.0, 0.5, 1.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2),
    );
    assert!((pose.translation.vector - expected.translation.vector).norm() < 1e-15);
}
