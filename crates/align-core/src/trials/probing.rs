//! Planning touches on a part: where to touch, and the joint configuration that puts the probe's
//! ball on each point with the probe along the inward normal. Used by the example data, `ips demo`
//! (to drive the simulated robot) and the diagnosis tests.

use crate::kinematics::{Chain, IkError, IkOptions};
use nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// Touches on the step block (part frame: point on the surface, outward normal) for a part on a
/// table, reachable from above and the sides: three on the top, two on the front, one on the
/// left end, then the step's tread and riser and the right end.
pub fn step_block_table_touches() -> Vec<(Point3<f64>, Vector3<f64>)> {
    let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
    vec![
        (Point3::new(0.05, 0.05, 0.15), z),
        (Point3::new(0.17, 0.06, 0.15), z),
        (Point3::new(0.1, 0.16, 0.15), z),
        (Point3::new(0.06, 0.0, 0.09), -y),
        (Point3::new(0.24, 0.0, 0.04), -y),
        (Point3::new(0.0, 0.1, 0.08), -x),
        (Point3::new(0.26, 0.12, 0.07), z),
        (Point3::new(0.2, 0.06, 0.11), x),
        (Point3::new(0.3, 0.15, 0.035), x),
    ]
}

/// Sixteen touches for diagnosis (enough to fit the pose plus six joint offsets), with probe
/// tilts up to 23 degrees so that a ball-radius change and a TCP shift look different:
/// (point, outward normal, tilt in rad).
pub fn step_block_diagnosis_touches() -> Vec<(Point3<f64>, Vector3<f64>, f64)> {
    let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
    vec![
        (Point3::new(0.05, 0.05, 0.15), z, 0.0),
        (Point3::new(0.17, 0.06, 0.15), z, 0.35),
        (Point3::new(0.1, 0.16, 0.15), z, 0.2),
        (Point3::new(0.03, 0.17, 0.15), z, 0.4),
        (Point3::new(0.18, 0.18, 0.15), z, 0.1),
        (Point3::new(0.06, 0.0, 0.09), -y, 0.1),
        (Point3::new(0.24, 0.0, 0.04), -y, 0.3),
        (Point3::new(0.12, 0.0, 0.12), -y, 0.0),
        (Point3::new(0.02, 0.0, 0.03), -y, 0.25),
        (Point3::new(0.0, 0.1, 0.08), -x, 0.25),
        (Point3::new(0.0, 0.04, 0.12), -x, 0.0),
        (Point3::new(0.0, 0.17, 0.03), -x, 0.15),
        (Point3::new(0.26, 0.12, 0.07), z, 0.15),
        (Point3::new(0.2, 0.06, 0.11), x, 0.2),
        (Point3::new(0.3, 0.15, 0.035), x, 0.0),
        (Point3::new(0.3, 0.03, 0.02), x, 0.3),
    ]
}

/// Joint vectors touching each point of `touches` on the part at `base_from_part`, each solved
/// from the previous (so the arm moves little between touches).
pub fn joint_targets(
    chain: &Chain,
    base_from_part: &Isometry3<f64>,
    flange_from_tcp: &Isometry3<f64>,
    tip_radius_m: f64,
    touches: &[(Point3<f64>, Vector3<f64>)],
    seed: &[f64],
) -> Result<Vec<Vec<f64>>, IkError> {
    let tilted: Vec<_> = touches.iter().map(|(p, n)| (*p, *n, 0.0)).collect();
    tilted_joint_targets(
        chain,
        base_from_part,
        flange_from_tcp,
        tip_radius_m,
        1.0,
        &tilted,
        seed,
    )
}

/// As [`joint_targets`], with each probe tilted by its angle about a horizontal axis and the
/// part scaled by `part_scale` about its origin (the real part may be larger than its model).
pub fn tilted_joint_targets(
    chain: &Chain,
    base_from_part: &Isometry3<f64>,
    flange_from_tcp: &Isometry3<f64>,
    tip_radius_m: f64,
    part_scale: f64,
    touches: &[(Point3<f64>, Vector3<f64>, f64)],
    seed: &[f64],
) -> Result<Vec<Vec<f64>>, IkError> {
    let oriented: Vec<_> = touches
        .iter()
        .map(|(point, normal, tilt)| {
            let normal_base = base_from_part.rotation * normal;
            let tilt_axis = normal_base.cross(&Vector3::new(0.3, 1.0, 0.2)).normalize();
            let probe_axis = UnitQuaternion::from_scaled_axis(tilt_axis * *tilt) * -normal_base;
            (
                *point,
                *normal,
                base_from_part.rotation.inverse() * probe_axis,
            )
        })
        .collect();
    oriented_joint_targets(
        chain,
        base_from_part,
        flange_from_tcp,
        tip_radius_m,
        part_scale,
        &oriented,
        seed,
    )
}

/// As [`tilted_joint_targets`], with each probe's axis (pointing from the flange to the ball,
/// part frame) given: a ball touches a face wherever its stylus points, as a CMM touches side
/// faces with a vertical stylus.
pub fn oriented_joint_targets(
    chain: &Chain,
    base_from_part: &Isometry3<f64>,
    flange_from_tcp: &Isometry3<f64>,
    tip_radius_m: f64,
    part_scale: f64,
    touches: &[(Point3<f64>, Vector3<f64>, Vector3<f64>)],
    seed: &[f64],
) -> Result<Vec<Vec<f64>>, IkError> {
    let start = seed;
    let mut seed = seed.to_vec();
    let mut targets = Vec::with_capacity(touches.len());
    for (point, normal, probe_axis_in_part) in touches {
        let surface = Point3::from(point.coords * part_scale);
        let centre = base_from_part * (surface + normal * tip_radius_m);
        let probe_axis = (base_from_part.rotation * probe_axis_in_part).normalize();
        // Probe z along the approach; x roughly along base x so the wrist stays tidy.
        let helper = if probe_axis.x.abs() > 0.9 {
            Vector3::y()
        } else {
            Vector3::x()
        };
        let y_axis = probe_axis.cross(&helper).normalize();
        let x_axis = y_axis.cross(&probe_axis);
        let rotation = Rotation3::from_basis_unchecked(&[x_axis, y_axis, probe_axis]);
        let base_from_tcp = Isometry3::from_parts(
            Translation3::from(centre.coords),
            UnitQuaternion::from_rotation_matrix(&rotation),
        );
        let base_from_flange = base_from_tcp * flange_from_tcp.inverse();
        // From the previous touch first (short moves); a redundant arm near its limits (the
        // iiwa) may need many restarts, so failing that, from the caller's seed with more.
        let solution = chain
            .inverse(&base_from_flange, &seed, &IkOptions::default())
            .or_else(|_| {
                chain.inverse(
                    &base_from_flange,
                    start,
                    &IkOptions {
                        max_attempts: 300,
                        ..IkOptions::default()
                    },
                )
            })?;
        seed.clone_from(&solution.q);
        targets.push(solution.q);
    }
    Ok(targets)
}
