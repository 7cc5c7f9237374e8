//! Gauss-Newton point-to-plane refinement of the base pose and the joints together.

use nalgebra::{DMatrix, DVector, Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::RobotFitOptions;
use super::placed::{Match, NO_HINT, Placed, correspond_hinted, placed_radius};
use crate::registration::articulated::body::{ArticulatedBody, JointAxis};

/// Gauss-Newton point-to-plane refinement of the base pose and all joints; returns iterations.
pub(super) fn refine(
    body: &ArticulatedBody,
    keypoints: &[Point3<f64>],
    world_from_root: &mut Isometry3<f64>,
    q: &mut [f64],
    band0: f64,
    options: &RobotFitOptions,
    exact: bool,
) -> usize {
    let all: Vec<usize> = (0..body.links().len()).collect();
    refine_links(
        body,
        keypoints,
        world_from_root,
        q,
        &all,
        &Refinement {
            options,
            band0_m: band0,
            damping: REFINE_DAMPING,
            exact,
        },
    )
}

/// Damping of the refinement's normal equations, relative to their largest diagonal entry.
const REFINE_DAMPING: f64 = 1e-6;
/// Damping while the beam search settles the links decided so far: much stronger, because
/// some of their motions are not constrained yet (the first joint and the base's turn about it
/// while every decided link is round about that axis) and must not wander until a link below
/// shows them.
pub(super) const SETTLE_DAMPING: f64 = 1e-3;

/// How a refinement runs, apart from what it moves and matches.
#[derive(Clone, Copy)]
pub(super) struct Refinement<'a> {
    /// The band it ends with, its iterations, tolerance and parallelism.
    pub(super) options: &'a RobotFitOptions,
    /// The band it starts from before shrinking to `options.band_min_m`, m.
    pub(super) band0_m: f64,
    /// Damping of the normal equations, relative to their largest diagonal entry.
    pub(super) damping: f64,
    /// Match against the exact link surfaces; false: their distance grids where they answer
    /// (see [`Placed::exact`]).
    pub(super) exact: bool,
}

/// [`refine`] on the surfaces of `links` only, with `refinement.damping` (relative to the
/// largest diagonal entry): joints that move none of them keep their values.
pub(super) fn refine_links(
    body: &ArticulatedBody,
    keypoints: &[Point3<f64>],
    world_from_root: &mut Isometry3<f64>,
    q: &mut [f64],
    links: &[usize],
    refinement: &Refinement,
) -> usize {
    let Refinement {
        options,
        band0_m: band0,
        damping,
        exact,
    } = *refinement;
    let n = 6 + q.len();
    // A refinement that starts in the narrow band has nothing to shrink.
    let shrink_iterations = if band0 > options.band_min_m {
        options.max_iterations.min(10)
    } else {
        0
    };
    let mut iterations = 0;
    let mut still = 0;
    // Once the band is fixed, correspondences switching between links or in and out of the
    // band can make Gauss-Newton cycle around the optimum by a few tenths of a millimetre
    // without two steps in a row below the tolerance: a refinement that runs out of
    // iterations ends at the state whose points carried the most weight (the robust kernel's
    // objective; a mean residual would favour states that push points out of the band).
    let mut best: Option<(f64, Isometry3<f64>, Vec<f64>)> = None;
    // Each keypoint's triangle at the previous step bounds its next exact search (the same
    // matches, fewer tree nodes opened; see `Placed::nearest_hinted`).
    let mut hints = if exact {
        vec![NO_HINT; keypoints.len()]
    } else {
        Vec::new()
    };
    while iterations < options.max_iterations {
        let fraction = if shrink_iterations == 0 {
            1.0
        } else {
            (iterations as f64 / shrink_iterations as f64).min(1.0)
        };
        let band = options.band_min_m
            + (band0 - options.band_min_m) * (fraction * std::f64::consts::FRAC_PI_2).cos();
        iterations += 1;
        let mut placed = Placed::new(body, world_from_root, q);
        placed.exact = exact;
        let matches = correspond_hinted(
            &placed,
            keypoints,
            band,
            links,
            options.parallel,
            &mut hints,
        );
        if matches.len() < 6 {
            break;
        }
        let total_weight: f64 = matches.iter().map(|m| m.weight).sum();
        if fraction >= 1.0
            && best
                .as_ref()
                .is_none_or(|(best_weight, _, _)| total_weight > *best_weight)
        {
            best = Some((total_weight, *world_from_root, q.to_vec()));
        }
        let scale = placed_radius(&placed);
        let equations = normal_equations(body, &placed, &matches, scale, exact, options.parallel);
        let Some(step) = solve_damped(&equations.normal, &equations.rhs, damping) else {
            break;
        };
        // How far the step moves the points along their normals (RMS). Against the exact
        // surfaces, of the link it moves most: over all points, a wrist's 100 among 30k moved by
        // a millimetre count a twentieth of that, below the tolerance, and the ABB IRB 1600's
        // joint 5 stopped 0.015 rad short (1.6 mm at its flange) in a ray-cast scan
        // (crates/cad-scans, `robot-scans`, scene 4 trial 0 at 50 mm). A link with fewer
        // matches than a link must have to count as seen does not hold the refinement up. On
        // the distance grids (a millimetre of blur at edges, before the exact refinements) the
        // motion of all points together is enough, and the per-link stop cost the shipped
        // robots' fits at 100 mm some 10 % more time (`articulated_starts`).
        let all_points_motion_m =
            (step.dot(&(&equations.normal * &step)).max(0.0) / total_weight).sqrt();
        let normal_motion_m = if exact {
            equations
                .largest_link_motion_m(&step, options.min_link_points as f64)
                .max(all_points_motion_m)
        } else {
            all_points_motion_m
        };
        let omega = Vector3::new(step[0], step[1], step[2]) / scale;
        let translation = Vector3::new(step[3], step[4], step[5]);
        let centre = world_from_root.translation.vector;
        let rotation = UnitQuaternion::from_scaled_axis(omega);
        let shift = centre + translation - rotation * centre;
        *world_from_root =
            Isometry3::from_parts(Translation3::from(shift), rotation) * *world_from_root;
        for (parameter, value) in q.iter_mut().enumerate() {
            let info = &body.parameters()[parameter];
            let change = step[6 + parameter] / if info.prismatic { 1.0 } else { scale };
            *value = (*value + change).clamp(info.lower, info.upper);
        }
        debug_assert_eq!(step.len(), n);
        still = if normal_motion_m < options.tolerance_m {
            still + 1
        } else {
            0
        };
        if fraction >= 1.0 && still >= 2 {
            return iterations;
        }
    }
    if let Some((_, best_pose, best_q)) = best {
        *world_from_root = best_pose;
        q.copy_from_slice(&best_q);
    }
    iterations
}

