//! The implicit function φ of a single element (Eq. 3.1–3.2), evaluated as a signed distance.
//!
//! Eq. 3.1 defines `φ(x) = min_{c∈S} B(x | c, r(c))` with the sphere function
//! `B(x | c, r) = ‖x − c‖² − r²` (Eq. 3.2). Since `B = (‖x − c‖ − r)(‖x − c‖ + r)` has the sign of
//! `‖x − c‖ − r`, replacing `B` by `‖x − c‖ − r` keeps the zero set, the inside/outside sign and
//! the minimising skeleton point, and turns φ into the Euclidean signed distance to the element
//! (exact inside too, because the interpolated balls are the element's maximal balls). The
//! trackers need distances, so that is the form evaluated here. The model-wide function
//! (Eq. 3.6) is [`super::SphereMeshGeometry::phi`].

use super::is_usable;
use super::point_pill::{valid_sphere, PillFrame};
use super::point_wedge::WedgeFrame;
use crate::shape::Sphere;
use nalgebra::Vector3;

/// Signed distance `φ_e(p)` from `p` to the pill `conv(a, b)` (Eq. 3.1 on a segment skeleton):
/// negative inside, zero on the surface. `None` for non-finite input or a negative radius.
pub fn phi_pill(p: &Vector3<f64>, a: &Sphere, b: &Sphere) -> Option<f64> {
    if !is_usable(p) || !valid_sphere(a) || !valid_sphere(b) {
        return None;
    }
    Some(PillFrame::new(a, b).distance(p))
}

/// Signed distance `φ_e(p)` from `p` to the wedge `conv(s[0], s[1], s[2])` (Eq. 3.1 on a triangle
/// skeleton): negative inside, zero on the surface. `None` for non-finite input or a negative
/// radius.
pub fn phi_wedge(p: &Vector3<f64>, s: [&Sphere; 3]) -> Option<f64> {
    if !is_usable(p) || !s.iter().all(|x| valid_sphere(x)) {
        return None;
    }
    Some(WedgeFrame::new(s).distance(p))
}
