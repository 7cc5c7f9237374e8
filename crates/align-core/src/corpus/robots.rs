//! Robot descriptions written here from the vendors' published Denavit-Hartenberg tables, not
//! from `robots/` (whose UR10, UR10e and iiwa 14 come from `robots/generate.py`): a UR5e from
//! Universal Robots' standard DH table with the ROS-Industrial `base_link` / `base` convention (the
//! two frames turned 180 degrees about z), and a Franka Emika Panda from Franka's modified
//! (Craig) DH table. Both are URDF text for [`crate::kinematics::RobotModel::from_urdf_str`].
//!
//! Every joint's origin is `Tx(a_prev) Rx(alpha_prev) Tz(d)`: the previous link's common normal
//! and twist, then this joint's offset along its axis (z). Rz(theta) commutes with Tz(d), so the
//! UR's standard DH product Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i) regroups into exactly this
//! form, and Craig's modified DH Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i) is it already.
//! Link frames are therefore each joint's frame (z along the joint axis).

use std::fmt::Write;

use nalgebra::{Point3, Rotation3, Vector3};

/// One revolute joint: the previous link's `a` and `alpha`, this joint's `d`, limits, and the
/// child link's mass and centre of mass (in the child link's frame).
#[derive(Debug, Clone, PartialEq)]
struct DhJoint {
    a_prev_m: f64,
    alpha_prev_rad: f64,
    d_m: f64,
    lower_rad: f64,
    upper_rad: f64,
    velocity_rad_s: f64,
    effort_nm: f64,
    mass_kg: f64,
    com_m: [f64; 3],
}

/// The URDF origin of `Tx(a) Rx(alpha) Tz(d)`: translation (a, -d sin alpha, d cos alpha) and
/// rotation rpy (alpha, 0, 0).
fn origin(a: f64, alpha: f64, d: f64) -> String {
    format!(
        "<origin xyz=\"{:.10} {:.10} {:.10}\" rpy=\"{:.15} 0 0\"/>",
        a,
        -d * alpha.sin(),
        d * alpha.cos(),
        alpha
    )
}

fn inertial(mass_kg: f64, com: [f64; 3]) -> String {
    // Inertia tensors are not used by the gravity model; a small diagonal keeps the URDF valid.
    format!(
        "<inertial><origin xyz=\"{:.6} {:.6} {:.6}\" rpy=\"0 0 0\"/><mass value=\"{mass_kg}\"/><inertia ixx=\"0.01\" ixy=\"0\" ixz=\"0\" iyy=\"0.01\" iyz=\"0\" izz=\"0.01\"/></inertial>",
        com[0], com[1], com[2]
    )
}

/// A serial chain `first_link` -> link_1 .. link_n -> `flange` (a fixed joint with `flange`'s
/// a, alpha, d), links named `{prefix}link_{i}`.
fn chain_urdf(
    out: &mut String,
    first_link: &str,
    prefix: &str,
    joints: &[DhJoint],
    flange: (f64, f64, f64),
) {
    let mut parent = first_link.to_owned();
    for (i, joint) in joints.iter().enumerate() {
        let child = format!("{prefix}link_{}", i + 1);
        let _ = write!(
            out,
            "  <link name=\"{child}\">{}</link>\n  <joint name=\"{prefix}joint_{}\" type=\"revolute\"><parent link=\"{parent}\"/><child link=\"{child}\"/>{}<axis xyz=\"0 0 1\"/><limit lower=\"{}\" upper=\"{}\" velocity=\"{}\" effort=\"{}\"/></joint>\n",
            inertial(joint.mass_kg, joint.com_m),
            i + 1,
            origin(joint.a_prev_m, joint.alpha_prev_rad, joint.d_m),
            joint.lower_rad,
            joint.upper_rad,
            joint.velocity_rad_s,
            joint.effort_nm,
        );
        parent = child;
    }
    let _ = write!(
        out,
        "  <link name=\"{prefix}flange\"/>\n  <joint name=\"{prefix}flange_joint\" type=\"fixed\"><parent link=\"{parent}\"/><child link=\"{prefix}flange\"/>{}</joint>\n",
        origin(flange.0, flange.1, flange.2)
    );
}

/// A centre of mass given in the standard-DH frame i (at the far end of link i, after
/// Tx(a_i) Rx(alpha_i)) expressed in this file's link frame i (before them).
fn com_from_dh_frame(a_m: f64, alpha_rad: f64, com_in_dh: [f64; 3]) -> [f64; 3] {
    let p = Rotation3::from_axis_angle(&Vector3::x_axis(), alpha_rad)
        * Point3::new(com_in_dh[0], com_in_dh[1], com_in_dh[2]);
    [p.x + a_m, p.y, p.z]
}

