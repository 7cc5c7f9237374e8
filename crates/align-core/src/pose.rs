//! Pose conventions shared by every file format and message: URDF roll-pitch-yaw (fixed axes
//! X, then Y, then Z, i.e. `R = Rz(yaw) * Ry(pitch) * Rx(roll)`) and 4x4 row-major matrices.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// Builds a transform from a translation and URDF roll-pitch-yaw angles.
pub fn isometry_from_xyz_rpy(xyz: [f64; 3], rpy: [f64; 3]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(xyz[0], xyz[1], xyz[2]),
        UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
    )
}

/// URDF roll-pitch-yaw of a rotation; at pitch = +-pi/2 roll is set to zero and yaw carries the
/// remaining rotation, so the result always reproduces the rotation.
pub fn rpy_from_rotation(rotation: &UnitQuaternion<f64>) -> [f64; 3] {
    // From R = Rz(yaw) Ry(pitch) Rx(roll). Pitch comes from atan2 rather than asin(-r20), which
    // loses half the digits near +-pi/2 (nalgebra's euler_angles does that).
    let r = rotation.to_rotation_matrix();
    let r = r.matrix();
    let cos_pitch = r[(0, 0)].hypot(r[(1, 0)]);
    let pitch = (-r[(2, 0)]).atan2(cos_pitch);
    if cos_pitch < 1e-12 {
        // Gimbal lock: only yaw - roll (or yaw + roll) is defined; put it all in yaw.
        [0.0, pitch, (-r[(0, 1)]).atan2(r[(1, 1)])]
    } else {
        [
            r[(2, 1)].atan2(r[(2, 2)]),
            pitch,
            r[(1, 0)].atan2(r[(0, 0)]),
        ]
    }
}

/// Translation and roll-pitch-yaw of a transform.
pub fn xyz_rpy(pose: &Isometry3<f64>) -> ([f64; 3], [f64; 3]) {
    let t = pose.translation.vector;
    ([t.x, t.y, t.z], rpy_from_rotation(&pose.rotation))
}

/// The homogeneous 4x4 matrix of a transform, as rows.
pub fn matrix_rows(pose: &Isometry3<f64>) -> [[f64; 4]; 4] {
    let m = pose.to_homogeneous();
    std::array::from_fn(|row| std::array::from_fn(|col| m[(row, col)]))
}

/// Rotation-vector (axis times angle) error that turns `current` into `target`, in the frame both
/// are expressed in: `exp([e]x) * current = target`.
pub fn rotation_error(current: &UnitQuaternion<f64>, target: &UnitQuaternion<f64>) -> Vector3<f64> {
    (target * current.inverse()).scaled_axis()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn rpy_is_fixed_axis_xyz() {
        let pose = isometry_from_xyz_rpy([0.0; 3], [0.3, -0.2, 1.1]);
        let expected = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 1.1)
            * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -0.2)
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.3);
        assert!(pose.rotation.angle_to(&expected) < 1e-15);
    }

    #[test]
    fn rpy_round_trips_including_gimbal_lock() {
        for rpy in [
            [0.1, 0.2, 0.3],
            [0.4, FRAC_PI_2, -0.7],
            [0.4, -FRAC_PI_2, 0.2],
        ] {
            let rotation = UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]);
            let back = rpy_from_rotation(&rotation);
            let again = UnitQuaternion::from_euler_angles(back[0], back[1], back[2]);
            assert!(rotation.angle_to(&again) < 1e-12, "{rpy:?} -> {back:?}");
        }
    }
}
