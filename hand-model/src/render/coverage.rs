//! Conservative screen coverage of sphere-mesh elements, for renderers that only need a few
//! pixels (the model→data term of Eq. 3.5 ray casts only pixels outside the sensor silhouette).
//!
//! The perspective image of a sphere `(c, r)` in front of the camera is an ellipse (the section
//! of the cone of half-angle `α = asin(r/‖c‖)` around `ĉ`); the image of an element — the convex
//! hull of its spheres — is the convex hull of those ellipses, because a central projection
//! maps convex sets in front of the camera to convex sets. Each ellipse lies in the disc around
//! the projected center `π(c)` of radius `δ + max(a, b)` (`δ` the offset of the ellipse center
//! from `π(c)`, `a`, `b` its semi-axes, all in closed form), so the element's image lies in the
//! convex hull of those discs, which is covered by the hull of the same discs all with the
//! largest radius: a 2D capsule per pair of spheres. Its intersection with a pixel row is an
//! interval, computed exactly; the pixels of that interval are the element's candidates.
//! Spheres not entirely in front of the camera (or seen at grazing angles) make their element a
//! candidate everywhere.

use nalgebra::Vector2;

use super::depth::Intrinsics;
use crate::shape::Sphere;

/// Slack (pixels) added to every projected radius: covers rounding only, the bound is exact.
const SLACK_PX: f64 = 0.5;

/// The conservative screen footprint of one element: the hull of discs of one radius.
#[derive(Copy, Clone, Debug, PartialEq)]
#[expect(
    clippy::large_enum_variant,
    reason = "one footprint at a time lives on the stack of the renderer's element loop"
)]
pub(crate) enum Footprint {
    /// Centers (pixels) of the element's spheres, the count used, the common radius, and the
    /// strips between pairs of centers (`None`: coincident centers, which the discs cover).
    Discs([Vector2<f64>; 3], usize, f64, [Option<Strip>; 3]),
    /// The element may be seen at any pixel.
    Everywhere,
}

/// The rectangle swept by a segment `ab` moved ±r along its normal, with its frame computed
/// once per element instead of once per pixel row ([`Footprint::span`] runs for every row).
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct Strip {
    a: Vector2<f64>,
    /// Unit direction of `ab`.
    t: Vector2<f64>,
    /// Unit normal of `ab`.
    n: Vector2<f64>,
    len: f64,
}

/// Radius (in normalized image units) of a disc around `π(c)` holding the image of the sphere,
/// or `None` when the sphere is not safely in front of the camera.
fn image_radius(s: &Sphere) -> Option<f64> {
    let d = s.center.norm();
    let gap = s.center.z - s.radius;
    if gap.is_nan() || gap <= 1e-6 * (1.0 + d) {
        return None;
    }
    let alpha = (s.radius / d).min(1.0).asin();
    let theta = (s.center.z / d).clamp(-1.0, 1.0).acos();
    if theta + alpha >= 1.5 {
        return None; // grazing: the ellipse degenerates toward a parabola
    }
    let (hi, lo) = ((theta + alpha).tan(), (theta - alpha).tan());
    let a = (hi - lo) / 2.0;
    let delta = ((hi + lo) / 2.0 - theta.tan()).abs();
    let cos2 = alpha.cos().powi(2) - theta.sin().powi(2);
    if cos2 <= 1e-9 {
        return None;
    }
    let b = alpha.sin() / cos2.sqrt();
    Some(delta + a.max(b))
}

impl Footprint {
    /// The footprint of the element made of `spheres` (2 or 3) under `intr`.
    pub(crate) fn new(intr: &Intrinsics, spheres: &[Sphere]) -> Self {
        let f = intr.fx.max(intr.fy);
        let mut centers = [Vector2::zeros(); 3];
        let mut radius: f64 = 0.0;
        for (c, s) in centers.iter_mut().zip(spheres) {
            let Some(r) = image_radius(s) else {
                return Self::Everywhere;
            };
            let [u, v] = intr.project(&s.center);
            *c = Vector2::new(u, v);
            radius = radius.max(f * r + SLACK_PX);
        }
        if !radius.is_finite() || centers.iter().any(|c| !c.iter().all(|x| x.is_finite())) {
            return Self::Everywhere;
        }
        let n = spheres.len().min(3);
        let mut strips = [None; 3];
        for (strip, (i, j)) in strips.iter_mut().zip(PAIRS.iter().filter(|&&(_, j)| j < n)) {
            *strip = Strip::new(&centers[*i], &centers[*j]);
        }
        Self::Discs(centers, n, radius, strips)
    }

    /// The rows `[v0, v1]` (inclusive, clipped to `height`) the footprint may touch; `None` when
    /// none.
    pub(crate) fn rows(&self, height: u32) -> Option<(u32, u32)> {
        let last = f64::from(height) - 1.0;
        let (lo, hi) = match self {
            Self::Everywhere => (0.0, last),
            Self::Discs(c, n, r, _) => {
                let ys = c[..*n].iter().map(|p| p.y);
                let lo = ys.clone().fold(f64::INFINITY, f64::min) - r;
                let hi = ys.fold(f64::NEG_INFINITY, f64::max) + r;
                (lo.ceil().max(0.0), hi.floor().min(last))
            }
        };
        (lo <= hi).then_some((lo as u32, hi as u32))
    }

