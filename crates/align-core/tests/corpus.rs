//! Tests of the touch corpus generator itself (not of any alignment): the parts are valid meshes
//! of the stated sizes, touches sit one ball radius off the surface plus the stated noise, tilts
//! cover 0-60 degrees and side contacts, the probe never collides, seeds reproduce, the DH robots
//! put their flanges where the published tables do, and IK sessions reproduce the touches
//! through the true robot.

use align_core::corpus::parts::{
    all_parts, fixture_plate, open_shell, robot_link_mesh, thin_wall_bracket, turned_part,
};
use align_core::corpus::robots::{PANDA_READY_RAD, panda_mdh_urdf, ur5e_dh_urdf};
use align_core::corpus::sessions::{
    HiddenEffects, ProbeTool, SessionRobot, generate_session, joint_session, place_part, scale_mesh,
};
use align_core::corpus::touches::{TouchOptions, blind_start, on_table, sample_touches};
use align_core::geometry::Mesh;
use align_core::rng::SplitMix64;
use align_core::{Chain, PackageMap, RobotModel};
use nalgebra::{Isometry3, Matrix4, Point3, Translation3, UnitQuaternion, Vector3};

fn some_pose() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.45, -0.12, 0.03),
        UnitQuaternion::from_euler_angles(0.3, -0.5, 1.1),
    )
}

#[test]
fn parts_are_valid_meshes_of_the_stated_sizes() {
    let parts = all_parts().unwrap();
    let names: Vec<&str> = parts.iter().map(|(name, _)| *name).collect();
    assert_eq!(
        names,
        [
            "fixture_plate",
            "thin_wall_bracket",
            "open_shell",
            "turned_part"
        ]
    );
    for (name, mesh) in &parts {
        let closed = *name != "open_shell";
        assert_eq!(mesh.is_watertight(), closed, "{name}: {:?}", mesh.notes());
        eprintln!("{name}: {} triangles", mesh.num_triangles());
    }
    let count = |name: &str| {
        parts
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, m)| m.num_triangles())
            .unwrap()
    };
    assert!((4000..=8000).contains(&count("fixture_plate")));
    assert!((8000..=12000).contains(&count("thin_wall_bracket")));
    assert!(count("open_shell") >= 1000);
    assert!(count("turned_part") >= 5000);
    // Sizes (bounds, m).
    let (lo, hi) = fixture_plate().unwrap().bounds();
    assert!(((hi.x - lo.x) - 0.18).abs() < 1e-9 && ((hi.y - lo.y) - 0.13).abs() < 1e-9);
    // The inclined block top is the highest point: 34 + 25 tan(20 deg) mm or a little less
    // (its rounded corners), above the 32 mm boss.
    assert!(hi.z > 0.040 && hi.z < 0.0432, "{}", hi.z);
}

#[test]
fn closed_parts_have_signs_inside_and_out() {
    let plate = fixture_plate().unwrap();
    let inside = plate.closest_point(&Point3::new(0.0, -0.01, 0.005));
    assert!(inside.signed_distance < 0.0);
    // Inside a through-hole and inside the blind bore: outside the part.
    assert!(
        plate
            .closest_point(&Point3::new(0.072, 0.047, 0.005))
            .signed_distance
            > 0.0
    );
    assert!(
        plate
            .closest_point(&Point3::new(0.040, 0.022, 0.025))
            .signed_distance
            > 0.0
    );
    let shaft = turned_part().unwrap();
    assert!(
        shaft
            .closest_point(&Point3::new(0.0, 0.0, 0.06))
            .signed_distance
            < 0.0
    );
    // The key flat: 13.5 mm off the axis in +x is outside between z 60 and 104 mm, inside
    // elsewhere on the shaft.
    assert!(
        shaft
            .closest_point(&Point3::new(0.0135, 0.0, 0.08))
            .signed_distance
            > 0.0
    );
    assert!(
        shaft
            .closest_point(&Point3::new(-0.0135, 0.0, 0.08))
            .signed_distance
            < 0.0
    );
    assert!(
        shaft
            .closest_point(&Point3::new(0.0135, 0.0, 0.112))
            .signed_distance
            < 0.0
    );
}

