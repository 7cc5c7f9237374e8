//! Alignment and diagnosis on touches made another way than the simulator's planner
//! (`align_core::corpus`): CAD-like parts, touches anywhere the probe fits, tilts up to 60
//! degrees plus side contacts at 90, 0.3-0.5 mm noise, blind starts, a robot built from a
//! published DH table with another base convention, effects nobody declared.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use align_core::corpus::parts::{fixture_plate, open_shell, thin_wall_bracket};
use align_core::corpus::robots::ur5e_dh_urdf;
use align_core::corpus::sessions::{
    HiddenEffects, JointSession, ProbeTool, SessionRobot, generate_session,
};
use align_core::corpus::touches::{TouchOptions, blind_start, on_table, sample_touches};
use align_core::diagnosis::{TouchSample, Verdict, diagnose};
use align_core::geometry::Mesh;
use align_core::kinematics::{Chain, PackageMap, RobotModel};
use align_core::registration::pose_distance;
use align_core::registration::psa::{
    PsaOptions, PsaResult, PsaTarget, Search, Touch, align_touches,
};
use align_core::rng::SplitMix64;
use align_core::tool::Tool;
use nalgebra::{Isometry3, Vector3};

fn psa_touches(set: &[align_core::corpus::touches::SampledTouch]) -> Vec<Touch> {
    set.iter()
        .map(|t| {
            let mut touch = Touch::new(t.id.clone(), t.ball_centre_in_base);
            touch.approach = Some(t.approach_in_base);
            touch
        })
        .collect()
}

/// The least-squares optimum the touches support: a plain local fit from the truth.
fn optimum(
    target: &PsaTarget<'_>,
    touches: &[Touch],
    truth: &Isometry3<f64>,
    radius: f64,
) -> PsaResult {
    let options = PsaOptions {
        tip_radius_m: radius,
        search: Search::Local,
        coherence: false,
        ..PsaOptions::default()
    };
    align_touches(target, touches, truth, &options).unwrap()
}

/// Regression (real touch sets, issue 18): the 45-degree coherence cone rejected true contacts
/// and the blind global search landed 45-216 mm off. Touches tilted up to 60 degrees with side
/// contacts at 90, 0.3-0.5 mm noise, a blind start: the result is the least-squares optimum.
#[test]
fn blind_global_alignment_of_steeply_tilted_noisy_touches_finds_the_least_squares_optimum() {
    let parts: [(&str, Mesh); 2] = [
        ("fixture_plate", fixture_plate().unwrap()),
        ("thin_wall_bracket", thin_wall_bracket().unwrap()),
    ];
    let options = TouchOptions {
        floor_z_in_base: Some(0.0),
        ..TouchOptions::default()
    };
    let (mut found, mut sessions) = (0, 0);
    for (name, mesh) in &parts {
        let target = PsaTarget::new(mesh);
        for session in 0..3u64 {
            sessions += 1;
            let mut rng = SplitMix64::new(0x5eed_0000 + session);
            let truth = on_table(mesh, rng.uniform() * std::f64::consts::TAU, [0.5, 0.0], 0.0);
            let set = sample_touches(mesh, &truth, 20, &options, &mut rng).unwrap();
            assert!(
                set.touches.iter().filter(|t| t.tilt_rad > 0.8).count() >= 3,
                "steep touches drawn"
            );
            let touches = psa_touches(&set.touches);
            let best = optimum(&target, &touches, &truth, options.ball_radius_m);
            let start = blind_start(&set.touches, mesh, &mut rng);
            let result = align_touches(
                &target,
                &touches,
                &start,
                &PsaOptions {
                    tip_radius_m: options.ball_radius_m,
                    ..PsaOptions::default()
                },
            )
            .unwrap();
            let apart = pose_distance(
                &result.alignment.base_from_part,
                &best.alignment.base_from_part,
                mesh.radius_m(),
            );
            assert!(result.alignment.converged, "{name} session {session}");
            if apart < 1e-3 && result.alignment.rms_m <= best.alignment.rms_m * 1.01 + 1e-6 {
                found += 1;
                assert!(result.incoherent.is_empty(), "{:?}", result.incoherent);
            } else {
                println!(
                    "{name} session {session}: {:.1} mm from the optimum, rms {:.4} mm against {:.4} mm",
                    apart * 1e3,
                    result.alignment.rms_m * 1e3,
                    best.alignment.rms_m * 1e3
                );
            }
        }
    }
    // Not yet every session: measured 5 of 6 (fixture_plate session 1 ends in another minimum,
    // rms 1.16 mm against 0.33 mm); docs/touch-corpus.md has the larger table.
    assert!(found >= 5, "{found}/{sessions} at the optimum");
}

