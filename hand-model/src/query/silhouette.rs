//! Object-space silhouette (contour generator) of one element under an orthographic view
//! (thesis §3.3.1 "Silhouette computation", Fig. 3.10).
//!
//! An element is the convex hull of 2 or 3 spheres, so its boundary point with outward normal
//! `n` is `cᵢ + rᵢ n` for the sphere maximising the support `n·cᵢ + rᵢ` (a whole generator
//! segment on a tie of two spheres, a tangent triangle on a tie of three). The contour generator
//! for the viewing direction `v` is the set of boundary points whose normal is orthogonal to `v`:
//! walking `n` around the great circle `n ⟂ v` gives exactly the outline of the 2-D convex hull
//! of the circles obtained by projecting the spheres along `v` (the thesis's "spheres are replaced
//! with circles and planes/cylinders with segments"), lifted back to 3-D. Its pieces are
//! - arcs of the spheres' great circles orthogonal to `v`, where that sphere is the support;
//! - generator segments `[cᵢ + rᵢ n, cⱼ + rⱼ n]` where `n` is a common outer tangent direction of
//!   the projected circles `i`, `j` (the cone's contour lines, and the planar faces' edges when a
//!   face is seen edge-on), kept when the third sphere does not stick out beyond them.

use super::{any_orthogonal, combine};
use nalgebra::{Vector2, Vector3};

/// Relative tolerance of the support comparisons: ties (a sphere exactly on a tangent line) keep
/// both pieces, which only duplicates a piece.
const SUPPORT_TOL: f64 = 1e-10;

/// For a wedge, at most 2 arcs per sphere and 6 tangent segments.
pub(crate) const MAX_ELEMENT_PIECES: usize = 12;

/// The viewing direction `v` completed to an orthonormal frame `(e₁, e₂, v)`: the image plane
/// onto which the spheres are projected as circles.
#[derive(Copy, Clone, Debug, PartialEq)]
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
    pub(crate) fn flatten(&self, x: &Vector3<f64>) -> Vector2<f64> {
        Vector2::new(self.e1.dot(x), self.e2.dot(x))
    }

    #[inline]
    pub(crate) fn lift(&self, n: &Vector2<f64>) -> Vector3<f64> {
        self.e1 * n.x + self.e2 * n.y
    }
}

/// One piece of an element's contour generator, in the element's local sphere indices.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) enum Piece {
    /// The great circle of sphere `sphere` orthogonal to `v`, at angles `θ ∈ [lo, hi]`
    /// (unwrapped, `hi − lo ≤ 2π`) in the view basis: `x(θ) = c + r (cos θ e₁ + sin θ e₂)`.
    Arc {
        /// Local sphere index.
        sphere: u8,
        /// Start angle.
        lo: f64,
        /// End angle.
        hi: f64,
    },
    /// The generator segment `x(t) = (1 − t)(cᵢ + rᵢ n) + t(cⱼ + rⱼ n)`, `t ∈ [0, 1]`.
    Segment {
        /// Local sphere indices `i`, `j`.
        spheres: [u8; 2],
        /// The common normal `n` (unit, orthogonal to `v`).
        normal: Vector3<f64>,
    },
}

/// A point of a piece: what a [`super::Projection`] needs, in local sphere indices.
#[derive(Copy, Clone, Debug, Default)]
pub(crate) struct PiecePoint {
    pub(crate) point: Vector3<f64>,
    pub(crate) normal: Vector3<f64>,
    pub(crate) skeleton_point: Vector3<f64>,
    pub(crate) spheres: [u8; 3],
    pub(crate) weights: [f64; 3],
}

impl Piece {
    /// The parameter range: `[lo, hi]` for arcs, `[0, 1]` for segments.
    pub(crate) fn range(&self) -> (f64, f64) {
        match *self {
            Piece::Arc { lo, hi, .. } => (lo, hi),
            Piece::Segment { .. } => (0.0, 1.0),
        }
    }

    /// A Lipschitz constant of `x(s)` (speed along the parameter): any 1-Lipschitz function of
    /// the position, such as a signed distance, changes at most this fast along the piece.
    pub(crate) fn speed(&self, centers: &[Vector3<f64>], radii: &[f64]) -> f64 {
        match *self {
            Piece::Arc { sphere, .. } => radii[sphere as usize],
            Piece::Segment {
                spheres: [i, j],
                normal,
            } => {
                let (i, j) = (i as usize, j as usize);
                ((centers[j] + normal * radii[j]) - (centers[i] + normal * radii[i])).norm()
            }
        }
    }

