//! Pose uncertainty of a Point Set Alignment: the covariance of the aligned pose that the touch
//! noise and the touch geometry imply, its 95 % confidence regions, the least constrained motion
//! and the pose distance it is within at 95 %. The cloud alignment's (`pca::uncertainty`) shares
//! the model through [`uncertainty_of_observations`], its matches in place of the touches.
//!
//! # Model
//!
//! Each touch `i` reports the centre `y_i` of the probe's ball (base frame). Its residual is the
//! signed distance of `y_i` from the part's surface minus the ball radius, `d_i`. A small rigid
//! motion of the part, applied in the base frame about the reference point `o`,
//!
//! ```text
//! x' = x + δω × (x - o) + δt          (left perturbation: R' = exp([δω]×) R)
//! ```
//!
//! changes it to first order as `d_i(δ) ≈ d_i - n_i · (δt + δω × (s_i - o))`, with `n_i` the
//! outward unit normal and `s_i` the closest surface point (base frame). Row `i` of the Jacobian is
//! `[(s_i - o) × n_i, n_i]` (the sign does not matter for `JᵀJ`). With independent N(0, σ²) touch
//! errors along the normals the least-squares pose has covariance
//!
//! ```text
//! Σ = σ² (JᵀJ)⁻¹,    order [rx, ry, rz, x, y, z], rad and m.
//! ```
//!
//! The reference point `o` is the part's origin in the base frame (`base_from_part.translation`),
//! so `δt` is exactly the error of the reported translation and `δω` the rotation vector of
//! `R_est R_trueᵀ` (see [`pose_deviation`]): the covariance describes the numbers the alignment
//! reports.
//!
//! # Normals at edges
//!
//! Inside a face the three candidate normals agree. Where the ball's closest surface point lies on
//! an edge or a vertex (a ball resting on an edge), the residual is the distance from the ball's
//! centre to that edge, whose gradient is the unit vector from the closest point to the ball's
//! centre: that is the direction in which a motion of the part changes the residual. The face
//! normal of whichever adjacent triangle the query returned is off by up to half the dihedral
//! angle, and the pseudo-normal is made for the inside/outside sign, not as a gradient. So this
//! module uses the face normal inside faces and the centre-to-ball direction on edges and vertices,
//! falling back to the pseudo-normal only when the ball's centre lies on the surface itself
//! (zero radius and zero residual), where the distance is not differentiable.
//!
//! The correspondence is the plain closest point at the given pose; at a converged alignment that
//! is the face the touch landed on (coherence and face hints of the alignment do not change it
//! there).

use nalgebra::{Isometry3, Matrix3, Matrix6, Point3, SymmetricEigen, Vector3, Vector6};

use super::psa::Touch;
use crate::geometry::Mesh;

/// Two-sided 95 % quantile of the standard normal distribution.
pub const Z_95: f64 = 1.959_963_984_540_054;
/// 95 % quantile of the chi-square distribution with 3 degrees of freedom.
pub const CHI2_95_3DOF: f64 = 7.814_727_903_251_178;
/// 95 % quantile of the chi-square distribution with 6 degrees of freedom.
pub const CHI2_95_6DOF: f64 = 12.591_587_243_743_977;
/// Smallest accepted ratio of the smallest to the largest eigenvalue of the scaled normal matrix.
pub const CONDITION_LIMIT: f64 = 1e-10;

/// Order of [`PoseUncertainty::covariance`]'s rows and columns.
pub const COVARIANCE_ORDER: [&str; 6] = ["rx", "ry", "rz", "x", "y", "z"];

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UncertaintyError {
    #[error("{count} touches cannot fix 6 degrees of freedom (at least 6 needed)")]
    TooFewTouches { count: usize },
    #[error("{what} is not finite")]
    NonFinite { what: String },
    #[error("the noise sigma must be finite and >= 0, got {0}")]
    InvalidSigma(f64),
    #[error("the tip radius must be finite and >= 0, got {0}")]
    InvalidTipRadius(f64),
    #[error(
        "the touches leave {motion} free (smallest/largest eigenvalue of the scaled normal matrix {ratio:.1e})"
    )]
    Underconstrained { motion: String, ratio: f64 },
    #[error("{residuals} residuals cannot estimate a sigma with {parameters} fitted parameters")]
    TooFewResiduals { residuals: usize, parameters: usize },
}