/// Regression: the local fit stopped "NOT converged after 330 iterations" above the optimum.
/// Property over 24 seeded sessions with tilts up to 90 degrees: from a start 5-10 mm and a few
/// degrees off, the default local fit always converges, and to the least-squares optimum (or a
/// better fit) in at least 22.
#[test]
fn local_fit_with_tilts_up_to_90_degrees_converges_to_the_least_squares_optimum() {
    let mesh = fixture_plate().unwrap();
    let target = PsaTarget::new(&mesh);
    let options = TouchOptions {
        max_tilt_rad: 90f64.to_radians(),
        floor_z_in_base: Some(0.0),
        ..TouchOptions::default()
    };
    let (mut at_optimum, mut refused) = (0, 0);
    for session in 0..24u64 {
        let mut rng = SplitMix64::new(0x90de_0000 + session);
        let truth = on_table(
            &mesh,
            rng.uniform() * std::f64::consts::TAU,
            [0.5, 0.1],
            0.0,
        );
        let set = sample_touches(&mesh, &truth, 16, &options, &mut rng).unwrap();
        let touches = psa_touches(&set.touches);
        let Ok(best) = align_touches(
            &target,
            &touches,
            &truth,
            &PsaOptions {
                tip_radius_m: options.ball_radius_m,
                search: Search::Local,
                coherence: false,
                ..PsaOptions::default()
            },
        ) else {
            // Sixteen touches drawn by area can leave a motion free: refused, tested elsewhere.
            refused += 1;
            continue;
        };
        let offset = Isometry3::new(
            rng.unit_vector() * (0.005 + 0.005 * rng.uniform()),
            rng.unit_vector() * 0.04 * rng.uniform(),
        );
        let start = truth * offset;
        let result = align_touches(
            &target,
            &touches,
            &start,
            &PsaOptions {
                tip_radius_m: options.ball_radius_m,
                search: Search::Local,
                ..PsaOptions::default()
            },
        );
        let Ok(result) = result else {
            refused += 1;
            continue;
        };
        let apart = pose_distance(
            &result.alignment.base_from_part,
            &best.alignment.base_from_part,
            mesh.radius_m(),
        );
        assert!(
            result.alignment.converged,
            "session {session}: {} iterations",
            result.alignment.iterations
        );
        if apart < 1e-5 || result.alignment.rms_m < best.alignment.rms_m {
            at_optimum += 1;
        } else {
            println!(
                "session {session}: another minimum {:.2} mm from the optimum, rms {:.4} against {:.4} mm",
                apart * 1e3,
                result.alignment.rms_m * 1e3,
                best.alignment.rms_m * 1e3
            );
        }
    }
    // A closest-point method has a basin: 10 mm off, with a quarter of the touches at 60-90
    // degrees, one start in 24 lands in a neighbouring minimum (measured: session 15).
    assert!(
        at_optimum + refused >= 22,
        "{at_optimum}/{} at the optimum",
        24 - refused
    );
}

fn ur5e() -> Chain {
    RobotModel::from_urdf_str(&ur5e_dh_urdf(), &PackageMap::new())
        .unwrap()
        .chain("base_link", "flange")
        .unwrap()
}

