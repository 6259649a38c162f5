//! One sphere-mesh element split into the primitives that bound it (thesis §3.3.2, Fig. 3.3):
//! *spherical* parts (its 2 or 3 spheres), *conical* parts (the truncated cone tangent to each
//! pair of spheres) and, for a wedge, the two *planar* parts (the planes tangent to all three
//! spheres, restricted to the triangle of tangent points).
//!
//! The element `E = ⋃_λ B(c(λ), r(λ))` (Eq. 3.1, centers and radii interpolated linearly over the
//! segment or triangle) is the convex hull of its spheres. It is covered by the union of the
//! spheres, the frusta between each pair of spheres and the slab between the two tangent
//! triangles, and each of those pieces lies inside `E`; so the first entry of a ray into `E` is the
//! first entry into one of the pieces, and a point is inside `E` when it is inside one of them.
//!
//! Degenerate elements are legal: equal radii (the cone is a cylinder), a sphere swallowed by
//! another or coincident centers (no tangent cone exists: the pair is just its larger sphere),
//! collinear or "no tangent plane" wedges (no planar part: the hull is the union of its pills),
//! zero radii (a point sphere has no surface; cones ending in it are true cones).

use nalgebra::{Matrix3, Vector3};

use crate::shape::{Element, Sphere};

type V3 = Vector3<f64>;

/// The truncated cone tangent to two spheres `a` and `b` (the lateral surface of a pill).
///
/// In coordinates `s` (along the axis from `a.center`) and `ρ` (distance to the axis), the cone
/// is the line `s·sin α + ρ·cos α = r_a` with `sin α = (r_a − r_b)/L`, and its tangent band runs
/// from `s_lo = r_a·sin α` to `s_hi = L + r_b·sin α`.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct Cone {
    pub(crate) apex_side: V3,
    pub(crate) axis: V3,
    pub(crate) len: f64,
    pub(crate) r_a: f64,
    pub(crate) sin: f64,
    pub(crate) cos: f64,
    pub(crate) s_lo: f64,
    pub(crate) s_hi: f64,
}

impl Cone {
    /// The tangent cone of two spheres, `None` when it does not exist (coincident centers, one
    /// sphere inside the other).
    pub(crate) fn new(a: &Sphere, b: &Sphere) -> Option<Cone> {
        let e = b.center - a.center;
        let len = e.norm();
        if len.is_nan() || len <= 0.0 {
            return None;
        }
        let sin = (a.radius - b.radius) / len;
        if sin.is_nan() || sin.abs() >= 1.0 - 1e-12 {
            return None;
        }
        let cos = (1.0 - sin * sin).sqrt();
        Some(Cone {
            apex_side: a.center,
            axis: e / len,
            len,
            r_a: a.radius,
            sin,
            cos,
            s_lo: a.radius * sin,
            s_hi: len + b.radius * sin,
        })
    }

    /// Outward unit normal of the cone at a point of its surface.
    #[inline]
    pub(crate) fn normal_at(&self, x: &V3) -> V3 {
        let v = x - self.apex_side;
        let s = v.dot(&self.axis);
        let radial = v - self.axis * s;
        let rho = radial.norm();
        let u = if rho > 1e-12 * (1.0 + self.len) {
            radial / rho
        } else {
            any_perpendicular(&self.axis)
        };
        self.axis * self.sin + u * self.cos
    }

    /// `min_λ ‖p − c(λ)‖ − r(λ)` over the *open* segment when the minimum is attained there
    /// (the thesis' pill projection, §3.3.1), `+∞` otherwise (then an end sphere attains it).
    #[inline]
    pub(crate) fn interior_phi(&self, p: &V3) -> f64 {
        let v = p - self.apex_side;
        let s = v.dot(&self.axis);
        let rho = (v - self.axis * s).norm();
        let lambda_len = s - rho * self.sin / self.cos;
        if (0.0..=self.len).contains(&lambda_len) {
            s * self.sin + rho * self.cos - self.r_a
        } else {
            f64::INFINITY
        }
    }
}

