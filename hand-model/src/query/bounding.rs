//! Bounding balls of element hulls, used to cull elements in the model-wide argmin of Eq. 3.6.
//!
//! For any set `E` inside a ball `B(C, R)`, the signed distance satisfies
//! `φ_E(p) ≥ ‖p − C‖ − R`, outside (distance to a superset) and inside (depth in a subset) alike,
//! so an element whose bound is not below the best distance found so far can be skipped.

use super::point_pill::{PillFrame, PillShape};
use super::point_wedge::WedgeFrame;
use nalgebra::Vector3;

/// Relative slack added to bounding radii so that rounding never makes a bound exceed the exact
/// distance it is compared with.
const SLACK: f64 = 1e-9;

/// A ball `B(center, radius)` containing an element (thesis §3.3.1: per-element culling of the
/// brute-force argmin of Eq. 3.6).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct BoundingBall {
    /// Center.
    pub center: Vector3<f64>,
    /// Radius (≥ the farthest surface point's distance from the center).
    pub radius: f64,
}

impl BoundingBall {
    /// The smallest ball containing two balls (what bounds a pill exactly).
    pub(crate) fn of_two(c0: &Vector3<f64>, r0: f64, c1: &Vector3<f64>, r1: f64) -> Self {
        let d = c1 - c0;
        let len = d.norm();
        if r0 >= len + r1 {
            return Self::slack(*c0, r0);
        }
        if r1 >= len + r0 {
            return Self::slack(*c1, r1);
        }
        // len > 0 here, otherwise one of the branches above applies.
        let radius = 0.5 * (len + r0 + r1);
        let center = c0 + d * ((radius - r0) / len);
        Self::slack(center, radius)
    }

    fn slack(center: Vector3<f64>, radius: f64) -> Self {
        let scale = radius + center.abs().max();
        Self {
            center,
            radius: radius + SLACK * scale,
        }
    }

    fn contains(&self, c: &Vector3<f64>, r: f64) -> bool {
        (c - self.center).norm() + r <= self.radius
    }

    /// Bound of a pill: the smallest ball containing its two spheres.
    pub(crate) fn of_pill(f: &PillFrame) -> Self {
        match f.shape {
            PillShape::Ball { which } => Self::slack(f.centers[which], f.radii[which]),
            PillShape::Cone { .. } => {
                Self::of_two(&f.centers[0], f.radii[0], &f.centers[1], f.radii[1])
            }
        }
    }

    /// Bound of a wedge: the smallest of the pairwise balls that contain the third sphere, the
    /// circumcenter ball and the centroid ball (not always the minimal enclosing ball of the
    /// three spheres, but close and cheap).
    pub(crate) fn of_wedge(f: &WedgeFrame) -> Self {
        let c = &f.centers;
        let r = &f.radii;
        let mut best: Option<Self> = None;
        let mut consider = |b: Self| {
            if best.is_none_or(|x| b.radius < x.radius) {
                best = Some(b);
            }
        };
        for (i, j, k) in [(0, 1, 2), (1, 2, 0), (2, 0, 1)] {
            let b = Self::of_two(&c[i], r[i], &c[j], r[j]);
            if b.contains(&c[k], r[k]) {
                consider(b);
            }
        }
        let enclosing = |center: Vector3<f64>| {
            let radius = (0..3)
                .map(|i| (c[i] - center).norm() + r[i])
                .fold(0.0, f64::max);
            Self::slack(center, radius)
        };
        if let Some(cc) = circumcenter(&c[0], &c[1], &c[2]) {
            consider(enclosing(cc));
        }
        consider(enclosing((c[0] + c[1] + c[2]) / 3.0));
        // `consider` was called at least once (the centroid ball).
        best.unwrap_or_else(|| enclosing(c[0]))
    }
}

/// Circumcenter of a non-degenerate triangle.
fn circumcenter(a: &Vector3<f64>, b: &Vector3<f64>, c: &Vector3<f64>) -> Option<Vector3<f64>> {
    let ab = b - a;
    let ac = c - a;
    let n = ab.cross(&ac);
    let n2 = n.norm_squared();
    if n2 <= 1e-20 * ab.norm_squared() * ac.norm_squared() || n2 == 0.0 {
        return None;
    }
    let offset = (n.cross(&ab) * ac.norm_squared() + ac.cross(&n) * ab.norm_squared()) / (2.0 * n2);
    Some(a + offset)
}