fn session_on(
    chain: &Chain,
    hidden: &HiddenEffects,
    mesh: &Mesh,
    count: usize,
    sigma_m: f64,
    seed: u64,
) -> JointSession {
    let tool = ProbeTool::straight(0.15, 0.003);
    let seeds = vec![
        vec![0.0, -1.3, 1.6, -1.9, -1.57, 0.0],
        vec![0.6, -1.0, 1.2, -1.7, -1.57, 0.5],
        vec![-0.6, -1.6, 2.0, -2.0, -1.57, -0.5],
    ];
    let robot = SessionRobot {
        chain,
        tool: &tool,
        hidden,
        seeds: &seeds,
    };
    let options = TouchOptions {
        max_tilt_rad: 35f64.to_radians(),
        side_contact_fraction: 0.0,
        sigma_range_m: (sigma_m, sigma_m),
        ..TouchOptions::default()
    };
    let mut rng = SplitMix64::new(seed);
    generate_session(&robot, mesh, count, &options, &mut rng).unwrap()
}

fn samples(session: &JointSession) -> Vec<TouchSample> {
    session
        .touches
        .iter()
        .map(|t| TouchSample::from_joints(t.touch.id.clone(), t.q_reported.clone(), None))
        .collect()
}

fn aligned(chain: &Chain, tool: &Tool, mesh: &Mesh, session: &JointSession) -> Isometry3<f64> {
    let touches: Vec<Touch> = session
        .touches
        .iter()
        .map(|t| {
            let tcp = chain.forward(&t.q_reported).unwrap() * tool.flange_from_tcp;
            let mut touch = Touch::new(t.touch.id.clone(), tcp.translation.vector.into());
            touch.approach = Some(tcp.rotation * Vector3::z());
            touch
        })
        .collect();
    align_touches(
        &PsaTarget::new(mesh),
        &touches,
        &session.base_from_part_truth,
        &PsaOptions {
            tip_radius_m: tool.tip_radius_m,
            search: Search::Local,
            ..PsaOptions::default()
        },
    )
    .unwrap()
    .alignment
    .base_from_part
}

/// Regression (independent synthetic sessions, issue 18): encoder offsets of 2-3 mrad on a UR's
/// three parallel joints together were never found (the parameter reduction dropped what the
/// data needed). A UR5e built from UR's DH table with ROS-Industrial's base turn, 24 touches.
#[test]
fn offsets_on_the_three_parallel_joints_of_a_ur_together_are_found() {
    let chain = ur5e();
    let mesh = fixture_plate().unwrap();
    let tool = Tool::new(Isometry3::translation(0.0, 0.0, 0.15), 0.003, 0.0).unwrap();
    let mut hidden = HiddenEffects::none(6);
    hidden.joint_offsets_rad = vec![0.0, 2e-3, -3e-3, 2.5e-3, 0.0, 0.0];
    let sigma = 5e-5;
    let mut found = 0;
    for seed in [11, 12, 13] {
        let session = session_on(&chain, &hidden, &mesh, 24, sigma, seed);
        let samples = samples(&session);
        let start = aligned(&chain, &tool, &mesh, &session);
        let diagnosis = diagnose(Some(&chain), &tool, &mesh, &samples, &start, sigma).unwrap();
        let report = format!(
            "{} ({}); before {:.1} um, after {:.1} um; {:?}; alternatives {:?}",
            diagnosis.verdict.name(),
            diagnosis.explanation,
            diagnosis.before.rms_m * 1e6,
            diagnosis.after.rms_m * 1e6,
            diagnosis.effect.as_ref().map(|(n, f)| (n, &f.params)),
            diagnosis
                .alternatives
                .iter()
                .map(|a| (&a.name, &a.reason))
                .collect::<Vec<_>>()
        );
        println!("seed {seed}: {report}");
        if diagnosis.verdict != Verdict::Effect {
            // Never a confident wrong answer: at worst the offsets are tied with an effect the
            // pose absorbs (measured on seed 13: BIC 46.3 against 40.4).
            assert_eq!(diagnosis.verdict, Verdict::Ambiguous, "{report}");
            assert!(diagnosis.explanation.contains("joint_offsets"), "{report}");
            continue;
        }
        found += 1;
        let (name, fit) = diagnosis.effect.clone().unwrap();
        assert_eq!(name, "joint_offsets", "{report}");
        for (parameter, truth) in [
            ("joint_2_rad", 2e-3),
            ("joint_3_rad", -3e-3),
            ("joint_4_rad", 2.5e-3),
        ] {
            let (_, value, stderr) = fit.params.iter().find(|(p, _, _)| p == parameter).unwrap();
            assert!(
                (value - truth).abs() <= 3.0 * stderr.max(1e-4),
                "{parameter}: {report}"
            );
        }
        assert!(fit.rms_m < 1.5 * sigma, "{report}");
        assert!(
            fit.loo_rms_m < diagnosis.before.loo_rms_m / 2.0,
            "held out {:.1} um against {:.1} um before: {report}",
            fit.loo_rms_m * 1e6,
            diagnosis.before.loo_rms_m * 1e6
        );
    }
    assert!(found >= 2, "found on {found} of 3 sessions");
}

