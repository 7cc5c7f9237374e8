//! The thesis's pose distance (eq. 22) and stopping criterion (section 2.1.4).

use std::collections::VecDeque;

use nalgebra::Isometry3;

/// d(T, T*) = sqrt(|t - t*|^2 + (r * dalpha)^2): translation and rotation combined, the rotation
/// weighted by the object radius `radius_m` so that it is the displacement of the part's rim.
pub fn pose_distance(a: &Isometry3<f64>, b: &Isometry3<f64>, radius_m: f64) -> f64 {
    let translation = (a.translation.vector - b.translation.vector).norm();
    let rotation = a.rotation.angle_to(&b.rotation) * radius_m;
    translation.hypot(rotation)
}

/// Stops when the current pose lies within `tolerance_m` (pose distance) of each of the last
/// `window` poses: the part has stopped moving.
#[derive(Debug, Clone)]
pub struct StopCriterion {
    window: usize,
    tolerance_m: f64,
    radius_m: f64,
    history: VecDeque<Isometry3<f64>>,
}

impl StopCriterion {
    pub fn new(window: usize, tolerance_m: f64, radius_m: f64) -> Self {
        Self {
            window: window.max(1),
            tolerance_m,
            radius_m,
            history: VecDeque::with_capacity(window.max(1) + 1),
        }
    }

    /// Records `pose` and says whether the iteration has converged.
    pub fn update(&mut self, pose: &Isometry3<f64>) -> bool {
        let converged = self.history.len() == self.window
            && self
                .history
                .iter()
                .all(|previous| pose_distance(pose, previous, self.radius_m) <= self.tolerance_m);
        if self.history.len() == self.window {
            self.history.pop_front();
        }
        self.history.push_back(*pose);
        converged
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    #[test]
    fn pose_distance_combines_translation_and_rim_displacement() {
        let a = Isometry3::identity();
        let b = Isometry3::from_parts(
            Translation3::new(0.003, 0.0, 0.004),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.01),
        );
        // 5 mm translation, 0.01 rad at r = 1.2 m -> 12 mm: hypot = 13 mm.
        assert!((pose_distance(&a, &b, 1.2) - 0.013).abs() < 1e-12);
    }

    #[test]
    fn stops_only_after_a_full_window_of_still_poses() {
        let mut stop = StopCriterion::new(3, 1e-6, 0.1);
        let still = Isometry3::identity();
        assert!(!stop.update(&Isometry3::translation(0.01, 0.0, 0.0)));
        assert!(!stop.update(&still));
        assert!(!stop.update(&still));
        // The window still holds the moved pose.
        assert!(!stop.update(&still));
        assert!(stop.update(&still));
    }
}
