//! Closest point on a pill, the convex hull of two spheres with linearly interpolated radii
//! (Fig. 3.7 left, §3.3.1 "Pill correspondences").
//!
//! The hull is the union of the balls `B(c(t), r(t))`, `c(t) = (1−t)c₀ + t c₁`,
//! `r(t) = (1−t)r₀ + t r₁`, so its signed distance is `f(t) = ‖p − c(t)‖ − r(t)` minimised over
//! `t ∈ [0, 1]` (exact inside as well: these balls are the maximal balls of the hull). `f` is
//! convex, so the minimiser is its stationary point clamped to the segment. In the plane of
//! `{c₀, c₁, p}` with `x` along the axis `u` and `y` the distance to the axis, the stationary
//! point is where the ray along the cone normal `n = −k u + h ŵ` (`k = (r₁ − r₀)/L`,
//! `h = √(1 − k²)`, `ŵ` the radial direction of `p`) meets the axis: `a = x + y·k/h`. Inside the
//! segment the footpoint is on the cone with signed distance `h y − k x − r₀`; outside it is on
//! the nearer sphere cap.

use super::{any_orthogonal, combine, is_usable, Part, Projection};
use crate::shape::Sphere;
use nalgebra::Vector3;

/// Below this `h = √(1 − k²)` one sphere contains the other to machine precision and the cone
/// has no extent; treating the pill as the larger ball avoids dividing by `h`.
const MIN_CONE_COSINE: f64 = 1e-12;
/// Points closer to the axis than this fraction of the pill's scale are treated as on the axis.
const AXIS_EPS: f64 = 1e-12;

/// The shape of a pill after classifying its degenerate cases once per pose.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) enum PillShape {
    /// One sphere contains the other (or the centers coincide): the hull is sphere `which`.
    Ball {
        /// Index (0 or 1) of the containing sphere.
        which: usize,
    },
    /// A proper tapered capsule.
    Cone {
        /// Unit axis `u = (c₁ − c₀)/L`.
        axis: Vector3<f64>,
        /// Axis length `L = ‖c₁ − c₀‖`.
        len: f64,
        /// Radius slope `k = (r₁ − r₀)/L`, in (−1, 1).
        slope: f64,
        /// `h = √(1 − k²)`, the cone normal's component away from the axis.
        cosine: f64,
        /// `k/h`: how far along the axis a point's cone-normal ray lands per unit of radial
        /// distance.
        shift: f64,
    },
}

/// Per-pose data of one pill: its spheres and its classified shape.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct PillFrame {
    pub(crate) centers: [Vector3<f64>; 2],
    pub(crate) radii: [f64; 2],
    pub(crate) shape: PillShape,
}

impl PillFrame {
    /// Classifies the pill spanned by two spheres (the caller guarantees finite input).
    pub(crate) fn new(a: &Sphere, b: &Sphere) -> Self {
        let d = b.center - a.center;
        let len = d.norm();
        let dr = b.radius - a.radius;
        let bigger = if dr > 0.0 { 1 } else { 0 };
        let shape = if len <= 0.0 || dr.abs() >= len {
            PillShape::Ball { which: bigger }
        } else {
            let slope = dr / len;
            let cosine = (1.0 - slope * slope).max(0.0).sqrt();
            if cosine <= MIN_CONE_COSINE {
                PillShape::Ball { which: bigger }
            } else {
                PillShape::Cone {
                    axis: d / len,
                    len,
                    slope,
                    cosine,
                    shift: slope / cosine,
                }
            }
        };
        Self {
            centers: [a.center, b.center],
            radii: [a.radius, b.radius],
            shape,
        }
    }