/// Regression: on a mesh that is not closed, distances were signed towards the probe, and a side
/// contact (its face's normal square to the probe) flipped sides with the noise; the fit from the
/// true pose then ended at 0.47 mm rms where the touches sit 0.35 mm from the surface. Now the
/// least-squares fit is never worse than the truth's own residual.
#[test]
fn an_open_mesh_fitted_from_the_truth_ends_no_worse_than_the_truth() {
    let mesh = open_shell().unwrap();
    assert!(!mesh.is_watertight());
    let target = PsaTarget::new(&mesh);
    let options = TouchOptions {
        floor_z_in_base: Some(0.0),
        ..TouchOptions::default()
    };
    for session in 0..3u64 {
        let mut rng = SplitMix64::new(0x0be4_0000 + session);
        let truth = on_table(
            &mesh,
            rng.uniform() * std::f64::consts::TAU,
            [0.5, 0.0],
            0.0,
        );
        let set = sample_touches(&mesh, &truth, 65, &options, &mut rng).unwrap();
        let touches = psa_touches(&set.touches);
        let part_from_base = truth.inverse();
        let at_truth = (set
            .touches
            .iter()
            .map(|t| {
                let d = mesh.closest_point(&(part_from_base * t.ball_centre_in_base));
                (d.signed_distance.abs() - options.ball_radius_m).powi(2)
            })
            .sum::<f64>()
            / set.touches.len() as f64)
            .sqrt();
        let fit = optimum(&target, &touches, &truth, options.ball_radius_m);
        assert!(
            fit.alignment.rms_m <= at_truth * 1.001,
            "session {session}: {:.4} mm against {:.4} mm at the truth",
            fit.alignment.rms_m * 1e3,
            at_truth * 1e3
        );
    }
}

/// A diagnosis with its reasons, for failure messages.
fn describe(diagnosis: &align_core::diagnosis::Diagnosis) -> String {
    format!(
        "{} ({}); before {:.1} um (held out {:.1}), after {:.1} um (held out {:.1}); {:?}; alternatives {:?}",
        diagnosis.verdict.name(),
        diagnosis.explanation,
        diagnosis.before.rms_m * 1e6,
        diagnosis.before.loo_rms_m * 1e6,
        diagnosis.after.rms_m * 1e6,
        diagnosis.after.loo_rms_m * 1e6,
        diagnosis.effect.as_ref().map(|(n, f)| (n, &f.params)),
        diagnosis
            .alternatives
            .iter()
            .map(|a| (&a.name, &a.reason))
            .collect::<Vec<_>>()
    )
}

/// A UR5e session of `count` touches on `mesh` made with `hidden` effects, aligned from the
/// truth and diagnosed with the declared `sigma`; the 15 cm straight probe with a 3 mm ball.
fn diagnosed(
    chain: &Chain,
    mesh: &Mesh,
    hidden: &HiddenEffects,
    count: usize,
    sigma: f64,
    seed: u64,
) -> align_core::diagnosis::Diagnosis {
    let tool = Tool::new(Isometry3::translation(0.0, 0.0, 0.15), 0.003, 0.0).unwrap();
    let session = session_on(chain, hidden, mesh, count, sigma, seed);
    let start = aligned(chain, &tool, mesh, &session);
    diagnose(Some(chain), &tool, mesh, &samples(&session), &start, sigma).unwrap()
}

