//! Pose uncertainty of Point Set Alignment: the predicted covariance against a Monte Carlo of
//! noisy alignments, underconstrained touch sets named, a weakly constrained rotation found, and
//! linear scaling with the noise.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use align_core::geometry::Mesh;
use align_core::geometry::shapes::extrude;
use align_core::registration::psa::{PsaOptions, PsaTarget, Search, Touch, align_touches};
use align_core::registration::uncertainty::{
    CHI2_95_6DOF, UncertaintyError, WeakDirection, pose_deviation, pose_uncertainty,
    sigma_from_residuals,
};
use align_core::rng::SplitMix64;
use nalgebra::{Isometry3, Matrix6, Point3, Translation3, UnitQuaternion, Vector3, Vector6};

const TIP_RADIUS_M: f64 = 0.003;

fn pose(xyz: [f64; 3], rpy: [f64; 3]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(xyz[0], xyz[1], xyz[2]),
        UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
    )
}

/// A 200 x 100 x 150 mm prism whose outline has a slanted corner: seven faces, three of them
/// not parallel to any other.
fn slanted_block() -> Mesh {
    let outline = [[0.0, 0.0], [0.2, 0.0], [0.2, 0.06], [0.14, 0.1], [0.0, 0.1]];
    extrude(&outline, 0.15).unwrap()
}

/// 20 (surface point, outward normal) pairs on six faces of [`slanted_block`], part frame.
fn slanted_block_contacts() -> Vec<(Point3<f64>, Vector3<f64>)> {
    let slant = Vector3::new(0.04, 0.06, 0.0).normalize();
    let on_slant = |t: f64, z: f64| Point3::new(0.2 - 0.06 * t, 0.06 + 0.04 * t, z);
    vec![
        (Point3::new(0.03, 0.02, 0.0), -Vector3::z()),
        (Point3::new(0.17, 0.03, 0.0), -Vector3::z()),
        (Point3::new(0.05, 0.08, 0.0), -Vector3::z()),
        (Point3::new(0.12, 0.06, 0.0), -Vector3::z()),
        (Point3::new(0.04, 0.03, 0.15), Vector3::z()),
        (Point3::new(0.15, 0.05, 0.15), Vector3::z()),
        (Point3::new(0.08, 0.09, 0.15), Vector3::z()),
        (Point3::new(0.04, 0.0, 0.05), -Vector3::y()),
        (Point3::new(0.16, 0.0, 0.1), -Vector3::y()),
        (Point3::new(0.1, 0.0, 0.13), -Vector3::y()),
        (Point3::new(0.05, 0.1, 0.03), Vector3::y()),
        (Point3::new(0.1, 0.1, 0.12), Vector3::y()),
        (Point3::new(0.0, 0.05, 0.07), -Vector3::x()),
        (Point3::new(0.0, 0.02, 0.13), -Vector3::x()),
        (Point3::new(0.0, 0.08, 0.02), -Vector3::x()),
        (Point3::new(0.2, 0.02, 0.04), Vector3::x()),
        (Point3::new(0.2, 0.04, 0.12), Vector3::x()),
        (on_slant(0.3, 0.03), slant),
        (on_slant(0.5, 0.11), slant),
        (on_slant(0.8, 0.06), slant),
    ]
}

/// Touches (ball centres, base frame) at `truth`, each pushed `offsets[i]` along its normal.
fn touches(
    contacts: &[(Point3<f64>, Vector3<f64>)],
    truth: &Isometry3<f64>,
    offsets: &[f64],
) -> Vec<Touch> {
    contacts
        .iter()
        .zip(offsets)
        .enumerate()
        .map(|(index, ((point, normal), offset))| {
            let centre = point + normal * (TIP_RADIUS_M + offset);
            Touch {
                id: format!("{}", index + 1),
                point: truth * centre,
                approach: Some(truth.rotation * -normal),
                face: None,
            }
        })
        .collect()
}

