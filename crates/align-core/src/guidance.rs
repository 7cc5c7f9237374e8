//! Where to touch next: given the touches taken so far on a part at its nominal pose, the
//! candidate touch that adds the most information about the part's pose (D-optimal design), and
//! whether the session still lacks the tilted touches that tell a ball-radius error from a TCP
//! length error.
//!
//! Each touch constrains the part pose along its surface normal: its signed distance changes by
//! `a . twist` for a small twist about the part's centre, with `a = [(p - c) x n / L, n]` (`L`
//! the part's radius, so that rotations and translations weigh alike). The touches' information
//! is `M = sum a a^T`; a candidate `a` raises `log det M` by `log(1 + a^T M^-1 a)`, so the best
//! next touch maximises `a^T M^-1 a`. Before six touches `M` is singular: a small ridge makes
//! the directions no touch has constrained yet dominate, which is what a 3-2-1 plan does too.

use nalgebra::{Isometry3, Matrix6, Point3, SymmetricEigen, Vector3, Vector6};

use crate::geometry::Mesh;
use crate::rng::SplitMix64;

/// A place on the part a probe could touch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// On the surface, part frame.
    pub point_in_part: Point3<f64>,
    /// Outward normal, part frame.
    pub normal_in_part: Vector3<f64>,
}

/// A touch already taken: its ball centre and, when known, the probe's direction of travel
/// (both in the base frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TakenTouch {
    pub ball_centre: Point3<f64>,
    pub approach: Option<Vector3<f64>>,
}

/// The suggested next touch, in the base frame.
#[derive(Debug, Clone, PartialEq)]
pub struct NextTouch {
    pub point: Point3<f64>,
    /// Outward normal of the surface there.
    pub normal: Vector3<f64>,
    /// The direction to travel in: into the surface, tilted when `tilt_rad` > 0.
    pub approach: Vector3<f64>,
    pub tilt_rad: f64,
    /// Why this touch, for people.
    pub reason: String,
}

/// Candidate surface points drawn: enough to cover every face of a machined part several times.
const CANDIDATES: usize = 600;
/// Probes do not come from below: a normal must point at most this far down (its z, base frame).
const LOWEST_NORMAL_Z: f64 = -0.2;
/// Length of the approach line behind the ball that must be clear of the part, m.
const CLEAR_APPROACH_M: f64 = 0.03;
/// Ridge added to the information, relative to one touch's: makes a singular `M` invertible.
const RIDGE: f64 = 1e-6;
/// Below this tilt from the normal a touch counts as head-on, rad (10 degrees).
const HEAD_ON_RAD: f64 = 0.17;
/// The tilt suggested to separate ball radius from TCP length, rad (30 degrees).
const SUGGESTED_TILT_RAD: f64 = 0.52;
/// Touches a diagnosis needs at least; below it a tilted touch is not worth asking for yet.
const DIAGNOSIS_TOUCHES: usize = 7;

/// Touchable places on `mesh` (part frame, metres) at `base_from_part` for a ball of
/// `radius_m`: drawn by area (fixed seed, so the same part always gets the same candidates),
/// kept where the normal does not point down and the ball and its approach line clear the part.
pub fn candidates(mesh: &Mesh, base_from_part: &Isometry3<f64>, radius_m: f64) -> Vec<Candidate> {
    let vertices: Vec<Point3<f64>> = mesh.vertices().collect();
    let areas: Vec<f64> = (0..mesh.num_triangles() as u32)
        .map(|t| mesh.triangle_area(t))
        .collect();
    let total: f64 = areas.iter().sum();
    if total.is_nan() || total <= 0.0 {
        return Vec::new();
    }
    let mut rng = SplitMix64::new(0x6e65_7874_746f_7563);
    let mut cumulative = Vec::with_capacity(areas.len());
    let mut sum = 0.0;
    for area in &areas {
        sum += area;
        cumulative.push(sum);
    }
    let mut found = Vec::new();
    for _ in 0..CANDIDATES {
        let target = rng.uniform() * total;
        let triangle = cumulative
            .partition_point(|c| *c < target)
            .min(areas.len() - 1);
        let normal = mesh.triangle_normal(triangle as u32);
        if (base_from_part.rotation * normal).z < LOWEST_NORMAL_Z
            || !normal.iter().all(|v| v.is_finite())
        {
            continue;
        }
        let [a, b, c] = mesh.triangles()[triangle].map(|i| vertices[i as usize]);
        let (mut s, mut t) = (rng.uniform(), rng.uniform());
        if s + t > 1.0 {
            (s, t) = (1.0 - s, 1.0 - t);
        }
        let point = a + (b - a) * s + (c - a) * t;
        let clear = (0..=3).all(|k| {
            let along = point + normal * (radius_m + CLEAR_APPROACH_M * f64::from(k) / 3.0);
            mesh.closest_point(&along).signed_distance >= radius_m * 0.99
        });
        if clear {
            found.push(Candidate {
                point_in_part: point,
                normal_in_part: normal,
            });
        }
    }
    found
}