/// The least constrained rigid motion of the part (base frame) and its 95 % size: 1.96 standard
/// deviations along that single direction.
#[derive(Debug, Clone, PartialEq)]
pub enum WeakDirection {
    /// A translation along a unit `direction`.
    Translation {
        direction: Vector3<f64>,
        size_95_mm: f64,
    },
    /// A rotation about the unit `axis` through `point` (the point of the axis nearest the
    /// part's centroid).
    Rotation {
        axis: Vector3<f64>,
        point: Point3<f64>,
        size_95_mrad: f64,
    },
    /// A rotation about `axis` through `point` combined with a translation along it of
    /// `pitch_m_per_rad` per radian (numerically mm per mrad). `translation_95_mm` is the
    /// translation along the axis that goes with `size_95_mrad`.
    Screw {
        axis: Vector3<f64>,
        point: Point3<f64>,
        pitch_m_per_rad: f64,
        size_95_mrad: f64,
        translation_95_mm: f64,
    },
}

impl WeakDirection {
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Translation { .. } => "translation",
            Self::Rotation { .. } => "rotation",
            Self::Screw { .. } => "screw",
        }
    }

    /// The translation's direction or the rotation's axis (unit, base frame).
    pub fn axis(&self) -> Vector3<f64> {
        match self {
            Self::Translation { direction, .. } => *direction,
            Self::Rotation { axis, .. } | Self::Screw { axis, .. } => *axis,
        }
    }

    /// A point on the rotation's axis (base frame, m); `None` for a translation.
    pub fn point(&self) -> Option<Point3<f64>> {
        match self {
            Self::Translation { .. } => None,
            Self::Rotation { point, .. } | Self::Screw { point, .. } => Some(*point),
        }
    }

    /// The 95 % size and its unit: mm for a translation, mrad for a rotation or screw.
    pub fn size_95(&self) -> (f64, &'static str) {
        match self {
            Self::Translation { size_95_mm, .. } => (*size_95_mm, "mm"),
            Self::Rotation { size_95_mrad, .. } | Self::Screw { size_95_mrad, .. } => {
                (*size_95_mrad, "mrad")
            }
        }
    }

    /// One sentence, e.g. "weakest: rotation about (0.000, 0.000, 1.000) through
    /// (0.612, 0.100, 0.050) m, 95% +-0.84 mrad".
    pub fn describe(&self) -> String {
        match self {
            Self::Translation {
                direction,
                size_95_mm,
            } => format!(
                "weakest: translation along {}, 95% +-{} mm",
                fmt_unit(direction),
                fmt_size(*size_95_mm)
            ),
            Self::Rotation {
                axis,
                point,
                size_95_mrad,
            } => format!(
                "weakest: rotation about {} through {} m, 95% +-{} mrad",
                fmt_unit(axis),
                fmt_point(point),
                fmt_size(*size_95_mrad)
            ),
            Self::Screw {
                axis,
                point,
                pitch_m_per_rad,
                size_95_mrad,
                translation_95_mm,
            } => format!(
                "weakest: screw about {} through {} m, pitch {:.4} mm/mrad, 95% +-{} mrad with +-{} mm along the axis",
                fmt_unit(axis),
                fmt_point(point),
                pitch_m_per_rad,
                fmt_size(*size_95_mrad),
                fmt_size(*translation_95_mm)
            ),
        }
    }
}

/// A 95 % confidence ellipsoid of three coordinates and their per-axis half-widths.
#[derive(Debug, Clone, PartialEq)]
pub struct Ellipsoid95 {
    /// Semi-axes, largest first: sqrt(7.8147 λ) for the eigenvalues λ of the 3x3 block.
    pub semi_axes: [f64; 3],
    /// Unit directions of the semi-axes, base frame.
    pub axes: [Vector3<f64>; 3],
    /// 1.96 standard deviations of x, y, z (or rx, ry, rz) alone.
    pub half_widths: [f64; 3],
}