    /// The columns `[u0, u1]` (inclusive, clipped to `width`) of row `v` inside the footprint.
    pub(crate) fn span(&self, v: u32, width: u32) -> Option<(u32, u32)> {
        let last = f64::from(width) - 1.0;
        let (lo, hi) = match self {
            Self::Everywhere => (0.0, last),
            Self::Discs(c, n, r, strips) => {
                let y = f64::from(v);
                let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
                let mut add = |iv: Option<(f64, f64)>| {
                    if let Some((a, b)) = iv {
                        lo = lo.min(a);
                        hi = hi.max(b);
                    }
                };
                for center in &c[..*n] {
                    add(disc_row(center, *r, y));
                }
                for strip in strips.iter().flatten() {
                    add(strip.row(*r, y));
                }
                (lo.ceil().max(0.0), hi.floor().min(last))
            }
        };
        (lo <= hi).then_some((lo as u32, hi as u32))
    }
}

/// `{u : ‖(u, y) − c‖ ≤ r}`.
fn disc_row(c: &Vector2<f64>, r: f64, y: f64) -> Option<(f64, f64)> {
    let dy = y - c.y;
    let h = r * r - dy * dy;
    (h >= 0.0).then(|| {
        let w = h.sqrt();
        (c.x - w, c.x + w)
    })
}

/// The pairs of centers joined by strips (the first one only for two centers).
const PAIRS: [(usize, usize); 3] = [(0, 1), (0, 2), (1, 2)];

impl Strip {
    /// The strip of segment `ab`; `None` when `a` and `b` coincide (the discs cover it).
    fn new(a: &Vector2<f64>, b: &Vector2<f64>) -> Option<Self> {
        let e = b - a;
        let len = e.norm();
        if len <= 1e-12 {
            return None;
        }
        let t = e / len;
        Some(Self {
            a: *a,
            t,
            n: Vector2::new(-t.y, t.x),
            len,
        })
    }

    /// `{u : (u, y) in the rectangle swept by the segment moved ±r along its normal}`.
    fn row(&self, r: f64, y: f64) -> Option<(f64, f64)> {
        let (a, t, n) = (&self.a, &self.t, &self.n);
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        // k·(u − a.x) + m ∈ [min, max] for (k, m) = (t.x, t.y (y − a.y)) and (n.x, n.y (y − a.y)).
        for (k, m, min, max) in [
            (t.x, t.y * (y - a.y), 0.0, self.len),
            (n.x, n.y * (y - a.y), -r, r),
        ] {
            if k.abs() <= 1e-12 {
                if m < min || m > max {
                    return None;
                }
                continue;
            }
            let (p, q) = ((min - m) / k + a.x, (max - m) / k + a.x);
            lo = lo.max(p.min(q));
            hi = hi.min(p.max(q));
        }
        (lo <= hi).then_some((lo, hi))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Points sampled on spheres and on segments between them project inside the footprint.
    #[test]
    fn footprint_contains_the_projected_element() {
        let intr = Intrinsics {
            fx: 287.0,
            fy: 290.0,
            cx: 160.0,
            cy: 120.0,
            width: 320,
            height: 240,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for _ in 0..200 {
            let spheres: Vec<Sphere> = (0..3)
                .map(|_| {
                    Sphere::new(
                        Vector3::new(
                            rng.random_range(-250.0..250.0),
                            rng.random_range(-200.0..200.0),
                            rng.random_range(150.0..600.0),
                        ),
                        rng.random_range(1.0..25.0),
                    )
                })
                .collect();
            let fp = Footprint::new(&intr, &spheres);
            for _ in 0..300 {
                // A point of the convex hull of the three balls.
                let mut w = [
                    rng.random::<f64>(),
                    rng.random::<f64>(),
                    rng.random::<f64>(),
                ];
                let s: f64 = w.iter().sum();
                w.iter_mut().for_each(|x| *x /= s);
                let dir = Vector3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                )
                .normalize();
                let p: Vector3<f64> = (0..3)
                    .map(|i| (spheres[i].center + dir * spheres[i].radius) * w[i])
                    .sum();
                if p.z <= 0.0 {
                    continue;
                }
                let [u, v] = intr.project(&p);
                let (ui, vi) = (u.round(), v.round());
                if ui < 0.0
                    || vi < 0.0
                    || ui > 319.0
                    || vi > 239.0
                    || (u - ui).abs() > 0.3
                    || (v - vi).abs() > 0.3
                {
                    continue;
                }
                let vi = vi as u32;
                let inside = fp.rows(240).is_some_and(|(a, b)| a <= vi && vi <= b)
                    && fp
                        .span(vi, 320)
                        .is_some_and(|(a, b)| a as f64 <= ui && ui <= b as f64);
                assert!(inside, "{p:?} at ({u}, {v}) outside {fp:?}");
            }
        }
    }
}