    /// [`distance`](Self::distance) when it is not above `best`; otherwise some value `> best`,
    /// without evaluating the pill when its enclosing capsule (the axis segment grown by the
    /// larger radius) is already farther than `best`. Ball survivors of the model-wide search
    /// are often neighbouring phalanges whose capsule rules them out without square roots.
    #[inline]
    pub(crate) fn distance_below(&self, p: &Vector3<f64>, best: f64) -> f64 {
        if let PillShape::Cone { axis, len, .. } = self.shape {
            let w = p - self.centers[0];
            let x = w.dot(&axis).clamp(0.0, len);
            let d2 = (w - axis * x).norm_squared();
            // The relative slack of the bounding balls covers the rounding of both sides.
            let scale = w.abs().max() + len + self.radii[0] + self.radii[1];
            let t = best + self.radii[0].max(self.radii[1]) + 1e-9 * scale;
            if t <= 0.0 || d2 > t * t {
                return f64::INFINITY;
            }
        }
        self.distance(p)
    }

    /// Signed distance from `p` to the pill surface (negative inside), without the footpoint.
    #[inline]
    pub(crate) fn distance(&self, p: &Vector3<f64>) -> f64 {
        match self.shape {
            PillShape::Ball { which } => (p - self.centers[which]).norm() - self.radii[which],
            PillShape::Cone {
                axis,
                len,
                slope,
                cosine,
                shift,
            } => {
                let w = p - self.centers[0];
                let x = w.dot(&axis);
                let y = (w - axis * x).norm();
                let a = x + shift * y;
                if a <= 0.0 {
                    w.norm() - self.radii[0]
                } else if a >= len {
                    (p - self.centers[1]).norm() - self.radii[1]
                } else {
                    cosine * y - slope * x - self.radii[0]
                }
            }
        }
    }

    /// Full closest-point projection; sphere indices are local (0, 1).
    #[inline]
    pub(crate) fn project(&self, p: &Vector3<f64>) -> Projection {
        match self.shape {
            PillShape::Ball { which } => self.cap(p, which, &Vector3::z()),
            PillShape::Cone {
                axis,
                len,
                slope,
                cosine,
                shift,
            } => {
                let w = p - self.centers[0];
                let x = w.dot(&axis);
                let radial = w - axis * x;
                let y = radial.norm();
                let a = x + shift * y;
                if a <= 0.0 {
                    self.cap(p, 0, &-axis)
                } else if a >= len {
                    self.cap(p, 1, &axis)
                } else {
                    let t = a / len;
                    // Within rounding of the axis the radial direction is noise (and not
                    // orthogonal to the axis); every direction is equally close there.
                    let out = if y > AXIS_EPS * (w.norm() + len) {
                        let o = radial - axis * axis.dot(&radial);
                        o / o.norm()
                    } else {
                        any_orthogonal(&axis)
                    };
                    let normal = out * cosine - axis * slope;
                    let weights = [1.0 - t, t, 0.0];
                    let (s, _, q) = combine(
                        [&self.centers[0], &self.centers[1], &self.centers[0]],
                        [self.radii[0], self.radii[1], self.radii[0]],
                        weights,
                        &normal,
                    );
                    Projection {
                        point: q,
                        normal,
                        skeleton_point: s,
                        element: 0,
                        spheres: [0, 1, 0],
                        weights,
                        distance: cosine * y - slope * x - self.radii[0],
                        part: Part::Cone,
                    }
                }
            }
        }
    }

    /// Projection on the cap of sphere `which`; `fallback` is the outward normal used when `p`
    /// sits exactly on the center (every direction is then equally close).
    #[inline]
    fn cap(&self, p: &Vector3<f64>, which: usize, fallback: &Vector3<f64>) -> Projection {
        let c = &self.centers[which];
        let v = p - c;
        let len = v.norm();
        let normal = if len > 0.0 { v / len } else { *fallback };
        let mut weights = [0.0; 3];
        weights[which] = 1.0;
        let (s, _, q) = combine(
            [&self.centers[0], &self.centers[1], &self.centers[0]],
            [self.radii[0], self.radii[1], self.radii[0]],
            weights,
            &normal,
        );
        Projection {
            point: q,
            normal,
            skeleton_point: s,
            element: 0,
            spheres: [0, 1, 0],
            weights,
            distance: len - self.radii[which],
            part: Part::Sphere,
        }
    }
}