/// The covariance of an aligned pose and what it means.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseUncertainty {
    /// Noise the covariance was computed with, m.
    pub sigma_m: f64,
    /// 6x6 covariance in [`COVARIANCE_ORDER`]: rotation vector (base frame, rad) first, then the
    /// translation of the part's origin (base frame, m).
    pub covariance: Matrix6<f64>,
    /// The point the rotation is taken about: the part's origin in the base frame.
    pub reference_point: Point3<f64>,
    /// The part's radius used to compare rotations with translations, m.
    pub radius_m: f64,
    /// Position of the part's origin: semi-axes and half-widths in mm.
    pub position_95_mm: Ellipsoid95,
    /// Orientation: semi-axes and half-widths in mrad.
    pub rotation_95_mrad: Ellipsoid95,
    pub weak_direction: WeakDirection,
    /// The point of the part (base frame) whose position is known best (smallest trace of its
    /// position covariance); `None` when not computable.
    pub least_uncertain_point: Option<Point3<f64>>,
    /// Smallest/largest eigenvalue of the scaled normal matrix (1 is ideal).
    pub condition: f64,
    /// The thesis's pose distance from the truth (|δt| and the angle times `radius_m`, combined
    /// as a hypotenuse) that 95 % of fits stay within, m (see [`pose_distance_quantile_95`]).
    pub pose_distance_95_m: f64,
}

impl PoseUncertainty {
    /// Covariance of the rotation vector, rad².
    pub fn rotation_covariance(&self) -> Matrix3<f64> {
        self.covariance.fixed_view::<3, 3>(0, 0).into_owned()
    }

    /// Covariance of the part origin's position, m².
    pub fn translation_covariance(&self) -> Matrix3<f64> {
        self.covariance.fixed_view::<3, 3>(3, 3).into_owned()
    }

    /// The same covariance in the order [x, y, z, rx, ry, rz].
    pub fn covariance_translation_first(&self) -> Matrix6<f64> {
        let mut swapped = Matrix6::zeros();
        for row in 0..6 {
            for col in 0..6 {
                swapped[(row, col)] = self.covariance[((row + 3) % 6, (col + 3) % 6)];
            }
        }
        swapped
    }

    /// Covariance (m²) of the position of the part point that sits at `point` (base frame).
    pub fn position_covariance_at(&self, point: &Point3<f64>) -> Matrix3<f64> {
        // δp = δt + δω × a = δt - [a]× δω.
        let a = point - self.reference_point;
        let mut map = nalgebra::Matrix3x6::zeros();
        map.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(-a.cross_matrix()));
        map.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&Matrix3::identity());
        map * self.covariance * map.transpose()
    }

    /// Squared Mahalanobis distance of a deviation (in [`COVARIANCE_ORDER`], see
    /// [`pose_deviation`]); `None` when the covariance is not invertible (zero sigma).
    pub fn mahalanobis_squared(&self, deviation: &Vector6<f64>) -> Option<f64> {
        let inverse = self.covariance.cholesky()?.inverse();
        Some((deviation.transpose() * inverse * deviation)[(0, 0)])
    }
}

/// Deviation of `pose` from `reference` in the parameterisation of the covariance:
/// [rotation vector of R_pose R_refᵀ (rad), t_pose - t_ref (m)].
pub fn pose_deviation(reference: &Isometry3<f64>, pose: &Isometry3<f64>) -> Vector6<f64> {
    let rotation = (pose.rotation * reference.rotation.inverse()).scaled_axis();
    let translation = pose.translation.vector - reference.translation.vector;
    Vector6::new(
        rotation.x,
        rotation.y,
        rotation.z,
        translation.x,
        translation.y,
        translation.z,
    )
}

/// Noise sigma estimated from the residuals of a fit: s = sqrt(RSS / (N - `fitted_parameters`)),
/// m. For a rigid alignment `fitted_parameters` is 6.
pub fn sigma_from_residuals(
    residuals_m: &[f64],
    fitted_parameters: usize,
) -> Result<f64, UncertaintyError> {
    if residuals_m.len() <= fitted_parameters {
        return Err(UncertaintyError::TooFewResiduals {
            residuals: residuals_m.len(),
            parameters: fitted_parameters,
        });
    }
    if let Some(index) = residuals_m.iter().position(|r| !r.is_finite()) {
        return Err(UncertaintyError::NonFinite {
            what: format!("residual {index}"),
        });
    }
    let rss: f64 = residuals_m.iter().map(|r| r * r).sum();
    Ok((rss / (residuals_m.len() - fitted_parameters) as f64).sqrt())
}