/// One of the two planes tangent to the three spheres of a wedge, restricted to its triangle.
///
/// `inv` inverts `[n, e₂, e₃]` (columns; `eᵢ = cᵢ − c₁`): it maps `p − c₁` to `(δ, β₂, β₃)` with
/// `p = c(β) + δ·n`, the "skewed projection" of §3.3.1. A point of the plane lies on the tangent
/// triangle exactly when `β` lies in the triangle of centers.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct Face {
    pub(crate) normal: V3,
    pub(crate) offset: f64,
    pub(crate) inv: Matrix3<f64>,
}

impl Face {
    /// Barycentric coordinates `(δ, β₂, β₃)` of `p` (see the type docs).
    #[inline]
    pub(crate) fn skew(&self, c1: &V3, p: &V3) -> V3 {
        self.inv * (p - c1)
    }
}

#[inline]
pub(crate) fn in_triangle(q: &V3) -> bool {
    q.y >= 0.0 && q.z >= 0.0 && q.y + q.z <= 1.0
}

/// A unit vector perpendicular to a unit vector.
pub(crate) fn any_perpendicular(a: &V3) -> V3 {
    let helper = if a.x.abs() < 0.9 { V3::x() } else { V3::y() };
    a.cross(&helper).normalize()
}

/// A pill or wedge decomposed into its spherical, conical and planar primitives, ready for ray
/// casting ([`PreparedElement::cast`](crate::render::PreparedElement::cast)) and inside tests.
///
/// Preparing solves the tangent cones and planes once; the depth renderer prepares every element
/// once per frame and then casts thousands of rays. Plain `Copy` data, no allocation.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct PreparedElement {
    pub(crate) spheres: [Sphere; 3],
    pub(crate) count: usize,
    pub(crate) cones: [Option<Cone>; 3],
    pub(crate) faces: Option<[Face; 2]>,
    /// `r₁`, `r₂ − r₁`, `r₃ − r₁` for the radius at a barycentric point.
    pub(crate) radius_plane: [f64; 3],
    pub(crate) bounds: Sphere,
    /// A bounding polytope `{x : nᵢ·x ≤ hᵢ}` tighter than the sphere (an oriented box around a
    /// pill, a triangular prism around a wedge), for culling rays; `count = 0` when degenerate.
    pub(crate) hull: Halfspaces,
}

/// Up to six half-spaces `n·x ≤ h` whose intersection contains an element.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct Halfspaces {
    pub(crate) planes: [(V3, f64); 6],
    pub(crate) count: usize,
}

impl Halfspaces {
    fn new(planes: &[(V3, f64)]) -> Self {
        let mut out = Self {
            planes: [(V3::zeros(), 0.0); 6],
            count: planes.len().min(6),
        };
        out.planes[..out.count].copy_from_slice(&planes[..out.count]);
        out
    }

    /// Whether the segment `o + t·d`, `t ∈ [t0, t1]`, meets the polytope.
    #[inline]
    pub(crate) fn meets(&self, o: &V3, d: &V3, mut t0: f64, mut t1: f64) -> bool {
        for (n, h) in &self.planes[..self.count] {
            let nd = n.dot(d);
            let gap = h - n.dot(o);
            if nd > 0.0 {
                t1 = t1.min(gap / nd);
            } else if nd < 0.0 {
                t0 = t0.max(gap / nd);
            } else if gap < 0.0 {
                return false;
            }
            if t0 > t1 {
                return false;
            }
        }
        true
    }
}

/// Margin added to the culling planes: relative to the element's size, plus a floor.
fn margin(spheres: &[Sphere]) -> (f64, f64) {
    let r_max = spheres.iter().map(|s| s.radius).fold(0.0, f64::max);
    let scale = spheres
        .iter()
        .map(|s| s.center.amax() + s.radius)
        .fold(1.0, f64::max);
    (r_max, 1e-9 * scale)
}

