//! Object-space silhouette (contour generator) of one element under an orthographic view
//! (thesis §3.3.1 "Silhouette computation", Fig. 3.10), and the closest points of its pieces.
//!
//! An element is the convex hull of 2 or 3 spheres, so its boundary point with outward normal
//! `n` is `cᵢ + rᵢ n` for the sphere maximising the support `n·cᵢ + rᵢ` (a whole generator
//! segment on a tie of two spheres, a tangent triangle on a tie of three). The contour generator
//! for the viewing direction `v` is the set of boundary points whose normal is orthogonal to `v`:
//! walking `n` around the great circle `n ⟂ v` gives exactly the outline of the 2-D convex hull
//! of the circles obtained by projecting the spheres along `v` (the thesis's "spheres are replaced
//! with circles and planes/cylinders with segments"), lifted back to 3-D:
//! - arcs of the spheres' great circles orthogonal to `v`, where that sphere is the support;
//! - generator segments `[cᵢ + rᵢ n, cⱼ + rⱼ n]` where `n` is a common outer tangent direction of
//!   the projected circles `i`, `j` (the cone's contour lines, and the planar faces' edges when a
//!   face is seen edge-on), kept when the third sphere does not stick out beyond them.
//!
//! For each piece the closest point to the query is a candidate; closest points on an arc that
//! fall outside the arc's active range are covered by the segment end points.

use super::{any_orthogonal, combine};
use nalgebra::{Vector2, Vector3};

/// Relative tolerance of the support comparisons: ties (a sphere exactly on a tangent line) keep
/// both pieces, which only duplicates a candidate.
const SUPPORT_TOL: f64 = 1e-10;

/// Two unit vectors `e₁`, `e₂` completing the (orthographic) viewing direction `v` to an
/// orthonormal frame: the image plane onto which the spheres are projected as circles.
#[derive(Copy, Clone, Debug)]
pub(crate) struct ViewBasis {
    e1: Vector3<f64>,
    e2: Vector3<f64>,
}

impl ViewBasis {
    /// `v` must be unit length.
    pub(crate) fn new(v: Vector3<f64>) -> Self {
        let e1 = any_orthogonal(&v);
        let e2 = v.cross(&e1);
        Self { e1, e2 }
    }

    #[inline]
    fn flatten(&self, x: &Vector3<f64>) -> Vector2<f64> {
        Vector2::new(self.e1.dot(x), self.e2.dot(x))
    }

    #[inline]
    fn lift(&self, n: &Vector2<f64>) -> Vector3<f64> {
        self.e1 * n.x + self.e2 * n.y
    }
}

/// Which silhouette piece a [`ContourPoint`] lies on, with its parameter there.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub(crate) enum Piece {
    /// Not a silhouette piece (a footpoint on a surface part).
    #[default]
    None,
    /// The great circle of sphere `spheres[0]` at angle `theta` in the view basis (see
    /// [`arc_point`]), within the arc `[lo, hi]` over which that sphere is the element's
    /// support (`lo ≤ theta ≤ hi`, unwrapped angles).
    Arc {
        /// Angle of the point.
        theta: f64,
        /// Start of the active arc.
        lo: f64,
        /// End of the active arc.
        hi: f64,
    },
    /// The generator segment of spheres `spheres[0]`, `spheres[1]` with the point's normal, at
    /// `t` (see [`segment_point`]).
    Segment(f64),
}

/// A silhouette point of one element, in the element's local sphere indices.
#[derive(Copy, Clone, Debug, Default)]
pub(crate) struct ContourPoint {
    /// The piece and parameter, for walking along it.
    pub(crate) piece: Piece,
    pub(crate) point: Vector3<f64>,
    pub(crate) normal: Vector3<f64>,
    pub(crate) skeleton_point: Vector3<f64>,
    pub(crate) spheres: [usize; 3],
    pub(crate) weights: [f64; 3],
    /// `‖p − point‖²`.
    pub(crate) dist2: f64,
}

/// For a wedge, at most 2 active arcs per sphere and 6 tangent segments.
pub(crate) const MAX_CONTOUR_POINTS: usize = 12;