#[test]
fn bracket_walls_are_two_and_a_half_millimetres_thick() {
    let bracket = thin_wall_bracket().unwrap();
    // Through the base flange (up) and through the upright (along +x), away from the holes.
    for (origin, direction) in [
        (Point3::new(0.030, 0.005, -0.01), Vector3::z()),
        (Point3::new(-0.01, 0.005, 0.030), Vector3::x()),
    ] {
        let entry = bracket.ray_hit_m(&origin, &direction, 1.0).unwrap();
        let inside = origin + direction * (entry + 1e-7);
        let exit = bracket.ray_hit_m(&inside, &direction, 1.0).unwrap() + 1e-7;
        assert!((exit - 0.0025).abs() < 1e-6, "wall {exit} m");
    }
    // A hole: the ray through the base hole's centre passes.
    let hole = Point3::new(0.052, 0.014, -0.01);
    assert!(bracket.ray_hit_m(&hole, &Vector3::z(), 0.02).is_none());
}

#[test]
fn the_open_shell_is_open_and_faces_outward() {
    let shell = open_shell().unwrap();
    assert!(!shell.is_watertight());
    // A point above the top: the nearest face's normal points up, at it.
    let above = shell.closest_point(&Point3::new(-0.02, 0.0, 0.05));
    assert!(shell.triangle_normal(above.triangle).z > 0.99);
    // Through the open bottom, a ray from below meets the top's underside; through the round
    // opening in the top it meets nothing.
    assert!(
        shell
            .ray_hit_m(&Point3::new(-0.02, 0.0, -0.01), &Vector3::z(), 1.0)
            .is_some()
    );
    assert!(
        shell
            .ray_hit_m(&Point3::new(0.025, 0.0, -0.01), &Vector3::z(), 1.0)
            .is_none()
    );
}

fn shaft_is_clear(mesh: &Mesh, centre: &Point3<f64>, approach: &Vector3<f64>, radius: f64) -> bool {
    (1..=120).all(|k| {
        let q = centre - approach * (0.0005 * k as f64);
        let found = mesh.closest_point(&q);
        found.signed_distance.abs() >= radius * (1.0 - 1e-9)
            && (!mesh.is_watertight() || found.signed_distance > 0.0)
    })
}

#[test]
fn touches_sit_one_radius_off_the_surface_with_a_clear_stylus() {
    let options = TouchOptions::default();
    let pose = some_pose();
    let part_from_base = pose.inverse();
    for (index, (name, mesh)) in all_parts().unwrap().into_iter().enumerate() {
        let mut rng = SplitMix64::new(11 + index as u64);
        let set = sample_touches(&mesh, &pose, 40, &options, &mut rng).unwrap();
        assert_eq!(set.touches.len(), 40);
        assert!((0.3e-3..=0.5e-3).contains(&set.sigma_m));
        for touch in &set.touches {
            let centre = part_from_base * touch.true_centre_in_base();
            let nearest = mesh.closest_point(&centre);
            assert!(
                (nearest.signed_distance.abs() - options.ball_radius_m).abs() < 1e-9,
                "{name} {}: {} m",
                touch.id,
                nearest.signed_distance
            );
            let contact = part_from_base * touch.surface_point_in_base;
            assert!(mesh.closest_point(&contact).signed_distance.abs() < 1e-9);
            assert!((touch.approach_in_base.norm() - 1.0).abs() < 1e-12);
            let cos = (-touch.approach_in_base).dot(&touch.normal_in_base);
            assert!((cos.clamp(-1.0, 1.0).acos() - touch.tilt_rad).abs() < 1e-9);
            let approach = part_from_base * touch.approach_in_base;
            assert!(
                shaft_is_clear(&mesh, &centre, &approach, 0.4 * options.ball_radius_m),
                "{name} {}: the stylus collides",
                touch.id
            );
        }
    }
}

#[test]
fn noise_has_the_session_sigma_along_the_normal() {
    let mesh = fixture_plate().unwrap();
    let pose = some_pose();
    let mut rng = SplitMix64::new(5);
    let set = sample_touches(&mesh, &pose, 600, &TouchOptions::default(), &mut rng).unwrap();
    let normal_noise: Vec<f64> = set
        .touches
        .iter()
        .map(|t| t.noise_in_base.dot(&t.normal_in_base))
        .collect();
    let rms = (normal_noise.iter().map(|e| e * e).sum::<f64>() / normal_noise.len() as f64).sqrt();
    assert!(
        (rms / set.sigma_m - 1.0).abs() < 0.12,
        "rms {rms} vs sigma {}",
        set.sigma_m
    );
}

