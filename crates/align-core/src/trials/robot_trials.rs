//! The thesis's PCA trials (3.4) on a robot: the whole robot and each link, aligned
//! independently (each link as a rigid part, as the thesis did) and hierarchically (base pose
//! and joints, children constrained by parents).
//!
//! Errors are surface deviations: the largest distance between a link's surface where the
//! alignment puts it and where it truly is (both ways). Unlike a pose distance this is zero for
//! a cylinder turned about its own axis, which no scan can tell apart.

use std::ops::Range;
use std::time::Instant;

use nalgebra::{Isometry3, Point3, UnitQuaternion};

use super::robot_scan::{RobotScanOptions, scan_robot};
use super::{SUCCESS_THRESHOLD_M, TrialRng, random_displacement};
use crate::geometry::Mesh;
use crate::registration::articulated::{
    ArticulatedBody, RobotFit, RobotFitOptions, align_robot, observed_joints_at,
};
use crate::registration::pca::{PcaOptions, align_cloud};

/// Largest distance between the surface at `estimated` and at `truth` (both world_from_mesh):
/// [`Mesh::deviation_m`].
pub fn surface_deviation_m(mesh: &Mesh, estimated: &Isometry3<f64>, truth: &Isometry3<f64>) -> f64 {
    mesh.deviation_m(estimated, truth)
}

/// Largest distance of the robot's surfaces from `origin`, m.
fn reach_from(
    body: &ArticulatedBody,
    poses: &[Isometry3<f64>],
    links: &[usize],
    origin: &Point3<f64>,
) -> f64 {
    links
        .iter()
        .filter_map(|&l| {
            let mesh = body.links()[l].surface.as_ref()?;
            Some((poses[l] * mesh.centroid() - origin).norm() + mesh.radius_m())
        })
        .fold(0.0, f64::max)
}

/// A start for the hierarchical fit: the robot displaced by the thesis's generator about its
/// centroid (radius: the robot's), as the thesis displaced its whole model, and every joint
/// moved by up to delta / (its links' reach), so that each joint alone moves its farthest
/// point by up to delta.
pub fn perturb_robot(
    body: &ArticulatedBody,
    world_from_root: &Isometry3<f64>,
    q: &[f64],
    delta_m: f64,
    rng: &mut TrialRng,
) -> (Isometry3<f64>, Vec<f64>) {
    let displacement = random_displacement(rng, delta_m, 1.0);
    let base = match body.rigid_mesh(q) {
        Some(mesh) => {
            let scaled = Isometry3::from_parts(
                displacement.translation,
                UnitQuaternion::from_scaled_axis(
                    displacement.rotation.scaled_axis() / mesh.radius_m(),
                ),
            );
            super::displace_about_centroid(world_from_root, &mesh, &scaled)
        }
        None => world_from_root * displacement,
    };
    let mut start = q.to_vec();
    let bounds = joint_start_bounds(body, world_from_root, q, delta_m);
    for ((parameter, value), bound) in start.iter_mut().enumerate().zip(bounds) {
        let info = &body.parameters()[parameter];
        *value = (*value + (2.0 * rng.uniform() - 1.0) * bound).clamp(info.lower, info.upper);
    }
    (base, start)
}

/// The most [`perturb_robot`] moves each joint from `q` (either way, before the limits): delta
/// over the reach of the links it moves, from the first one's origin (at least 5 cm), capped at
/// a half turn; delta for a prismatic joint.
pub fn joint_start_bounds(
    body: &ArticulatedBody,
    world_from_root: &Isometry3<f64>,
    q: &[f64],
    delta_m: f64,
) -> Vec<f64> {
    let poses = body.link_poses(world_from_root, q);
    let root = world_from_root * Point3::origin();
    (0..q.len())
        .map(|parameter| {
            if body.parameters()[parameter].prismatic {
                return delta_m;
            }
            let moved = body.moved_by(parameter);
            let origin = moved.first().map_or(root, |&l| poses[l] * Point3::origin());
            (delta_m / reach_from(body, &poses, &moved, &origin).max(0.05))
                .min(std::f64::consts::PI)
        })
        .collect()
}

