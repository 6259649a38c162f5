//! Exact ray casting on a [`Segment`] (the query behind the silhouette rasterizer of thesis
//! §2.3.1 "2D correspondences", [`super::raster`]).
//!
//! The solid is the union of three closed pieces, each the same geometry as
//! [`Segment::contains_local_point`] (see the module documentation of [`crate::cylinder`]):
//! - the start cap, the half-ellipsoid `x²/r1² + (y² + z²)/r1y² ≤ 1`, `y ≤ 0`;
//! - the side, `x²/r(y)² + z²/ry(y)² ≤ 1` for `0 ≤ y ≤ length`, with `r`, `ry` linear in `y`;
//! - the end cap, the half-ellipsoid around `(0, length, 0)` with half-axes `(r2, r2y, r2y)`,
//!   `y ≥ length`.
//!
//! The first entry of a ray into the union is the smallest entry into a piece.
//!
//! - **Caps** (exact, closed form): scaling local x by `ry/r` turns the ellipsoid into a sphere
//!   of radius `ry` (the ray parameter is unchanged), intersected in the numerically stable
//!   closest-approach form and clipped to the cap's half-space.
//! - **Side** (exact up to rounding, by polynomial root isolation): on the ray `p(s) = o + s·d`
//!   the coordinates `x, z` and the radii `r, ry` are all linear in `s`, so the side's implicit
//!   `P(s) = x²ry² + z²r² − r²ry²` (negative inside where `r, ry > 0`) is a **quartic** in `s`.
//!   When the cross-section keeps its shape (`r2·r1y = r1·r2y`, every circular finger segment)
//!   `P = r²·(c²x² + z² − ry²)` with the constant ratio `c = ry/r`, and the quadratic factor is
//!   used instead. A closed form of the quartic (Ferrari) is badly conditioned near double roots
//!   (grazing rays, which every silhouette boundary has), so its roots are isolated instead:
//!   the roots of the derivative split the interval into monotone pieces (recursively, down to
//!   a quadratic solved by the cancellation-free closed form) and each sign change is solved by
//!   safeguarded Newton (bisection fallback), which converges to full precision; only the first
//!   root is refined unless it is rejected. The ray is first clipped to the slab
//!   `0 ≤ y ≤ length` and to the bounding cylinder `x² + z² ≤ max(radii)²`, and the polynomial
//!   is expanded about the clipped start, so its coefficients stay well scaled even with the
//!   camera 40 cm away. A root where a radius vanishes (a cone tip, where `P` vanishes for
//!   every `x, z`) is kept only when the point actually lies on the section.

use nalgebra::Vector3;

use super::model::Segment;

/// Coefficients `c[0] + c[1]·u + … + c[4]·u⁴`.
type Poly = [f64; 5];

#[inline]
fn eval(p: &Poly, deg: usize, u: f64) -> f64 {
    let mut v = p[deg];
    for k in (0..deg).rev() {
        v = v * u + p[k];
    }
    v
}

#[inline]
fn derivative(p: &Poly, deg: usize) -> Poly {
    let mut d = [0.0; 5];
    for k in 1..=deg {
        d[k - 1] = p[k] * k as f64;
    }
    d
}

/// The product of two polynomials whose degrees sum to at most 4.
#[inline]
fn mul(a: &Poly, da: usize, b: &Poly, db: usize) -> Poly {
    let mut c = [0.0; 5];
    for i in 0..=da {
        for j in 0..=db {
            c[i + j] += a[i] * b[j];
        }
    }
    c
}

/// The root of `p` in `[a, b]`, where `p` is monotone and `p(a)`, `p(b)` have opposite signs:
/// Newton steps, replaced by bisection whenever they leave the bracket or stall.
fn solve_monotone(p: &Poly, dp: &Poly, deg: usize, mut a: f64, mut b: f64, fa: f64) -> f64 {
    let rising = fa < 0.0;
    let mut x = 0.5 * (a + b);
    for _ in 0..100 {
        let f = eval(p, deg, x);
        if f == 0.0 {
            return x;
        }
        if (f < 0.0) == rising {
            a = x;
        } else {
            b = x;
        }
        if b - a <= 1e-14 * (1.0 + a.abs().max(b.abs())) {
            break;
        }
        let df = eval(dp, deg - 1, x);
        let newton = x - f / df;
        x = if newton > a && newton < b && df != 0.0 {
            newton
        } else {
            0.5 * (a + b)
        };
    }
    x
}