#[test]
fn predicted_covariance_matches_a_monte_carlo_of_alignments() {
    let mesh = slanted_block();
    let contacts = slanted_block_contacts();
    let truth = pose([0.62, -0.25, 0.02], [0.1, -0.05, 0.3]);
    let sigma = 0.4e-3;
    let exact = touches(&contacts, &truth, &vec![0.0; contacts.len()]);
    let predicted = pose_uncertainty(&mesh, &exact, &truth, TIP_RADIUS_M, sigma).unwrap();

    let target = PsaTarget::new(&mesh);
    let options = PsaOptions {
        search: Search::Local,
        tip_radius_m: TIP_RADIUS_M,
        ..Default::default()
    };
    let mut rng = SplitMix64::new(20_240_611);
    let trials = 200;
    let mut deviations = Vec::with_capacity(trials);
    for _ in 0..trials {
        let offsets: Vec<f64> = (0..contacts.len())
            .map(|_| sigma * rng.gaussian())
            .collect();
        let noisy = touches(&contacts, &truth, &offsets);
        let result = align_touches(&target, &noisy, &truth, &options).unwrap();
        assert!(result.alignment.converged);
        deviations.push(pose_deviation(&truth, &result.alignment.base_from_part));
    }

    let mean = deviations.iter().fold(Vector6::zeros(), |sum, d| sum + d) / trials as f64;
    let empirical = deviations.iter().fold(Matrix6::zeros(), |sum, d| {
        sum + (d - mean) * (d - mean).transpose()
    }) / (trials - 1) as f64;
    let names = ["rx", "ry", "rz", "x", "y", "z"];
    let mut report = String::new();
    let mut worst: f64 = 0.0;
    for (i, name) in names.iter().enumerate() {
        let want = predicted.covariance[(i, i)].sqrt();
        let got = empirical[(i, i)].sqrt();
        let unit = if i < 3 { "mrad" } else { "mm" };
        report += &format!(
            "{name}: predicted sd {:.4} {unit}, empirical {:.4} {unit} ({:+.1}%)\n",
            want * 1e3,
            got * 1e3,
            (got / want - 1.0) * 100.0
        );
        worst = worst.max((got / want - 1.0).abs());
    }
    let inside = deviations
        .iter()
        .filter(|d| predicted.mahalanobis_squared(d).unwrap() <= CHI2_95_6DOF)
        .count();
    let coverage = inside as f64 / trials as f64;
    report += &format!("inside the 95% ellipsoid: {inside} of {trials}\n");
    // The pose distance (translation and angle times the radius, as a hypotenuse) the report
    // says 95 % of fits stay within.
    let radius_m = predicted.radius_m;
    let distance = |d: &Vector6<f64>| {
        (Vector3::new(d[0], d[1], d[2]).norm() * radius_m)
            .hypot(Vector3::new(d[3], d[4], d[5]).norm())
    };
    let within = deviations
        .iter()
        .filter(|d| distance(d) <= predicted.pose_distance_95_m)
        .count();
    report += &format!(
        "within the 95% pose distance ({:.4} mm): {within} of {trials}",
        predicted.pose_distance_95_m * 1e3
    );
    println!("{report}");
    assert!(worst < 0.25, "{report}");
    assert!((0.90..=1.0).contains(&coverage), "{report}");
    assert!(
        (0.90..=0.99).contains(&(within as f64 / trials as f64)),
        "{report}"
    );
    // The mean deviation is consistent with zero (no bias beyond 4 standard errors).
    for i in 0..6 {
        let standard_error = (predicted.covariance[(i, i)] / trials as f64).sqrt();
        assert!(mean[i].abs() < 4.0 * standard_error, "{i}: {report}");
    }
}

#[test]
fn touches_on_two_perpendicular_faces_name_the_free_translation() {
    let mesh = Mesh::cuboid([0.2, 0.15, 0.1]).unwrap();
    let contacts = vec![
        (Point3::new(-0.08, -0.05, 0.05), Vector3::z()),
        (Point3::new(0.07, -0.06, 0.05), Vector3::z()),
        (Point3::new(0.02, 0.06, 0.05), Vector3::z()),
        (Point3::new(-0.05, 0.03, 0.05), Vector3::z()),
        (Point3::new(0.1, -0.05, -0.03), Vector3::x()),
        (Point3::new(0.1, 0.05, -0.02), Vector3::x()),
        (Point3::new(0.1, 0.0, 0.03), Vector3::x()),
        (Point3::new(0.1, 0.04, 0.04), Vector3::x()),
    ];
    let truth = Isometry3::identity();
    let set = touches(&contacts, &truth, &[0.0; 8]);
    let error = pose_uncertainty(&mesh, &set, &truth, TIP_RADIUS_M, 1e-4).unwrap_err();
    let UncertaintyError::Underconstrained { motion, .. } = &error else {
        panic!("{error}");
    };
    assert!(
        motion.contains("translation along (0.000, 1.000, 0.000)"),
        "{error}"
    );

    // The same in a rotated pose: the free direction is the part's y axis in the base frame.
    let truth = pose([0.4, 0.1, 0.2], [0.0, 0.0, std::f64::consts::FRAC_PI_2]);
    let set = touches(&contacts, &truth, &[0.0; 8]);
    let error = pose_uncertainty(&mesh, &set, &truth, TIP_RADIUS_M, 1e-4).unwrap_err();
    assert!(
        error
            .to_string()
            .contains("translation along (1.000, 0.000, 0.000)"),
        "{error}"
    );
}