/// Outcome of one alignment of one object (the robot or a link).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outcome {
    pub error_m: f64,
    pub time_s: f64,
    /// The fit reported what the scan could not tell, and `error_m` is the error of what it did
    /// claim: the joints moving the link that it reported as unseen (`observed: false`) set to
    /// the truth's values, or the fit's twin (reported `ambiguous`) where the twin is the true pose. A
    /// fit that reports what it cannot tell has not guessed; one that picks wrong unreported has.
    pub reported: bool,
}

/// Succeed / reported / fail / mean error / mean time over trials.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Tally {
    pub succeeded: usize,
    /// Trials within the threshold only through what the fit reported
    /// ([`Outcome::reported`]); not counted in `succeeded`.
    pub reported: usize,
    pub failed: usize,
    pub mean_error_m: f64,
    pub mean_time_s: f64,
    /// Indices in the seeded sequence of the trials that failed, to reproduce them with
    /// `first_trial` (see [`run_robot_trials`]).
    pub failed_trials: Vec<usize>,
}

impl Tally {
    /// Tallies outcomes numbered by their trials.
    pub fn from_numbered(outcomes: &[(usize, Outcome)]) -> Self {
        let n = outcomes.len().max(1) as f64;
        let failed_trials: Vec<usize> = outcomes
            .iter()
            .filter(|(_, o)| o.error_m >= SUCCESS_THRESHOLD_M)
            .map(|(trial, _)| *trial)
            .collect();
        let reported = outcomes
            .iter()
            .filter(|(_, o)| o.error_m < SUCCESS_THRESHOLD_M && o.reported)
            .count();
        Self {
            succeeded: outcomes.len() - failed_trials.len() - reported,
            reported,
            failed: failed_trials.len(),
            mean_error_m: outcomes.iter().map(|(_, o)| o.error_m).sum::<f64>() / n,
            mean_time_s: outcomes.iter().map(|(_, o)| o.time_s).sum::<f64>() / n,
            failed_trials,
        }
    }
}

/// One row of the table: an object (the robot, or a link) at one delta, both methods.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotTrialRow {
    pub object: String,
    pub delta_m: f64,
    pub independent: Option<Tally>,
    pub hierarchical: Option<Tally>,
}

/// Which methods a trial run compares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Methods {
    pub independent: bool,
    pub hierarchical: bool,
}

/// The scene the trials scan: the robot's root at `world_from_root`, joints at `q`.
#[derive(Debug, Clone)]
pub struct RobotScene {
    pub world_from_root: Isometry3<f64>,
    pub q: Vec<f64>,
    pub scan: RobotScanOptions,
}

/// A robot's true placement and a cloud of it, from any scanner: [`run_robot_trials_on_cloud`]
/// aligns to clouds this crate did not make (crates/cad-scans ray-casts them).
#[derive(Debug, Clone, Copy)]
pub struct ScannedRobot<'a> {
    pub world_from_root: Isometry3<f64>,
    /// The joint values the robot was scanned at.
    pub q: &'a [f64],
    pub cloud: &'a [Point3<f64>],
}

/// Mixed into the seed of the independent method's stream.
const INDEPENDENT_STREAM: u64 = 0x1D3E_7A11_0000_0001;

