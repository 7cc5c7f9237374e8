//! The measurement model the diagnosis fits: each touch's signed distance from the part's
//! surface as a function of the part pose and the effect parameters, its Jacobian, and a
//! Levenberg-Marquardt fit.

use std::sync::Mutex;

use nalgebra::{DMatrix, DVector, Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use super::effects::Effect;
use super::{Fit, TouchSample};
use crate::geometry::{Mesh, NearbyTriangles, SignedClosest};
use crate::kinematics::Chain;
use crate::tool::Tool;

/// One fitted effect parameter: the effect and the index among its parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub(super) struct Param {
    pub effect: Effect,
    pub index: usize,
}

/// The effect parameters' values, zero where not fitted.
#[derive(Debug, Default)]
pub(super) struct Extras {
    pub joint_offsets_rad: Vec<f64>,
    pub compliance_rad_per_nm: Vec<f64>,
    pub latency_s: f64,
    pub tcp_shift_m: Vector3<f64>,
    pub delta_radius_m: f64,
    pub scale_minus_one: f64,
}

impl Extras {
    /// Whether these effects change a joint angle (then the kinematics must run again).
    fn moves_joints(&self) -> bool {
        self.latency_s != 0.0
            || self.joint_offsets_rad.iter().any(|v| *v != 0.0)
            || self.compliance_rad_per_nm.iter().any(|v| *v != 0.0)
    }
}

pub(super) struct Problem<'a> {
    pub chain: Option<&'a Chain>,
    pub tool: &'a Tool,
    pub mesh: &'a Mesh,
    pub touches: &'a [TouchSample],
    pub start: Isometry3<f64>,
    pub centre: Point3<f64>,
    /// Gravity torque on each joint at each touch (N m), for `joint_compliance`; empty for a
    /// touch given as a flange pose.
    pub gravity_torques_nm: Vec<Vec<f64>>,
    /// Each touch's flange pose with no effect applied: fits that change no joint (the pose
    /// alone, TCP, radius, scale) reuse it instead of running the kinematics per evaluation.
    nominal_base_from_flange: Vec<Isometry3<f64>>,
    /// The triangles near each touch's last query: successive evaluations move a touch
    /// little, so most queries scan only those. Behind a lock so that fits may share the
    /// problem across threads; the answers do not depend on what the cache holds.
    nearby: Vec<Mutex<NearbyTriangles>>,
}

impl<'a> Problem<'a> {
    pub fn new(
        chain: Option<&'a Chain>,
        tool: &'a Tool,
        mesh: &'a Mesh,
        touches: &'a [TouchSample],
        start: Isometry3<f64>,
        gravity_torques_nm: Vec<Vec<f64>>,
    ) -> Self {
        let nominal_base_from_flange = touches
            .iter()
            .map(|touch| match (&touch.base_from_flange, chain) {
                (Some(pose), _) => *pose,
                (None, Some(chain)) => chain.forward_unchecked(&touch.q),
                // `diagnose` refuses joint touches without a chain.
                (None, None) => Isometry3::identity(),
            })
            .collect();
        Self {
            chain,
            tool,
            mesh,
            touches,
            start,
            centre: mesh.centroid(),
            gravity_torques_nm,
            nominal_base_from_flange,
            nearby: touches
                .iter()
                .map(|_| Mutex::new(NearbyTriangles::default()))
                .collect(),
        }
    }
}