/// The covariance of the pose `base_from_part` aligned to `touches` (ball centres, base frame)
/// when each touch errs along its surface normal with standard deviation `noise_sigma_m`.
pub fn pose_uncertainty(
    mesh: &Mesh,
    touches: &[Touch],
    base_from_part: &Isometry3<f64>,
    tip_radius_m: f64,
    noise_sigma_m: f64,
) -> Result<PoseUncertainty, UncertaintyError> {
    if !(noise_sigma_m.is_finite() && noise_sigma_m >= 0.0) {
        return Err(UncertaintyError::InvalidSigma(noise_sigma_m));
    }
    if !(tip_radius_m.is_finite() && tip_radius_m >= 0.0) {
        return Err(UncertaintyError::InvalidTipRadius(tip_radius_m));
    }
    if touches.len() < 6 {
        return Err(UncertaintyError::TooFewTouches {
            count: touches.len(),
        });
    }
    let pose_finite = base_from_part
        .translation
        .vector
        .iter()
        .chain(base_from_part.rotation.coords.iter())
        .all(|c| c.is_finite());
    if !pose_finite {
        return Err(UncertaintyError::NonFinite {
            what: "the pose".to_owned(),
        });
    }
    let part_from_base = base_from_part.inverse();
    let mut observations = Vec::with_capacity(touches.len());
    for touch in touches {
        if !touch.point.coords.iter().all(|c| c.is_finite()) {
            return Err(UncertaintyError::NonFinite {
                what: format!("touch '{}'", touch.id),
            });
        }
        let in_part = part_from_base * touch.point;
        // The distance's gradient, as the alignment linearises it (its sign does not change
        // J^T J).
        let closest = mesh.signed_closest(&in_part);
        if !closest.signed_distance_m.is_finite() {
            return Err(UncertaintyError::NonFinite {
                what: format!("the distance of touch '{}' from the mesh", touch.id),
            });
        }
        observations.push(SurfaceObservation {
            surface: base_from_part * closest.point,
            direction: base_from_part.rotation * closest.gradient,
        });
    }
    uncertainty_of_observations(
        &observations,
        base_from_part,
        mesh.radius_m(),
        &(base_from_part * mesh.centroid()),
        noise_sigma_m,
    )
}

/// One residual of a fit to the part's surface: the surface point it was measured against (base
/// frame) and the unit direction along which it is measured (base frame; its sign does not
/// matter).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceObservation {
    pub surface: Point3<f64>,
    pub direction: Vector3<f64>,
}

/// The covariance `σ² (JᵀJ)⁻¹` of the pose `base_from_part` fitted to `observations` whose
/// residuals err with standard deviation `sigma_m` each, independently. `centre` (base frame) is
/// where the weak direction's axis is placed nearest; `radius_m` compares rotations with
/// translations.
pub fn uncertainty_of_observations(
    observations: &[SurfaceObservation],
    base_from_part: &Isometry3<f64>,
    radius_m: f64,
    centre: &Point3<f64>,
    sigma_m: f64,
) -> Result<PoseUncertainty, UncertaintyError> {
    if !(sigma_m.is_finite() && sigma_m >= 0.0) {
        return Err(UncertaintyError::InvalidSigma(sigma_m));
    }
    let origin = Point3::from(base_from_part.translation.vector);
    let radius_m = radius_m.max(1e-9);

    // Normal matrix with the rotation columns divided by the radius: all entries in m⁰, so its
    // conditioning compares like with like.
    let mut scaled_normal = Matrix6::zeros();
    for observation in observations {
        let normal = observation.direction;
        let lever = observation.surface - origin;
        let moment = lever.cross(&normal) / radius_m;
        let row = Vector6::new(moment.x, moment.y, moment.z, normal.x, normal.y, normal.z);
        if !row.iter().all(|c| c.is_finite()) {
            return Err(UncertaintyError::NonFinite {
                what: "an observation".to_owned(),
            });
        }
        scaled_normal += row * row.transpose();
    }

    let eigen = SymmetricEigen::new(scaled_normal);
    let largest = eigen.eigenvalues.max();
    let (weakest, smallest) = eigen
        .eigenvalues
        .iter()
        .copied()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, 0.0));
    let condition = if largest > 0.0 {
        smallest / largest
    } else {
        0.0
    };
    if condition.is_nan() || condition <= CONDITION_LIMIT {
        let direction = eigen.eigenvectors.column(weakest).into_owned();
        let motion = classify(&direction, radius_m, &origin, centre);
        return Err(UncertaintyError::Underconstrained {
            motion: motion.free_motion(),
            ratio: condition.max(0.0),
        });
    }

    // Scaled covariance σ² V Λ⁻¹ Vᵀ (rotation in rad·radius), then unscaled.
    let variance = sigma_m * sigma_m;
    let inverse_values = eigen.eigenvalues.map(|l| variance / l);
    let scaled_covariance = eigen.eigenvectors
        * Matrix6::from_diagonal(&inverse_values)
        * eigen.eigenvectors.transpose();
    let unscale = Vector6::new(
        1.0 / radius_m,
        1.0 / radius_m,
        1.0 / radius_m,
        1.0,
        1.0,
        1.0,
    );
    let mut covariance =
        Matrix6::from_diagonal(&unscale) * scaled_covariance * Matrix6::from_diagonal(&unscale);
    covariance = (covariance + covariance.transpose()) * 0.5;

    let rotation_block = covariance.fixed_view::<3, 3>(0, 0).into_owned();
    let translation_block = covariance.fixed_view::<3, 3>(3, 3).into_owned();
    let position_95_mm = ellipsoid(&translation_block, 1e3);
    let rotation_95_mrad = ellipsoid(&rotation_block, 1e3);

    // The largest-variance direction of the scaled covariance is the smallest-eigenvalue
    // direction of the scaled normal matrix; its standard deviation is σ / sqrt(λ_min).
    let direction = eigen.eigenvectors.column(weakest).into_owned();
    let sd = sigma_m / smallest.sqrt();
    let weak_direction = classify(&direction, radius_m, &origin, centre).sized(sd);

    let least_uncertain_point = least_uncertain_point(&covariance, &origin);

    let pose_distance_95_m = pose_distance_quantile_95(&scaled_covariance);

    Ok(PoseUncertainty {
        sigma_m,
        pose_distance_95_m,
        covariance,
        reference_point: origin,
        radius_m,
        position_95_mm,
        rotation_95_mrad,
        weak_direction,
        least_uncertain_point,
        condition,
    })
}