/// One hierarchical fit from a perturbed start: the outcome for the whole robot (its worst
/// link), then one per link of `links`.
fn hierarchical_trial(
    body: &ArticulatedBody,
    scanned: &ScannedRobot,
    poses: &[Isometry3<f64>],
    links: &[usize],
    delta_m: f64,
    rng: &mut TrialRng,
) -> Vec<Outcome> {
    let (base, q0) = perturb_robot(body, &scanned.world_from_root, scanned.q, delta_m, rng);
    let started = Instant::now();
    let fit = align_robot(
        body,
        scanned.cloud,
        &base,
        &q0,
        delta_m,
        &RobotFitOptions::default(),
    );
    let time_s = started.elapsed().as_secs_f64();
    // A failed alignment (no pose) counts with the error delta.
    let Ok(fit) = &fit else {
        return vec![
            Outcome {
                error_m: delta_m,
                time_s,
                reported: false,
            };
            links.len() + 1
        ];
    };
    // Which joints the scan pins at the true pose, judged as the fit judges its own state: a
    // joint the fit reports unseen is forgiven only where the scan does not show it.
    let shown = observed_joints_at(
        body,
        scanned.cloud,
        &base,
        delta_m,
        &scanned.world_from_root,
        scanned.q,
        &RobotFitOptions::default(),
    )
    .unwrap_or_else(|_| vec![true; scanned.q.len()]);
    let truth = Truth {
        poses,
        q: scanned.q,
        shown: &shown,
    };
    let fit_errors = link_errors(body, fit, &truth, links);
    // The other pose the fit reported as equally good, when it did.
    let twin_errors = fit.twin.as_ref().filter(|t| t.ambiguous).map(|twin| {
        let as_fit = RobotFit {
            world_from_root: twin.world_from_root,
            q: twin.q.clone(),
            ..fit.clone()
        };
        link_errors(body, &as_fit, &truth, links)
    });
    let worst = |errors: &[(f64, bool)]| {
        let error_m = errors.iter().map(|(e, _)| *e).fold(0.0, f64::max);
        (error_m, errors.iter().any(|(_, reported)| *reported))
    };
    let pick = |fit: (f64, bool), twin: Option<(f64, bool)>| match twin {
        Some((twin_m, _)) if fit.0 >= SUCCESS_THRESHOLD_M && twin_m < SUCCESS_THRESHOLD_M => {
            (twin_m, true)
        }
        _ => fit,
    };
    let whole = pick(worst(&fit_errors), twin_errors.as_deref().map(worst));
    let per_link =
        (0..links.len()).map(|i| pick(fit_errors[i], twin_errors.as_ref().map(|errors| errors[i])));
    std::iter::once(whole)
        .chain(per_link)
        .map(|(error_m, reported)| Outcome {
            error_m: finite_or_delta(error_m, delta_m),
            time_s,
            reported,
        })
        .collect()
}

/// What a trial knows that no fit does: every link's true pose, the true joint values, and
/// which joints the scan pins at the true pose ([`observed_joints_at`]).
struct Truth<'a> {
    poses: &'a [Isometry3<f64>],
    q: &'a [f64],
    shown: &'a [bool],
}

/// Each link's error in `fit`, and whether it counts only because the fit reported joints
/// that move the link as unseen where the scan does not show them
/// ([`unseen_joints_forgiven_m`]).
fn link_errors(
    body: &ArticulatedBody,
    fit: &RobotFit,
    truth: &Truth,
    links: &[usize],
) -> Vec<(f64, bool)> {
    let fitted = body.link_poses(&fit.world_from_root, &fit.q);
    links
        .iter()
        .map(|&link| {
            let mesh = body.links()[link].surface.as_ref().expect("has surface");
            let error_m = surface_deviation_m(mesh, &fitted[link], &truth.poses[link]);
            if error_m < SUCCESS_THRESHOLD_M {
                return (error_m, false);
            }
            match unseen_joints_forgiven_m(body, fit, link, truth) {
                Some(forgiven_m) if forgiven_m < error_m => (forgiven_m, true),
                _ => (error_m, false),
            }
        })
        .collect()
}

/// The error of `link` in `fit` with every joint that moves it and that the fit reported as
/// not seen in the scan (`observed: false`, kept at its start value) set to the truth's value,
/// the base and the joints it claimed as fitted. `None` when the fit claimed every joint that
/// moves the link, or when it reported unseen a joint the scan pins at the true pose
/// (`truth.shown`): that joint the fit lost, it did not fail to see it. Forgiven: a flange whose
/// spin the scan cannot show (the ABB IRB 1600's link_6), a wrist the scan shows on a few
/// points that do not pin its joint. A joint claimed and wrong stays the link's error.
fn unseen_joints_forgiven_m(
    body: &ArticulatedBody,
    fit: &RobotFit,
    link: usize,
    truth: &Truth,
) -> Option<f64> {
    let unseen: Vec<usize> = body
        .movers(link)
        .iter()
        .copied()
        .filter(|&parameter| {
            fit.joints
                .get(parameter)
                .is_some_and(|joint| !joint.observed)
        })
        .collect();
    if unseen.is_empty()
        || unseen
            .iter()
            .any(|&parameter| truth.shown.get(parameter).is_none_or(|&shown| shown))
    {
        return None;
    }
    let mut q = fit.q.clone();
    for parameter in unseen {
        q[parameter] = *truth.q.get(parameter)?;
    }
    let mesh = body.links()[link].surface.as_ref()?;
    Some(surface_deviation_m(
        mesh,
        &body.link_poses(&fit.world_from_root, &q)[link],
        &truth.poses[link],
    ))
}