/// The normal equations of the point-to-plane residuals: J^T W J and J^T W r over every
/// match, and, when asked for, J^T W J and the weight of each link's matches alone (zero for a
/// link without any), which measure how far a step moves that link's points.
pub(super) struct NormalEquations {
    pub(super) normal: DMatrix<f64>,
    pub(super) rhs: DVector<f64>,
    /// Empty unless asked for.
    pub(super) link_normals: Vec<DMatrix<f64>>,
    link_weights: Vec<f64>,
}

impl NormalEquations {
    /// The RMS motion along their normals that `step` gives the matched points of the link it
    /// moves most, among links whose matches weigh at least `min_weight`, m (0 without the
    /// links' own equations). Motions no point constrains (a symmetric link's spin) do not
    /// count.
    pub(super) fn largest_link_motion_m(&self, step: &DVector<f64>, min_weight: f64) -> f64 {
        self.link_normals
            .iter()
            .zip(&self.link_weights)
            .filter(|&(_, &weight)| weight > 0.0 && weight >= min_weight)
            .map(|(normal, weight)| (step.dot(&(normal * step)).max(0.0) / weight).sqrt())
            .fold(0.0, f64::max)
    }
}

/// J^T W J and J^T W r of the point-to-plane residuals, and each link's own J^T W J when
/// `per_link`; rotations (base and revolute joints) are scaled by `scale` (m) so that every
/// column is in metres. The sums run over blocks of [`MATCHES_PER_BLOCK`] matches, side by side
/// with `parallel`, and are added in block order: the same answer with or without threads.
pub(super) fn normal_equations(
    body: &ArticulatedBody,
    placed: &Placed,
    matches: &[Match],
    scale: f64,
    per_link: bool,
    parallel: bool,
) -> NormalEquations {
    let n = 6 + body.parameters().len();
    let rows = JacobianRows::new(body, placed, scale);
    let links = if per_link { body.links().len() } else { 1 };
    let sum = |some: &[Match]| Sums::of(some, &rows, n, links, per_link);
    // The same blocks either way, so that a fit is the same with and without threads.
    let mut blocks: Vec<Sums> = if parallel {
        matches.par_chunks(MATCHES_PER_BLOCK).map(sum).collect()
    } else {
        matches.chunks(MATCHES_PER_BLOCK).map(sum).collect()
    };
    if blocks.is_empty() {
        blocks.push(sum(&[]));
    }
    let mut sums = blocks.remove(0);
    for other in &blocks {
        sums.add(other);
    }
    let symmetric = |buffer: &[f64]| {
        let mut matrix = DMatrix::from_column_slice(n, n, buffer);
        // The rank-one updates fill the lower triangles only; the refinement's measures of a
        // step (step . normal step) need the whole matrices.
        matrix.fill_upper_triangle_with_lower_triangle();
        matrix
    };
    let matrices: Vec<DMatrix<f64>> = sums.lower.chunks_exact(n * n).map(symmetric).collect();
    let (normal, link_normals, link_weights) = if per_link {
        let mut normal = DMatrix::zeros(n, n);
        for link_normal in &matrices {
            normal += link_normal;
        }
        (normal, matrices, sums.weights)
    } else {
        let normal = matrices.into_iter().next().expect("one matrix");
        (normal, Vec::new(), Vec::new())
    };
    NormalEquations {
        normal,
        rhs: DVector::from_vec(sums.rhs),
        link_normals,
        link_weights,
    }
}