#[test]
fn tilts_cover_sixty_degrees_and_side_contacts() {
    let mesh = fixture_plate().unwrap();
    let mut rng = SplitMix64::new(21);
    let set = sample_touches(&mesh, &some_pose(), 400, &TouchOptions::default(), &mut rng).unwrap();
    let degrees: Vec<f64> = set
        .touches
        .iter()
        .map(|t| t.tilt_rad.to_degrees())
        .collect();
    let side = degrees.iter().filter(|&&d| (d - 90.0).abs() < 1e-9).count();
    let ordinary: Vec<f64> = degrees.iter().copied().filter(|&d| d < 89.0).collect();
    assert_eq!(side + ordinary.len(), degrees.len());
    assert!(ordinary.iter().all(|&d| d <= 60.0 + 1e-9));
    assert!(ordinary.iter().any(|&d| d > 57.0) && ordinary.iter().any(|&d| d < 3.0));
    let beyond_35 = degrees.iter().filter(|&&d| d > 35.0).count() as f64 / degrees.len() as f64;
    // Uniform tilt in [0, 60] puts 5/12 beyond 35 degrees, side contacts add theirs; collisions
    // thin out the steep ones a little.
    assert!((0.3..0.65).contains(&beyond_35), "{beyond_35}");
    let side_share = side as f64 / degrees.len() as f64;
    assert!((0.05..0.25).contains(&side_share), "{side_share}");
    for touch in set.touches.iter().filter(|t| t.tilt_rad > 1.5) {
        assert!(touch.approach_in_base.dot(&touch.normal_in_base).abs() < 1e-12);
    }
}

#[test]
fn seeds_reproduce_and_differ() {
    let mesh = thin_wall_bracket().unwrap();
    let draw = |seed| {
        let mut rng = SplitMix64::new(seed);
        let set =
            sample_touches(&mesh, &some_pose(), 20, &TouchOptions::default(), &mut rng).unwrap();
        let start = blind_start(&set.touches, &mesh, &mut rng);
        (set, start)
    };
    assert_eq!(draw(7), draw(7));
    assert_ne!(draw(7).0, draw(8).0);
}

#[test]
fn blind_start_puts_the_centroid_on_the_touches() {
    let mesh = turned_part().unwrap();
    let mut rng = SplitMix64::new(3);
    let set = sample_touches(&mesh, &some_pose(), 20, &TouchOptions::default(), &mut rng).unwrap();
    let start = blind_start(&set.touches, &mesh, &mut rng);
    let centroid = set
        .touches
        .iter()
        .fold(Vector3::zeros(), |s, t| s + t.ball_centre_in_base.coords)
        / 20.0;
    assert!(((start * mesh.centroid()).coords - centroid).norm() < 1e-12);
}

#[test]
fn a_table_keeps_the_probe_above_it() {
    let mesh = fixture_plate().unwrap();
    let pose = on_table(&mesh, 0.4, [0.5, 0.1], 0.0);
    let options = TouchOptions {
        floor_z_in_base: Some(0.0),
        ..TouchOptions::default()
    };
    let mut rng = SplitMix64::new(9);
    let set = sample_touches(&mesh, &pose, 200, &options, &mut rng).unwrap();
    for touch in &set.touches {
        let centre = touch.true_centre_in_base();
        assert!(centre.z >= options.ball_radius_m - 1e-12);
        assert!((centre - touch.approach_in_base * options.stylus_length_m).z > 0.0);
    }
    // Nothing was touched from underneath.
    assert!(set.touches.iter().all(|t| t.normal_in_base.z > -0.99));
}

/// Standard DH: Rz(theta) Tz(d) Tx(a) Rx(alpha), written out independently of the URDF.
fn dh(theta: f64, d: f64, a: f64, alpha: f64) -> Matrix4<f64> {
    let (st, ct) = theta.sin_cos();
    let (sa, ca) = alpha.sin_cos();
    Matrix4::new(
        ct,
        -st * ca,
        st * sa,
        a * ct,
        st,
        ct * ca,
        -ct * sa,
        a * st,
        0.0,
        sa,
        ca,
        d,
        0.0,
        0.0,
        0.0,
        1.0,
    )
}

/// Modified (Craig) DH: Rx(alpha) Tx(a) Rz(theta) Tz(d).
fn mdh(a: f64, alpha: f64, theta: f64, d: f64) -> Matrix4<f64> {
    let (st, ct) = theta.sin_cos();
    let (sa, ca) = alpha.sin_cos();
    Matrix4::new(
        ct,
        -st,
        0.0,
        a,
        st * ca,
        ct * ca,
        -sa,
        -d * sa,
        st * sa,
        ct * sa,
        ca,
        d * ca,
        0.0,
        0.0,
        0.0,
        1.0,
    )
}

fn chain_of(urdf: &str, base: &str, tip: &str) -> Chain {
    RobotModel::from_urdf_str(urdf, &PackageMap::new())
        .expect("the URDF loads")
        .chain(base, tip)
        .expect("the chain exists")
}