/// The real roots of `a u² + b u + c` in `[lo, hi]`, increasing, by the cancellation-free
/// formula (`q = −(b + sign(b)√Δ)/2`, roots `q/a` and `c/q`); linear when `a = 0`.
fn quadratic_roots_in(c: f64, b: f64, a: f64, lo: f64, hi: f64, out: &mut [f64; 4]) -> usize {
    let mut n = 0;
    let mut push = |u: f64, n: &mut usize| {
        if (lo..=hi).contains(&u) {
            out[*n] = u;
            *n += 1;
        }
    };
    if a == 0.0 {
        if b != 0.0 {
            push(-c / b, &mut n);
        } else if c == 0.0 {
            push(lo, &mut n);
        }
        return n;
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return 0;
    }
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    if q == 0.0 {
        // b = 0 and c = 0: a double root at 0.
        push(0.0, &mut n);
        return n;
    }
    let (r0, r1) = (q / a, c / q);
    let (r0, r1) = if r0 <= r1 { (r0, r1) } else { (r1, r0) };
    push(r0, &mut n);
    if r1 != r0 {
        push(r1, &mut n);
    }
    n
}

/// All roots of `p` (degree `deg ≤ 4`) in `[lo, hi]` in increasing order: closed form up to
/// degree 2; above, the sign changes between consecutive critical points (and the exact zeros
/// at them). At most `deg` roots, and at most `max` (the first ones).
fn roots_in(p: &Poly, deg: usize, lo: f64, hi: f64, max: usize, out: &mut [f64; 4]) -> usize {
    let max = max.min(4);
    let mut n = 0;
    if deg == 0 || lo > hi {
        return 0;
    }
    if deg <= 2 {
        let a = if deg == 2 { p[2] } else { 0.0 };
        return quadratic_roots_in(p[0], p[1], a, lo, hi, out);
    }
    let dp = derivative(p, deg);
    let mut crit = [0.0; 4];
    let nc = roots_in(&dp, deg - 1, lo, hi, 4, &mut crit);
    let mut x0 = lo;
    let mut f0 = eval(p, deg, lo);
    for x1 in crit[..nc].iter().copied().chain(std::iter::once(hi)) {
        let f1 = eval(p, deg, x1);
        if f0 == 0.0 {
            if n == 0 || out[n - 1] < x0 {
                out[n] = x0;
                n += 1;
            }
        } else if f1 != 0.0 && (f0 < 0.0) != (f1 < 0.0) {
            out[n] = solve_monotone(p, &dp, deg, x0, x1, f0);
            n += 1;
        }
        if n >= max {
            return n;
        }
        x0 = x1;
        f0 = f1;
    }
    if f0 == 0.0 && (n == 0 || out[n - 1] < x0) && n < max {
        out[n] = x0;
        n += 1;
    }
    n
}

/// The interval of `s` where `lo ≤ o + s·d ≤ hi` (`None` when empty).
#[inline]
fn slab(o: f64, d: f64, lo: f64, hi: f64) -> Option<(f64, f64)> {
    if d != 0.0 {
        let (a, b) = ((lo - o) / d, (hi - o) / d);
        Some(if a <= b { (a, b) } else { (b, a) })
    } else if o >= lo && o <= hi {
        Some((f64::NEG_INFINITY, f64::INFINITY))
    } else {
        None
    }
}

