//! Point Set Alignment on parts built in the test (nothing here depends on the shipped parts):
//! exact recovery on noiseless touches, error consistent with the noise, degenerate touch sets
//! named, symmetric parts reported ambiguous, face hints resolving them.

use align_core::geometry::Mesh;
use align_core::geometry::shapes::extrude;
use align_core::registration::psa::{
    Face, PsaMethod, PsaOptions, PsaTarget, Search, Touch, align_touches,
};
use nalgebra::{Isometry3, Matrix6, Point3, Translation3, UnitQuaternion, Vector3, Vector6};
use rand::{Rng, SeedableRng, rngs::StdRng};

const TIP_RADIUS_M: f64 = 0.003;

/// A standard normal sample (Box-Muller).
fn gaussian(rng: &mut StdRng) -> f64 {
    let u: f64 = rng.random_range(f64::EPSILON..1.0);
    let v: f64 = rng.random();
    (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
}

/// A 200 x 100 x 150 mm block with a 60 x 40 mm step cut from one corner: no rotational symmetry.
fn step_block() -> Mesh {
    let outline = [
        [0.0, 0.0],
        [0.2, 0.0],
        [0.2, 0.06],
        [0.14, 0.06],
        [0.14, 0.1],
        [0.0, 0.1],
    ];
    extrude(&outline, 0.15).expect("step block")
}

/// (point on the surface, outward normal, face name) in the part frame: 3 on the bottom, 2 on the
/// front, 1 on the left end (3-2-1), then the top, the back and the step's face.
fn step_block_touches() -> Vec<(Point3<f64>, Vector3<f64>, &'static str)> {
    vec![
        (Point3::new(0.03, 0.02, 0.0), -Vector3::z(), "bottom"),
        (Point3::new(0.17, 0.03, 0.0), -Vector3::z(), "bottom"),
        (Point3::new(0.05, 0.08, 0.0), -Vector3::z(), "bottom"),
        (Point3::new(0.04, 0.0, 0.05), -Vector3::y(), "front"),
        (Point3::new(0.16, 0.0, 0.1), -Vector3::y(), "front"),
        (Point3::new(0.0, 0.05, 0.07), -Vector3::x(), "left"),
        (Point3::new(0.1, 0.05, 0.15), Vector3::z(), "top"),
        (Point3::new(0.07, 0.1, 0.08), Vector3::y(), "back"),
        (Point3::new(0.17, 0.06, 0.07), Vector3::y(), "step"),
    ]
}

fn step_block_faces() -> Vec<Face> {
    let face = |name: &str, normal: Vector3<f64>, point: Point3<f64>| Face {
        name: name.to_owned(),
        normal,
        point,
    };
    vec![
        face("bottom", -Vector3::z(), Point3::origin()),
        face("top", Vector3::z(), Point3::new(0.0, 0.0, 0.15)),
        face("front", -Vector3::y(), Point3::origin()),
        face("back", Vector3::y(), Point3::new(0.0, 0.1, 0.0)),
        face("left", -Vector3::x(), Point3::origin()),
        face("step", Vector3::y(), Point3::new(0.17, 0.06, 0.0)),
    ]
}

/// Ball-centre touches of the part at its true pose, optionally with Gaussian noise.
fn touches_at(
    truth: &Isometry3<f64>,
    surface: &[(Point3<f64>, Vector3<f64>, &'static str)],
    count: usize,
    noise: Option<(&mut StdRng, f64)>,
    with_faces: bool,
) -> Vec<Touch> {
    let mut noise = noise;
    surface
        .iter()
        .take(count)
        .enumerate()
        .map(|(index, (point, normal, face))| {
            let mut centre = truth * (point + normal * TIP_RADIUS_M);
            if let Some((rng, sigma)) = noise.as_mut() {
                let offset: Vector3<f64> = Vector3::from_fn(|_, _| gaussian(rng));
                centre += offset * *sigma;
            }
            Touch {
                id: (index + 1).to_string(),
                point: centre,
                approach: Some(truth.rotation * -normal),
                face: with_faces.then(|| (*face).to_owned()),
            }
        })
        .collect()
}

/// The thesis's random displacement (eq. 27-31): t = beta mu, R = exp(alpha mu'), beta ~ U[0,
/// delta], alpha ~ U[0, delta / r], mu and mu' independent random unit vectors.
fn displacement(rng: &mut StdRng, delta_m: f64, radius_m: f64) -> Isometry3<f64> {
    let mut unit = || {
        let v: Vector3<f64> = Vector3::from_fn(|_, _| gaussian(rng));
        v.normalize()
    };
    let (direction, axis) = (unit(), unit());
    let beta = rng.random_range(0.0..=delta_m);
    let alpha = rng.random_range(0.0..=delta_m / radius_m);
    Isometry3::from_parts(
        Translation3::from(direction * beta),
        UnitQuaternion::from_scaled_axis(axis * alpha),
    )
}

/// The start pose: the truth displaced about the part's centroid, so that delta bounds how far
/// the part's points move (beta + alpha r) wherever the part sits in the cell.
fn displaced(
    truth: &Isometry3<f64>,
    mesh: &Mesh,
    rng: &mut StdRng,
    delta_m: f64,
) -> Isometry3<f64> {
    let centre = Isometry3::translation(mesh.centroid().x, mesh.centroid().y, mesh.centroid().z);
    truth * centre * displacement(rng, delta_m, mesh.radius_m()) * centre.inverse()
}

fn base_from_part_truth() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.6, -0.1, 0.05),
        UnitQuaternion::from_euler_angles(0.0, 0.0, 0.4),
    )
}