/// One-sided 95 % quantile of the standard normal distribution.
const Z_95_ONE_SIDED: f64 = 1.644_853_626_951_472_2;

/// The 95 % quantile of the pose distance, m, for the scaled covariance (rotations times the
/// radius): its square is Σ μ_i z_i² over the eigenvalues μ_i, taken as a χ² with matched mean and
/// variance (a χ²_ν times Σμ² / Σμ, ν = (Σμ)² / Σμ², Welch-Satterthwaite) and that χ²'s quantile
/// by Wilson and Hilferty's cube root (within 3 % of the exact one for ν >= 1).
fn pose_distance_quantile_95(scaled_covariance: &Matrix6<f64>) -> f64 {
    let eigenvalues = SymmetricEigen::new(*scaled_covariance).eigenvalues;
    let (sum, sum_of_squares) = eigenvalues
        .iter()
        .map(|mu| mu.max(0.0))
        .fold((0.0, 0.0), |(sum, squares), mu| {
            (sum + mu, squares + mu * mu)
        });
    if sum <= 0.0 || sum_of_squares <= 0.0 {
        return 0.0;
    }
    let scale = sum_of_squares / sum;
    let dof = sum * sum / sum_of_squares;
    let spread = (2.0 / (9.0 * dof)).sqrt();
    let quantile = dof * (1.0 - spread * spread + Z_95_ONE_SIDED * spread).powi(3);
    (scale * quantile).sqrt()
}

/// The 95 % ellipsoid of a 3x3 covariance block, scaled by `unit` (1e3: m -> mm, rad -> mrad).
fn ellipsoid(block: &Matrix3<f64>, unit: f64) -> Ellipsoid95 {
    let eigen = SymmetricEigen::new(*block);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
    let semi_axes = order.map(|i| (CHI2_95_3DOF * eigen.eigenvalues[i].max(0.0)).sqrt() * unit);
    let axes = order.map(|i| canonical_sign(&eigen.eigenvectors.column(i).into_owned()));
    let half_widths = [0, 1, 2].map(|i| Z_95 * block[(i, i)].max(0.0).sqrt() * unit);
    Ellipsoid95 {
        semi_axes,
        axes,
        half_widths,
    }
}

