//! A whole robot in a ray-cast scan: its links' CAD (visual meshes, or primitives) posed by the
//! URDF's forward kinematics, standing on the floor beside a box, seen by the same scanner
//! model as the parts (crates/cad-scans/src/scanner.rs: occlusion, range noise along the ray,
//! mixed pixels at depth edges, spurious returns). The project's own robot scans
//! (`align_core::trials::robot_scan`) sample the surfaces they know; this one knows only
//! triangles and rays, so the robot trials can be checked on clouds made another way.

use align_core::registration::articulated::ArticulatedBody;
use align_core::rng::SplitMix64;
use align_core::trials::robot_trials::{
    Methods, RobotTrialRow, ScannedRobot, run_robot_trials_on_cloud,
};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};

use crate::scanner::{Origin, ScanNoise, ScanPoint, Scanner, SceneMesh, SceneObject, Surface};
use crate::scenes::{bounds_centre, clutter_box, floor, scan_around};

/// A robot is far larger than a link: a grid of up to 601 rays a side keeps the spacing on it
/// within 3-10 mm from 0.8-1.6 m plus its radius away (a 301 grid spaced a 1 m robot's rays
/// 7-10 mm apart at best).
const ROBOT_MAX_GRID_SIDE: usize = 601;

/// Poses the robot is scanned at are redrawn while some link other than the root comes this
/// close to the floor (m): a pose through the floor is no scene.
const FLOOR_CLEARANCE_M: f64 = 0.01;

/// Draws of a scene's joint values before it falls back to the home pose.
const POSE_DRAWS: usize = 50;

/// One ray-cast scan of a robot: where the robot is, the joint values it was scanned at and
/// what the scanners returned. (`align_core`'s `RobotScene` is the scene its own generator
/// scans.)
#[derive(Debug, Clone)]
pub struct RobotScan {
    pub world_from_root: Isometry3<f64>,
    pub q: Vec<f64>,
    pub points: Vec<ScanPoint>,
    pub scanners: Vec<Scanner>,
    /// The ray spacing each scanner was set up for at the robot's centre, m.
    pub spacing_m: Vec<f64>,
}

impl RobotScan {
    pub fn cloud(&self) -> Vec<Point3<f64>> {
        self.points.iter().map(|p| p.point).collect()
    }

    pub fn count(&self, origin: Origin) -> usize {
        self.points.iter().filter(|p| p.origin == origin).count()
    }
}

