//! Writes `examples/step_block_ur10/`: a UR10 session touching the step block nine times at a
//! pose the session does not contain (kept in `truth.json` for tests and readers).
//!
//!     cargo run -p ips-client --example make_example_session
//!
//! Touch plan for a part on a table (reachable from above and the sides): three on the top, two
//! on the front, one on the left end, then the step's tread and riser and the right end.

use std::path::Path;

use align_core::io::{TriangleSoup, write_stl_binary};
use align_core::pose::{isometry_from_xyz_rpy, xyz_rpy};
use align_core::robots::ShippedRobot;
use align_core::trials::parts::step_block;
use nalgebra::Isometry3;
use protocol::Pose;
use protocol::session::{FORMAT, Inspection, PartSection, RobotSection, SessionFile, ToolSection};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let folder = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/step_block_ur10");
    std::fs::create_dir_all(&folder)?;
    let part = step_block()?;
    let soup = TriangleSoup {
        vertices: part.mesh.vertices().map(|p| p * 1000.0).collect(),
        triangles: part.mesh.triangles().to_vec(),
    };
    write_stl_binary(&folder.join("step_block.stl"), &soup)?;

    let truth = isometry_from_xyz_rpy([0.62, -0.25, 0.02], [0.0, 0.0, 0.35]);
    let nominal = isometry_from_xyz_rpy([0.65, -0.22, 0.02], [0.0, 0.0, 0.25]);
    let tcp = isometry_from_xyz_rpy([0.0, 0.0, 0.15], [0.0, 0.0, 0.0]);
    let tip_radius = 0.003;
    let chain = ShippedRobot::Ur10.chain()?;
    let targets = align_core::trials::probing::joint_targets(
        &chain,
        &truth,
        &tcp,
        tip_radius,
        &align_core::trials::probing::step_block_table_touches(),
        &[0.0, -1.57, 1.57, -1.57, -1.57, 0.0],
    )?;
    let inspections: Vec<Inspection> = targets
        .into_iter()
        .enumerate()
        .map(|(index, q)| Inspection {
            id: (index + 1).to_string(),
            q: Some(q),
            flange_pose: None,
            qd: None,
            stamp: Some(index as f64 * 4.0),
            face: None,
            trigger: None,
        })
        .collect();
    let pose = |p: &Isometry3<f64>| {
        let (xyz, rpy) = xyz_rpy(p);
        Pose::new(xyz, rpy)
    };
    let session = SessionFile {
        format: FORMAT.to_owned(),
        robot: Some(RobotSection {
            urdf: "../../robots/ur10.urdf".to_owned(),
            base_link: "base_link".to_owned(),
            tip_link: "tool0".to_owned(),
            package_dirs: Default::default(),
            kinematics: None,
            joint_offsets: None,
            joint_compliance: None,
            trigger_latency_s: None,
        }),
        tool: ToolSection {
            tcp: pose(&tcp),
            tip_radius,
            mass: 0.4,
        },
        part: PartSection {
            mesh: "step_block.stl".to_owned(),
            mesh_scale: 0.001,
            nominal_pose: pose(&nominal),
            faces: Vec::new(),
        },
        noise_sigma: Some(0.00005),
        inspections,
        results: None,
    };
    std::fs::write(
        folder.join("session.json"),
        serde_json::to_string_pretty(&session)? + "\n",
    )?;
    std::fs::write(
        folder.join("truth.json"),
        serde_json::to_string_pretty(&serde_json::json!({"base_from_part": pose(&truth)}))? + "\n",
    )?;
    // The same cell touched with a 3.4 mm ball while the session still declares 3 mm: an
    // undeclared effect for `ips diagnose` to find. Each point is touched head-on and tilted
    // either way by 0.6 rad: on head-on touches alone a larger ball and a longer TCP look the
    // same, and the diagnosis would rightly call it ambiguous.
    let three_ways: Vec<_> = align_core::trials::probing::step_block_table_touches()
        .into_iter()
        .flat_map(|(p, n)| [(p, n, 0.0), (p, n, 0.6), (p, n, -0.6)])
        .collect();
    let bigger_ball = align_core::trials::probing::tilted_joint_targets(
        &chain,
        &truth,
        &tcp,
        0.0034,
        1.0,
        &three_ways,
        &[0.0, -1.57, 1.57, -1.57, -1.57, 0.0],
    )?;
    let mut wrong_radius = session.clone();
    wrong_radius.inspections = bigger_ball
        .into_iter()
        .enumerate()
        .map(|(index, q)| Inspection {
            id: (index + 1).to_string(),
            q: Some(q),
            flange_pose: None,
            qd: None,
            stamp: None,
            face: None,
            trigger: None,
        })
        .collect();
    std::fs::write(
        folder.join("session_probe_radius.json"),
        serde_json::to_string_pretty(&wrong_radius)? + "\n",
    )?;
    // A scan of the same cell: three scanner positions, the floor, a neighbouring box, 10%
    // outliers and 0.3 mm noise, written in mm with 0.01 mm resolution.
    let scan = align_core::trials::clouds::ScanOptions {
        spacing_m: 0.008,
        seed: 2024,
        ..align_core::trials::clouds::pca_trial_scan()
    };
    let cloud = align_core::trials::clouds::scan_part(&part.mesh, &truth, &scan);
    let text: String = cloud
        .iter()
        .map(|p| format!("{:.2} {:.2} {:.2}\n", p.x * 1e3, p.y * 1e3, p.z * 1e3))
        .collect();
    std::fs::write(
        folder.join("scan.xyz"),
        format!("# x y z [mm], robot base frame\n{text}"),
    )?;
    println!("wrote {}", folder.display());
    Ok(())
}