/// A 1 m bar of 50 x 50 mm section touched only near the edge where its top and side meet: the
/// roll about the bar's axis is barely constrained.
fn bar_touches(truth: &Isometry3<f64>) -> (Mesh, Vec<Touch>) {
    let mesh = Mesh::cuboid([1.0, 0.05, 0.05]).unwrap();
    let mut contacts = Vec::new();
    for (k, x) in [-0.45, -0.15, 0.15, 0.4].into_iter().enumerate() {
        let near = if k % 2 == 0 { 0.002 } else { -0.002 };
        contacts.push((Point3::new(x, near, 0.025), Vector3::z()));
        contacts.push((Point3::new(x + 0.03, 0.025, -near), Vector3::y()));
    }
    contacts.push((Point3::new(0.5, 0.001, -0.001), Vector3::x()));
    let offsets = vec![0.0; contacts.len()];
    let set = touches(&contacts, truth, &offsets);
    (mesh, set)
}

#[test]
fn a_weakly_constrained_roll_is_the_weak_direction() {
    let truth = pose([0.5, 0.3, 0.1], [0.2, 0.1, -0.4]);
    let (mesh, set) = bar_touches(&truth);
    let result = pose_uncertainty(&mesh, &set, &truth, TIP_RADIUS_M, 1e-4).unwrap();
    let bar_axis = truth.rotation * Vector3::x();
    println!("{}", result.weak_direction.describe());
    let WeakDirection::Rotation {
        axis,
        point,
        size_95_mrad,
    } = result.weak_direction
    else {
        panic!("{:?}", result.weak_direction);
    };
    let angle = axis.dot(&bar_axis).abs().min(1.0).acos().to_degrees();
    assert!(
        angle < 3.0,
        "axis {axis:?} is {angle:.2} degrees off the bar"
    );
    // The axis runs along the bar's centre line.
    let from_line = (point - truth.translation.vector).coords;
    let off_line = (from_line - bar_axis * bar_axis.dot(&from_line)).norm();
    assert!(
        off_line < 0.005,
        "axis {off_line} m off the bar's centre line"
    );
    // And it is by far the largest rotation uncertainty.
    let rotation = &result.rotation_95_mrad;
    assert!(
        rotation.semi_axes[0] > 5.0 * rotation.semi_axes[1],
        "{rotation:?}"
    );
    assert!(rotation.axes[0].dot(&bar_axis).abs() > 3f64.to_radians().cos());
    assert!(size_95_mrad > 0.0);
    assert!(
        result
            .weak_direction
            .describe()
            .starts_with("weakest: rotation about (")
    );
}

#[test]
fn the_uncertainty_scales_linearly_with_sigma() {
    let mesh = slanted_block();
    let contacts = slanted_block_contacts();
    let truth = pose([0.62, -0.25, 0.02], [0.1, -0.05, 0.3]);
    let set = touches(&contacts, &truth, &vec![0.0; contacts.len()]);
    let one = pose_uncertainty(&mesh, &set, &truth, TIP_RADIUS_M, 1e-4).unwrap();
    let three = pose_uncertainty(&mesh, &set, &truth, TIP_RADIUS_M, 3e-4).unwrap();
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()) + 1e-300;
    for (a, b) in one.covariance.iter().zip(three.covariance.iter()) {
        assert!(close(9.0 * a, *b), "{a} {b}");
    }
    for (a, b) in [
        (&one.position_95_mm, &three.position_95_mm),
        (&one.rotation_95_mrad, &three.rotation_95_mrad),
    ] {
        for i in 0..3 {
            assert!(close(3.0 * a.semi_axes[i], b.semi_axes[i]));
            assert!(close(3.0 * a.half_widths[i], b.half_widths[i]));
            assert!(a.axes[i].dot(&b.axes[i]) > 1.0 - 1e-9);
        }
    }
    assert_eq!(one.weak_direction.kind(), three.weak_direction.kind());
    assert!(close(
        3.0 * one.weak_direction.size_95().0,
        three.weak_direction.size_95().0
    ));
    assert!(one.weak_direction.axis().dot(&three.weak_direction.axis()) > 1.0 - 1e-9);
}