impl Problem<'_> {
    pub fn dof(&self) -> usize {
        self.chain.map_or(0, Chain::dof)
    }

    pub fn names(&self, params: &[Param]) -> Vec<String> {
        params
            .iter()
            .map(|p| p.effect.parameter_names(self.dof())[p.index].clone())
            .collect()
    }

    fn extras(&self, params: &[Param], theta: &DVector<f64>) -> Extras {
        let dof = self.dof();
        let mut extras = Extras {
            joint_offsets_rad: vec![0.0; dof],
            compliance_rad_per_nm: vec![0.0; dof],
            ..Extras::default()
        };
        for (k, param) in params.iter().enumerate() {
            let value = theta[6 + k];
            param.effect.apply(&mut extras, param.index, value);
        }
        extras
    }

    /// The pose a parameter vector stands for: a twist about the part centre applied to the start.
    pub fn pose(&self, theta: &DVector<f64>) -> Isometry3<f64> {
        let radius = self.mesh.radius_m().max(1e-6);
        let rotation =
            UnitQuaternion::from_scaled_axis(Vector3::new(theta[0], theta[1], theta[2]) / radius);
        let translation = Vector3::new(theta[3], theta[4], theta[5]);
        let centre = self.start * self.centre;
        let shift = centre.coords + translation - rotation * centre.coords;
        Isometry3::from_parts(Translation3::from(shift), rotation) * self.start
    }

    /// The TCP of touch `index` in the base frame under the effects.
    fn base_from_tcp(&self, index: usize, extras: &Extras) -> Isometry3<f64> {
        let touch = &self.touches[index];
        let base_from_flange = match (&touch.base_from_flange, self.chain) {
            (Some(pose), _) => *pose,
            (None, Some(chain)) if extras.moves_joints() => {
                let mut q = touch.q.clone();
                for (j, v) in q.iter_mut().enumerate() {
                    *v += extras.joint_offsets_rad[j];
                    if let Some(torque) = self.gravity_torques_nm[index].get(j) {
                        *v += extras.compliance_rad_per_nm[j] * torque;
                    }
                }
                if let Some(qd) = &touch.qd {
                    q.iter_mut()
                        .zip(qd)
                        .for_each(|(v, d)| *v -= d * extras.latency_s);
                }
                chain.forward_unchecked(&q)
            }
            (None, _) => self.nominal_base_from_flange[index],
        };
        let mut flange_from_tcp = self.tool.flange_from_tcp;
        flange_from_tcp.translation.vector += extras.tcp_shift_m;
        base_from_flange * flange_from_tcp
    }

    /// Touch `index`'s ball centre in the base frame.
    fn centre_in_base(&self, index: usize, extras: &Extras) -> Point3<f64> {
        Point3::from(self.base_from_tcp(index, extras).translation.vector)
    }

    /// A ball centre in the part frame divided by the part's scale.
    fn in_part(
        centre_in_base: &Point3<f64>,
        extras: &Extras,
        part_from_base: &Isometry3<f64>,
    ) -> Point3<f64> {
        let mut in_part = part_from_base * centre_in_base;
        in_part.coords /= 1.0 + extras.scale_minus_one;
        in_part
    }

    /// Touch `index`'s ball centre in the part frame divided by the part's scale.
    fn query(&self, index: usize, extras: &Extras, part_from_base: &Isometry3<f64>) -> Point3<f64> {
        Self::in_part(&self.centre_in_base(index, extras), extras, part_from_base)
    }

    /// The signed closest point of touch `index`'s (scaled, part-frame) ball centre.
    fn closest(&self, index: usize, query: &Point3<f64>) -> SignedClosest {
        match self.nearby[index].lock() {
            Ok(mut nearby) => self.mesh.signed_closest_cached(query, &mut nearby),
            // A fit that panicked elsewhere poisoned the lock; the plain query needs no cache.
            Err(_) => self.mesh.signed_closest(query),
        }
    }

    fn radius(&self, extras: &Extras) -> f64 {
        self.tool.tip_radius_m + extras.delta_radius_m
    }

    fn kept(&self, skip: Option<usize>) -> impl Iterator<Item = usize> + '_ {
        (0..self.touches.len()).filter(move |i| Some(*i) != skip)
    }

    /// Signed distances of the touches (ball radius removed) for a parameter vector.
    pub fn residual(
        &self,
        params: &[Param],
        theta: &DVector<f64>,
        skip: Option<usize>,
    ) -> DVector<f64> {
        let extras = self.extras(params, theta);
        let part_from_base = self.pose(theta).inverse();
        let scale = 1.0 + extras.scale_minus_one;
        let values: Vec<f64> = self
            .kept(skip)
            .map(|index| {
                let query = self.query(index, &extras, &part_from_base);
                let found = self.closest(index, &query);
                found.signed_distance_m * scale - self.radius(&extras)
            })
            .collect();
        DVector::from_vec(values)
    }

    /// The residuals' Jacobian. The surface is linearised once at each touch's closest point (its
    /// distance's gradient there), and the ball centres are differentiated numerically through
    /// the kinematics: one closest-point query per touch instead of two per parameter.
    pub fn jacobian(
        &self,
        params: &[Param],
        theta: &DVector<f64>,
        skip: Option<usize>,
    ) -> DMatrix<f64> {
        let extras = self.extras(params, theta);
        let part_from_base = self.pose(theta).inverse();
        let kept: Vec<usize> = self.kept(skip).collect();
        // The pose columns move the part, not the ball centres: those are computed once.
        let centres: Vec<Point3<f64>> = kept
            .iter()
            .map(|&index| self.centre_in_base(index, &extras))
            .collect();
        let planes: Vec<(Point3<f64>, Vector3<f64>, f64)> = kept
            .iter()
            .zip(&centres)
            .map(|(&index, centre)| {
                let query = Self::in_part(centre, &extras, &part_from_base);
                let found = self.closest(index, &query);
                (query, found.gradient, found.signed_distance_m)
            })
            .collect();
        let linearised = |theta: &DVector<f64>, column: usize| -> DVector<f64> {
            let extras = self.extras(params, theta);
            let part_from_base = self.pose(theta).inverse();
            let scale = 1.0 + extras.scale_minus_one;
            DVector::from_iterator(
                kept.len(),
                kept.iter().zip(&centres).zip(&planes).map(
                    |((&index, centre), (at, gradient, distance))| {
                        let query = if column < 6 {
                            Self::in_part(centre, &extras, &part_from_base)
                        } else {
                            self.query(index, &extras, &part_from_base)
                        };
                        (distance + gradient.dot(&(query - at))) * scale - self.radius(&extras)
                    },
                ),
            )
        };
        let mut jacobian = DMatrix::zeros(kept.len(), theta.len());
        for column in 0..theta.len() {
            let step = if column < 6 {
                1e-6
            } else {
                1e-4 * params[column - 6].effect.bound()
            };
            let (mut plus, mut minus) = (theta.clone(), theta.clone());
            plus[column] += step;
            minus[column] -= step;
            let difference =
                (linearised(&plus, column) - linearised(&minus, column)) / (2.0 * step);
            jacobian.set_column(column, &difference);
        }
        jacobian
    }

    /// Levenberg-Marquardt with Marquardt's diagonal scaling from the start pose and no effect.
    pub fn fit(&self, params: &[Param], skip: Option<usize>) -> DVector<f64> {
        self.fit_from(params, skip, DVector::zeros(6 + params.len()))
    }

    /// Levenberg-Marquardt from `theta`.
    pub fn fit_from(
        &self,
        params: &[Param],
        skip: Option<usize>,
        mut theta: DVector<f64>,
    ) -> DVector<f64> {
        let mut residual = self.residual(params, &theta, skip);
        let mut cost = residual.norm_squared();
        let mut lambda = 1e-3;
        let mut jacobian = self.jacobian(params, &theta, skip);
        for _ in 0..60 {
            let normal = jacobian.transpose() * &jacobian;
            let gradient = jacobian.transpose() * &residual;
            let mut damped = normal.clone();
            for i in 0..damped.nrows() {
                damped[(i, i)] += lambda * normal[(i, i)].max(1e-12);
            }
            let Some(step) = damped.cholesky().map(|c| c.solve(&(-gradient))) else {
                lambda *= 10.0;
                if lambda > 1e8 {
                    break;
                }
                continue;
            };
            let candidate = &theta + &step;
            let candidate_residual = self.residual(params, &candidate, skip);
            let candidate_cost = candidate_residual.norm_squared();
            if candidate_cost < cost {
                let converged =
                    (cost - candidate_cost) < 1e-14 * cost.max(1e-30) || step.norm() < 1e-13;
                theta = candidate;
                residual = candidate_residual;
                cost = candidate_cost;
                lambda = (lambda * 0.3).max(1e-12);
                if converged {
                    break;
                }
                jacobian = self.jacobian(params, &theta, skip);
            } else {
                lambda *= 10.0;
                if lambda > 1e8 {
                    break;
                }
            }
        }
        theta
    }

    /// The fit's report: residuals, parameters with standard errors from the declared noise,
    /// BIC and the linearised leave-one-out RMS. `Err` when the information matrix is singular.
    pub fn summarise(
        &self,
        params: &[Param],
        theta: &DVector<f64>,
        sigma: f64,
    ) -> Result<Fit, String> {
        let residual = self.residual(params, theta, None);
        let n = residual.len();
        let k = theta.len();
        if n <= k {
            return Err(format!("{n} touches cannot fit {k} parameters"));
        }
        let jacobian = self.jacobian(params, theta, None);
        let information = jacobian.transpose() * &jacobian;
        let covariance = scaled_inverse(&information).ok_or_else(|| {
            "singular information matrix: the parameters trade off exactly".to_owned()
        })?;
        let rss = residual.norm_squared();
        let values = params
            .iter()
            .zip(self.names(params))
            .enumerate()
            .map(|(i, (_, name))| {
                (
                    name,
                    theta[6 + i],
                    sigma * covariance[(6 + i, 6 + i)].max(0.0).sqrt(),
                )
            })
            .collect();
        let extras = self.extras(params, theta);
        Ok(Fit {
            base_from_part: self.pose(theta),
            ball_centres_m: (0..n).map(|i| self.centre_in_base(i, &extras)).collect(),
            rms_m: (rss / n as f64).sqrt(),
            max_m: residual.iter().fold(0.0f64, |m, r| m.max(r.abs())),
            loo_rms_m: press_rms(&jacobian, &covariance, &residual),
            residuals_m: residual.iter().copied().collect(),
            // The noise is declared, not estimated: -2 log-likelihood is RSS / sigma^2. (With
            // the variance estimated from RSS, two fits both below the noise would differ by
            // n ln(RSS ratio), tens of units for a meaningless difference.)
            bic: rss / (sigma * sigma) + k as f64 * (n as f64).ln(),
            params: values,
        })
    }

    /// RMS of each touch's residual predicted by a fit without it, each refitted from `theta`
    /// (the fit with every touch, which one touch less moves only a little).
    pub fn leave_one_out(&self, params: &[Param], theta: &DVector<f64>) -> f64 {
        let n = self.touches.len();
        if n <= theta.len() + 1 {
            return f64::NAN;
        }
        let sum: f64 = (0..n)
            .map(|held| {
                let without = self.fit_from(params, Some(held), theta.clone());
                let all = self.residual(params, &without, None);
                all[held] * all[held]
            })
            .sum();
        (sum / n as f64).sqrt()
    }
}