/// Closest-point projection of `p` on the pill `conv(a, b)` (thesis §3.3.1 "Pill
/// correspondences", Fig. 3.7 left): cone part or one of the two sphere caps, in closed form.
///
/// Sphere indices in the result are local: 0 is `a`, 1 is `b`. Degenerate pills (coincident
/// centers, one sphere inside the other, zero radii) are handled. Returns `None` when `p` or a
/// sphere is not finite or a radius is negative.
pub fn project_point_pill(p: &Vector3<f64>, a: &Sphere, b: &Sphere) -> Option<Projection> {
    if !is_usable(p) || !valid_sphere(a) || !valid_sphere(b) {
        return None;
    }
    Some(PillFrame::new(a, b).project(p))
}

pub(crate) fn valid_sphere(s: &Sphere) -> bool {
    is_usable(&s.center) && (0.0..=super::MAX_COORDINATE).contains(&s.radius)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere(x: f64, y: f64, z: f64, r: f64) -> Sphere {
        Sphere::new(Vector3::new(x, y, z), r)
    }

    #[test]
    fn cone_footpoint_of_a_cylinder_is_radial() {
        let a = sphere(0.0, 0.0, 0.0, 2.0);
        let b = sphere(10.0, 0.0, 0.0, 2.0);
        let pr = project_point_pill(&Vector3::new(4.0, 5.0, 0.0), &a, &b).unwrap();
        assert_eq!(pr.part, Part::Cone);
        assert!((pr.point - Vector3::new(4.0, 2.0, 0.0)).norm() < 1e-12);
        assert!((pr.distance - 3.0).abs() < 1e-12);
        assert!((pr.weights[1] - 0.4).abs() < 1e-12);
    }

    #[test]
    fn tapered_cone_matches_the_tangent_line() {
        // r goes 3 → 1 over 10: the cone line in the xy-plane is tangent to both circles.
        let a = sphere(0.0, 0.0, 0.0, 3.0);
        let b = sphere(10.0, 0.0, 0.0, 1.0);
        let p = Vector3::new(5.0, 8.0, 0.0);
        let pr = project_point_pill(&p, &a, &b).unwrap();
        assert_eq!(pr.part, Part::Cone);
        // Tangent points lie on the line: n·x = n·c₀ + r₀.
        let n = pr.normal;
        assert!((n.dot(&pr.point) - (n.dot(&a.center) + a.radius)).abs() < 1e-12);
        assert!((n.dot(&pr.point) - (n.dot(&b.center) + b.radius)).abs() < 1e-12);
        assert!(((p - pr.point).norm() - pr.distance).abs() < 1e-12);
    }

    #[test]
    fn caps_beyond_the_segment() {
        let a = sphere(0.0, 0.0, 0.0, 3.0);
        let b = sphere(10.0, 0.0, 0.0, 1.0);
        let pr = project_point_pill(&Vector3::new(-5.0, 0.5, 0.0), &a, &b).unwrap();
        assert_eq!(pr.part, Part::Sphere);
        assert_eq!(pr.weights, [1.0, 0.0, 0.0]);
        let pr = project_point_pill(&Vector3::new(15.0, 0.5, 0.0), &a, &b).unwrap();
        assert_eq!(pr.weights, [0.0, 1.0, 0.0]);
    }

    #[test]
    fn non_finite_input_is_rejected() {
        let a = sphere(0.0, 0.0, 0.0, 3.0);
        let b = sphere(10.0, 0.0, 0.0, 1.0);
        assert!(project_point_pill(&Vector3::new(f64::NAN, 0.0, 0.0), &a, &b).is_none());
        assert!(project_point_pill(&Vector3::new(f64::INFINITY, 0.0, 0.0), &a, &b).is_none());
        assert!(project_point_pill(&Vector3::zeros(), &sphere(0.0, 0.0, 0.0, -1.0), &b).is_none());
    }
}