#[test]
fn blocks_half_widths_and_points_are_consistent() {
    let mesh = slanted_block();
    let contacts = slanted_block_contacts();
    let truth = pose([0.62, -0.25, 0.02], [0.1, -0.05, 0.3]);
    let set = touches(&contacts, &truth, &vec![0.0; contacts.len()]);
    let result = pose_uncertainty(&mesh, &set, &truth, TIP_RADIUS_M, 2e-4).unwrap();
    // Translation first is the same matrix reordered.
    let swapped = result.covariance_translation_first();
    assert_eq!(
        swapped.fixed_view::<3, 3>(0, 0),
        result.translation_covariance()
    );
    assert_eq!(
        swapped.fixed_view::<3, 3>(3, 3),
        result.rotation_covariance()
    );
    // At the reference point the position covariance is the translation block.
    let at_origin = result.position_covariance_at(&result.reference_point);
    assert!((at_origin - result.translation_covariance()).norm() < 1e-18);
    for i in 0..3 {
        let sd_mm = result.covariance[(i + 3, i + 3)].sqrt() * 1e3;
        assert!((result.position_95_mm.half_widths[i] - 1.959_964 * sd_mm).abs() < 1e-6 * sd_mm);
        // A semi-axis of the 3-dof ellipsoid is wider than any 1-dof half-width.
        assert!(result.position_95_mm.semi_axes[0] >= result.position_95_mm.half_widths[i]);
    }
    // The least uncertain point beats the origin and the centroid.
    let best = result.least_uncertain_point.unwrap();
    let centroid = truth * mesh.centroid();
    let trace = |p: &Point3<f64>| result.position_covariance_at(p).trace();
    assert!(trace(&best) <= trace(&result.reference_point) * (1.0 + 1e-12));
    assert!(trace(&best) <= trace(&centroid) * (1.0 + 1e-12));
    for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
        assert!(trace(&best) <= trace(&(best + axis * 0.01)));
    }
}

#[test]
fn sigma_from_residuals_uses_the_remaining_degrees_of_freedom() {
    let residuals = [1e-4, -2e-4, 2e-4, 0.0, -1e-4, 1e-4, 3e-4, -1e-4];
    let rss: f64 = residuals.iter().map(|r| r * r).sum();
    let sigma = sigma_from_residuals(&residuals, 6).unwrap();
    assert!((sigma - (rss / 2.0).sqrt()).abs() < 1e-15);
    assert!(matches!(
        sigma_from_residuals(&residuals[..6], 6),
        Err(UncertaintyError::TooFewResiduals { .. })
    ));
    assert!(sigma_from_residuals(&[1.0, f64::NAN, 0.0], 1).is_err());
}

#[test]
fn bad_inputs_are_refused() {
    let mesh = slanted_block();
    let contacts = slanted_block_contacts();
    let truth = Isometry3::identity();
    let set = touches(&contacts, &truth, &vec![0.0; contacts.len()]);
    assert!(matches!(
        pose_uncertainty(&mesh, &set[..5], &truth, TIP_RADIUS_M, 1e-4),
        Err(UncertaintyError::TooFewTouches { count: 5 })
    ));
    assert!(matches!(
        pose_uncertainty(&mesh, &set, &truth, TIP_RADIUS_M, -1.0),
        Err(UncertaintyError::InvalidSigma(_))
    ));
    assert!(matches!(
        pose_uncertainty(&mesh, &set, &truth, f64::NAN, 1e-4),
        Err(UncertaintyError::InvalidTipRadius(_))
    ));
}