    /// A segment piece's generator `x(t) = a + t·ab` as `(a, ab)` and the parameter `t` of the
    /// foot of `p` on its line (unclamped; 0 for a degenerate segment); `None` for an arc.
    pub(crate) fn segment_foot(
        &self,
        centers: &[Vector3<f64>],
        radii: &[f64],
        p: &Vector3<f64>,
    ) -> Option<(Vector3<f64>, Vector3<f64>, f64)> {
        let Piece::Segment {
            spheres: [i, j],
            normal,
        } = *self
        else {
            return None;
        };
        let (i, j) = (i as usize, j as usize);
        let a = centers[i] + normal * radii[i];
        let ab = centers[j] + normal * radii[j] - a;
        let ab2 = ab.norm_squared();
        let foot = if ab2 > 0.0 {
            (p - a).dot(&ab) / ab2
        } else {
            0.0
        };
        Some((a, ab, foot))
    }

    /// A ball `[x, y, z, R]` containing the piece.
    pub(crate) fn bound(&self, centers: &[Vector3<f64>], radii: &[f64]) -> [f64; 4] {
        match *self {
            Piece::Arc { sphere, .. } => {
                let c = centers[sphere as usize];
                [c.x, c.y, c.z, radii[sphere as usize]]
            }
            Piece::Segment {
                spheres: [i, j],
                normal,
            } => {
                let (i, j) = (i as usize, j as usize);
                let a = centers[i] + normal * radii[i];
                let b = centers[j] + normal * radii[j];
                let m = (a + b) * 0.5;
                [m.x, m.y, m.z, 0.5 * (b - a).norm()]
            }
        }
    }

    /// The point of an arc with in-plane unit normal direction `d` (no trigonometry).
    #[inline]
    pub(crate) fn arc_at_direction(
        sphere: u8,
        centers: &[Vector3<f64>],
        radii: &[f64],
        basis: &ViewBasis,
        d: &Vector2<f64>,
    ) -> PiecePoint {
        let normal = basis.lift(d);
        let spheres = [sphere; 3];
        let weights = [1.0, 0.0, 0.0];
        let (skeleton_point, _, point) = combine(
            spheres.map(|k| &centers[k as usize]),
            spheres.map(|k| radii[k as usize]),
            weights,
            &normal,
        );
        PiecePoint {
            point,
            normal,
            skeleton_point,
            spheres,
            weights,
        }
    }

    /// The point at parameter `s`. Computed through [`combine`] so the projection identity
    /// `q = Σ w c + (Σ w r) n` holds exactly.
    #[inline]
    pub(crate) fn at(
        &self,
        centers: &[Vector3<f64>],
        radii: &[f64],
        basis: &ViewBasis,
        s: f64,
    ) -> PiecePoint {
        let (spheres, weights, normal) = match *self {
            Piece::Arc { sphere, .. } => {
                let (sin, cos) = s.sin_cos();
                (
                    [sphere; 3],
                    [1.0, 0.0, 0.0],
                    basis.lift(&Vector2::new(cos, sin)),
                )
            }
            Piece::Segment {
                spheres: [i, j],
                normal,
            } => ([i, j, i], [1.0 - s, s, 0.0], normal),
        };
        let (skeleton_point, _, point) = combine(
            spheres.map(|k| &centers[k as usize]),
            spheres.map(|k| radii[k as usize]),
            weights,
            &normal,
        );
        PiecePoint {
            point,
            normal,
            skeleton_point,
            spheres,
            weights,
        }
    }
}

/// Writes the contour pieces of the hull of the given spheres (2 or 3) under view `basis` to
/// `out` and returns how many.
pub(crate) fn element_pieces(
    centers: &[Vector3<f64>],
    radii: &[f64],
    basis: &ViewBasis,
    out: &mut [Piece; MAX_ELEMENT_PIECES],
) -> usize {
    let n = centers.len().min(radii.len()).min(3);
    let mut flat = [Vector2::zeros(); 3];
    let mut scale: f64 = 0.0;
    for i in 0..n {
        flat[i] = basis.flatten(&centers[i]);
        scale = scale.max(flat[i].norm() + radii[i]);
    }
    let tol = SUPPORT_TOL * (1.0 + scale);
    let support = |i: usize, dir: &Vector2<f64>| dir.dot(&flat[i]) + radii[i];
    let mut count = 0;

    for i in 0..n {
        let (arcs, k) = active_arcs(&flat[..n], &radii[..n], i);
        for &(lo, hi) in &arcs[..k] {
            out[count] = Piece::Arc {
                sphere: i as u8,
                lo,
                hi,
            };
            count += 1;
        }
    }

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
                if (0..n).all(|k| k == i || k == j || support(k, &dir) <= own + tol) {
                    out[count] = Piece::Segment {
                        spheres: [i as u8, j as u8],
                        normal: basis.lift(&dir),
                    };
                    count += 1;
                }
            }
        }
    }
    count
}

