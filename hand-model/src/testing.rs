//! Helpers for checking Jacobians against central finite differences (STYLE practice 10).

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