fn options(tip_radius_m: f64) -> PsaOptions {
    PsaOptions {
        tip_radius_m,
        ..PsaOptions::default()
    }
}

#[test]
fn noiseless_touches_recover_random_poses_within_200_mm_to_a_micrometre() {
    let mesh = step_block();
    let target = PsaTarget::new(&mesh);
    let truth = base_from_part_truth();
    let mut rng = StdRng::seed_from_u64(1);
    for count in [6, 9] {
        let touches = touches_at(&truth, &step_block_touches(), count, None, false);
        for trial in 0..40 {
            let delta = [0.05, 0.1, 0.2][trial % 3];
            let start = displaced(&truth, &mesh, &mut rng, delta);
            let result =
                align_touches(&target, &touches, &start, &options(TIP_RADIUS_M)).expect("aligns");
            let position_error = (result.alignment.base_from_part.translation.vector
                - truth.translation.vector)
                .norm();
            let rotation_error = result
                .alignment
                .base_from_part
                .rotation
                .angle_to(&truth.rotation);
            if count == 9 {
                assert!(
                    !result.is_ambiguous(),
                    "9 touches with the step are unambiguous"
                );
            }
            // 6 touches on the bottom, front and left also fit the block turned half a turn about
            // its vertical axis (front -> back, left -> right end): then the result must be
            // reported ambiguous with the truth among the candidates.
            let truth_is_a_candidate = result.ambiguous_with.iter().any(|candidate| {
                (candidate.base_from_part.translation.vector - truth.translation.vector).norm()
                    < 1e-6
                    && candidate.base_from_part.rotation.angle_to(&truth.rotation) < 1e-6
            });
            if truth_is_a_candidate {
                continue;
            }
            assert!(
                position_error < 1e-6 && rotation_error < 1e-6,
                "{count} touches, trial {trial}: {position_error:e} m, {rotation_error:e} rad"
            );
            assert!(
                result.alignment.converged && result.alignment.rms_m < 1e-9,
                "{}",
                result.alignment.rms_m
            );
        }
    }
}