/// The arcs (at most two, `(lo, hi)` unwrapped angles) of sphere `i`'s great circle orthogonal
/// to the view on which sphere `i` supports the hull of the given spheres: on the rest of the
/// circle the sphere's surface is inside that hull (a sphere inside a convex body touches its
/// boundary only where it is the support).
pub(crate) fn sphere_arcs(
    centers: &[Vector3<f64>],
    radii: &[f64],
    basis: &ViewBasis,
    i: usize,
) -> ([(f64, f64); 2], usize) {
    let n = centers.len().min(radii.len()).min(3);
    let mut flat = [Vector2::zeros(); 3];
    for (f, c) in flat.iter_mut().zip(&centers[..n]) {
        *f = basis.flatten(c);
    }
    active_arcs(&flat[..n], &radii[..n], i)
}

/// The arcs (at most two, as `(lo, hi)` unwrapped angles with `lo < hi`) of the projected
/// circle `i` on the outline of the 2-D hull of the projected circles: where sphere `i` beats
/// every other sphere `j` in support, `ρ cos(θ − ψ) ≥ rⱼ − rᵢ` with `ρ, ψ` the polar coordinates
/// of `cᵢ − cⱼ`. Each constraint is an arc of half-width `acos((rⱼ − rᵢ)/ρ)` around `ψ`; with
/// three spheres two such arcs can intersect in two pieces (a large middle circle showing on
/// both sides).
fn active_arcs(flat: &[Vector2<f64>], radii: &[f64], i: usize) -> ([(f64, f64); 2], usize) {
    use core::f64::consts::{PI, TAU};
    // The current set as circular arcs (start, length).
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
        if c >= 1.0 {
            return ([(0.0, 0.0); 2], 0); // circle i inside circle j: never on the outline
        }
        let half = c.acos();
        let (start, len) = ((d.y.atan2(d.x) - half).rem_euclid(TAU), 2.0 * half);
        let mut next = [(0.0, 0.0); 2];
        let mut k = 0;
        for &(a, la) in &set[..count] {
            if la >= TAU {
                next[k] = (start, len);
                k += 1;
                continue;
            }
            // The constraint arc relative to `a`, and its copy one turn back.
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
        *o = if la >= TAU {
            (a - PI, a + PI)
        } else {
            (a, a + la)
        };
    }
    (out, count)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pieces(centers: &[Vector3<f64>], radii: &[f64]) -> Vec<Piece> {
        let basis = ViewBasis::new(Vector3::z());
        let mut out = [Piece::Arc {
            sphere: 0,
            lo: 0.0,
            hi: 0.0,
        }; MAX_ELEMENT_PIECES];
        let n = element_pieces(centers, radii, &basis, &mut out);
        out[..n].to_vec()
    }

    #[test]
    fn pill_seen_from_the_side_has_two_lines_and_two_arcs() {
        let centers = [Vector3::new(0.0, 0.0, 0.0), Vector3::new(10.0, 0.0, 0.0)];
        let radii = [3.0, 1.0];
        let basis = ViewBasis::new(Vector3::z());
        let ps = pieces(&centers, &radii);
        assert_eq!(ps.len(), 4);
        for piece in &ps {
            let (a, b) = piece.range();
            for s in [a, 0.5 * (a + b), b] {
                let x = piece.at(&centers, &radii, &basis, s);
                assert!(x.normal.z.abs() < 1e-12);
                assert!((x.normal.norm() - 1.0).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn pill_seen_along_its_axis_is_the_bigger_circle() {
        let ps = pieces(
            &[Vector3::zeros(), Vector3::new(0.0, 0.0, 10.0)],
            &[3.0, 1.0],
        );
        assert_eq!(ps.len(), 1);
        assert!(matches!(ps[0], Piece::Arc { sphere: 0, .. }));
    }

    #[test]
    fn middle_circle_shows_on_both_sides() {
        let flat = [
            Vector2::new(-20.0, 0.0),
            Vector2::new(0.0, 0.0),
            Vector2::new(20.0, 0.0),
        ];
        let (arcs, k) = active_arcs(&flat, &[1.0, 5.0, 1.0], 1);
        assert_eq!(k, 2);
        for (lo, hi) in &arcs[..k] {
            assert!(
                (0.5 * (lo + hi)).sin().abs() > 0.99,
                "arc around ±y: {lo} {hi}"
            );
        }
        assert_eq!(active_arcs(&flat, &[1.0, 5.0, 1.0], 0).1, 1);
    }
}