/// Regression (independent synthetic sessions, issue 18): gravity sag was missed in one session
/// of three. A UR5e from UR's published DH table and masses, a hidden compliance on the shoulder
/// and elbow, 24 touches on a small plate: found, with the held-out error falling, or at worst
/// tied with the encoder offsets it resembles there (the shoulder's gravity torque changes little
/// over a plate 0.2 m across), never missed or misnamed.
#[test]
fn gravity_sag_of_an_independent_robot_is_found_or_tied_never_missed() {
    let chain = ur5e();
    let mesh = fixture_plate().unwrap();
    let mut hidden = HiddenEffects::none(6);
    hidden.compliance_rad_per_nm = vec![0.0, 4e-5, 6e-5, 0.0, 0.0, 0.0];
    let sigma = 5e-5;
    let mut found = 0;
    for seed in [21, 22, 23] {
        let diagnosis = diagnosed(&chain, &mesh, &hidden, 24, sigma, seed);
        let report = describe(&diagnosis);
        println!("seed {seed}: {report}");
        let (name, fit) = diagnosis.effect.clone().unwrap();
        assert_eq!(name, "joint_compliance", "seed {seed}: {report}");
        if diagnosis.verdict == Verdict::Effect {
            assert!(fit.rms_m < 1.5 * sigma, "seed {seed}: {report}");
            assert!(
                diagnosis.after.loo_rms_m < diagnosis.before.loo_rms_m / 2.0,
                "seed {seed}: {report}"
            );
            found += 1;
        } else {
            assert_eq!(
                diagnosis.verdict,
                Verdict::Ambiguous,
                "seed {seed}: {report}"
            );
            assert!(
                diagnosis.explanation.contains("joint_compliance"),
                "{report}"
            );
        }
    }
    assert!(found >= 2, "found in {found} of 3 sessions");
}

/// Pairs compete with single effects (issue 18): a TCP error and a part larger than its CAD model
/// together are named as the pair, and the pair's correction generalises (held-out error).
#[test]
fn a_tcp_error_and_a_part_scale_together_are_found_as_a_pair() {
    let chain = ur5e();
    let mesh = fixture_plate().unwrap();
    let mut hidden = HiddenEffects::none(6);
    hidden.tcp_error_m = Vector3::new(0.0015, -0.001, 0.0);
    hidden.part_scale = 1.004;
    let sigma = 5e-5;
    let mut found = 0;
    for seed in [31, 32, 33] {
        let diagnosis = diagnosed(&chain, &mesh, &hidden, 40, sigma, seed);
        let report = describe(&diagnosis);
        println!("seed {seed}: {report}");
        // Never a single effect named in the pair's place.
        if diagnosis.verdict == Verdict::Effect {
            let (name, fit) = diagnosis.effect.clone().unwrap();
            assert_eq!(name, "tcp_offset+part_scale", "seed {seed}: {report}");
            let scale = fit.params.iter().find(|p| p.0 == "scale_minus_one");
            if let Some((_, value, stderr)) = scale {
                assert!((value - 0.004).abs() <= 3.0 * stderr.max(2e-4), "{report}");
            }
            assert!(
                diagnosis.after.loo_rms_m < diagnosis.before.loo_rms_m / 2.0,
                "{report}"
            );
            found += 1;
        } else {
            assert_eq!(
                diagnosis.verdict,
                Verdict::Ambiguous,
                "seed {seed}: {report}"
            );
        }
    }
    assert!(found >= 2, "the pair found in {found} of 3 sessions");
}