#[test]
fn ur5e_flange_matches_the_published_dh_table() {
    let urdf = ur5e_dh_urdf();
    let chain = chain_of(&urdf, "base", "flange");
    // At zero the arm is stretched along -x: x = a2 + a3, y = -(d4 + d6), z = d1 - d5, the tool
    // axis along -y.
    let zero = chain.forward(&[0.0; 6]).unwrap();
    let expected = Vector3::new(-0.425 - 0.3922, -(0.1333 + 0.0996), 0.1625 - 0.0997);
    assert!(
        (zero.translation.vector - expected).norm() < 1e-12,
        "{zero}"
    );
    assert!((zero.rotation * Vector3::z() + Vector3::y()).norm() < 1e-12);
    // ROS-Industrial's base_link is the base turned 180 degrees about z.
    let ros = chain_of(&urdf, "base_link", "flange")
        .forward(&[0.0; 6])
        .unwrap();
    let flipped = Vector3::new(-expected.x, -expected.y, expected.z);
    assert!((ros.translation.vector - flipped).norm() < 1e-12);
    // Anywhere: the product of the DH table's matrices.
    let a = [0.0, -0.425, -0.3922, 0.0, 0.0, 0.0];
    let d = [0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996];
    let alpha = [90.0f64, 0.0, 0.0, 90.0, -90.0, 0.0].map(f64::to_radians);
    let mut rng = SplitMix64::new(1);
    for _ in 0..20 {
        let q: Vec<f64> = (0..6).map(|_| (rng.uniform() * 2.0 - 1.0) * 3.0).collect();
        let product = (0..6).fold(Matrix4::identity(), |m, i| {
            m * dh(q[i], d[i], a[i], alpha[i])
        });
        let got = chain.forward(&q).unwrap().to_homogeneous();
        assert!((got - product).abs().max() < 1e-12);
    }
    // The approximate inertials load the joints.
    let tau = chain.gravity_torques_nm(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0], None);
    assert!(tau[1].abs() > 20.0, "{tau:?}");
}

#[test]
fn panda_flange_matches_the_published_dh_table() {
    let chain = chain_of(&panda_mdh_urdf(), "link_0", "flange");
    assert_eq!(chain.dof(), 7);
    // Worked by hand from the table at the ready pose: x = -0.316 sin45 + 0.0825 sin45 + 0.384 +
    // 0.088, z = 0.333 + 0.316 cos45 + 0.0825 cos45 + 0.0825 - 0.107, flange z axis down.
    let ready = chain.forward(&PANDA_READY_RAD).unwrap();
    let s = std::f64::consts::FRAC_1_SQRT_2;
    let expected = Vector3::new(
        -0.316 * s + 0.0825 * s + 0.384 + 0.088,
        0.0,
        0.333 + 0.316 * s + 0.0825 * s + 0.0825 - 0.107,
    );
    assert!(
        (ready.translation.vector - expected).norm() < 1e-12,
        "{ready}"
    );
    assert!((expected - Vector3::new(0.30689, 0.0, 0.59028)).norm() < 1e-5);
    assert!((ready.rotation * Vector3::z() + Vector3::z()).norm() < 1e-12);
    let rows = [
        (0.0, 0.333, 0.0),
        (0.0, 0.0, -90.0f64),
        (0.0, 0.316, 90.0),
        (0.0825, 0.0, 90.0),
        (-0.0825, 0.384, -90.0),
        (0.0, 0.0, 90.0),
        (0.088, 0.0, 90.0),
    ];
    let mut rng = SplitMix64::new(2);
    for _ in 0..20 {
        let q: Vec<f64> = chain
            .joints()
            .iter()
            .map(|j| j.limits.lower + (j.limits.upper - j.limits.lower) * rng.uniform())
            .collect();
        let product = (0..7).fold(Matrix4::<f64>::identity(), |m, i| {
            m * mdh(rows[i].0, rows[i].2.to_radians(), q[i], rows[i].1)
        }) * mdh(0.0, 0.0, 0.0, 0.107);
        let got = chain.forward(&q).unwrap().to_homogeneous();
        assert!((got - product).abs().max() < 1e-12);
    }
    assert!(chain.joints()[3].limits.upper < 0.0);
}