/// The support function `max_i (n·cᵢ + rᵢ)` of the convex hull of `spheres` in the unit
/// direction `n`, plus `eps`: the tightest half-space of normal `n` that holds the element.
fn support(spheres: &[Sphere], n: &V3, eps: f64) -> (V3, f64) {
    let h = spheres
        .iter()
        .map(|s| n.dot(&s.center) + s.radius)
        .fold(f64::NEG_INFINITY, f64::max);
    (*n, h + eps)
}

/// The oriented box around a pill: along the axis from `a` to `b`, each end sphere's own
/// radius beyond its center (the support planes), `r_max` around the axis.
fn pill_hull(a: &Sphere, b: &Sphere) -> Halfspaces {
    let (r, eps) = margin(&[*a, *b]);
    let e = b.center - a.center;
    let axis = if e.norm() > 0.0 {
        e.normalize()
    } else {
        V3::x()
    };
    let u = any_perpendicular(&axis);
    let v = axis.cross(&u);
    Halfspaces::new(&[
        support(&[*a, *b], &axis, eps),
        support(&[*a, *b], &-axis, eps),
        (u, u.dot(&a.center) + r + eps),
        (-u, -u.dot(&a.center) + r + eps),
        (v, v.dot(&a.center) + r + eps),
        (-v, -v.dot(&a.center) + r + eps),
    ])
}

/// The triangular prism around a wedge: the two tangent planes (the plane of centers ± `r_max`
/// where they do not exist), and the support plane of each edge's in-plane outward normal.
/// Empty (no culling) for degenerate triangles.
fn wedge_hull(a: &Sphere, b: &Sphere, c: &Sphere, faces: &Option<[Face; 2]>) -> Halfspaces {
    let (r, eps) = margin(&[*a, *b, *c]);
    let m = (b.center - a.center).cross(&(c.center - a.center));
    let scale = (b.center - a.center)
        .norm_squared()
        .max((c.center - a.center).norm_squared());
    if m.norm_squared() <= 1e-12 * scale * scale || scale == 0.0 {
        return Halfspaces::new(&[]);
    }
    let m = m.normalize();
    let mut planes = match faces {
        Some([f, g]) => [
            (f.normal, f.offset + eps),
            (g.normal, g.offset + eps),
            (m, 0.0),
            (m, 0.0),
            (m, 0.0),
        ],
        None => [
            (m, m.dot(&a.center) + r + eps),
            (-m, -m.dot(&a.center) + r + eps),
            (m, 0.0),
            (m, 0.0),
            (m, 0.0),
        ],
    };
    for (k, (p, q, other)) in [(a, b, c), (b, c, a), (c, a, b)].into_iter().enumerate() {
        let mut n = (q.center - p.center).cross(&m).normalize();
        if n.dot(&(other.center - p.center)) > 0.0 {
            n = -n;
        }
        planes[2 + k] = support(&[*a, *b, *c], &n, eps);
    }
    Halfspaces::new(&planes)
}

fn sphere_ok(s: &Sphere) -> bool {
    s.center.iter().all(|x| x.is_finite()) && s.radius.is_finite() && s.radius >= 0.0
}

impl PreparedElement {
    /// Prepare element `element` (Fig. 3.3 decomposition) whose sphere indices refer to `spheres` (e.g. the posed spheres
    /// of a [`PosedSphereMesh`](crate::spheremesh::PosedSphereMesh)).
    ///
    /// `None` when an index is out of range, or a sphere is non-finite or has a negative radius.
    pub fn new(spheres: &[Sphere], element: &Element) -> Option<Self> {
        match *element {
            Element::Pill([a, b]) => Self::pill(spheres.get(a as usize)?, spheres.get(b as usize)?),
            Element::Wedge([a, b, c]) => Self::wedge(
                spheres.get(a as usize)?,
                spheres.get(b as usize)?,
                spheres.get(c as usize)?,
            ),
        }
    }