/// Regression (issue 18): with a TCP error or a kinematic error present, the alignment from a
/// nominal pose 10-30 mm off ended 3-6 mm rms where the pose-only optimum was 0.2-0.55 mm. The
/// default (global) alignment must reach the fit the diagnosis's pose-only stage finds.
#[test]
fn with_a_tcp_or_kinematic_error_the_alignment_reaches_the_pose_only_optimum() {
    let chain = ur5e();
    let tool = Tool::new(Isometry3::translation(0.0, 0.0, 0.15), 0.003, 0.0).unwrap();
    let sigma = 5e-5;
    let mut tcp = HiddenEffects::none(6);
    tcp.tcp_error_m = Vector3::new(0.002, 0.0, 0.001);
    let mut kinematic = HiddenEffects::none(6);
    kinematic.joint_offsets_rad = vec![0.0, 2e-3, -3e-3, 2.5e-3, 0.0, 0.0];
    for (case, mesh, hidden) in [
        ("tcp, bracket", thin_wall_bracket().unwrap(), &tcp),
        ("joints, bracket", thin_wall_bracket().unwrap(), &kinematic),
        ("tcp, plate", fixture_plate().unwrap(), &tcp),
    ] {
        let session = session_on(&chain, hidden, &mesh, 30, sigma, 41);
        let touches: Vec<Touch> = session
            .touches
            .iter()
            .map(|t| {
                let tcp = chain.forward(&t.q_reported).unwrap() * tool.flange_from_tcp;
                let mut touch = Touch::new(t.touch.id.clone(), tcp.translation.vector.into());
                touch.approach = Some(tcp.rotation * Vector3::z());
                touch
            })
            .collect();
        // The nominal pose: the truth 20 mm and 2 degrees off.
        let nominal = Isometry3::new(
            Vector3::new(0.012, -0.016, 0.0),
            Vector3::new(0.0, 0.0, 2f64.to_radians()),
        ) * session.base_from_part_truth;
        let result = align_touches(
            &PsaTarget::new(&mesh),
            &touches,
            &nominal,
            &PsaOptions {
                tip_radius_m: tool.tip_radius_m,
                ..PsaOptions::default()
            },
        )
        .unwrap();
        let diagnosis = diagnose(
            Some(&chain),
            &tool,
            &mesh,
            &samples(&session),
            &session.base_from_part_truth,
            sigma,
        )
        .unwrap();
        let optimum_m = diagnosis.before.rms_m;
        assert!(
            result.alignment.rms_m <= optimum_m * 1.01 + 1e-6,
            "{case}: rms {:.3} mm where the pose alone reaches {:.3} mm",
            result.alignment.rms_m * 1e3,
            optimum_m * 1e3
        );
        let apart = pose_distance(
            &result.alignment.base_from_part,
            &diagnosis.before.base_from_part,
            mesh.radius_m(),
        );
        assert!(
            apart < 1e-3,
            "{case}: {:.2} mm from the optimum",
            apart * 1e3
        );
    }
}

/// Regression (real touches, issue 18): on people's touches with real noise (0.3-0.5 mm) a
/// lateral TCP error of about 2 mm explained much of the residual, yet the diagnosis said
/// `not_attributable`. At 0.3 mm noise and 65 touches it is named, with its size, and the
/// correction predicts held-out touches better.
#[test]
fn a_lateral_tcp_error_under_real_noise_is_found() {
    let chain = ur5e();
    let mesh = fixture_plate().unwrap();
    let mut hidden = HiddenEffects::none(6);
    hidden.tcp_error_m = Vector3::new(0.002, 0.0, 0.0);
    let sigma = 3e-4;
    let mut found = 0;
    for seed in [51, 52, 53] {
        let diagnosis = diagnosed(&chain, &mesh, &hidden, 65, sigma, seed);
        let report = describe(&diagnosis);
        println!("seed {seed}: {report}");
        assert_ne!(
            diagnosis.verdict,
            Verdict::NotAttributable,
            "seed {seed}: {report}"
        );
        if diagnosis.verdict != Verdict::Effect {
            continue;
        }
        let (name, fit) = diagnosis.effect.clone().unwrap();
        assert_eq!(name, "tcp_offset", "seed {seed}: {report}");
        let (_, dx, stderr) = fit.params.iter().find(|p| p.0 == "dx_m").unwrap();
        assert!((dx - 0.002).abs() <= 3.0 * stderr, "seed {seed}: {report}");
        assert!(
            diagnosis.after.loo_rms_m < diagnosis.before.loo_rms_m,
            "seed {seed}: {report}"
        );
        found += 1;
    }
    assert!(found >= 2, "found in {found} of 3 sessions");
}
