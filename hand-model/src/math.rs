//! Small fixed-size math: rigid transforms, elementary rotations and XYZ Euler angles.
//!
//! A [`Rigid3`] keeps its rotation as a 3×3 matrix rather than a quaternion because forward
//! kinematics transforms far more points than it composes frames.

use nalgebra::{Matrix3, Rotation3, Unit, Vector3};

/// A rigid transform `x ↦ R·x + t` (`b_from_a` when it maps frame-a coordinates to frame b).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Rigid3 {
    /// Rotation `R` (orthonormal, det +1).
    pub rotation: Matrix3<f64>,
    /// Translation `t` (mm).
    pub translation: Vector3<f64>,
}

impl Default for Rigid3 {
    fn default() -> Self {
        Self::identity()
    }
}

impl Rigid3 {
    /// The identity transform.
    pub fn identity() -> Self {
        Self {
            rotation: Matrix3::identity(),
            translation: Vector3::zeros(),
        }
    }

    /// A transform from its rotation and translation.
    pub fn new(rotation: Matrix3<f64>, translation: Vector3<f64>) -> Self {
        Self {
            rotation,
            translation,
        }
    }

    /// A pure translation.
    pub fn from_translation(translation: Vector3<f64>) -> Self {
        Self::new(Matrix3::identity(), translation)
    }

    /// A pure rotation.
    pub fn from_rotation(rotation: Matrix3<f64>) -> Self {
        Self::new(rotation, Vector3::zeros())
    }

    /// `self ∘ other` (apply `other` first).
    #[inline]
    pub fn compose(&self, other: &Rigid3) -> Rigid3 {
        Rigid3 {
            rotation: self.rotation * other.rotation,
            translation: self.rotation * other.translation + self.translation,
        }
    }

    /// Post-multiply by a rotation (`self ∘ R`), the way joint rotations are applied.
    #[inline]
    pub fn rotated(&self, rotation: &Matrix3<f64>) -> Rigid3 {
        Rigid3 {
            rotation: self.rotation * rotation,
            translation: self.translation,
        }
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Rigid3 {
        let rt = self.rotation.transpose();
        Rigid3 {
            rotation: rt,
            translation: -(rt * self.translation),
        }
    }

    /// Transform a point.
    #[inline]
    pub fn transform_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * p + self.translation
    }

    /// Transform a direction (rotation only).
    #[inline]
    pub fn transform_vector(&self, v: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * v
    }

    /// Whether every entry is finite.
    pub fn is_finite(&self) -> bool {
        self.rotation.iter().all(|x| x.is_finite())
            && self.translation.iter().all(|x| x.is_finite())
    }

    /// Re-orthonormalize the rotation (polar projection), for rotations read from text files.
    pub fn orthonormalized(&self) -> Rigid3 {
        Rigid3::new(
            Rotation3::from_matrix(&self.rotation).into_inner(),
            self.translation,
        )
    }
}

/// Rotation by `angle` about the unit `axis`.
#[inline]
pub fn axis_angle(axis: &Vector3<f64>, angle: f64) -> Matrix3<f64> {
    Rotation3::from_axis_angle(&Unit::new_unchecked(*axis), angle).into_inner()
}

/// The rotation `exp([ω]×)` of a rotation vector ω (angle = ‖ω‖).
#[inline]
pub fn exp_so3(omega: &Vector3<f64>) -> Matrix3<f64> {
    Rotation3::new(*omega).into_inner()
}

/// `Rx(a)·Ry(b)·Rz(c)`: the XYZ Euler convention of the original global pose (ANCHOR-FACTS §1.2).
pub fn euler_xyz_to_matrix(a: f64, b: f64, c: f64) -> Matrix3<f64> {
    axis_angle(&Vector3::x(), a) * axis_angle(&Vector3::y(), b) * axis_angle(&Vector3::z(), c)
}

/// Inverse of [`euler_xyz_to_matrix`]; at gimbal lock (|b| = π/2) the third angle is set to 0 so
/// that the extraction stays defined (the solvers never differentiate through it, see
/// [`crate::kinematics::Pose::retract`]).
pub fn matrix_to_euler_xyz(r: &Matrix3<f64>) -> [f64; 3] {
    let sb = r[(0, 2)].clamp(-1.0, 1.0);
    let b = sb.asin();
    if sb.abs() < 1.0 - 1e-12 {
        let a = (-r[(1, 2)]).atan2(r[(2, 2)]);
        let c = (-r[(0, 1)]).atan2(r[(0, 0)]);
        [a, b, c]
    } else {
        // Rz is absorbed into Rx: with c = 0, R = Rx(a)·Ry(±π/2), whose second column is
        // (0, cos a, sin a).
        let a = r[(2, 1)].atan2(r[(1, 1)]);
        [a, b, 0.0]
    }
}

/// Skew-symmetric matrix `[v]×` with `[v]×·w = v × w`.
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn euler_round_trip_including_gimbal_lock() {
        let cases = [
            [0.3, -0.2, 1.1],
            [-2.9, 1.2, -0.4],
            [0.7, std::f64::consts::FRAC_PI_2, 0.0],
            [0.7, -std::f64::consts::FRAC_PI_2, 0.0],
        ];
        for [a, b, c] in cases {
            let r = euler_xyz_to_matrix(a, b, c);
            let [a2, b2, c2] = matrix_to_euler_xyz(&r);
            let r2 = euler_xyz_to_matrix(a2, b2, c2);
            assert!((r - r2).norm() < 1e-9, "{a} {b} {c}");
        }
    }

    #[test]
    fn rigid_inverse_composes_to_identity() {
        let t = Rigid3::new(
            euler_xyz_to_matrix(0.4, -1.0, 2.0),
            Vector3::new(1.0, -2.0, 3.0),
        );
        let id = t.compose(&t.inverse());
        assert!((id.rotation - Matrix3::identity()).norm() < 1e-12);
        assert!(id.translation.norm() < 1e-12);
    }
}
