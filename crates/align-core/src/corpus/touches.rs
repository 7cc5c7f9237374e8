//! A touch sampler that knows nothing of touch planning: points drawn uniformly by area over the
//! whole mesh, the probe tilted as a person hand-guiding a robot tilts it (0 to 60 degrees from
//! the surface normal, and a share of side contacts at exactly 90 degrees, the ball's equator on
//! the surface), draws where the ball or the stylus would collide with the part (or the table)
//! redrawn, and hand-guided noise: 0.3-0.5 mm rms per session.

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

use super::CorpusError;
use crate::geometry::{Mesh, tangents};
use crate::rng::SplitMix64;

/// How touches are drawn.
#[derive(Debug, Clone, PartialEq)]
pub struct TouchOptions {
    /// Radius of the probe's ball, m.
    pub ball_radius_m: f64,
    /// Tilts of ordinary touches are uniform in angle on [0, max_tilt_rad] from the reversed
    /// surface normal, with uniform azimuth.
    pub max_tilt_rad: f64,
    /// Share of touches made at exactly 90 degrees (stylus parallel to the surface).
    pub side_contact_fraction: f64,
    /// A session's noise sigma is drawn uniformly in this range, m; each touch then gets
    /// isotropic Gaussian noise N(0, sigma^2) on every axis of its ball centre, so that the
    /// noise along the surface normal (the distance-to-surface error) has rms sigma.
    pub sigma_range_m: (f64, f64),
    /// Stylus shaft checked for collisions behind the ball, m.
    pub stylus_length_m: f64,
    /// Stylus shaft radius as a fraction of the ball radius.
    pub stylus_radius_ratio: f64,
    /// Height of the table the part stands on (base frame z, m): the ball and the stylus must
    /// stay above it. `None`: no table.
    pub floor_z_in_base: Option<f64>,
    /// Draws allowed per touch before the part is declared untouchable.
    pub max_draws_per_touch: usize,
}

impl Default for TouchOptions {
    fn default() -> Self {
        Self {
            ball_radius_m: 0.003,
            max_tilt_rad: 60f64.to_radians(),
            side_contact_fraction: 0.15,
            sigma_range_m: (0.3e-3, 0.5e-3),
            stylus_length_m: 0.06,
            stylus_radius_ratio: 0.4,
            floor_z_in_base: None,
            max_draws_per_touch: 5000,
        }
    }
}

/// One drawn touch, in the robot base frame.
#[derive(Debug, Clone, PartialEq)]
pub struct SampledTouch {
    pub id: String,
    /// Where the robot reports the ball centre: the true centre plus the noise.
    pub ball_centre_in_base: Point3<f64>,
    /// Unit direction the probe travelled into the surface (the tool's z axis).
    pub approach_in_base: Vector3<f64>,
    /// The true contact point on the part's surface.
    pub surface_point_in_base: Point3<f64>,
    /// The touched face's outward unit normal.
    pub normal_in_base: Vector3<f64>,
    /// Angle between the approach and the reversed normal, rad (pi/2 for a side contact).
    pub tilt_rad: f64,
    /// The noise added to the true centre, m.
    pub noise_in_base: Vector3<f64>,
    /// Index of the touched triangle in the part mesh.
    pub triangle: u32,
}

impl SampledTouch {
    /// The ball centre without noise.
    pub fn true_centre_in_base(&self) -> Point3<f64> {
        self.ball_centre_in_base - self.noise_in_base
    }
}

/// A session's touches and the noise they were drawn with.
#[derive(Debug, Clone, PartialEq)]
pub struct TouchSet {
    pub touches: Vec<SampledTouch>,
    pub sigma_m: f64,
    /// Draws redrawn because the probe would have collided with the part or the table.
    pub rejected_draws: usize,
}

/// Picks triangles with probability proportional to their area.
#[derive(Debug, Clone)]
struct AreaSampler {
    cumulative: Vec<f64>,
}

