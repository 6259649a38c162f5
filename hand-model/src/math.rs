//! Small fixed-size math: rigid transforms, elementary rotations, XYZ Euler angles and the
//! least-squares similarity between paired point sets (Umeyama 1991).
//!
//! A [`Rigid3`] keeps its rotation as a 3×3 matrix rather than a quaternion because forward
//! kinematics transforms far more points than it composes frames.
//!
//! The similarity fit lives here, below every chapter crate, because both the offline
//! calibration (bringing a template in mm onto a scan of arbitrary scale) and `eval` (comparing a
//! fitted model with a reference fitted by someone else, in another frame and unit) need the
//! same closed form, and `eval` must not depend on `datasets` to get it.

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

/// A similarity transform `x ↦ s·R·x + t` (`b_from_a`), e.g. from a template in mm to a scan
/// in arbitrary units.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Similarity3 {
    /// Scale `s > 0`.
    pub scale: f64,
    /// Rotation `R` (orthonormal, det +1).
    pub rotation: Matrix3<f64>,
    /// Translation `t`, in the units of the target frame.
    pub translation: Vector3<f64>,
}

impl Similarity3 {
    /// Transform a point.
    #[inline]
    pub fn transform_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.scale * (self.rotation * p) + self.translation
    }

    /// The inverse similarity (`a_from_b`).
    pub fn inverse(&self) -> Similarity3 {
        let rt = self.rotation.transpose();
        Similarity3 {
            scale: 1.0 / self.scale,
            rotation: rt,
            translation: -(rt * self.translation) / self.scale,
        }
    }

    /// Root-mean-square distance `sqrt(mean ‖s R a_i + t − b_i‖²)` over paired points, in the
    /// units of `b`. `None` when the slices differ in length or are empty.
    pub fn rms_residual(&self, a: &[Vector3<f64>], b: &[Vector3<f64>]) -> Option<f64> {
        if a.len() != b.len() || a.is_empty() {
            return None;
        }
        let sum: f64 = a
            .iter()
            .zip(b)
            .map(|(p, q)| (self.transform_point(p) - q).norm_squared())
            .sum();
        Some((sum / a.len() as f64).sqrt())
    }
}

/// Why [`fit_similarity`] / [`fit_rigid`] found no transform.
#[derive(Copy, Clone, Debug, PartialEq, thiserror::Error)]
pub enum AlignError {
    /// The two point lists differ in length.
    #[error("paired point lists differ in length: {from} source vs {to} target points")]
    LengthMismatch {
        /// Number of source points.
        from: usize,
        /// Number of target points.
        to: usize,
    },
    /// Fewer than 3 pairs: a rotation in 3-D needs at least three non-collinear points.
    #[error("{got} point pairs; a 3-D similarity needs at least 3 non-collinear pairs")]
    TooFewPoints {
        /// Number of pairs given.
        got: usize,
    },
    /// A coordinate is NaN or infinite.
    #[error("point pair {index} has a non-finite coordinate")]
    NonFinite {
        /// Index of the offending pair.
        index: usize,
    },
    /// The points are coincident or collinear (on either side), so the rotation is not unique.
    #[error("the paired points are coincident or collinear: the rotation is not determined")]
    Degenerate,
}