fn check_session_reproduces(chain: &Chain, mesh: &Mesh, seed: u64, hidden: &HiddenEffects) {
    let tool = ProbeTool::straight(0.15, 0.003);
    let mut rng = SplitMix64::new(seed);
    let seeds = [vec![0.0; chain.dof()]];
    let robot = SessionRobot {
        chain,
        tool: &tool,
        hidden,
        seeds: &seeds,
    };
    let session =
        generate_session(&robot, mesh, 10, &TouchOptions::default(), &mut rng).expect("a session");
    assert_eq!(session.touches.len() + session.unreachable.len(), 10);
    assert!(
        session.touches.len() >= 6,
        "unreachable: {:?}",
        session.unreachable
    );
    for joint_touch in &session.touches {
        // The true robot puts the ball on the (noisy) touch centre with the tool along the
        // approach.
        let q_true = hidden.true_joints(chain, &joint_touch.q_reported);
        assert!(chain.within_limits(&q_true));
        let base_from_tcp =
            chain.forward(&q_true).expect("finite joints") * hidden.true_flange_from_tcp(&tool);
        let centre = Point3::from(base_from_tcp.translation.vector);
        assert!((centre - joint_touch.touch.ball_centre_in_base).norm() < 1e-6);
        let axis = base_from_tcp.rotation * Vector3::z();
        assert!((axis - joint_touch.touch.approach_in_base).norm() < 1e-6);
        assert!(
            (hidden.true_ball_centre(chain, &tool, &joint_touch.q_reported) - centre).norm() < 1e-9
        );
        // The reported flange is the nominal model's.
        let nominal = chain
            .forward(&joint_touch.q_reported)
            .expect("finite joints");
        assert!(
            (nominal.to_homogeneous() - joint_touch.base_from_flange_nominal.to_homogeneous())
                .abs()
                .max()
                < 1e-12
        );
    }
}

#[test]
fn ur5e_sessions_reproduce_the_touches_through_the_true_robot() {
    let chain = chain_of(&ur5e_dh_urdf(), "base", "flange");
    let hidden = HiddenEffects {
        joint_offsets_rad: vec![0.002, -0.0015, 0.001, 0.0025, -0.002, 0.003],
        tcp_error_m: Vector3::new(0.002, -0.001, 0.0005),
        part_scale: 1.0,
        compliance_rad_per_nm: vec![0.0, 2e-5, 2e-5, 0.0, 0.0, 0.0],
    };
    check_session_reproduces(&chain, &fixture_plate().unwrap(), 31, &hidden);
    // With nothing hidden the model's ball centre is the touch centre.
    let none = HiddenEffects::none(6);
    let tool = ProbeTool::straight(0.15, 0.003);
    let mesh = turned_part().unwrap();
    let mut rng = SplitMix64::new(4);
    let pose = place_part(&mesh, 0.45, 0.0, &mut rng);
    let options = TouchOptions {
        floor_z_in_base: Some(0.0),
        ..TouchOptions::default()
    };
    let set = sample_touches(&mesh, &pose, 6, &options, &mut rng).unwrap();
    let session = joint_session(&chain, &tool, &set, &pose, &none, &[]).unwrap();
    for t in &session.touches {
        assert!((t.nominal_ball_centre(&tool) - t.touch.ball_centre_in_base).norm() < 1e-6);
        assert!((t.nominal_approach(&tool) - t.touch.approach_in_base).norm() < 1e-6);
    }
}

#[test]
fn panda_sessions_reproduce_the_touches_through_the_true_robot() {
    let chain = chain_of(&panda_mdh_urdf(), "link_0", "flange");
    let hidden = HiddenEffects {
        joint_offsets_rad: vec![0.001, -0.002, 0.0, 0.0015, 0.0, -0.001, 0.002],
        tcp_error_m: Vector3::new(-0.0015, 0.002, 0.0),
        part_scale: 1.002,
        compliance_rad_per_nm: Vec::new(),
    };
    let seeds = vec![PANDA_READY_RAD.to_vec()];
    let tool = ProbeTool::straight(0.12, 0.003);
    let mut rng = SplitMix64::new(8);
    let mesh = thin_wall_bracket().unwrap();
    let robot = SessionRobot {
        chain: &chain,
        tool: &tool,
        hidden: &hidden,
        seeds: &seeds,
    };
    let session = generate_session(&robot, &mesh, 8, &TouchOptions::default(), &mut rng).unwrap();
    assert!(
        session.touches.len() >= 5,
        "unreachable: {:?}",
        session.unreachable
    );
    check_session_reproduces(&chain, &open_shell().unwrap(), 12, &hidden);
}

#[test]
fn scaling_and_external_meshes() {
    let mesh = turned_part().unwrap();
    let scaled = scale_mesh(&mesh, 1.01).unwrap();
    let (_, hi) = scaled.bounds();
    assert!((hi.z - 0.1212).abs() < 1e-9);
    assert!(robot_link_mesh(None, 0.001).unwrap().is_none());
}