/// Matches per block of [`normal_equations`]'s parallel sums: an exact refinement of the ABB
/// IRB 1600's 20k-point scan matches about 15 000 keypoints a step, and summing them on one
/// core was a tenth of its fit (docs/BENCHMARKS.md).
const MATCHES_PER_BLOCK: usize = 4096;

/// [`normal_equations`]' sums over some matches: the lower triangles of J^T W J (column-major,
/// one n x n matrix per link when per link, else one), each link's weight, J^T W r.
struct Sums {
    lower: Vec<f64>,
    weights: Vec<f64>,
    rhs: Vec<f64>,
}

impl Sums {
    /// Element (i, j), i >= j, of a matrix gains (w row[j]) row[i] for each match in order, and
    /// J^T W r its (r w) row: the arithmetic of nalgebra's `syger` and `axpy`, which every trial
    /// was measured with (a unit test compares them to the last bit).
    fn of(matches: &[Match], rows: &JacobianRows, n: usize, links: usize, per_link: bool) -> Self {
        let mut sums = Self {
            lower: vec![0.0; links * n * n],
            weights: vec![0.0; links],
            rhs: vec![0.0; n],
        };
        let mut row = vec![0.0; n];
        for m in matches {
            rows.fill(m, &mut row);
            let residual = m.normal.dot(&(m.point - m.surface));
            let link = if per_link { m.link } else { 0 };
            sums.weights[link] += m.weight;
            let lower = &mut sums.lower[link * n * n..(link + 1) * n * n];
            for (j, column) in lower.chunks_exact_mut(n).enumerate() {
                let scaled = m.weight * row[j];
                for (sum, value) in column[j..].iter_mut().zip(&row[j..]) {
                    *sum += scaled * value;
                }
            }
            let scaled = residual * m.weight;
            for (sum, value) in sums.rhs.iter_mut().zip(&row) {
                *sum += scaled * value;
            }
        }
        sums
    }

    fn add(&mut self, other: &Self) {
        let pairs = self
            .lower
            .iter_mut()
            .chain(&mut self.weights)
            .chain(&mut self.rhs)
            .zip(other.lower.iter().chain(&other.weights).chain(&other.rhs));
        for (sum, value) in pairs {
            *sum += value;
        }
    }
}

/// The point-to-plane Jacobian's rows: a match's motion along its normal per unit of each
/// parameter, the base's turn (about the root's origin) and shift, then the joints'. Turns
/// (the base's and revolute joints') are per `scale` metres of arc, so that every column is in
/// metres.
pub(super) struct JacobianRows {
    axes: Vec<Option<(JointAxis, usize, f64)>>,
    joints_above: Vec<Vec<usize>>,
    centre: Vector3<f64>,
    scale: f64,
}

impl JacobianRows {
    pub(super) fn new(body: &ArticulatedBody, placed: &Placed, scale: f64) -> Self {
        Self {
            axes: body.axes(&placed.poses),
            joints_above: (0..body.links().len())
                .map(|link| body.joints_above(link))
                .collect(),
            centre: placed.poses[body.root()].translation.vector,
            scale,
        }
    }

    /// `m`'s row, into `row` (6 + parameters long).
    pub(super) fn fill(&self, m: &Match, row: &mut [f64]) {
        row.fill(0.0);
        let lever = (m.surface.coords - self.centre).cross(&m.normal) / self.scale;
        for axis in 0..3 {
            row[axis] = lever[axis];
            row[3 + axis] = m.normal[axis];
        }
        for &joint in &self.joints_above[m.link] {
            if let Some((frame, parameter, multiplier)) = self.axes[joint] {
                row[6 + parameter] += multiplier
                    * if frame.prismatic {
                        frame.axis.dot(&m.normal)
                    } else {
                        frame.axis.dot(&(m.surface - frame.origin).cross(&m.normal)) / self.scale
                    };
            }
        }
    }
}

/// Solves the normal equations with a little damping, so that a direction no point constrains
/// (a symmetric link's spin, a link nobody sees) stays where it is instead of blowing up.
fn solve_damped(normal: &DMatrix<f64>, rhs: &DVector<f64>, damping: f64) -> Option<DVector<f64>> {
    let mut normal = normal.clone();
    let largest = (0..normal.nrows())
        .map(|i| normal[(i, i)])
        .fold(0.0, f64::max);
    for i in 0..normal.nrows() {
        normal[(i, i)] += largest * damping + 1e-12;
    }
    Some(normal.cholesky()?.solve(rhs))
}