/// The interval of `s` where the (not necessarily unit) ray `m + s·d` is within `radius` of
/// the origin of its space, in closest-approach form.
#[inline]
fn ball(m: &Vector3<f64>, d: &Vector3<f64>, radius: f64) -> Option<(f64, f64)> {
    let a = d.norm_squared();
    if a == 0.0 {
        return (m.norm_squared() <= radius * radius).then_some((f64::NEG_INFINITY, f64::INFINITY));
    }
    let sc = -m.dot(d) / a;
    let h2 = radius * radius - (m + d * sc).norm_squared();
    if h2.is_nan() || h2 < 0.0 {
        return None;
    }
    let half = (h2 / a).sqrt();
    Some((sc - half, sc + half))
}

/// The interval of `s` where `x² + z² ≤ radius²` on the ray (2D version of [`ball`]).
#[inline]
fn tube(o: &Vector3<f64>, d: &Vector3<f64>, radius: f64) -> Option<(f64, f64)> {
    ball(
        &Vector3::new(o.x, 0.0, o.z),
        &Vector3::new(d.x, 0.0, d.z),
        radius,
    )
}

impl Segment {
    /// The first point of the closed segment on the ray `origin + s·dir`, `s ∈ [0, max_s]`, in
    /// the bone frame: the smallest such `s` (0 when the origin is inside), `None` when the ray
    /// misses. `dir` need not be unit (`s` is in its units). Exact for caps, roots of the side's
    /// implicit polynomial to full precision (see the [module documentation](self)).
    pub fn cast_local_ray(
        &self,
        origin: &Vector3<f64>,
        dir: &Vector3<f64>,
        max_s: f64,
    ) -> Option<f64> {
        if !(origin.iter().chain(dir.iter()).all(|v| v.is_finite()) && max_s >= 0.0) {
            return None;
        }
        // Bounding capsule check: the segment lies within `reach` of its axis, in the slab
        // `−reach ≤ y ≤ length + reach`.
        let l = self.length;
        let reach = self.r1.max(self.r2).max(self.r1y).max(self.r2y);
        let (a0, b0) = slab(origin.y, dir.y, -reach, l + reach)?;
        let (a1, b1) = tube(origin, dir, reach)?;
        if a0.max(a1).max(0.0) > b0.min(b1).min(max_s) {
            return None;
        }
        let mut best = f64::INFINITY;
        let consider = |best: &mut f64, piece: Option<(f64, f64)>| {
            if let Some((a, b)) = piece {
                let a = a.max(0.0);
                if a <= b.min(max_s) && a < *best {
                    *best = a;
                }
            }
        };
        // Caps: ellipsoids scaled to spheres of radius ry, clipped to their half-space.
        for (r, ry, cy, lo, hi) in [
            (self.r1, self.r1y, 0.0, f64::NEG_INFINITY, 0.0),
            (self.r2, self.r2y, l, l, f64::INFINITY),
        ] {
            if !(r > 0.0 && ry > 0.0) {
                continue;
            }
            let k = ry / r;
            let m = Vector3::new(origin.x * k, origin.y - cy, origin.z);
            let d = Vector3::new(dir.x * k, dir.y, dir.z);
            consider(
                &mut best,
                ball(&m, &d, ry).and_then(|(a, b)| {
                    let (c, e) = slab(origin.y, dir.y, lo, hi)?;
                    Some((a.max(c), b.min(e)))
                }),
            );
        }
        if l > 0.0 {
            let side = self.cast_local_side(origin, dir, max_s.min(best));
            consider(&mut best, side);
        }
        best.is_finite().then_some(best)
    }