/// The UR5e (e-Series) from Universal Robots' published standard DH table ("DH parameters for
/// calculations of kinematics and dynamics", universal-robots.com): a = (0, -0.425, -0.3922, 0,
/// 0, 0) m, d = (0.1625, 0, 0, 0.1333, 0.0997, 0.0996) m, alpha = (90, 0, 0, 90, -90, 0) deg; link
/// masses (3.761, 8.058, 2.846, 1.37, 1.3, 0.365) kg and centres of mass from the same table, in
/// the DH frames. Joint ranges +-360 deg and 180 deg/s from the UR5e technical specification;
/// torques 150 N m (base, shoulder, elbow) and 28 N m (wrists) as in UR's ROS description.
///
/// Links: `base_link` (ROS convention) -> `base` (turned 180 degrees about z: the controller's
/// base frame, the DH frame 0, as ROS-Industrial's `base_link-base_fixed_joint` does) ->
/// `link_1`..`link_6` -> `flange` (DH frame 6). Inertials are approximate (the published point
/// masses; inertia tensors are placeholders): enough for gravity-sag experiments only.
pub fn ur5e_dh_urdf() -> String {
    let a = [0.0, -0.425, -0.3922, 0.0, 0.0, 0.0];
    let d = [0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996];
    let alpha = [90.0f64, 0.0, 0.0, 90.0, -90.0, 0.0].map(f64::to_radians);
    let mass = [3.761, 8.058, 2.846, 1.37, 1.3, 0.365];
    let com_dh = [
        [0.0, -0.02561, 0.00193],
        [0.2125, 0.0, 0.11336],
        [0.15, 0.0, 0.0265],
        [0.0, -0.0018, 0.01634],
        [0.0, 0.0018, 0.01634],
        [0.0, 0.0, -0.001159],
    ];
    let effort = [150.0, 150.0, 150.0, 28.0, 28.0, 28.0];
    let turn = 2.0 * std::f64::consts::PI;
    let joints: Vec<DhJoint> = (0..6)
        .map(|i| DhJoint {
            a_prev_m: if i == 0 { 0.0 } else { a[i - 1] },
            alpha_prev_rad: if i == 0 { 0.0 } else { alpha[i - 1] },
            d_m: d[i],
            lower_rad: -turn,
            upper_rad: turn,
            velocity_rad_s: std::f64::consts::PI,
            effort_nm: effort[i],
            mass_kg: mass[i],
            com_m: com_from_dh_frame(a[i], alpha[i], com_dh[i]),
        })
        .collect();
    let mut out = String::from(
        "<?xml version=\"1.0\"?>\n<robot name=\"ur5e_dh\">\n  <link name=\"base_link\"/>\n  <link name=\"base\"/>\n  <joint name=\"base_link-base\" type=\"fixed\"><parent link=\"base_link\"/><child link=\"base\"/><origin xyz=\"0 0 0\" rpy=\"0 0 3.141592653589793\"/></joint>\n",
    );
    chain_urdf(&mut out, "base", "", &joints, (a[5], alpha[5], 0.0));
    out.push_str("</robot>\n");
    out
}

/// The Franka Emika Panda from Franka's published modified (Craig) DH table (Franka Control
/// Interface documentation, "Robot and interface specifications"): rows (a, d, alpha) =
/// (0, 0.333, 0), (0, 0, -90), (0, 0.316, 90), (0.0825, 0, 90), (-0.0825, 0.384, -90), (0, 0, 90),
/// (0.088, 0, 90) and the flange (0, 0.107, 0), m and degrees; joint limits from the same page:
/// +-2.8973 rad (joints 1, 3, 5, 7), +-1.7628 (2), [-3.0718, -0.0698] (4), [-0.0175, 3.7525] (6),
/// 2.175 rad/s (1-4) and 2.61 rad/s (5-7), 87 N m (1-4) and 12 N m (5-7).
///
/// Links: `link_0` (the base) -> `link_1`..`link_7` -> `flange`. Masses are rounded from a
/// published identification of the Panda's dynamics (Gaz et al., IEEE RA-L 2019); centres of
/// mass are rough guesses along each link: approximate, for gravity-sag experiments only.
pub fn panda_mdh_urdf() -> String {
    let rows: [(f64, f64, f64); 7] = [
        (0.0, 0.333, 0.0),
        (0.0, 0.0, -90.0),
        (0.0, 0.316, 90.0),
        (0.0825, 0.0, 90.0),
        (-0.0825, 0.384, -90.0),
        (0.0, 0.0, 90.0),
        (0.088, 0.0, 90.0),
    ];
    let limits = [
        (-2.8973, 2.8973),
        (-1.7628, 1.7628),
        (-2.8973, 2.8973),
        (-3.0718, -0.0698),
        (-2.8973, 2.8973),
        (-0.0175, 3.7525),
        (-2.8973, 2.8973),
    ];
    let mass = [4.97, 0.65, 3.23, 3.59, 1.23, 1.67, 0.74];
    let com = [
        [0.0, -0.04, -0.05],
        [0.0, -0.07, 0.03],
        [0.04, 0.03, -0.07],
        [-0.05, 0.1, 0.03],
        [0.0, 0.04, -0.11],
        [0.05, -0.01, 0.01],
        [0.0, 0.0, 0.08],
    ];
    let joints: Vec<DhJoint> = (0..7)
        .map(|i| DhJoint {
            a_prev_m: rows[i].0,
            alpha_prev_rad: rows[i].2.to_radians(),
            d_m: rows[i].1,
            lower_rad: limits[i].0,
            upper_rad: limits[i].1,
            velocity_rad_s: if i < 4 { 2.175 } else { 2.61 },
            effort_nm: if i < 4 { 87.0 } else { 12.0 },
            mass_kg: mass[i],
            com_m: com[i],
        })
        .collect();
    let mut out = String::from(
        "<?xml version=\"1.0\"?>\n<robot name=\"panda_mdh\">\n  <link name=\"link_0\"/>\n",
    );
    chain_urdf(&mut out, "link_0", "", &joints, (0.0, 0.0, 0.107));
    out.push_str("</robot>\n");
    out
}

/// The Panda's "ready" pose from Franka's examples: (0, -pi/4, 0, -3pi/4, 0, pi/2, pi/4).
pub const PANDA_READY_RAD: [f64; 7] = [
    0.0,
    -std::f64::consts::FRAC_PI_4,
    0.0,
    -3.0 * std::f64::consts::FRAC_PI_4,
    0.0,
    std::f64::consts::FRAC_PI_2,
    std::f64::consts::FRAC_PI_4,
];