    /// A pill: the convex hull of two spheres (Eq. 3.1, Fig. 3.3; `None` for non-finite input or negative radii).
    pub fn pill(a: &Sphere, b: &Sphere) -> Option<Self> {
        if !(sphere_ok(a) && sphere_ok(b)) {
            return None;
        }
        let spheres = [*a, *b, *b];
        Some(Self {
            spheres,
            count: 2,
            cones: [Cone::new(a, b), None, None],
            faces: None,
            radius_plane: [a.radius, b.radius - a.radius, 0.0],
            bounds: bounding_sphere(&spheres[..2]),
            hull: pill_hull(a, b),
        })
    }

    /// A wedge: the convex hull of three spheres (Eq. 3.1, Fig. 3.3; `None` for non-finite input or negative radii).
    pub fn wedge(a: &Sphere, b: &Sphere, c: &Sphere) -> Option<Self> {
        if !(sphere_ok(a) && sphere_ok(b) && sphere_ok(c)) {
            return None;
        }
        let spheres = [*a, *b, *c];
        let faces = tangent_faces(a, b, c);
        Some(Self {
            spheres,
            count: 3,
            cones: [Cone::new(a, b), Cone::new(b, c), Cone::new(c, a)],
            faces,
            radius_plane: [a.radius, b.radius - a.radius, c.radius - a.radius],
            bounds: bounding_sphere(&spheres),
            hull: wedge_hull(a, b, c, &faces),
        })
    }

    /// The spheres of the element (2 for a pill, 3 for a wedge; Fig. 3.3).
    pub fn spheres(&self) -> &[Sphere] {
        &self.spheres[..self.count]
    }

    /// A sphere enclosing the element (used for culling rays and screen tiles, §3.3.2).
    pub fn bounds(&self) -> Sphere {
        self.bounds
    }

    /// The axis-aligned box `[min, max]` of the element (the box of its spheres' boxes), used by
    /// the mesher (§3.3.2 / Fig. 3.4).
    pub fn aabb(&self) -> [Vector3<f64>; 2] {
        let mut lo = V3::repeat(f64::INFINITY);
        let mut hi = V3::repeat(f64::NEG_INFINITY);
        for s in self.spheres() {
            lo = lo.inf(&(s.center - V3::repeat(s.radius)));
            hi = hi.sup(&(s.center + V3::repeat(s.radius)));
        }
        [lo, hi]
    }

    /// Whether the element has planar parts (a wedge whose tangent planes exist, Fig. 3.3).
    pub fn has_planar_faces(&self) -> bool {
        self.faces.is_some()
    }

    /// The implicit function `φ_e(p) = min_λ ‖p − c(λ)‖ − r(λ)` of the element (Eq. 3.6): the
    /// distance to the surface outside, negative inside. Render-local helper: the closest-point
    /// queries of the trackers live elsewhere.
    pub(crate) fn phi(&self, p: &V3) -> f64 {
        let mut best = f64::INFINITY;
        for s in self.spheres() {
            best = best.min((p - s.center).norm() - s.radius);
        }
        for cone in self.cones.iter().flatten() {
            best = best.min(cone.interior_phi(p));
        }
        if let Some(faces) = &self.faces {
            let c1 = self.spheres[0].center;
            for f in faces {
                let q = f.skew(&c1, p);
                if q.x >= 0.0 && in_triangle(&q) {
                    let r = self.radius_plane[0]
                        + q.y * self.radius_plane[1]
                        + q.z * self.radius_plane[2];
                    best = best.min(q.x - r);
                }
            }
        }
        best
    }

    /// Bounding sphere of the element with these spheres (what [`PreparedElement::bounds`] gives),
    /// without preparing it.
    pub(crate) fn bounds_of(spheres: &[Sphere]) -> Sphere {
        bounding_sphere(spheres)
    }

    /// Whether `p` lies strictly inside the element (`φ_e(p) < 0`, Eq. 3.6).
    pub fn contains(&self, p: &Vector3<f64>) -> bool {
        let b = &self.bounds;
        if (p - b.center).norm_squared() > b.radius * b.radius {
            return false;
        }
        self.phi(p) < 0.0
    }
}