fn finite_or_delta(error_m: f64, delta_m: f64) -> f64 {
    if error_m.is_finite() {
        error_m
    } else {
        delta_m
    }
}

/// Runs the seeded trials `trials` (indices into each delta's sequence; the starts of the trials
/// before `trials.start` are drawn and skipped, so a long run can be split and a failed trial
/// reproduced alone) per delta on the scene's cloud ([`scan_robot`]): see
/// [`run_robot_trials_on_cloud`].
pub fn run_robot_trials(
    body: &ArticulatedBody,
    scene: &RobotScene,
    deltas_m: &[f64],
    trials: Range<usize>,
    seed: u64,
    methods: Methods,
    on_trial: impl FnMut(f64, usize),
) -> Vec<RobotTrialRow> {
    let cloud = scan_robot(body, &scene.world_from_root, &scene.q, &scene.scan);
    let scanned = ScannedRobot {
        world_from_root: scene.world_from_root,
        q: &scene.q,
        cloud: &cloud,
    };
    run_robot_trials_on_cloud(body, &scanned, deltas_m, trials, seed, methods, on_trial)
}

/// The trials of [`run_robot_trials`] on a cloud made elsewhere: per delta, the hierarchical
/// fit of the robot from a perturbed start and the rigid alignment of the whole robot and of
/// each link from the thesis's displacement, as `methods` asks. Links are those with geometry.
/// Each method draws from its own seeded stream, so a method's figures are the same whether or
/// not the other one runs.
pub fn run_robot_trials_on_cloud(
    body: &ArticulatedBody,
    scanned: &ScannedRobot,
    deltas_m: &[f64],
    trials: Range<usize>,
    seed: u64,
    methods: Methods,
    mut on_trial: impl FnMut(f64, usize),
) -> Vec<RobotTrialRow> {
    let cloud = scanned.cloud;
    let poses = body.link_poses(&scanned.world_from_root, scanned.q);
    let links: Vec<usize> = (0..body.links().len())
        .filter(|&l| body.links()[l].surface.is_some())
        .collect();
    let whole = body.rigid_mesh(scanned.q);
    // The independent method's objects: the whole robot (when it has geometry), then each link.
    let objects: Vec<(&Mesh, Isometry3<f64>)> = whole
        .iter()
        .map(|mesh| (mesh, scanned.world_from_root))
        .chain(links.iter().map(|&link| {
            (
                body.links()[link].surface.as_ref().expect("has surface"),
                poses[link],
            )
        }))
        .collect();
    let pca_options = PcaOptions::default();
    let mut rows = Vec::new();
    for &delta_m in deltas_m {
        let mut rng = TrialRng::new(seed ^ delta_m.to_bits());
        let mut rigid_rng = TrialRng::new(seed ^ delta_m.to_bits() ^ INDEPENDENT_STREAM);
        for _ in 0..trials.start {
            perturb_robot(body, &scanned.world_from_root, scanned.q, delta_m, &mut rng);
            for (mesh, _) in &objects {
                random_displacement(&mut rigid_rng, delta_m, mesh.radius_m());
            }
        }
        // Outcomes per object: index 0 the whole robot, then one per link.
        let mut hierarchical: Vec<Vec<(usize, Outcome)>> = vec![Vec::new(); links.len() + 1];
        let mut rigid: Vec<Vec<(usize, Outcome)>> = vec![Vec::new(); links.len() + 1];
        let rigid_offset = usize::from(whole.is_none());
        for trial in trials.clone() {
            on_trial(delta_m, trial);
            if methods.hierarchical {
                hierarchical_trial(body, scanned, &poses, &links, delta_m, &mut rng)
                    .into_iter()
                    .zip(hierarchical.iter_mut())
                    .for_each(|(outcome, slot)| slot.push((trial, outcome)));
            }
            if !methods.independent {
                continue;
            }
            for (slot, (mesh, truth)) in objects.iter().enumerate() {
                let displacement = random_displacement(&mut rigid_rng, delta_m, mesh.radius_m());
                let start = super::displace_about_centroid(truth, mesh, &displacement);
                let started = Instant::now();
                let result = align_cloud(mesh, cloud, &start, delta_m, &pca_options);
                let time_s = started.elapsed().as_secs_f64();
                let error_m = result.map_or(delta_m, |r| {
                    surface_deviation_m(mesh, &r.alignment.base_from_part, truth)
                });
                rigid[slot + rigid_offset].push((
                    trial,
                    Outcome {
                        error_m,
                        time_s,
                        reported: false,
                    },
                ));
            }
        }
        let names = std::iter::once(body.robot.clone())
            .chain(links.iter().map(|&l| body.links()[l].name.clone()));
        for (slot, object) in names.enumerate() {
            rows.push(RobotTrialRow {
                object,
                delta_m,
                independent: methods
                    .independent
                    .then(|| Tally::from_numbered(&rigid[slot])),
                hierarchical: methods
                    .hierarchical
                    .then(|| Tally::from_numbered(&hierarchical[slot])),
            });
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::{PackageMap, RobotModel};
    use crate::registration::articulated::JointFit;
    use nalgebra::Translation3;

    /// A base and a flat flange on a joint about x: the flange's spin shows (it is a plate).
    const PLATE_FLANGE_URDF: &str = r#"<robot name="plate_flange">
  <link name="base"><visual><geometry><box size="0.2 0.2 0.2"/></geometry></visual></link>
  <link name="flange"><visual><origin xyz="0.05 0 0"/><geometry><box size="0.1 0.06 0.01"/></geometry></visual></link>
  <joint name="spin" type="revolute"><parent link="base"/><child link="flange"/>
    <origin xyz="0.1 0 0"/><axis xyz="1 0 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
</robot>"#;

    /// A base, a wrist on a joint about y and a plate flange on a joint about x beyond it: the
    /// wrist's joint moves both links.
    const WRIST_URDF: &str = r#"<robot name="wrist">
  <link name="base"><visual><geometry><box size="0.2 0.2 0.2"/></geometry></visual></link>
  <link name="wrist"><visual><origin xyz="0.05 0 0"/><geometry><box size="0.1 0.04 0.04"/></geometry></visual></link>
  <link name="flange"><visual><origin xyz="0.005 0 0.02"/><geometry><box size="0.01 0.06 0.04"/></geometry></visual></link>
  <joint name="bend" type="revolute"><parent link="base"/><child link="wrist"/>
    <origin xyz="0.1 0 0"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="spin" type="revolute"><parent link="wrist"/><child link="flange"/>
    <origin xyz="0.1 0 0"/><axis xyz="1 0 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
</robot>"#;

    fn fit_of(world_from_root: Isometry3<f64>, joints: &[(f64, bool)]) -> RobotFit {
        RobotFit {
            world_from_root,
            q: joints.iter().map(|(q, _)| *q).collect(),
            links: Vec::new(),
            joints: joints
                .iter()
                .enumerate()
                .map(|(index, &(value, observed))| JointFit {
                    name: format!("joint {index}"),
                    value,
                    observed,
                    turns_with_base: false,
                    within_95: None,
                })
                .collect(),
            iterations: 0,
            rms_m: 0.0,
            time_s: 0.0,
            twin: None,
        }
    }

    fn fit(world_from_root: Isometry3<f64>, q: f64, observed: bool) -> RobotFit {
        fit_of(world_from_root, &[(q, observed)])
    }

    fn body_of(urdf: &str) -> ArticulatedBody {
        let model = RobotModel::from_urdf_str(urdf, &PackageMap::new()).unwrap();
        ArticulatedBody::from_model(&model).unwrap()
    }

    fn link_named(body: &ArticulatedBody, name: &str) -> usize {
        (0..body.links().len())
            .find(|&l| body.links()[l].name == name)
            .unwrap()
    }

    #[test]
    fn only_a_spin_the_fit_reported_as_unseen_is_forgiven_and_nothing_else() {
        let body = body_of(PLATE_FLANGE_URDF);
        let flange = link_named(&body, "flange");
        let true_q = [0.3];
        let poses = body.link_poses(&Isometry3::identity(), &true_q);
        let truth = Truth {
            poses: &poses,
            q: &true_q,
            shown: &[false],
        };
        let mesh = body.links()[flange].surface.as_ref().unwrap();
        // Turned 0.8 rad from the truth: the plate's corners are some 20 mm off.
        let turned = fit(Isometry3::identity(), 1.1, false);
        let fitted = body.link_poses(&turned.world_from_root, &turned.q)[flange];
        assert!(surface_deviation_m(mesh, &fitted, &poses[flange]) > 0.01);
        let forgiven = unseen_joints_forgiven_m(&body, &turned, flange, &truth).unwrap();
        assert!(forgiven < 1e-9, "{forgiven}");
        // A spin the fit claims to have seen is its error.
        let claimed = fit(Isometry3::identity(), 1.1, true);
        assert_eq!(
            unseen_joints_forgiven_m(&body, &claimed, flange, &truth),
            None
        );
        // A spin reported unseen that the scan shows at the true pose is one the fit lost.
        let shown = Truth {
            shown: &[true],
            ..truth
        };
        assert_eq!(
            unseen_joints_forgiven_m(&body, &turned, flange, &shown),
            None
        );
        // Forgiving the spin does not hide a base 2 mm off.
        let shifted = fit(Translation3::new(0.0, 0.002, 0.0).into(), 1.1, false);
        let forgiven = unseen_joints_forgiven_m(&body, &shifted, flange, &truth).unwrap();
        assert!((forgiven - 0.002).abs() < 2e-4, "{forgiven}");
    }

    #[test]
    fn a_wrist_joint_reported_unseen_is_forgiven_on_every_link_it_moves_and_a_claimed_one_is_not() {
        let body = body_of(WRIST_URDF);
        let (wrist, flange) = (link_named(&body, "wrist"), link_named(&body, "flange"));
        let names: Vec<&str> = body.parameters().iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["bend", "spin"]);
        let true_q = [0.4, 0.2];
        let poses = body.link_poses(&Isometry3::identity(), &true_q);
        let truth = Truth {
            poses: &poses,
            q: &true_q,
            shown: &[false, false],
        };
        let error_of = |fit: &RobotFit, link: usize| {
            let fitted = body.link_poses(&fit.world_from_root, &fit.q)[link];
            surface_deviation_m(
                body.links()[link].surface.as_ref().unwrap(),
                &fitted,
                &poses[link],
            )
        };
        // The wrist bent 0.3 rad the wrong way and reported unseen, the flange's spin seen and
        // right: both links are forgiven to the truth.
        let unseen_bend = fit_of(Isometry3::identity(), &[(0.1, false), (0.2, true)]);
        for link in [wrist, flange] {
            assert!(error_of(&unseen_bend, link) > 0.01);
            let forgiven = unseen_joints_forgiven_m(&body, &unseen_bend, link, &truth).unwrap();
            assert!(forgiven < 1e-9, "{forgiven}");
        }
        // Not where the scan shows the bend at the true pose: the fit lost it.
        let bend_shown = Truth {
            shown: &[true, false],
            ..truth
        };
        for link in [wrist, flange] {
            assert_eq!(
                unseen_joints_forgiven_m(&body, &unseen_bend, link, &bend_shown),
                None
            );
        }
        // The bend claimed as seen and wrong, the spin reported unseen: the wrist is not
        // forgiven at all, the flange only its spin, which leaves the bend's error.
        let claimed_bend = fit_of(Isometry3::identity(), &[(0.1, true), (1.0, false)]);
        assert_eq!(
            unseen_joints_forgiven_m(&body, &claimed_bend, wrist, &truth),
            None
        );
        let flange_forgiven =
            unseen_joints_forgiven_m(&body, &claimed_bend, flange, &truth).unwrap();
        let bend_only = fit_of(Isometry3::identity(), &[(0.1, true), (0.2, true)]);
        assert!(flange_forgiven > 0.01, "{flange_forgiven}");
        assert!(
            (flange_forgiven - error_of(&bend_only, flange)).abs() < 1e-12,
            "{flange_forgiven}"
        );
    }
}
