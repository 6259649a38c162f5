//! Conservative screen coverage of sphere-mesh elements, for renderers that only need a few
//! pixels (the model→data term of Eq. 3.5 ray casts only pixels outside the sensor silhouette).
//!
//! The perspective image of a sphere `(c, r)` in front of the camera is an ellipse (the section
//! of the cone of half-angle `α = asin(r/‖c‖)` around `ĉ`); the image of an element — the convex
//! hull of its spheres — is the convex hull of those ellipses, because a central projection
//! maps convex sets in front of the camera to convex sets. Each ellipse lies in the disc around
//! the projected center `π(c)` of radius `δ + max(a, b)` (`δ` the offset of the ellipse center
//! from `π(c)`, `a`, `b` its semi-axes, all in closed form), so the element's image lies in the
//! convex hull of those discs: the union of the discs and, per pair of discs, the quadrilateral
//! between their outer tangents (the hull of three discs adds the triangle of their centers,
//! which lies between the pieces on every row). Its intersection with a pixel row is an
//! interval, computed exactly; the pixels of that interval are the element's candidates. (With
//! every disc grown to the largest radius the hull was simpler, but a fingertip's footprint
//! then had the width of its base: twice the rays cast along the model's outline.)
//! Spheres not entirely in front of the camera (or seen at grazing angles) make their element a
//! candidate everywhere.

use nalgebra::Vector2;

use super::depth::Intrinsics;
use crate::shape::Sphere;

/// Slack (pixels) added to every projected radius: covers rounding only, the bound is exact.
const SLACK_PX: f64 = 0.5;

/// The conservative screen footprint of one element: the hull of discs.
#[derive(Copy, Clone, Debug, PartialEq)]
#[expect(
    clippy::large_enum_variant,
    reason = "one footprint at a time lives on the stack of the renderer's element loop"
)]
pub(crate) enum Footprint {
    /// Centers (pixels) of the element's spheres, their radii, the count used, and the
    /// tangent quadrilaterals between pairs of discs (`None` where one disc holds the other).
    Discs([Vector2<f64>; 3], [f64; 3], usize, [Option<Quad>; 3]),
    /// The element may be seen at any pixel.
    Everywhere,
}

/// The quadrilateral between the outer tangents of two discs (its corners are the tangent
/// points, in order around it), framed once per element instead of once per pixel row
/// ([`Footprint::span`] runs for every row): per edge, from corner `i` to the next, its start,
/// its slope `dx/dy` (0 along a row) and its extent in `y`.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct Quad {
    x: [f64; 4],
    y: [f64; 4],
    slope: [f64; 4],
    y_min: [f64; 4],
    y_max: [f64; 4],
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
        let mut radii = [0.0; 3];
        for ((c, radius), s) in centers.iter_mut().zip(&mut radii).zip(spheres) {
            let Some(r) = image_radius(s) else {
                return Self::Everywhere;
            };
            let [u, v] = intr.project(&s.center);
            *c = Vector2::new(u, v);
            *radius = f * r + SLACK_PX;
        }
        let finite = |c: &Vector2<f64>| c.iter().all(|x| x.is_finite());
        if !radii.iter().all(|r| r.is_finite()) || !centers.iter().all(finite) {
            return Self::Everywhere;
        }
        let n = spheres.len().min(3);
        let mut quads = [None; 3];
        for (quad, &(i, j)) in quads.iter_mut().zip(PAIRS.iter().filter(|&&(_, j)| j < n)) {
            *quad = Quad::new(&centers[i], radii[i], &centers[j], radii[j]);
        }
        Self::Discs(centers, radii, n, quads)
    }

    /// The rows `[v0, v1]` (inclusive, clipped to `height`) the footprint may touch; `None` when
    /// none.
    pub(crate) fn rows(&self, height: u32) -> Option<(u32, u32)> {
        let last = f64::from(height) - 1.0;
        let (lo, hi) = match self.extent(1) {
            None => (0.0, last),
            Some((lo, hi)) => (lo.ceil().max(0.0), hi.floor().min(last)),
        };
        (lo <= hi).then_some((lo as u32, hi as u32))
    }

    /// The discs' extent `[min, max]` along image axis `axis` (0: u, 1: v); `None` for
    /// [`Footprint::Everywhere`].
    fn extent(&self, axis: usize) -> Option<(f64, f64)> {
        let Self::Discs(c, r, n, _) = self else {
            return None;
        };
        let discs = c[..*n].iter().zip(r);
        let lo = discs
            .clone()
            .map(|(p, r)| p[axis] - r)
            .fold(f64::INFINITY, f64::min);
        let hi = discs
            .map(|(p, r)| p[axis] + r)
            .fold(f64::NEG_INFINITY, f64::max);
        Some((lo, hi))
    }

    /// Columns `[u0, u1]` (inclusive, clipped to `width`) that hold every row's
    /// [`span`](Self::span): the discs' extent (the quadrilaterals join tangent points of the
    /// discs) grown by a pixel against rounding; `None` when no row has a span.
    pub(crate) fn columns(&self, width: u32) -> Option<(u32, u32)> {
        let last = f64::from(width) - 1.0;
        let (lo, hi) = match self.extent(0) {
            None => (0.0, last),
            Some((lo, hi)) => ((lo - 1.0).floor().max(0.0), (hi + 1.0).ceil().min(last)),
        };
        (lo <= hi).then_some((lo as u32, hi as u32))
    }

    /// The columns `[u0, u1]` (inclusive, clipped to `width`) of row `v` inside the footprint.
    pub(crate) fn span(&self, v: u32, width: u32) -> Option<(u32, u32)> {
        let last = f64::from(width) - 1.0;
        let (lo, hi) = match self {
            Self::Everywhere => (0.0, last),
            Self::Discs(c, r, n, quads) => {
                let y = f64::from(v);
                let (mut lo, mut hi) = (FAR, -FAR);
                let mut add = |(a, b): (f64, f64)| {
                    lo = lo.min(a);
                    hi = hi.max(b);
                };
                for (center, r) in c[..*n].iter().zip(r) {
                    add(disc_row(center, *r, y));
                }
                for quad in quads.iter().flatten() {
                    add(quad.row(y));
                }
                (lo.ceil().max(0.0), hi.floor().min(last))
            }
        };
        (lo <= hi).then_some((lo as u32, hi as u32))
    }
}

