//! The camera a monocular front-facing query looks from (thesis §3.3.1 "Monocular
//! Correspondences").

use super::is_usable;
use nalgebra::Vector3;

/// How the sensor views the model, in the frame of the model's spheres.
///
/// A footpoint `q` with outward normal `n` is *back-facing* iff `n·v ≥ 0`, where `v` is the
/// viewing direction toward `q` (thesis §3.3.1: "testing the sign of `v·N_M(q)`").
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum View {
    /// Parallel projection along this direction (from the camera into the scene; need not be
    /// unit length). In the OpenCV camera frame a camera looking down its optical axis is
    /// `Orthographic(Vector3::z())`.
    Orthographic(Vector3<f64>),
    /// Pinhole camera at `camera_center`: the viewing direction toward `q` is `q − camera_center`.
    Perspective {
        /// Optical center of the camera.
        camera_center: Vector3<f64>,
    },
}

impl View {
    /// The unit viewing direction toward `x`, or `None` when it is undefined (`x` at the camera
    /// center, a zero or non-finite direction).
    #[inline]
    pub fn direction_to(&self, x: &Vector3<f64>) -> Option<Vector3<f64>> {
        let d = match self {
            View::Orthographic(d) => *d,
            View::Perspective { camera_center } => x - camera_center,
        };
        let len = d.norm();
        (len > 0.0 && len.is_finite() && is_usable(&d)).then(|| d / len)
    }

    /// Whether a surface point `x` with outward normal `n` faces away from the camera (`n·v ≥ 0`).
    #[inline]
    pub fn is_back_facing(&self, x: &Vector3<f64>, n: &Vector3<f64>) -> bool {
        match self {
            View::Orthographic(d) => n.dot(d) >= 0.0,
            View::Perspective { camera_center } => n.dot(&(x - camera_center)) >= 0.0,
        }
    }

    pub(crate) fn is_valid(&self) -> bool {
        match self {
            View::Orthographic(d) => is_usable(d) && d.norm_squared() > 0.0,
            View::Perspective { camera_center } => is_usable(camera_center),
        }
    }
}