    /// Entry of the ray into the side piece `0 ≤ y ≤ length` (as an interval start).
    fn cast_local_side(
        &self,
        o: &Vector3<f64>,
        d: &Vector3<f64>,
        max_s: f64,
    ) -> Option<(f64, f64)> {
        let l = self.length;
        let reach = self.r1.max(self.r2).max(self.r1y).max(self.r2y);
        if reach.is_nan() || reach <= 0.0 {
            return None;
        }
        let (a0, b0) = slab(o.y, d.y, 0.0, l)?;
        let (a1, b1) = tube(o, d, reach)?;
        let sa = a0.max(a1).max(0.0);
        let sb = b0.min(b1).min(max_s);
        if sa.is_nan() || sb.is_nan() || sa > sb {
            return None;
        }
        let span = sb - sa;
        let b = o + d * sa;
        // Linear polynomials in u = s − sa.
        let x: Poly = [b.x, d.x, 0.0, 0.0, 0.0];
        let z: Poly = [b.z, d.z, 0.0, 0.0, 0.0];
        let (dr, dry) = ((self.r2 - self.r1) / l, (self.r2y - self.r1y) / l);
        let r: Poly = [self.r1 + dr * b.y, dr * d.y, 0.0, 0.0, 0.0];
        let ry: Poly = [self.r1y + dry * b.y, dry * d.y, 0.0, 0.0, 0.0];
        let x2 = mul(&x, 1, &x, 1);
        let z2 = mul(&z, 1, &z, 1);
        let ry2 = mul(&ry, 1, &ry, 1);
        let scale = reach * reach;
        let (p, deg) = if (self.r2 * self.r1y - self.r1 * self.r2y).abs() <= 1e-12 * scale {
            // Constant ratio: P = r²·(c²x² + z² − ry²).
            let c = if self.r1 > 0.0 {
                self.r1y / self.r1
            } else {
                self.r2y / self.r2
            };
            let mut q = [0.0; 5];
            for k in 0..3 {
                q[k] = c * c * x2[k] + z2[k] - ry2[k];
            }
            (q, 2)
        } else {
            let r2 = mul(&r, 1, &r, 1);
            let a = mul(&x2, 2, &ry2, 2);
            let bb = mul(&z2, 2, &r2, 2);
            let cc = mul(&r2, 2, &ry2, 2);
            let mut q = [0.0; 5];
            for k in 0..5 {
                q[k] = a[k] + bb[k] - cc[k];
            }
            (q, 4)
        };
        let on_section = |u: f64| {
            let pt = b + d * u;
            let t = (pt.y / l).clamp(0.0, 1.0);
            let (rr, rry) = self.radii_at(t);
            if rr > 0.0 && rry > 0.0 {
                (pt.x / rr).powi(2) + (pt.z / rry).powi(2) <= 1.0 + 1e-9
            } else {
                pt.x.hypot(pt.z) <= 1e-9 * (1.0 + reach)
            }
        };
        if eval(&p, deg, 0.0) <= 0.0 && on_section(0.0) {
            return Some((sa, sb));
        }
        // Usually the first root is the entry; a root at a cone tip is not, then look further.
        let mut roots = [0.0; 4];
        let n = roots_in(&p, deg, 0.0, span, 1, &mut roots);
        if n >= 1 && on_section(roots[0]) {
            return Some((sa + roots[0], sb));
        }
        let n = roots_in(&p, deg, 0.0, span, 4, &mut roots);
        roots[..n]
            .iter()
            .find(|&&u| on_section(u))
            .map(|&u| (sa + u, sb))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn roots_of_a_quartic_with_close_roots() {
        // (u − 1)(u − 1.001)(u − 3)(u + 2) = roots 1, 1.001, 3 in [0, 5].
        let lin = |r: f64| [-r, 1.0, 0.0, 0.0, 0.0];
        let p = mul(
            &mul(&lin(1.0), 1, &lin(1.001), 1),
            2,
            &mul(&lin(3.0), 1, &lin(-2.0), 1),
            2,
        );
        let mut out = [0.0; 4];
        let n = roots_in(&p, 4, 0.0, 5.0, 4, &mut out);
        assert_eq!(n, 3, "{out:?}");
        for (got, want) in out.iter().zip([1.0, 1.001, 3.0]) {
            assert!((got - want).abs() < 1e-12, "{got} vs {want}");
        }
        // A double root touching zero is found when exact.
        let q = mul(&lin(2.0), 1, &lin(2.0), 1);
        assert_eq!(roots_in(&q, 2, 0.0, 5.0, 4, &mut out), 1);
        assert_eq!(out[0], 2.0);
        // Only the first root when asked.
        assert_eq!(roots_in(&p, 4, 0.0, 5.0, 1, &mut out), 1);
        assert!((out[0] - 1.0).abs() < 1e-12);
    }

    /// Brute-force first hit: march with `contains_local_point`, bisect to 1e-11.
    fn march(seg: &Segment, o: &Vector3<f64>, d: &Vector3<f64>, s_max: f64) -> Option<f64> {
        let step = 0.01;
        let mut prev = 0.0;
        let mut s = 0.0;
        while s <= s_max {
            if seg.contains_local_point(&(o + d * s)) {
                let (mut a, mut b) = (prev, s);
                while b - a > 1e-11 {
                    let m = 0.5 * (a + b);
                    if seg.contains_local_point(&(o + d * m)) {
                        b = m;
                    } else {
                        a = m;
                    }
                }
                return Some(b);
            }
            prev = s;
            s += step;
        }
        None
    }

    #[test]
    fn cast_matches_marching_on_random_rays() {
        let segs = [
            // Circular tapered finger.
            Segment {
                bone: 0,
                length: 30.0,
                r1: 8.0,
                r2: 6.0,
                r1y: 8.0,
                r2y: 6.0,
            },
            // Palm-like: width tapers, thickness constant (quartic side).
            Segment {
                bone: 0,
                length: 60.0,
                r1: 25.0,
                r2: 38.0,
                r1y: 11.0,
                r2y: 11.0,
            },
            // Both taper differently.
            Segment {
                bone: 0,
                length: 20.0,
                r1: 5.0,
                r2: 12.0,
                r1y: 9.0,
                r2y: 4.0,
            },
            // Zero length: an ellipsoid.
            Segment {
                bone: 0,
                length: 0.0,
                r1: 7.0,
                r2: 7.0,
                r1y: 2.0,
                r2y: 2.0,
            },
        ];
        let mut rng = ChaCha8Rng::seed_from_u64(42);
        for seg in &segs {
            let (mut hits, mut misses, mut grazing) = (0, 0, 0);
            for _ in 0..300 {
                let dir = Vector3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                )
                .normalize();
                let (rx, rz) = (seg.r1.max(seg.r2) * 1.3, seg.r1y.max(seg.r2y) * 1.3);
                let aim = Vector3::new(
                    rng.random_range(-rx..rx),
                    rng.random_range(-rz..seg.length + rz),
                    rng.random_range(-rz..rz),
                );
                let o = aim - dir * 80.0;
                let got = seg.cast_local_ray(&o, &dir, 160.0);
                let want = march(seg, &o, &dir, 160.0);
                match (got, want) {
                    (Some(g), Some(w)) => {
                        hits += 1;
                        assert!((g - w).abs() < 1e-8, "{seg:?} {o:?} {dir:?}: {g} vs {w}");
                    }
                    (None, None) => misses += 1,
                    // A grazing ray can clip a sliver thinner than the marching step; the hit
                    // must still lie on the boundary.
                    (Some(g), None) => {
                        grazing += 1;
                        assert!(!seg.contains_local_point(&(o + dir * (g - 1e-7))));
                    }
                    (None, Some(w)) => panic!("{seg:?} {o:?} {dir:?}: missed, marching {w}"),
                }
            }
            assert!(
                hits > 40 && misses > 40 && grazing <= 3,
                "{hits} hits, {misses} misses, {grazing} grazing"
            );
        }
        // Origin inside: 0; limit respected; non-finite rays miss.
        let s = segs[0];
        let o = Vector3::new(0.0, 10.0, 0.0);
        assert_eq!(s.cast_local_ray(&o, &Vector3::x(), 100.0), Some(0.0));
        let o = Vector3::new(-50.0, 10.0, 0.0);
        assert!(s.cast_local_ray(&o, &Vector3::x(), 30.0).is_none());
        let hit = s.cast_local_ray(&o, &Vector3::x(), 100.0).unwrap();
        assert!((hit - (50.0 - (8.0 - 2.0 / 3.0))).abs() < 1e-9, "{hit}");
        let nan = Vector3::new(f64::NAN, 0.0, 0.0);
        assert!(s.cast_local_ray(&o, &nan, 100.0).is_none());
        assert!(s.cast_local_ray(&nan, &Vector3::x(), 100.0).is_none());
    }
}