#[derive(Debug, thiserror::Error)]
pub enum RobotScanError {
    #[error("'{0}' has no link with geometry to scan")]
    NoGeometry(String),
    #[error("{values} joint values for the {joints} moving joints of '{robot}'")]
    JointCount {
        robot: String,
        values: usize,
        joints: usize,
    },
    #[error(transparent)]
    Scene(#[from] crate::SceneError),
}

/// The joint values scene `seed` scans the robot at: `home` itself for seed 0, else every joint
/// moved by up to `spread_rad` (or m for a prismatic joint) from it within its limits, redrawn
/// while a link other than the root would come within a centimetre of the floor (after
/// [`POSE_DRAWS`] draws, `home`).
pub fn scene_joints(
    body: &ArticulatedBody,
    world_from_root: &Isometry3<f64>,
    home: &[f64],
    spread_rad: f64,
    seed: u64,
) -> Vec<f64> {
    if seed == 0 || spread_rad <= 0.0 {
        return home.to_vec();
    }
    let mut rng = SplitMix64::new(seed ^ 0x5CE4_E0B0_7000_0001);
    for _ in 0..POSE_DRAWS {
        let q: Vec<f64> = home
            .iter()
            .zip(body.parameters())
            .map(|(value, parameter)| {
                (value + spread_rad * (2.0 * rng.uniform() - 1.0))
                    .clamp(parameter.lower, parameter.upper)
            })
            .collect();
        if lowest_above_root_m(body, world_from_root, &q) > FLOOR_CLEARANCE_M {
            return q;
        }
    }
    home.to_vec()
}

/// The lowest vertex of every link but the root, z in the world.
fn lowest_above_root_m(body: &ArticulatedBody, world_from_root: &Isometry3<f64>, q: &[f64]) -> f64 {
    let poses = body.link_poses(world_from_root, q);
    body.links()
        .iter()
        .enumerate()
        .filter(|(index, _)| *index != body.root())
        .filter_map(|(index, link)| Some((poses[index], link.surface.as_ref()?)))
        .flat_map(|(pose, mesh)| mesh.vertices().map(move |v| (pose * v).z))
        .fold(f64::INFINITY, f64::min)
}

/// Scans the robot (root at `world_from_root`, joints at `q`) on a floor at z = 0 beside a box
/// 8-30 cm a side, from two or three seeded scanner positions.
pub fn scan_robot_raycast(
    body: &ArticulatedBody,
    world_from_root: &Isometry3<f64>,
    q: &[f64],
    seed: u64,
    noise: &ScanNoise,
) -> Result<RobotScan, RobotScanError> {
    if q.len() != body.parameters().len() {
        return Err(RobotScanError::JointCount {
            robot: body.robot.clone(),
            values: q.len(),
            joints: body.parameters().len(),
        });
    }
    let poses = body.link_poses(world_from_root, q);
    let mut objects: Vec<SceneObject> = body
        .links()
        .iter()
        .zip(&poses)
        .filter_map(|(link, pose)| {
            let mesh = link.surface.as_ref()?;
            Some(SceneObject {
                surface: Surface::Part,
                vertices: mesh.vertices().map(|v| pose * v).collect(),
                triangles: mesh.triangles().to_vec(),
            })
        })
        .collect();
    let robot_vertices: Vec<Point3<f64>> = objects
        .iter()
        .flat_map(|o| o.vertices.iter().copied())
        .collect();
    if robot_vertices.is_empty() {
        return Err(RobotScanError::NoGeometry(body.robot.clone()));
    }
    let centre = bounds_centre(&robot_vertices);
    let radius_m = robot_vertices
        .iter()
        .map(|v| (v - centre).norm())
        .fold(0.0, f64::max);
    let footprint_m = robot_vertices
        .iter()
        .map(|v| (v.xy() - centre.xy()).norm())
        .fold(0.0, f64::max);
    let mut rng = SplitMix64::new(seed);
    let (box_vertices, box_triangles) = clutter_box(&centre, footprint_m, &mut rng);
    let (floor_vertices, floor_triangles) = floor(&centre, (4.0 * radius_m).max(4.0));
    objects.push(SceneObject {
        surface: Surface::Floor,
        vertices: floor_vertices,
        triangles: floor_triangles,
    });
    objects.push(SceneObject {
        surface: Surface::Clutter,
        vertices: box_vertices,
        triangles: box_triangles,
    });
    let scene = SceneMesh::new(&objects)?;
    let (points, scanners, spacing_m) = scan_around(
        &scene,
        &centre,
        radius_m,
        ROBOT_MAX_GRID_SIDE,
        noise,
        &mut rng,
    );
    Ok(RobotScan {
        world_from_root: *world_from_root,
        q: q.to_vec(),
        points,
        scanners,
        spacing_m,
    })
}

/// Scene `scene` of a run seeded `seed`: the robot's root at (0.2, -0.1, 0) as the project's
/// robot trials put it, turned 0.4 rad in scene 0 and a seeded turn in the others, its joints
/// drawn about `home` ([`scene_joints`]), scanned from the scene's seeded scanners.
pub fn seeded_scene(
    body: &ArticulatedBody,
    home: &[f64],
    spread_rad: f64,
    seed: u64,
    scene: usize,
    noise: &ScanNoise,
) -> Result<RobotScan, RobotScanError> {
    let yaw = if scene == 0 {
        0.4
    } else {
        SplitMix64::new(seed ^ (scene as u64).wrapping_mul(0x9E37)).uniform()
            * std::f64::consts::TAU
    };
    let world_from_root = Isometry3::from_parts(
        Translation3::new(0.2, -0.1, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
    );
    let q = scene_joints(body, &world_from_root, home, spread_rad, scene as u64);
    let scan_seed = seed ^ (scene as u64 + 1).wrapping_mul(0xA24B_AED4_963E_E407);
    scan_robot_raycast(body, &world_from_root, &q, scan_seed, noise)
}

/// The hierarchical fit's trials (`trials` of each delta's seeded sequence) on scene `scene` of
/// a run seeded `seed` ([`seeded_scene`]), as `align_core`'s robot trials run them on their own
/// scans: the base displaced by the thesis's scheme and every joint moved too.
pub fn scene_trials(
    body: &ArticulatedBody,
    scanned: &RobotScan,
    deltas_m: &[f64],
    trials: std::ops::Range<usize>,
    seed: u64,
    scene: usize,
    on_trial: impl FnMut(f64, usize),
) -> Vec<RobotTrialRow> {
    let cloud = scanned.cloud();
    run_robot_trials_on_cloud(
        body,
        &ScannedRobot {
            world_from_root: scanned.world_from_root,
            q: &scanned.q,
            cloud: &cloud,
        },
        deltas_m,
        trials,
        seed ^ scene as u64,
        Methods {
            independent: false,
            hierarchical: true,
        },
        on_trial,
    )
}

/// One link's (or the whole robot's) trials at one delta, over every scene.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RobotCell {
    pub object: String,
    pub delta_mm: f64,
    pub trials: usize,
    pub succeeded: usize,
    /// Within 1 mm only through what the fit reported (joints it said the scan does not show,
    /// where the scan does not pin them at the true pose either, or its ambiguous twin): not
    /// in `succeeded`.
    pub reported: usize,
    pub failed: usize,
    pub mean_error_mm: f64,
    pub mean_time_s: f64,
    /// `scene/trial` of each failure (rerun one with `--scene S --first-trial T --trials 1`).
    pub failures: Vec<String>,
}

/// Adds one scene's rows (`align_core`'s tallies, trials numbered within the scene) to the
/// cells, one per object and delta in the order first seen.
pub fn add_scene_rows(cells: &mut Vec<RobotCell>, scene: usize, rows: &[RobotTrialRow]) {
    for row in rows {
        let Some(tally) = &row.hierarchical else {
            continue;
        };
        let delta_mm = row.delta_m * 1e3;
        let index = match cells
            .iter()
            .position(|c| c.object == row.object && c.delta_mm == delta_mm)
        {
            Some(index) => index,
            None => {
                cells.push(RobotCell {
                    object: row.object.clone(),
                    delta_mm,
                    trials: 0,
                    succeeded: 0,
                    reported: 0,
                    failed: 0,
                    mean_error_mm: 0.0,
                    mean_time_s: 0.0,
                    failures: Vec::new(),
                });
                cells.len() - 1
            }
        };
        let cell = &mut cells[index];
        let added = tally.succeeded + tally.reported + tally.failed;
        let total = cell.trials + added;
        if total == 0 {
            continue;
        }
        let weigh = |mean: f64, new_mean: f64| {
            (mean * cell.trials as f64 + new_mean * added as f64) / total as f64
        };
        cell.mean_error_mm = weigh(cell.mean_error_mm, tally.mean_error_m * 1e3);
        cell.mean_time_s = weigh(cell.mean_time_s, tally.mean_time_s);
        cell.trials = total;
        cell.succeeded += tally.succeeded;
        cell.reported += tally.reported;
        cell.failed += tally.failed;
        cell.failures
            .extend(tally.failed_trials.iter().map(|t| format!("{scene}/{t}")));
    }
}

/// The Markdown table: per object, successes (+ reported) of trials at each delta, then the
/// failures to rerun.
pub fn robot_markdown(cells: &[RobotCell]) -> String {
    let mut deltas: Vec<f64> = cells.iter().map(|c| c.delta_mm).collect();
    deltas.sort_by(f64::total_cmp);
    deltas.dedup();
    let mut objects: Vec<&str> = Vec::new();
    for cell in cells {
        if !objects.contains(&cell.object.as_str()) {
            objects.push(&cell.object);
        }
    }
    let mut text = String::from("| object |");
    for delta in &deltas {
        text += &format!(" {delta:.0} mm |");
    }
    text += "\n| --- |";
    text += &" ---: |".repeat(deltas.len());
    text += "\n";
    for object in &objects {
        text += &format!("| {object} |");
        for delta in &deltas {
            let cell = cells
                .iter()
                .find(|c| c.object == *object && c.delta_mm == *delta);
            text += &match cell {
                Some(c) if c.reported > 0 => {
                    format!(
                        " {} (+{} reported) /{} |",
                        c.succeeded, c.reported, c.trials
                    )
                }
                Some(c) => format!(" {}/{} |", c.succeeded, c.trials),
                None => " - |".to_owned(),
            };
        }
        text += "\n";
    }
    text += "| mean time per fit (s) |";
    for delta in &deltas {
        let time = cells
            .iter()
            .find(|c| c.delta_mm == *delta)
            .map_or(f64::NAN, |c| c.mean_time_s);
        text += &format!(" {time:.2} |");
    }
    text += "\n";
    let failures: Vec<String> = cells
        .iter()
        .filter(|c| !c.failures.is_empty())
        .map(|c| {
            format!(
                "- {} at {:.0} mm (scene/trial): {}\n",
                c.object,
                c.delta_mm,
                c.failures.join(", ")
            )
        })
        .collect();
    if !failures.is_empty() {
        text += "\nFailures:\n\n";
        text += &failures.concat();
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use align_core::robots::ShippedRobot;

    fn ur10() -> (ArticulatedBody, Vec<f64>) {
        let robot = ShippedRobot::from_name("ur10").expect("shipped");
        let body = ArticulatedBody::from_model(&robot.model().expect("model")).expect("body");
        (body, robot.home())
    }

    fn root() -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.2, -0.1, 0.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.4),
        )
    }

    #[test]
    fn scene_poses_stay_within_limits_and_off_the_floor_and_scene_0_is_home() {
        let (body, home) = ur10();
        assert_eq!(scene_joints(&body, &root(), &home, 0.5, 0), home);
        for seed in 1..8 {
            let q = scene_joints(&body, &root(), &home, 0.5, seed);
            assert_ne!(q, home, "scene {seed} moves the joints");
            for ((value, start), parameter) in q.iter().zip(&home).zip(body.parameters()) {
                assert!((parameter.lower..=parameter.upper).contains(value));
                assert!((value - start).abs() <= 0.5 + 1e-12);
            }
            assert!(lowest_above_root_m(&body, &root(), &q) > FLOOR_CLEARANCE_M);
        }
    }

    #[test]
    fn a_robot_scan_holds_the_robot_the_floor_and_the_scanners_artefacts() {
        let (body, home) = ur10();
        let scene =
            scan_robot_raycast(&body, &root(), &home, 7, &ScanNoise::default()).expect("a scene");
        let part = scene.count(Origin::Surface(Surface::Part));
        let floor = scene.count(Origin::Surface(Surface::Floor));
        let outliers = scene.count(Origin::Outlier);
        assert!(part > 2_000, "{part} points on the robot");
        assert!(floor > part, "{floor} on the floor");
        assert!(scene.count(Origin::MixedPixel) > 0);
        let fraction =
            (outliers + scene.count(Origin::MixedPixel)) as f64 / scene.points.len() as f64;
        assert!((fraction - 0.1).abs() < 0.01, "{fraction}");
        assert!(scene.spacing_m.iter().all(|s| (0.003..=0.010).contains(s)));
        let wrong = scan_robot_raycast(&body, &root(), &home[..3], 7, &ScanNoise::default());
        assert!(matches!(
            wrong,
            Err(RobotScanError::JointCount { values: 3, .. })
        ));
    }
}