/// The similarity `b ≈ s·R·a + t` minimising `Σ ‖s R a_i + t − b_i‖²` over paired points, in
/// closed form (Umeyama, "Least-squares estimation of transformation parameters between two
/// point patterns", TPAMI 13(4), 1991, Eq. 40–42).
///
/// With `μ` the means, `σ_a² = mean ‖a_i − μ_a‖²` and the cross-covariance
/// `Σ = mean (b_i − μ_b)(a_i − μ_a)ᵀ = U D Vᵀ`: `R = U S Vᵀ` with `S = diag(1, 1, det(U)·det(V))`
/// (so that a reflection is never returned, even when the best orthogonal matrix would be
/// one), `s = tr(D S) / σ_a²`, `t = μ_b − s R μ_a`.
///
/// Errors: lists of different length, fewer than 3 pairs, non-finite coordinates, or points
/// that do not determine a rotation (rank `Σ` < 2: coincident or collinear points).
pub fn fit_similarity(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> Result<Similarity3, AlignError> {
    umeyama(a, b, true)
}

/// Centroid and principal axes of a point set: the eigenvectors of its covariance as columns,
/// largest spread first (signs arbitrary). `None` for fewer than 3 points.
pub fn principal_axes(points: &[Vector3<f64>]) -> Option<(Vector3<f64>, Matrix3<f64>)> {
    if points.len() < 3 {
        return None;
    }
    let n = points.len() as f64;
    let c = points.iter().sum::<Vector3<f64>>() / n;
    let cov = points
        .iter()
        .map(|p| (p - c) * (p - c).transpose())
        .sum::<Matrix3<f64>>()
        / n;
    let eig = nalgebra::SymmetricEigen::new(cov);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let axes = Matrix3::from_columns(&order.map(|i| eig.eigenvectors.column(i).into_owned()));
    Some((c, axes))
}

/// [`fit_similarity`] with the scale held at 1: the least-squares rigid motion (Kabsch with
/// Umeyama's reflection correction), for point sets already in the same unit.
pub fn fit_rigid(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> Result<Rigid3, AlignError> {
    umeyama(a, b, false).map(|s| Rigid3::new(s.rotation, s.translation))
}

fn umeyama(
    a: &[Vector3<f64>],
    b: &[Vector3<f64>],
    with_scale: bool,
) -> Result<Similarity3, AlignError> {
    if a.len() != b.len() {
        return Err(AlignError::LengthMismatch {
            from: a.len(),
            to: b.len(),
        });
    }
    if a.len() < 3 {
        return Err(AlignError::TooFewPoints { got: a.len() });
    }
    if let Some(index) = a
        .iter()
        .zip(b)
        .position(|(p, q)| !p.iter().chain(q.iter()).all(|x| x.is_finite()))
    {
        return Err(AlignError::NonFinite { index });
    }
    let n = a.len() as f64;
    let mean_a = a.iter().sum::<Vector3<f64>>() / n;
    let mean_b = b.iter().sum::<Vector3<f64>>() / n;
    let mut var_a = 0.0;
    let mut var_b = 0.0;
    let mut cov = Matrix3::zeros();
    for (p, q) in a.iter().zip(b) {
        let (da, db) = (p - mean_a, q - mean_b);
        var_a += da.norm_squared();
        var_b += db.norm_squared();
        cov += db * da.transpose();
    }
    var_a /= n;
    var_b /= n;
    cov /= n;
    let svd = cov.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(AlignError::Degenerate);
    };
    let d = svd.singular_values;
    // Rank Σ ≥ 2 is Umeyama's condition for a unique rotation; the tolerance is relative to the
    // largest possible singular value σ_a·σ_b (Cauchy–Schwarz), so the test is unit-free.
    let mut sorted = [d[0], d[1], d[2]];
    sorted.sort_by(|x, y| y.total_cmp(x));
    let bound = (var_a * var_b).sqrt();
    if bound <= 0.0 || sorted[1] <= 1e-12 * bound {
        return Err(AlignError::Degenerate);
    }
    let mut s_diag = Vector3::new(1.0, 1.0, 1.0);
    if u.determinant() * v_t.determinant() < 0.0 {
        // Flip the direction of the smallest singular value: the closest proper rotation.
        let smallest = (0..3).min_by(|&i, &j| d[i].total_cmp(&d[j])).unwrap_or(2);
        s_diag[smallest] = -1.0;
    }
    let rotation = u * Matrix3::from_diagonal(&s_diag) * v_t;
    let scale = if with_scale {
        d.component_mul(&s_diag).sum() / var_a
    } else {
        1.0
    };
    Ok(Similarity3 {
        scale,
        rotation,
        translation: mean_b - scale * (rotation * mean_a),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn principal_axes_follow_the_spread() {
        // A box of points 40 × 10 × 2 along three orthogonal directions, turned and moved.
        let r = Rotation3::from_euler_angles(0.3, -0.7, 1.1).into_inner();
        let c = Vector3::new(5.0, -2.0, 30.0);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let points: Vec<Vector3<f64>> = (0..500)
            .map(|_| {
                let local = Vector3::new(
                    rng.random_range(-20.0..20.0),
                    rng.random_range(-5.0..5.0),
                    rng.random_range(-1.0..1.0),
                );
                c + r * local
            })
            .collect();
        let (centroid, axes) = principal_axes(&points).unwrap();
        assert!((centroid - c).norm() < 1.0);
        for k in 0..3 {
            let cos = axes.column(k).dot(&r.column(k)).abs();
            assert!(cos > 0.99, "axis {k}: |cos| {cos}");
        }
        assert!(principal_axes(&points[..2]).is_none());
    }

    fn random_points(rng: &mut ChaCha8Rng, n: usize) -> Vec<Vector3<f64>> {
        (0..n)
            .map(|_| {
                Vector3::new(
                    rng.random_range(-50.0..50.0),
                    rng.random_range(-50.0..50.0),
                    rng.random_range(-50.0..50.0),
                )
            })
            .collect()
    }

    #[test]
    fn similarity_recovers_a_known_transform_from_noisy_pairs() {
        let mut rng = ChaCha8Rng::seed_from_u64(42);
        for trial in 0..50 {
            let truth = Similarity3 {
                scale: rng.random_range(0.01..20.0),
                rotation: euler_xyz_to_matrix(
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-1.5..1.5),
                    rng.random_range(-3.0..3.0),
                ),
                translation: Vector3::new(
                    rng.random_range(-100.0..100.0),
                    rng.random_range(-100.0..100.0),
                    rng.random_range(-100.0..100.0),
                ),
            };
            let a = random_points(&mut rng, 40);
            // Noise of 0.1 % of the target's extent.
            let noise = 0.001 * 50.0 * truth.scale;
            let b: Vec<_> = a
                .iter()
                .map(|p| {
                    truth.transform_point(p)
                        + noise
                            * Vector3::new(
                                rng.random_range(-1.0..1.0),
                                rng.random_range(-1.0..1.0),
                                rng.random_range(-1.0..1.0),
                            )
                })
                .collect();
            let fit = fit_similarity(&a, &b).unwrap();
            assert!(
                (fit.scale / truth.scale - 1.0).abs() < 2e-3,
                "trial {trial}"
            );
            assert!(
                (fit.rotation - truth.rotation).norm() < 5e-3,
                "trial {trial}"
            );
            assert!((fit.rotation.determinant() - 1.0).abs() < 1e-12);
            let rms = fit.rms_residual(&a, &b).unwrap();
            assert!(rms <= 1.2 * noise, "trial {trial}: rms {rms} noise {noise}");
            // Exact pairs are reproduced to rounding, and the inverse undoes the fit.
            let exact: Vec<_> = a.iter().map(|p| truth.transform_point(p)).collect();
            let fit = fit_similarity(&a, &exact).unwrap();
            assert!(fit.rms_residual(&a, &exact).unwrap() < 1e-9 * truth.scale.max(1.0));
            let back = fit.inverse().transform_point(&exact[0]);
            assert!((back - a[0]).norm() < 1e-9);
        }
    }

    #[test]
    fn rigid_fit_keeps_unit_scale() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let a = random_points(&mut rng, 10);
        let truth = Rigid3::new(
            euler_xyz_to_matrix(0.3, 0.2, -0.5),
            Vector3::new(1.0, 2.0, 3.0),
        );
        let b: Vec<_> = a.iter().map(|p| truth.transform_point(p)).collect();
        let fit = fit_rigid(&a, &b).unwrap();
        assert!((fit.rotation - truth.rotation).norm() < 1e-12);
        assert!((fit.translation - truth.translation).norm() < 1e-10);
    }

    #[test]
    fn mirrored_targets_still_give_a_proper_rotation() {
        // b is a mirror image of a: the best orthogonal matrix is a reflection, which Umeyama's
        // correction replaces by the closest rotation (det +1).
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let a = random_points(&mut rng, 30);
        let b: Vec<_> = a.iter().map(|p| Vector3::new(-p.x, p.y, p.z)).collect();
        let fit = fit_similarity(&a, &b).unwrap();
        assert!((fit.rotation.determinant() - 1.0).abs() < 1e-12);
        assert!((fit.rotation * fit.rotation.transpose() - Matrix3::identity()).norm() < 1e-12);
        assert!(fit.scale > 0.0);
        // A planar pattern and its mirror image: the reflection is exactly a rotation by π
        // about the mirror line, so the fit is exact with det +1.
        let planar: Vec<_> = a.iter().map(|p| Vector3::new(p.x, p.y, 0.0)).collect();
        let mirrored: Vec<_> = planar
            .iter()
            .map(|p| Vector3::new(-p.x, p.y, 0.0))
            .collect();
        let fit = fit_similarity(&planar, &mirrored).unwrap();
        assert!((fit.rotation.determinant() - 1.0).abs() < 1e-12);
        assert!(fit.rms_residual(&planar, &mirrored).unwrap() < 1e-9);
        assert!((fit.scale - 1.0).abs() < 1e-12);
    }

    #[test]
    fn degenerate_input_is_an_error() {
        let p = |x: f64, y: f64, z: f64| Vector3::new(x, y, z);
        let line = [
            p(0.0, 0.0, 0.0),
            p(1.0, 1.0, 1.0),
            p(2.0, 2.0, 2.0),
            p(5.0, 5.0, 5.0),
        ];
        let tri = [
            p(0.0, 0.0, 0.0),
            p(1.0, 0.0, 0.0),
            p(0.0, 1.0, 0.0),
            p(0.0, 0.0, 1.0),
        ];
        let same = [p(1.0, 2.0, 3.0); 4];
        assert_eq!(fit_similarity(&line, &tri), Err(AlignError::Degenerate));
        assert_eq!(fit_similarity(&tri, &line), Err(AlignError::Degenerate));
        assert_eq!(fit_similarity(&same, &tri), Err(AlignError::Degenerate));
        assert_eq!(
            fit_similarity(&tri[..2], &tri[..2]),
            Err(AlignError::TooFewPoints { got: 2 })
        );
        assert_eq!(
            fit_similarity(&tri, &tri[..3]),
            Err(AlignError::LengthMismatch { from: 4, to: 3 })
        );
        let mut nan = tri;
        nan[2].y = f64::NAN;
        assert_eq!(
            fit_similarity(&tri, &nan),
            Err(AlignError::NonFinite { index: 2 })
        );
        assert!(fit_rigid(&tri, &[p(f64::INFINITY, 0.0, 0.0); 4]).is_err());
    }

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