impl AreaSampler {
    fn new(mesh: &Mesh) -> Self {
        let mut sum = 0.0;
        let cumulative = (0..mesh.num_triangles() as u32)
            .map(|t| {
                sum += mesh.triangle_area(t);
                sum
            })
            .collect();
        Self { cumulative }
    }

    fn pick(&self, rng: &mut SplitMix64) -> u32 {
        let total = self.cumulative.last().copied().unwrap_or(0.0);
        let target = rng.uniform() * total;
        let index = self.cumulative.partition_point(|&c| c <= target);
        index.min(self.cumulative.len() - 1) as u32
    }
}

/// Draws `count` touches on `mesh` standing at `base_from_part`.
pub fn sample_touches(
    mesh: &Mesh,
    base_from_part: &Isometry3<f64>,
    count: usize,
    options: &TouchOptions,
    rng: &mut SplitMix64,
) -> Result<TouchSet, CorpusError> {
    check(options)?;
    let (low, high) = options.sigma_range_m;
    let sigma_m = low + (high - low) * rng.uniform();
    let vertices: Vec<Point3<f64>> = mesh.vertices().collect();
    let triangles = mesh.triangles();
    let sampler = AreaSampler::new(mesh);
    let r = options.ball_radius_m;
    let mut touches = Vec::with_capacity(count);
    let mut rejected_draws = 0;
    let mut draws = 0;
    while touches.len() < count {
        if draws >= options.max_draws_per_touch * count.max(1) {
            return Err(CorpusError::NoTouchableSurface {
                found: touches.len(),
                draws,
            });
        }
        draws += 1;
        let triangle = sampler.pick(rng);
        let [ia, ib, ic] = triangles[triangle as usize];
        let (a, b, c) = (
            vertices[ia as usize],
            vertices[ib as usize],
            vertices[ic as usize],
        );
        let (mut u, mut v) = (rng.uniform(), rng.uniform());
        if u + v > 1.0 {
            (u, v) = (1.0 - u, 1.0 - v);
        }
        let point = a + u * (b - a) + v * (c - a);
        let normal = mesh.triangle_normal(triangle);
        let side_contact = rng.uniform() < options.side_contact_fraction;
        let tilt_rad = if side_contact {
            std::f64::consts::FRAC_PI_2
        } else {
            options.max_tilt_rad * rng.uniform()
        };
        let azimuth = std::f64::consts::TAU * rng.uniform();
        let (e1, e2) = tangents(&normal);
        let approach = (-tilt_rad.cos() * normal
            + tilt_rad.sin() * (azimuth.cos() * e1 + azimuth.sin() * e2))
            .normalize();
        // The ball touches at `point` for any tilt up to 90 degrees: the contact lies on the
        // ball's front hemisphere, and its centre sits one radius off the face.
        let centre = point + r * normal;
        if !probe_is_free(mesh, base_from_part, &centre, &approach, options) {
            rejected_draws += 1;
            continue;
        }
        let noise = sigma_m * Vector3::new(rng.gaussian(), rng.gaussian(), rng.gaussian());
        touches.push(SampledTouch {
            id: format!("t{:03}", touches.len()),
            ball_centre_in_base: base_from_part * centre + noise,
            approach_in_base: base_from_part * approach,
            surface_point_in_base: base_from_part * point,
            normal_in_base: base_from_part * normal,
            tilt_rad,
            noise_in_base: noise,
            triangle,
        });
    }
    Ok(TouchSet {
        touches,
        sigma_m,
        rejected_draws,
    })
}

fn check(options: &TouchOptions) -> Result<(), CorpusError> {
    let (low, high) = options.sigma_range_m;
    let valid = options.ball_radius_m > 0.0
        && (0.0..=std::f64::consts::FRAC_PI_2).contains(&options.max_tilt_rad)
        && (0.0..=1.0).contains(&options.side_contact_fraction)
        && low >= 0.0
        && high >= low
        && options.stylus_length_m >= 0.0
        && options.stylus_radius_ratio >= 0.0
        && options.max_draws_per_touch > 0;
    if valid {
        Ok(())
    } else {
        Err(CorpusError::BadOption(format!("{options:?}")))
    }
}