/// The row of the pose information a touch at `point` with outward `normal` adds (part frame).
fn row(
    point: &Point3<f64>,
    normal: &Vector3<f64>,
    centre: &Point3<f64>,
    length: f64,
) -> Vector6<f64> {
    let moment = (point - centre).cross(normal) / length;
    Vector6::new(moment.x, moment.y, moment.z, normal.x, normal.y, normal.z)
}

/// Words for the pose direction `v` (rotation part first, scaled like the rows).
fn describe_direction(v: &Vector6<f64>, base_from_part: &Isometry3<f64>) -> String {
    let rotation = base_from_part.rotation * Vector3::new(v[0], v[1], v[2]);
    let translation = base_from_part.rotation * Vector3::new(v[3], v[4], v[5]);
    let axis = |d: &Vector3<f64>| {
        let names = ["x", "y", "z"];
        let (index, value) = d
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .map(|(i, v)| (i, *v))
            .unwrap_or((0, 0.0));
        let sign = if value < 0.0 { "-" } else { "" };
        if value.abs() > 0.9 * d.norm() {
            format!("{sign}{} of the base frame", names[index])
        } else {
            format!("({:.2}, {:.2}, {:.2}) in the base frame", d.x, d.y, d.z)
        }
    };
    if rotation.norm() >= translation.norm() {
        format!("the rotation about {}", axis(&rotation.normalize()))
    } else {
        format!("the position along {}", axis(&translation.normalize()))
    }
}

/// The next touch among `candidates` for `taken` touches on `mesh` at `base_from_part`; `None`
/// when there is no candidate.
pub fn next_touch(
    mesh: &Mesh,
    base_from_part: &Isometry3<f64>,
    candidates: &[Candidate],
    taken: &[TakenTouch],
) -> Option<NextTouch> {
    let centre = mesh.centroid();
    let length = mesh.radius_m().max(1e-6);
    let part_from_base = base_from_part.inverse();
    let mut information = Matrix6::zeros();
    let mut head_on = 0;
    for touch in taken {
        let surface = mesh.closest_point(&(part_from_base * touch.ball_centre));
        let a = row(&surface.point, &surface.normal, &centre, length);
        information += a * a.transpose();
        let normal_base = base_from_part.rotation * surface.normal;
        if let Some(approach) = touch.approach
            && approach.angle(&-normal_base) < HEAD_ON_RAD
        {
            head_on += 1;
        }
    }
    let ridged = information + Matrix6::identity() * RIDGE;
    let inverse = ridged.try_inverse()?;
    let (best, gain) = candidates
        .iter()
        .map(|c| {
            let a = row(&c.point_in_part, &c.normal_in_part, &centre, length);
            (c, (a.transpose() * inverse * a)[(0, 0)])
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    let normal = base_from_part.rotation * best.normal_in_part;
    let point = base_from_part * best.point_in_part;
    let eigen = SymmetricEigen::new(information);
    let weakest = eigen
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, _)| eigen.eigenvectors.column(i).into_owned())
        .unwrap_or_else(Vector6::zeros);
    let free = eigen.eigenvalues.iter().filter(|v| **v < 1e-9).count();
    let mut reason = if free > 0 {
        format!(
            "{} of the part's 6 pose directions are not fixed yet ({} least); this touch fixes the most",
            free,
            describe_direction(&weakest, base_from_part)
        )
    } else {
        format!(
            "the touches fix every direction; this one narrows the least certain, {}, the most (information gain {:.2})",
            describe_direction(&weakest, base_from_part),
            (1.0 + gain).ln()
        )
    };
    // Every touch head-on: a ball-radius error and a TCP-length error move them alike. One
    // tilted touch tells them apart.
    let tilt = if taken.len() + 1 >= DIAGNOSIS_TOUCHES && head_on == taken.len() {
        reason += "; tilt the probe about 30 degrees from the normal: every touch so far came in \
                   head-on, and a tilted one tells a ball-radius error from a TCP-length error";
        SUGGESTED_TILT_RAD
    } else {
        0.0
    };
    let side = normal
        .cross(&Vector3::z())
        .try_normalize(1e-6)
        .unwrap_or_else(Vector3::x);
    let approach = nalgebra::UnitQuaternion::from_scaled_axis(side * tilt) * -normal;
    Some(NextTouch {
        point,
        normal,
        approach,
        tilt_rad: tilt,
        reason,
    })
}