/// `{u : ‖(u, y) − c‖ ≤ r}`, or `(FAR, −FAR)` when empty.
#[inline]
fn disc_row(c: &Vector2<f64>, r: f64, y: f64) -> (f64, f64) {
    let dy = y - c.y;
    let h = r * r - dy * dy;
    let w = h.max(0.0).sqrt();
    let far = far_unless(h >= 0.0);
    (c.x - w + far, c.x + w - far)
}

/// Beyond any column: what a piece that a row misses adds to the ends of its span, so that the
/// row's pieces are merged without branching (which pieces a row crosses changes from row to
/// row, and branches on it mispredicted; `x + 0` is `x`, so the crossed pieces are exact).
const FAR: f64 = 1e300;

/// 0 when `crosses`, else [`FAR`] (by arithmetic: a `bool` select compiled to a branch).
#[inline]
fn far_unless(crosses: bool) -> f64 {
    f64::from(u8::from(!crosses)) * FAR
}

/// The pairs of discs joined by tangent quadrilaterals (the first one only for two discs).
const PAIRS: [(usize, usize); 3] = [(0, 1), (0, 2), (1, 2)];

impl Quad {
    /// The quadrilateral between the outer tangents of the discs `(a, ra)` and `(b, rb)`;
    /// `None` when one disc holds the other (the discs then cover the hull).
    fn new(a: &Vector2<f64>, ra: f64, b: &Vector2<f64>, rb: f64) -> Option<Self> {
        let e = b - a;
        let len = e.norm();
        if len <= (ra - rb).abs() || len <= 1e-12 {
            return None;
        }
        // The outer tangents' unit normals n have n·(b − a) = ra − rb.
        let t = e / len;
        let perp = Vector2::new(-t.y, t.x);
        let sine = (ra - rb) / len;
        let cosine = (1.0 - sine * sine).sqrt();
        let (plus, minus) = (t * sine + perp * cosine, t * sine - perp * cosine);
        let corners = [a + plus * ra, b + plus * rb, b + minus * rb, a + minus * ra];
        let mut quad = Self {
            x: [0.0; 4],
            y: [0.0; 4],
            slope: [0.0; 4],
            y_min: [0.0; 4],
            y_max: [0.0; 4],
        };
        for (i, p) in corners.iter().enumerate() {
            let q = &corners[(i + 1) % 4];
            let dy = q.y - p.y;
            quad.x[i] = p.x;
            quad.y[i] = p.y;
            // An edge along the row reports its start only: its end starts the next edge.
            quad.slope[i] = if dy == 0.0 { 0.0 } else { (q.x - p.x) / dy };
            quad.y_min[i] = p.y.min(q.y);
            quad.y_max[i] = p.y.max(q.y);
        }
        Some(quad)
    }

    /// `{u : (u, y) in the quadrilateral}`: where row `y` crosses its edges, `(FAR, −FAR)` when
    /// nowhere. The crossings come from the slopes rather than a division per edge and row: they
    /// may differ from the exact ones by a rounding, which the footprint's slack covers (the
    /// element's image stays more than [`SLACK_PX`] inside), so no ray that hits is dropped.
    #[inline]
    fn row(&self, y: f64) -> (f64, f64) {
        let (mut lo, mut hi) = (FAR, -FAR);
        for i in 0..4 {
            let x = self.x[i] + (y - self.y[i]) * self.slope[i];
            let far = far_unless((self.y_min[i] <= y) & (y <= self.y_max[i]));
            lo = lo.min(x + far);
            hi = hi.max(x - far);
        }
        (lo, hi)
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