/// The part point whose position covariance has the smallest trace: minimises
/// E|δt + δω × a|² = E|δt|² + 2 a·E[δt × δω] + aᵀ (tr Σωω I - Σωω) a over a.
fn least_uncertain_point(covariance: &Matrix6<f64>, origin: &Point3<f64>) -> Option<Point3<f64>> {
    let rotation = covariance.fixed_view::<3, 3>(0, 0).into_owned();
    let cross = |i: usize, j: usize| covariance[(3 + i, j)]; // E[δt_i δω_j]
    let b = Vector3::new(
        cross(1, 2) - cross(2, 1),
        cross(2, 0) - cross(0, 2),
        cross(0, 1) - cross(1, 0),
    );
    let m = Matrix3::identity() * rotation.trace() - rotation;
    let a = -m.cholesky()?.solve(&b);
    a.iter().all(|c| c.is_finite()).then(|| origin + a)
}

/// A unit direction of the scaled parameter space, as a motion of the part.
#[derive(Debug, Clone, Copy)]
struct Motion {
    kind: MotionKind,
    /// Rotation angle per unit of the scaled direction, rad (0 for a translation).
    angle: f64,
    /// Translation per unit (along the direction for a translation, along the axis for a screw), m.
    shift: f64,
}

#[derive(Debug, Clone, Copy)]
enum MotionKind {
    Translation {
        direction: Vector3<f64>,
    },
    Rotation {
        axis: Vector3<f64>,
        point: Point3<f64>,
    },
    Screw {
        axis: Vector3<f64>,
        point: Point3<f64>,
        pitch: f64,
    },
}

/// Decomposes `direction` (scaled: rotation·radius, translation at `origin`) into a screw. An
/// axis more than ten radii from the part's centre moves the part as a translation; a pitch below
/// 5 % of the radius per radian is a plain rotation.
fn classify(
    direction: &Vector6<f64>,
    radius_m: f64,
    origin: &Point3<f64>,
    centre: &Point3<f64>,
) -> Motion {
    let omega = Vector3::new(direction[0], direction[1], direction[2]) / radius_m;
    let velocity = Vector3::new(direction[3], direction[4], direction[5]);
    let angle = omega.norm();
    let translation_only = |velocity_at_centre: Vector3<f64>| {
        let shift = velocity_at_centre.norm();
        let direction = velocity_at_centre
            .try_normalize(1e-300)
            .unwrap_or_else(Vector3::x);
        Motion {
            kind: MotionKind::Translation {
                direction: canonical_sign(&direction),
            },
            angle: 0.0,
            shift,
        }
    };
    let at_centre = velocity + omega.cross(&(centre - origin));
    if angle == 0.0 {
        return translation_only(at_centre);
    }
    let axis = omega / angle;
    // Foot of the axis from the origin: o + ω × v / |ω|².
    let foot = origin + omega.cross(&velocity) / (angle * angle);
    let point = foot + axis * axis.dot(&(centre - foot));
    if (point - centre).norm() > 10.0 * radius_m {
        return translation_only(at_centre);
    }
    let along = axis.dot(&velocity);
    let pitch = along / angle;
    // The pitch (handedness) does not depend on the axis's sign, so the axis can be canonical.
    let signed_axis = canonical_sign(&axis);
    let kind = if pitch.abs() < 0.05 * radius_m {
        MotionKind::Rotation {
            axis: signed_axis,
            point,
        }
    } else {
        MotionKind::Screw {
            axis: signed_axis,
            point,
            pitch,
        }
    };
    Motion {
        kind,
        angle,
        shift: along.abs(),
    }
}

impl Motion {
    /// The weak direction with `sd` standard deviations of the scaled direction.
    fn sized(&self, sd: f64) -> WeakDirection {
        let size_95_mrad = Z_95 * sd * self.angle * 1e3;
        let size_95_mm = Z_95 * sd * self.shift * 1e3;
        match self.kind {
            MotionKind::Translation { direction } => WeakDirection::Translation {
                direction,
                size_95_mm,
            },
            MotionKind::Rotation { axis, point } => WeakDirection::Rotation {
                axis,
                point,
                size_95_mrad,
            },
            MotionKind::Screw { axis, point, pitch } => WeakDirection::Screw {
                axis,
                point,
                pitch_m_per_rad: pitch,
                size_95_mrad,
                translation_95_mm: size_95_mm,
            },
        }
    }