/// The touch that best tells apart poses an ambiguous alignment found equally good: among
/// `candidates` (part frame), the place whose position under the chosen pose `base_from_part`
/// lies farthest from the part's surface under every `alternative` (the smallest of those
/// distances is maximised). `None` without alternatives or candidates, or when no place is a
/// tenth of a millimetre apart (the alternatives are the same pose, or the part is symmetric
/// there).
pub fn separating_touch(
    mesh: &Mesh,
    base_from_part: &Isometry3<f64>,
    alternatives: &[Isometry3<f64>],
    candidates: &[Candidate],
) -> Option<NextTouch> {
    if alternatives.is_empty() {
        return None;
    }
    let (best, separation) = candidates
        .iter()
        .map(|c| {
            let point = base_from_part * c.point_in_part;
            let nearest = alternatives
                .iter()
                .map(|alternative| {
                    mesh.closest_point(&(alternative.inverse() * point))
                        .signed_distance
                        .abs()
                })
                .fold(f64::INFINITY, f64::min);
            (c, nearest)
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    if separation < 1e-4 {
        return None;
    }
    let normal = base_from_part.rotation * best.normal_in_part;
    Some(NextTouch {
        point: base_from_part * best.point_in_part,
        normal,
        approach: -normal,
        tilt_rad: 0.0,
        reason: format!(
            "the alignment found {} other pose(s) as good as the one shown; here the part of the \
             closest of them is {:.1} mm away, so this touch tells them apart",
            alternatives.len(),
            separation * 1e3
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cuboid() -> Mesh {
        Mesh::cuboid([0.2, 0.1, 0.05]).expect("a cuboid")
    }

    fn taken_at(
        mesh: &Mesh,
        pose: &Isometry3<f64>,
        points: &[(Point3<f64>, Vector3<f64>)],
    ) -> Vec<TakenTouch> {
        let _ = mesh;
        points
            .iter()
            .map(|(p, n)| TakenTouch {
                ball_centre: pose * (p + n * 0.003),
                approach: Some(pose.rotation * -n),
            })
            .collect()
    }

    #[test]
    fn an_ambiguous_pose_is_told_apart_where_the_alternatives_differ_most() {
        // A block turned half a turn about z is the same block: touches on its faces cannot
        // tell the two apart, except where the step is.
        let mesh = cuboid();
        let pose = Isometry3::translation(0.6, 0.0, 0.1);
        let found = candidates(&mesh, &pose, 0.003);
        let turned = pose * Isometry3::rotation(Vector3::z() * std::f64::consts::PI);
        assert!(separating_touch(&mesh, &pose, &[turned], &found).is_none());
        let shifted = pose * Isometry3::translation(0.004, 0.0, 0.0);
        let next = separating_touch(&mesh, &pose, &[shifted], &found).expect("a touch");
        // A 4 mm shift along x shows on the faces square to x.
        assert!(next.normal.x.abs() > 0.99, "{next:?}");
        assert!(next.reason.contains("4.0 mm away"), "{}", next.reason);
    }

    #[test]
    fn after_three_touches_on_top_the_next_one_is_on_a_side() {
        let mesh = cuboid();
        let pose = Isometry3::translation(0.6, 0.0, 0.1);
        let found = candidates(&mesh, &pose, 0.003);
        assert!(found.len() > 100, "{}", found.len());
        // Nothing touched from below.
        assert!(found.iter().all(|c| c.normal_in_part.z > -0.5));
        let up = Vector3::z();
        let top = [
            (Point3::new(-0.08, -0.03, 0.025), up),
            (Point3::new(0.08, -0.03, 0.025), up),
            (Point3::new(0.0, 0.04, 0.025), up),
        ];
        let next =
            next_touch(&mesh, &pose, &found, &taken_at(&mesh, &pose, &top)).expect("a touch");
        assert!(next.normal.z.abs() < 0.1, "{next:?}");
        assert!(
            next.reason
                .starts_with("3 of the part's 6 pose directions are not fixed"),
            "{}",
            next.reason
        );
    }

    #[test]
    fn with_the_pose_fixed_by_head_on_touches_a_tilted_one_is_asked_for() {
        let mesh = cuboid();
        let pose = Isometry3::translation(0.6, 0.0, 0.1);
        let found = candidates(&mesh, &pose, 0.003);
        let touches = [
            (Point3::new(-0.08, -0.03, 0.025), Vector3::z()),
            (Point3::new(0.08, -0.03, 0.025), Vector3::z()),
            (Point3::new(0.0, 0.04, 0.025), Vector3::z()),
            (Point3::new(-0.05, -0.05, 0.0), -Vector3::y()),
            (Point3::new(0.05, -0.05, 0.0), -Vector3::y()),
            (Point3::new(0.1, 0.0, 0.0), Vector3::x()),
        ];
        let next =
            next_touch(&mesh, &pose, &found, &taken_at(&mesh, &pose, &touches)).expect("a touch");
        assert!(
            next.reason.starts_with("the touches fix every direction"),
            "{}",
            next.reason
        );
        assert!((next.tilt_rad - SUGGESTED_TILT_RAD).abs() < 1e-12);
        assert!((next.approach.angle(&-next.normal) - SUGGESTED_TILT_RAD).abs() < 1e-9);
        // A tilted touch already taken: no more asked for.
        let mut taken = taken_at(&mesh, &pose, &touches);
        taken[0].approach = Some((Vector3::new(0.5, 0.0, -1.0)).normalize());
        let next = next_touch(&mesh, &pose, &found, &taken).expect("a touch");
        assert_eq!(next.tilt_rad, 0.0);
    }
}