/// The inverse of an information matrix, computed on its unit-diagonal scaling so that the
/// parameters' units do not decide what counts as singular.
pub(super) fn scaled_inverse(information: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let k = information.nrows();
    let scale = DVector::from_iterator(
        k,
        (0..k).map(|i| information[(i, i)].max(1e-300).sqrt().recip()),
    );
    let scaled = DMatrix::from_fn(k, k, |i, j| information[(i, j)] * scale[i] * scale[j]);
    let eigen = scaled.clone().symmetric_eigen();
    let (low, high) = eigen
        .eigenvalues
        .iter()
        .fold((f64::MAX, 0.0f64), |(lo, hi), v| (lo.min(*v), hi.max(*v)));
    if low.is_nan() || low <= high * 1e-12 {
        return None;
    }
    let inverse = scaled.try_inverse()?;
    Some(DMatrix::from_fn(k, k, |i, j| {
        inverse[(i, j)] * scale[i] * scale[j]
    }))
}

/// Leave-one-out RMS of a least-squares fit from its hat matrix (the PRESS statistic): touch i's
/// held-out residual is r_i / (1 - h_ii). Exact for a linear model, a close guide near the
/// optimum of this one.
fn press_rms(jacobian: &DMatrix<f64>, covariance: &DMatrix<f64>, residual: &DVector<f64>) -> f64 {
    let n = residual.len();
    let sum: f64 = (0..n)
        .map(|i| {
            let row = jacobian.row(i);
            let leverage = (row * covariance * row.transpose())[(0, 0)];
            let held_out = residual[i] / (1.0 - leverage).max(1e-6);
            held_out * held_out
        })
        .sum();
    (sum / n as f64).sqrt()
}