/// True when the ball at `centre` (part frame) and a straight stylus behind it along
/// `-approach` clear the part and the table.
fn probe_is_free(
    mesh: &Mesh,
    base_from_part: &Isometry3<f64>,
    centre: &Point3<f64>,
    approach: &Vector3<f64>,
    options: &TouchOptions,
) -> bool {
    let r = options.ball_radius_m;
    let ball = mesh.closest_point(centre);
    // A closed mesh's signed distance also rejects a centre inside the part; an open one's is
    // unsigned, and the ray test below catches a stylus through the skin.
    let ball_clear = if mesh.is_watertight() {
        ball.signed_distance >= r * (1.0 - 1e-6)
    } else {
        ball.signed_distance.abs() >= r * (1.0 - 1e-6)
    };
    if !ball_clear {
        return false;
    }
    let back = -approach;
    let length = options.stylus_length_m;
    // The stylus axis must not cross the surface: this also keeps it outside a closed part.
    if length > 0.0 && mesh.ray_hit_m(centre, &back, length).is_some() {
        return false;
    }
    // Clearance of the shaft: samples closer together than the shaft's diameter, so that an
    // edge or a thin sheet cannot slip between two of them unnoticed.
    let shaft_radius = options.stylus_radius_ratio * r;
    if shaft_radius > 0.0 && length > 0.0 {
        let step = (2e-3f64).min(shaft_radius);
        let steps = (length / step).ceil() as usize;
        for k in 1..=steps {
            let q = centre + back * (length * k as f64 / steps as f64);
            if mesh.closest_point_within(&q, shaft_radius).is_some() {
                return false;
            }
        }
    }
    if let Some(floor_z) = options.floor_z_in_base {
        let ball_bottom = (base_from_part * centre).z - r;
        let stylus_end = (base_from_part * (centre + back * length)).z - shaft_radius;
        if ball_bottom < floor_z || stylus_end < floor_z {
            return false;
        }
    }
    true
}

/// A rotation drawn uniformly over SO(3) (a normalised 4-D Gaussian is uniform on the
/// quaternion sphere).
pub fn random_rotation(rng: &mut SplitMix64) -> UnitQuaternion<f64> {
    loop {
        let q = nalgebra::Quaternion::new(
            rng.gaussian(),
            rng.gaussian(),
            rng.gaussian(),
            rng.gaussian(),
        );
        if q.norm() > 1e-9 {
            return UnitQuaternion::from_quaternion(q);
        }
    }
}

/// A start for a blind alignment: a uniformly random orientation, translated so that the mesh's
/// centroid lands on the touches' centroid (all an operator who knows nothing else can give).
pub fn blind_start(touches: &[SampledTouch], mesh: &Mesh, rng: &mut SplitMix64) -> Isometry3<f64> {
    let rotation = random_rotation(rng);
    let centroid = if touches.is_empty() {
        Vector3::zeros()
    } else {
        touches.iter().fold(Vector3::zeros(), |sum, t| {
            sum + t.ball_centre_in_base.coords
        }) / touches.len() as f64
    };
    let translation = centroid - rotation * mesh.centroid().coords;
    Isometry3::from_parts(Translation3::from(translation), rotation)
}

/// A rotation about z by `yaw_rad` as an isometry, with the part lifted so that its lowest
/// vertex rests on `table_z_m`, its centroid's horizontal position at `xy_m`: a part standing
/// on a table, as it is probed.
pub fn on_table(mesh: &Mesh, yaw_rad: f64, xy_m: [f64; 2], table_z_m: f64) -> Isometry3<f64> {
    let rotation = UnitQuaternion::from_axis_angle(&Unit::new_unchecked(Vector3::z()), yaw_rad);
    let lowest = mesh.vertices().map(|p| p.z).fold(f64::INFINITY, f64::min);
    let centroid = rotation * mesh.centroid().coords;
    let translation = Vector3::new(
        xy_m[0] - centroid.x,
        xy_m[1] - centroid.y,
        table_z_m - lowest,
    );
    Isometry3::from_parts(Translation3::from(translation), rotation)
}