#[test]
fn local_search_alone_recovers_small_displacements_with_both_steps() {
    let mesh = step_block();
    let target = PsaTarget::new(&mesh);
    let truth = base_from_part_truth();
    let touches = touches_at(&truth, &step_block_touches(), 9, None, false);
    let mut rng = StdRng::seed_from_u64(2);
    // The basin of a closest-point method ends where a touch, pushed inside the part, finds
    // another face nearer than its own: these touches lie 20-30 mm from edges, so 10 mm.
    for method in [PsaMethod::PointToPlane, PsaMethod::PointToPoint] {
        let options = PsaOptions {
            method,
            search: Search::Local,
            tolerance_m: 1e-10,
            ..options(TIP_RADIUS_M)
        };
        for _ in 0..20 {
            let start = displaced(&truth, &mesh, &mut rng, 0.01);
            let result = align_touches(&target, &touches, &start, &options).expect("aligns");
            let error = (result.alignment.base_from_part.translation.vector
                - truth.translation.vector)
                .norm();
            // Point-to-point converges linearly (touches slide along faces a fraction per
            // iteration), so it is held to a looser bound than point-to-plane.
            let bound = if method == PsaMethod::PointToPlane {
                1e-9
            } else {
                1e-5
            };
            assert!(
                error < bound,
                "{method:?}: {error:e} m after {} iterations, rms {:e} {:?}, start {:e} m {} rad",
                result.alignment.iterations,
                result.alignment.rms_m,
                result.residuals,
                (start.translation.vector - truth.translation.vector).norm(),
                start.rotation.angle_to(&truth.rotation)
            );
        }
    }
}

/// With touch noise sigma, the pose error follows N(0, sigma^2 (J^T J)^-1), J the point-to-plane
/// Jacobian at the truth. Its Mahalanobis norm squared is chi-square with 6 degrees of freedom
/// (mean 6, variance 12); over 200 trials the mean lies within 6 +- 1.5 (6 standard errors).
#[test]
fn pose_error_under_noise_is_what_the_noise_predicts() {
    let mesh = step_block();
    let target = PsaTarget::new(&mesh);
    let truth = base_from_part_truth();
    let sigma = 50e-6;
    let surface = step_block_touches();
    let centre = truth * Point3::new(0.1, 0.05, 0.075);
    let mut information = Matrix6::zeros();
    for (point, normal, _) in &surface {
        let (p, n) = (truth * point, truth.rotation * normal);
        let lever = (p - centre).cross(&n);
        let row = Vector6::new(lever.x, lever.y, lever.z, n.x, n.y, n.z);
        information += row * row.transpose() / (sigma * sigma);
    }
    let mut rng = StdRng::seed_from_u64(3);
    let trials = 200;
    let mut sum = 0.0;
    for _ in 0..trials {
        let touches = touches_at(&truth, &surface, 9, Some((&mut rng, sigma)), false);
        let start = displaced(&truth, &mesh, &mut rng, 0.02);
        let options = PsaOptions {
            search: Search::Local,
            ..options(TIP_RADIUS_M)
        };
        let result = align_touches(&target, &touches, &start, &options).expect("aligns");
        let delta = result.alignment.base_from_part * truth.inverse();
        let omega = delta.rotation.scaled_axis();
        // Express the error as rotation about `centre` followed by a translation t.
        let t = delta.translation.vector - centre.coords + delta.rotation * centre.coords;
        let error = Vector6::new(omega.x, omega.y, omega.z, t.x, t.y, t.z);
        sum += (error.transpose() * information * error)[0];
    }
    let mean = sum / trials as f64;
    assert!(
        (4.5..=7.5).contains(&mean),
        "mean Mahalanobis^2 {mean}, expected 6"
    );
}