/// Appends to `out` the closest point to `p` of every silhouette piece of the hull of the given
/// spheres (2 or 3) under view `basis`, and returns how many were written.
pub(crate) fn contour_points(
    centers: &[Vector3<f64>],
    radii: &[f64],
    basis: &ViewBasis,
    p: &Vector3<f64>,
    out: &mut [ContourPoint; MAX_CONTOUR_POINTS],
) -> usize {
    let n = centers.len().min(radii.len()).min(3);
    let mut flat = [Vector2::zeros(); 3];
    let mut scale: f64 = 0.0;
    for i in 0..n {
        flat[i] = basis.flatten(&centers[i]);
        scale = scale.max(flat[i].norm() + radii[i]);
    }
    let tol = SUPPORT_TOL * (1.0 + scale);
    let p2 = basis.flatten(p);
    let support = |i: usize, dir: &Vector2<f64>| dir.dot(&flat[i]) + radii[i];
    let mut count = 0;

    // Arcs: on each arc where sphere i is the support, the point nearest to p (the angle of p
    // around the circle, clamped to the arc).
    for i in 0..n {
        let d = p2 - flat[i];
        let theta = if d.norm_squared() > 0.0 {
            d.y.atan2(d.x)
        } else {
            0.0
        };
        let (arcs, k) = active_arcs(&flat[..n], &radii[..n], i);
        for &(lo, hi) in &arcs[..k] {
            let t = clamp_angle(theta, lo, hi);
            let mut c = arc_point(centers, radii, basis, i, t, p);
            c.piece = Piece::Arc { theta: t, lo, hi };
            out[count] = c;
            count += 1;
        }
    }

    // Tangent segments of each pair of projected circles.
    for i in 0..n {
        for j in (i + 1)..n {
            let d = flat[i] - flat[j];
            let rho = d.norm();
            let dr = radii[j] - radii[i];
            if rho - dr.abs() <= tol {
                continue; // one circle contains the other: no common outer tangent
            }
            let cos_a = dr / rho;
            let sin_a = (1.0 - cos_a * cos_a).max(0.0).sqrt();
            let u = d / rho;
            let perp = Vector2::new(-u.y, u.x);
            for sign in [1.0, -1.0] {
                let dir = u * cos_a + perp * (sign * sin_a);
                let own = support(i, &dir);
                if !(0..n).all(|k| k == i || k == j || support(k, &dir) <= own + tol) {
                    continue;
                }
                let normal = basis.lift(&dir);
                let a = centers[i] + normal * radii[i];
                let b = centers[j] + normal * radii[j];
                let ab = b - a;
                let ab2 = ab.norm_squared();
                let t = if ab2 > 0.0 {
                    ((p - a).dot(&ab) / ab2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                out[count] = segment_point(centers, radii, [i, j], normal, t, p);
                count += 1;
            }
        }
    }
    count
}

/// The point at angle `theta` (in the view basis) on the great circle of sphere `i` orthogonal
/// to the viewing direction.
#[inline]
pub(crate) fn arc_point(
    centers: &[Vector3<f64>],
    radii: &[f64],
    basis: &ViewBasis,
    i: usize,
    theta: f64,
    p: &Vector3<f64>,
) -> ContourPoint {
    let (sin, cos) = theta.sin_cos();
    let normal = basis.lift(&Vector2::new(cos, sin));
    finish(centers, radii, [i, i, i], [1.0, 0.0, 0.0], normal, p)
}

/// The point at `t ∈ [0, 1]` on the generator segment `[cᵢ + rᵢ n, cⱼ + rⱼ n]`.
#[inline]
pub(crate) fn segment_point(
    centers: &[Vector3<f64>],
    radii: &[f64],
    [i, j]: [usize; 2],
    normal: Vector3<f64>,
    t: f64,
    p: &Vector3<f64>,
) -> ContourPoint {
    let mut c = finish(centers, radii, [i, j, i], [1.0 - t, t, 0.0], normal, p);
    c.piece = Piece::Segment(t);
    c
}

/// The arcs (at most two, as `(lo, hi)` unwrapped angles with `lo ≤ hi`) of the projected
/// circle `i` on the outline of the 2-D hull of the projected circles: where sphere `i` beats
/// every other sphere `j` in support, `ρ cos(θ − ψ) ≥ rⱼ − rᵢ` with `ρ, ψ` the polar coordinates
/// of `cᵢ − cⱼ`. Each constraint is an arc of half-width `acos((rⱼ − rᵢ)/ρ)` around `ψ`; with
/// three spheres two such arcs can intersect in two pieces (a large middle circle showing on
/// both sides).
fn active_arcs(flat: &[Vector2<f64>], radii: &[f64], i: usize) -> ([(f64, f64); 2], usize) {
    use core::f64::consts::{PI, TAU};
    // Current set as (start, length) circular arcs.
    let mut set = [(0.0, TAU), (0.0, 0.0)];
    let mut count = 1;
    for j in (0..flat.len()).filter(|&j| j != i) {
        let d = flat[i] - flat[j];
        let rho = d.norm();
        let c = if rho > 0.0 {
            (radii[j] - radii[i]) / rho
        } else if radii[i] >= radii[j] {
            -1.0
        } else {
            1.0
        };
        if c <= -1.0 {
            continue; // circle j inside circle i: no constraint
        }
        if c > 1.0 {
            return ([(0.0, 0.0); 2], 0); // circle i inside circle j: never on the outline
        }
        let half = c.acos();
        let (start, len) = ((d.y.atan2(d.x) - half).rem_euclid(TAU), 2.0 * half);
        let mut next = [(0.0, 0.0); 2];
        let mut k = 0;
        for &(a, la) in &set[..count] {
            if la >= TAU {
                if len > 0.0 {
                    next[k] = (start, len);
                    k += 1;
                }
                continue;
            }
            // The constraint arc in coordinates relative to `a`, and its copy one turn back.
            let rel = (start - a).rem_euclid(TAU);
            for shift in [rel, rel - TAU] {
                let lo = shift.max(0.0);
                let hi = (shift + len).min(la);
                if hi > lo && k < 2 {
                    next[k] = (a + lo, hi - lo);
                    k += 1;
                }
            }
        }
        set = next;
        count = k;
    }
    let mut out = [(0.0, 0.0); 2];
    for (o, &(a, la)) in out.iter_mut().zip(&set[..count]) {
        *o = if la >= TAU { (a - PI, a + PI) } else { (a, a + la) };
    }
    (out, count)
}

/// The angle of the arc `[lo, hi]` nearest to `theta` (angular distance), unwrapped into it.
fn clamp_angle(theta: f64, lo: f64, hi: f64) -> f64 {
    use core::f64::consts::TAU;
    if hi - lo >= TAU {
        // A full circle: any unwrapping of theta lies in it.
        return lo + (theta - lo).rem_euclid(TAU);
    }
    let rel = (theta - lo).rem_euclid(TAU);
    if rel <= hi - lo {
        lo + rel
    } else if TAU - rel < rel - (hi - lo) {
        lo
    } else {
        hi
    }
}

#[inline]
pub(crate) fn finish(
    centers: &[Vector3<f64>],
    radii: &[f64],
    spheres: [usize; 3],
    weights: [f64; 3],
    normal: Vector3<f64>,
    p: &Vector3<f64>,
) -> ContourPoint {
    let (s, _, q) = combine(
        spheres.map(|i| &centers[i]),
        spheres.map(|i| radii[i]),
        weights,
        &normal,
    );
    ContourPoint {
        piece: Piece::None,
        point: q,
        normal,
        skeleton_point: s,
        spheres,
        weights,
        dist2: (p - q).norm_squared(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn middle_circle_shows_on_both_sides() {
        // A big circle between two small ones far apart: two arcs.
        let flat = [Vector2::new(-20.0, 0.0), Vector2::new(0.0, 0.0), Vector2::new(20.0, 0.0)];
        let (arcs, k) = active_arcs(&flat, &[1.0, 5.0, 1.0], 1);
        assert_eq!(k, 2);
        for (lo, hi) in &arcs[..k] {
            let mid = 0.5 * (lo + hi);
            assert!(mid.sin().abs() > 0.99, "arc around ±y: {lo} {hi}");
        }
        assert_eq!(active_arcs(&flat, &[1.0, 5.0, 1.0], 0).1, 1);
    }

    #[test]
    fn pill_seen_from_the_side_has_two_lines_and_two_arcs() {
        let centers = [Vector3::new(0.0, 0.0, 0.0), Vector3::new(10.0, 0.0, 0.0)];
        let radii = [3.0, 1.0];
        let basis = ViewBasis::new(Vector3::z());
        let mut out = [ContourPoint::default(); MAX_CONTOUR_POINTS];
        let p = Vector3::new(5.0, 1.0, 4.0);
        let n = contour_points(&centers, &radii, &basis, &p, &mut out);
        assert_eq!(n, 4);
        for c in &out[..n] {
            assert!(c.normal.z.abs() < 1e-12);
            assert!((c.normal.norm() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn pill_seen_along_its_axis_is_the_bigger_circle() {
        let centers = [Vector3::new(0.0, 0.0, 0.0), Vector3::new(0.0, 0.0, 10.0)];
        let radii = [3.0, 1.0];
        let basis = ViewBasis::new(Vector3::z());
        let mut out = [ContourPoint::default(); MAX_CONTOUR_POINTS];
        let n = contour_points(&centers, &radii, &basis, &Vector3::new(5.0, 0.0, 4.0), &mut out);
        assert_eq!(n, 1);
        assert!((out[0].point - Vector3::new(3.0, 0.0, 0.0)).norm() < 1e-12);
    }
}
