//! Helpers for checking Jacobians against central finite differences (STYLE practice 10), and
//! test data shared by the trackers' tests.

/// Relative error `‖a − b‖ / max(‖a‖, ‖b‖, floor)` used by the Jacobian checks; `floor` keeps
/// near-zero columns from amplifying rounding noise.
pub fn relative_error(a: &nalgebra::Vector3<f64>, b: &nalgebra::Vector3<f64>, floor: f64) -> f64 {
    (a - b).norm() / a.norm().max(b.norm()).max(floor)
}

/// Central finite difference `(f(+h) − f(−h)) / 2h` of a vector-valued function of one scalar.
pub fn central_difference(
    h: f64,
    mut f: impl FnMut(f64) -> nalgebra::Vector3<f64>,
) -> nalgebra::Vector3<f64> {
    (f(h) - f(-h)) / (2.0 * h)
}

/// The cylinder-model test pose shared by the tests of `hand-model` and `htrack-icp`: the hand
/// 40 cm in front of the camera, palm toward it, turned a little, a few fingers bent.
pub fn cylinder_test_pose(model: &crate::cylinder::CylinderModel) -> crate::kinematics::Pose {
    crate::kinematics::Pose::from_named(
        &model.skeleton,
        [
            ("global_tx", 0.0),
            ("global_ty", -80.0),
            ("global_tz", 400.0),
            ("global_rx", 0.2),
            ("global_ry", -0.15),
            ("global_rz", 0.1),
            ("thumb_cmc_flex", 0.2),
            ("index_mcp_flex", 0.3),
            ("middle_pip_flex", 0.4),
            ("ring_mcp_flex", 0.5),
            ("pinky_mcp_flex", 0.3),
            ("pinky_pip_flex", 0.3),
        ],
    )
    .expect("every cylinder model has the 26 named DOFs")
}

/// `points` moved along their camera rays (from the origin) by Gaussian noise of σ mm, the
/// depth noise of a sensor (Box–Muller); `uniform` draws each point's two independent uniforms,
/// the first in (0, 1], the second in [0, 1).
pub fn with_depth_noise(
    points: &[nalgebra::Vector3<f64>],
    sigma: f64,
    mut uniform: impl FnMut() -> (f64, f64),
) -> Vec<nalgebra::Vector3<f64>> {
    points
        .iter()
        .map(|p| {
            let (u1, u2) = uniform();
            let n = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos() * sigma;
            p * (1.0 + n / p.norm())
        })
        .collect()
}