#[test]
fn a_cube_probed_3_2_1_is_ambiguous_and_face_hints_resolve_the_step_block() {
    let cube = Mesh::cuboid([0.1, 0.1, 0.1]).expect("cube");
    let truth = base_from_part_truth();
    let surface = vec![
        (Point3::new(-0.02, -0.03, -0.05), -Vector3::z(), "bottom"),
        (Point3::new(0.03, -0.02, -0.05), -Vector3::z(), "bottom"),
        (Point3::new(0.0, 0.03, -0.05), -Vector3::z(), "bottom"),
        (Point3::new(-0.03, -0.05, 0.0), -Vector3::y(), "front"),
        (Point3::new(0.03, -0.05, 0.02), -Vector3::y(), "front"),
        (Point3::new(-0.05, 0.01, 0.01), -Vector3::x(), "left"),
    ];
    let touches = touches_at(&truth, &surface, 6, None, false);
    let result = align_touches(
        &PsaTarget::new(&cube),
        &touches,
        &truth,
        &options(TIP_RADIUS_M),
    )
    .expect("aligns");
    assert!(
        result.is_ambiguous(),
        "a cube has 24 rotations fitting 3-2-1 touches"
    );
    assert!(
        result.ambiguous_with.len() >= 5,
        "{}",
        result.ambiguous_with.len()
    );
    // The reported pose is the candidate nearest the start, here the truth.
    assert!(
        (result.alignment.base_from_part.translation.vector - truth.translation.vector).norm()
            < 1e-6
    );

    let block = step_block();
    let target = PsaTarget::new(&block)
        .with_faces(&step_block_faces())
        .expect("faces");
    let touches = touches_at(&truth, &step_block_touches(), 6, None, true);
    let mut rng = StdRng::seed_from_u64(4);
    for _ in 0..10 {
        let start = displaced(&truth, &block, &mut rng, 1.0);
        let result =
            align_touches(&target, &touches, &start, &options(TIP_RADIUS_M)).expect("aligns");
        assert!(!result.is_ambiguous());
        let error =
            (result.alignment.base_from_part.translation.vector - truth.translation.vector).norm();
        assert!(error < 1e-6, "{error:e}");
    }
}

#[test]
fn touch_sets_that_leave_a_dof_free_are_refused_naming_it() {
    let mesh = step_block();
    let target = PsaTarget::new(&mesh);
    let truth = Isometry3::identity();
    let surface = step_block_touches();
    // Bottom and front only: nothing stops the part sliding along x.
    let bottom_front: Vec<_> = surface[..5].to_vec();
    let touches = touches_at(&truth, &bottom_front, 5, None, false);
    let local = PsaOptions {
        search: Search::Local,
        ..options(TIP_RADIUS_M)
    };
    let error = align_touches(&target, &touches, &truth, &local).expect_err("x is free");
    let message = error.to_string();
    assert!(
        message.contains("translation along (1.000, 0.000, 0.000)")
            || message.contains("translation along (-1.000, 0.000, 0.000)"),
        "{message}"
    );
    // Bottom only: x, y and the rotation about z are free.
    let touches = touches_at(&truth, &surface[..3], 3, None, false);
    let error = align_touches(&target, &touches, &truth, &local).expect_err("free");
    assert!(
        error.to_string().contains("leave a degree of freedom free"),
        "{error}"
    );
    let error = align_touches(&target, &touches[..2], &truth, &local).expect_err("2 touches");
    assert_eq!(
        error.to_string(),
        "registration needs at least 3 points with positive weight, got 2"
    );
    let mut bad = touches_at(&truth, &surface, 6, None, false);
    bad[4].point.y = f64::NAN;
    let error = align_touches(&target, &bad, &truth, &local).expect_err("NaN");
    assert_eq!(error.to_string(), "point 4 or its weight is not finite");
}

#[test]
fn coherence_keeps_working_on_consistent_touches() {
    let mesh = step_block();
    let target = PsaTarget::new(&mesh);
    let truth = base_from_part_truth();
    let touches = touches_at(&truth, &step_block_touches(), 9, None, false);
    let mut rng = StdRng::seed_from_u64(6);
    let options = PsaOptions {
        coherence: true,
        search: Search::Local,
        ..options(TIP_RADIUS_M)
    };
    let start = displaced(&truth, &mesh, &mut rng, 0.05);
    let result = align_touches(&target, &touches, &start, &options).expect("aligns");
    assert!(
        (result.alignment.base_from_part.translation.vector - truth.translation.vector).norm()
            < 1e-6
    );
}