    /// The motion named in words, for an underconstrained touch set.
    fn free_motion(&self) -> String {
        match self.kind {
            MotionKind::Translation { direction } => {
                format!(
                    "translation along {} in the base frame",
                    fmt_unit(&direction)
                )
            }
            MotionKind::Rotation { axis, point } => format!(
                "rotation about the axis {} through {} m in the base frame",
                fmt_unit(&axis),
                fmt_point(&point)
            ),
            MotionKind::Screw { axis, point, pitch } => format!(
                "a screw about the axis {} through {} m with pitch {:.4} m/rad in the base frame",
                fmt_unit(&axis),
                fmt_point(&point),
                pitch
            ),
        }
    }
}

/// `v` or `-v`, whichever has its largest-magnitude component positive.
fn canonical_sign(v: &Vector3<f64>) -> Vector3<f64> {
    let largest = v.iter().copied().fold(
        0.0_f64,
        |best, c| {
            if c.abs() > best.abs() { c } else { best }
        },
    );
    if largest < 0.0 { -v } else { *v }
}

/// Rounded first so that -0.0001 prints as 0.000, not -0.000.
fn round3(c: f64) -> f64 {
    (c * 1000.0).round() / 1000.0 + 0.0
}

fn fmt_unit(v: &Vector3<f64>) -> String {
    format!(
        "({:.3}, {:.3}, {:.3})",
        round3(v.x),
        round3(v.y),
        round3(v.z)
    )
}

fn fmt_point(p: &Point3<f64>) -> String {
    format!(
        "({:.3}, {:.3}, {:.3})",
        round3(p.x),
        round3(p.y),
        round3(p.z)
    )
}

/// Two significant digits at least, e.g. 0.84, 0.021, 12.
fn fmt_size(value: f64) -> String {
    if value >= 10.0 || value == 0.0 {
        format!("{value:.1}")
    } else {
        let decimals = (1 - value.log10().floor() as i32).max(2) as usize;
        format!("{value:.decimals$}")
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Matrix6, Vector6};

    use super::{CHI2_95_6DOF, Z_95, pose_distance_quantile_95};
    use crate::rng::SplitMix64;

    /// The 95 % quantile of the pose distance drawn from the covariance (scaled: every entry in
    /// m), by sampling.
    fn sampled_quantile(covariance: &Matrix6<f64>, seed: u64) -> f64 {
        let root = covariance.cholesky().map(|c| c.l()).unwrap_or_default();
        let mut rng = SplitMix64::new(seed);
        let mut distances: Vec<f64> = (0..20_000)
            .map(|_| (root * Vector6::from_fn(|_, _| rng.gaussian())).norm())
            .collect();
        distances.sort_by(f64::total_cmp);
        distances[distances.len() * 95 / 100]
    }

    #[test]
    fn the_pose_distance_quantile_matches_the_chi_square_limits_and_sampling() {
        // Six equal variances: the 6-dof chi-square; one dominant: the normal's two-sided 95 %.
        let equal = Matrix6::identity() * 1e-8;
        let expected = (CHI2_95_6DOF * 1e-8f64).sqrt();
        let got = pose_distance_quantile_95(&equal);
        assert!(
            (got / expected - 1.0).abs() < 0.01,
            "{got} against {expected}"
        );
        let one = Matrix6::from_diagonal(&Vector6::new(1e-6, 1e-12, 1e-12, 1e-12, 1e-12, 1e-12));
        let got = pose_distance_quantile_95(&one);
        assert!((got / (Z_95 * 1e-3) - 1.0).abs() < 0.03, "{got}");
        // Mixed spectra, correlated: within 3 % of 20 000 draws.
        for (seed, diagonal) in [
            (1, Vector6::<f64>::new(4.0, 1.0, 0.5, 0.2, 0.1, 0.05)),
            (2, Vector6::new(1.0, 1.0, 0.01, 0.01, 0.01, 0.01)),
            (3, Vector6::new(9.0, 0.3, 0.3, 0.3, 0.3, 0.3)),
        ] {
            let mut covariance: Matrix6<f64> = Matrix6::from_diagonal(&(diagonal * 1e-8));
            covariance[(0, 3)] = 0.5 * (covariance[(0, 0)] * covariance[(3, 3)]).sqrt();
            covariance[(3, 0)] = covariance[(0, 3)];
            let got = pose_distance_quantile_95(&covariance);
            let sampled = sampled_quantile(&covariance, seed);
            assert!(
                (got / sampled - 1.0).abs() < 0.03,
                "{diagonal:?}: {got} against {sampled} sampled"
            );
        }
        assert_eq!(pose_distance_quantile_95(&Matrix6::zeros()), 0.0);
    }
}