/// An enclosing sphere: centered at the mean of the centers, just large enough for every sphere
/// (with a relative margin of 1e-9 so that culling never rejects a grazing hit).
fn bounding_sphere(spheres: &[Sphere]) -> Sphere {
    let mut m = V3::zeros();
    for s in spheres {
        m += s.center;
    }
    m /= spheres.len() as f64;
    let r = spheres
        .iter()
        .map(|s| (s.center - m).norm() + s.radius)
        .fold(0.0, f64::max);
    Sphere::new(m, r * (1.0 + 1e-9) + 1e-9)
}

/// The two planes tangent to three spheres, on either side of the plane of centers.
///
/// An outward unit normal `n` satisfies `n·cᵢ + rᵢ = h` for all three spheres, i.e.
/// `n·(cᵢ − c₁) = r₁ − rᵢ`: its in-plane part `n₀` solves a 2×2 Gram system and
/// `n = n₀ ± √(1 − ‖n₀‖²)·m̂` with `m̂` the unit normal of the triangle of centers. No plane
/// exists for (nearly) collinear centers or when `‖n₀‖ ≥ 1` (one sphere dominates).
fn tangent_faces(a: &Sphere, b: &Sphere, c: &Sphere) -> Option<[Face; 2]> {
    let e2 = b.center - a.center;
    let e3 = c.center - a.center;
    let (g00, g01, g11) = (e2.dot(&e2), e2.dot(&e3), e3.dot(&e3));
    let det = g00 * g11 - g01 * g01;
    if det.is_nan() || det <= 1e-10 * g00 * g11 {
        return None;
    }
    let (k2, k3) = (a.radius - b.radius, a.radius - c.radius);
    let alpha = (g11 * k2 - g01 * k3) / det;
    let beta = (g00 * k3 - g01 * k2) / det;
    let n0 = e2 * alpha + e3 * beta;
    let h2 = 1.0 - n0.norm_squared();
    if h2.is_nan() || h2 <= 1e-10 {
        return None;
    }
    let m = e2.cross(&e3).normalize();
    let mut faces = [None, None];
    for (k, sign) in [1.0, -1.0].into_iter().enumerate() {
        let n = (n0 + m * (sign * h2.sqrt())).normalize();
        let inv = Matrix3::from_columns(&[n, e2, e3]).try_inverse()?;
        faces[k] = Some(Face {
            normal: n,
            offset: n.dot(&a.center) + a.radius,
            inv,
        });
    }
    Some([faces[0]?, faces[1]?])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::testutil::{point_in_cube, rng, skeleton_samples};
    use rand::Rng;

    #[test]
    fn culling_volumes_contain_the_element() {
        let mut rng = rng(11);
        for k in 0..200 {
            let mut spheres = [Sphere::new(V3::zeros(), 0.0); 3];
            for s in &mut spheres {
                *s = Sphere::new(
                    point_in_cube(&mut rng, &V3::new(0.0, 0.0, 300.0), 40.0),
                    rng.random_range(0.0..20.0),
                );
            }
            if k % 10 == 0 {
                spheres[2].center = (spheres[0].center + spheres[1].center) * 0.5;
                // collinear
            }
            let element = if k % 2 == 0 {
                Element::Pill([0, 1])
            } else {
                Element::Wedge([0, 1, 2])
            };
            let p = PreparedElement::new(&spheres, &element).unwrap();
            let b = p.bounds();
            let [lo, hi] = p.aabb();
            for s in skeleton_samples(&spheres, &element, 1.0) {
                assert!((s.center - b.center).norm() + s.radius <= b.radius);
                for (n, h) in &p.hull.planes[..p.hull.count] {
                    assert!(
                        n.dot(&s.center) + s.radius <= *h + 1e-9,
                        "{element:?} {spheres:?}"
                    );
                }
                assert!((s.center - V3::repeat(s.radius) - lo).min() >= -1e-9);
                assert!((hi - s.center - V3::repeat(s.radius)).min() >= -1e-9);
            }
        }
    }
}
