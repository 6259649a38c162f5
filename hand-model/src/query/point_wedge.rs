//! Closest point on a wedge, the convex hull of three spheres (Fig. 3.7 right, §3.3.1 "Wedge
//! correspondences"): spherical, conical and planar parts.
//!
//! As for pills, the hull is the union of interpolated balls, so the signed distance is the
//! minimum over the triangle's barycentric coordinates `λ` of the convex function
//! `f(λ) = ‖p − c(λ)‖ − r(λ)`. In the triangle plane the radius is affine, `r(x) = r₀ + g·(x − c₀)`
//! with `g` the in-plane radius gradient. An interior stationary point needs a unit `n` with
//! in-plane part `−g`, i.e. one of the two tangent-plane normals `n± = −g ± h m` (`m` the
//! triangle normal, `h = √(1 − ‖g‖²)`), which exist iff `‖g‖ < 1`. The stationary point is then
//! the *skewed* projection `s = p − μ n` of `p` along the normal of the plane on `p`'s side of
//! the triangle. If `s` is inside the triangle the footpoint is on that tangent plane; otherwise
//! the constrained minimum lies on an edge whose opposite barycentric coordinate is negative
//! (convexity: at the constrained minimum some active constraint must be violated by the
//! unconstrained one), so only those one or two edge pills are evaluated. Without tangent planes
//! (a swallowed sphere, collinear centers) the minimum is on one of the three edge pills.

use super::point_pill::{valid_sphere, PillFrame};
use super::{combine, is_usable, Part, Projection};
use crate::shape::Sphere;
use nalgebra::Vector3;

/// Triangles whose `‖e₁ × e₂‖` is below this fraction of `‖e₁‖‖e₂‖` are treated as collinear:
/// the plane normal would be noise.
const MIN_SINE: f64 = 1e-10;
/// Below this `h` the tangent planes are tangent to the radius cone to machine precision and
/// the planar part has no extent.
const MIN_PLANE_COSINE: f64 = 1e-9;

/// Edge `i` of a wedge is the one opposite vertex `i`.
pub(crate) const EDGE_VERTICES: [[usize; 2]; 3] = [[1, 2], [2, 0], [0, 1]];

/// The two planes tangent to all three spheres of a wedge, cached per pose ("tangent planes are
/// expensive: compute them once", cf. hmodel's `compute_tangent_point`).
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct TangentPlanes {
    /// Unit normal `m` of the center triangle (c₀, c₁, c₂), right-handed.
    pub(crate) m: Vector3<f64>,
    /// In-plane radius gradient `g`, `‖g‖ < 1`.
    pub(crate) gradient: Vector3<f64>,
    /// `h = √(1 − ‖g‖²) = |m·n±|`.
    pub(crate) cosine: f64,
    /// `1/h`, the skewed travel per unit of distance from the center plane.
    pub(crate) inv_cosine: f64,
    /// Outward unit normals: `[n₊, n₋] = [−g + h m, −g − h m]`.
    pub(crate) normals: [Vector3<f64>; 2],
    /// Dual basis of the edges `e₁ = c₁ − c₀`, `e₂ = c₂ − c₀` in the plane: `λᵢ(x) = bᵢ·(x − c₀)`.
    pub(crate) dual: [Vector3<f64>; 2],
    /// `bᵢ·n±` (equal for both normals since `bᵢ ⟂ m`): how `λᵢ` moves per unit of skewed travel.
    pub(crate) dual_dot_normal: [f64; 2],
}

/// Per-pose data of one wedge.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct WedgeFrame {
    pub(crate) centers: [Vector3<f64>; 3],
    pub(crate) radii: [f64; 3],
    pub(crate) planes: Option<TangentPlanes>,
    /// Edge pills, edge `i` opposite vertex `i` (see [`EDGE_VERTICES`]).
    pub(crate) edges: [PillFrame; 3],
    /// The wedge lies in the slab `|m·(x − c₀)| ≤ max rᵢ` around its center triangle (normal
    /// `m`); `None` for degenerate triangles. A cheap lower bound that culls wedges the
    /// bounding-ball test lets through (points above or below a flat palm wedge).
    pub(crate) slab: Option<Slab>,
}

/// A slab `|m·x − offset| ≤ half_width` containing a wedge.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct Slab {
    pub(crate) m: Vector3<f64>,
    pub(crate) offset: f64,
    pub(crate) half_width: f64,
}

/// Barycentric coordinates and skewed travel of a point's planar candidate.
#[derive(Copy, Clone, Debug)]
pub(crate) struct PlanarFoot {
    pub(crate) lambda: [f64; 3],
    /// Signed travel `μ` along the plane normal: `s = p − μ n`.
    pub(crate) mu: f64,
    /// Which plane (0: `n₊`, 1: `n₋`).
    pub(crate) side: usize,
}

impl PlanarFoot {
    #[inline]
    pub(crate) fn inside(&self) -> bool {
        self.lambda[0] >= 0.0 && self.lambda[1] >= 0.0 && self.lambda[2] >= 0.0
    }
}

impl WedgeFrame {
    /// Computes the tangent planes and edge pills of `conv(a, b, c)` (finite input assumed).
    pub(crate) fn new(s: [&Sphere; 3]) -> Self {
        let centers = [s[0].center, s[1].center, s[2].center];
        let radii = [s[0].radius, s[1].radius, s[2].radius];
        let edges = EDGE_VERTICES.map(|[i, j]| PillFrame::new(s[i], s[j]));
        let e1 = centers[1] - centers[0];
        let e2 = centers[2] - centers[0];
        let cross = e1.cross(&e2);
        let area2 = cross.norm();
        let (l1, l2) = (e1.norm(), e2.norm());
        let mut planes = None;
        let mut slab = None;
        if area2 > MIN_SINE * l1 * l2 && area2 > 0.0 {
            let m = cross / area2;
            slab = Some(Slab {
                m,
                offset: m.dot(&centers[0]),
                half_width: radii[0].max(radii[1]).max(radii[2]),
            });
            // Dual basis from the Gram matrix G = [e₁·e₁ e₁·e₂; e₁·e₂ e₂·e₂], det G = ‖e₁×e₂‖².
            let (g11, g12, g22) = (e1.dot(&e1), e1.dot(&e2), e2.dot(&e2));
            let det = area2 * area2;
            let b1 = (e1 * g22 - e2 * g12) / det;
            let b2 = (e2 * g11 - e1 * g12) / det;
            let gradient = b1 * (radii[1] - radii[0]) + b2 * (radii[2] - radii[0]);
            let g2 = gradient.norm_squared();
            if g2 < 1.0 {
                let cosine = (1.0 - g2).sqrt();
                if cosine > MIN_PLANE_COSINE {
                    let plus = m * cosine - gradient;
                    let minus = -m * cosine - gradient;
                    planes = Some(TangentPlanes {
                        m,
                        gradient,
                        cosine,
                        inv_cosine: 1.0 / cosine,
                        normals: [plus, minus],
                        dual: [b1, b2],
                        dual_dot_normal: [-b1.dot(&gradient), -b2.dot(&gradient)],
                    });
                }
            }
        }
        Self {
            centers,
            radii,
            planes,
            edges,
            slab,
        }
    }

    /// Skewed projection of `p` along the normal of plane `side` into the center triangle,
    /// `s = p − μ n` (μ may be negative when `p` is on the other side).
    #[inline]
    pub(crate) fn planar_foot(
        tp: &TangentPlanes,
        c0: &Vector3<f64>,
        p: &Vector3<f64>,
        side: usize,
    ) -> PlanarFoot {
        let w = p - c0;
        let delta = tp.m.dot(&w);
        let mu = if side == 0 {
            delta * tp.inv_cosine
        } else {
            -delta * tp.inv_cosine
        };
        let l1 = tp.dual[0].dot(&w) - mu * tp.dual_dot_normal[0];
        let l2 = tp.dual[1].dot(&w) - mu * tp.dual_dot_normal[1];
        PlanarFoot {
            lambda: [1.0 - l1 - l2, l1, l2],
            mu,
            side,
        }
    }

    /// The plane on `p`'s side of the triangle (the only one whose skewed travel is ≥ 0).
    #[inline]
    fn own_side(tp: &TangentPlanes, c0: &Vector3<f64>, p: &Vector3<f64>) -> usize {
        if tp.m.dot(&(p - c0)) >= 0.0 {
            0
        } else {
            1
        }
    }

    #[inline]
    pub(crate) fn planar_radius(&self, lambda: &[f64; 3]) -> f64 {
        self.radii[0] * lambda[0] + self.radii[1] * lambda[1] + self.radii[2] * lambda[2]
    }

    /// [`distance`](Self::distance) when it is not above `best`; otherwise some value `> best`
    /// (the slab bound), without evaluating the wedge.
    #[inline]
    pub(crate) fn distance_below(&self, p: &Vector3<f64>, best: f64) -> f64 {
        if let Some(slab) = &self.slab {
            let bound = (slab.m.dot(p) - slab.offset).abs() - slab.half_width;
            if bound > best {
                return bound;
            }
        }
        self.distance(p)
    }

    /// Signed distance from `p` to the wedge surface (negative inside), without the footpoint.
    #[inline]
    pub(crate) fn distance(&self, p: &Vector3<f64>) -> f64 {
        if let Some(tp) = &self.planes {
            let side = Self::own_side(tp, &self.centers[0], p);
            let foot = Self::planar_foot(tp, &self.centers[0], p, side);
            if foot.inside() {
                return foot.mu - self.planar_radius(&foot.lambda);
            }
            let mut best = f64::INFINITY;
            for (edge, l) in self.edges.iter().zip(foot.lambda) {
                if l < 0.0 {
                    best = best.min(edge.distance(p));
                }
            }
            best
        } else {
            self.edges
                .iter()
                .fold(f64::INFINITY, |best, e| best.min(e.distance(p)))
        }
    }

    /// Full closest-point projection; sphere indices are local (0, 1, 2).
    #[inline]
    pub(crate) fn project(&self, p: &Vector3<f64>) -> Projection {
        if let Some(tp) = &self.planes {
            let side = Self::own_side(tp, &self.centers[0], p);
            let foot = Self::planar_foot(tp, &self.centers[0], p, side);
            if foot.inside() {
                return self.plane_projection(tp, &foot);
            }
            let mut best: Option<Projection> = None;
            for (i, l) in foot.lambda.iter().enumerate() {
                if *l < 0.0 {
                    best = Some(self.better(best, i, p));
                }
            }
            // Some λ is negative whenever the foot is outside, so `best` is set; the fallback
            // only guards against a NaN λ from non-finite input.
            match best {
                Some(b) => b,
                None => self.project_on_edges(p),
            }
        } else {
            self.project_on_edges(p)
        }
    }

    /// The footpoint on tangent plane `foot.side` for a foot inside the triangle.
    #[inline]
    pub(crate) fn plane_projection(&self, tp: &TangentPlanes, foot: &PlanarFoot) -> Projection {
        let normal = tp.normals[foot.side];
        let (s, radius, q) = combine(
            [&self.centers[0], &self.centers[1], &self.centers[2]],
            self.radii,
            foot.lambda,
            &normal,
        );
        Projection {
            point: q,
            normal,
            skeleton_point: s,
            element: 0,
            spheres: [0, 1, 2],
            weights: foot.lambda,
            distance: foot.mu - radius,
            part: Part::Plane,
        }
    }

    fn project_on_edges(&self, p: &Vector3<f64>) -> Projection {
        let mut best = self.edge_projection(0, p);
        for i in 1..3 {
            best = self.better(Some(best), i, p);
        }
        best
    }

    #[inline]
    fn better(&self, current: Option<Projection>, edge: usize, p: &Vector3<f64>) -> Projection {
        let candidate = self.edge_projection(edge, p);
        match current {
            Some(c) if c.distance <= candidate.distance => c,
            _ => candidate,
        }
    }

    /// Projection on edge pill `edge`, re-expressed over the wedge's local sphere indices.
    #[inline]
    pub(crate) fn edge_projection(&self, edge: usize, p: &Vector3<f64>) -> Projection {
        let [i, j] = EDGE_VERTICES[edge];
        let mut pr = self.edges[edge].project(p);
        let [wi, wj, _] = pr.weights;
        pr.spheres = [i as u32, j as u32, i as u32];
        pr.weights = [wi, wj, 0.0];
        pr
    }
}

/// Closest-point projection of `p` on the wedge `conv(s[0], s[1], s[2])` (thesis §3.3.1 "Wedge
/// correspondences", Fig. 3.7 right): skewed projection along the tangent-plane normal into the
/// center triangle, else the closest edge pill.
///
/// Sphere indices in the result are local (0, 1, 2 = argument order). Builds the tangent planes
/// on every call; for repeated queries use [`super::SphereMeshGeometry`], which caches them per
/// pose. Returns `None` when `p` or a sphere is not finite or a radius is negative.
pub fn project_point_wedge(p: &Vector3<f64>, s: [&Sphere; 3]) -> Option<Projection> {
    if !is_usable(p) || !s.iter().all(|x| valid_sphere(x)) {
        return None;
    }
    Some(WedgeFrame::new(s).project(p))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere(x: f64, y: f64, z: f64, r: f64) -> Sphere {
        Sphere::new(Vector3::new(x, y, z), r)
    }

    #[test]
    fn equal_radii_plane_is_an_offset_of_the_triangle() {
        let s = [
            sphere(0.0, 0.0, 0.0, 2.0),
            sphere(10.0, 0.0, 0.0, 2.0),
            sphere(0.0, 10.0, 0.0, 2.0),
        ];
        let pr = project_point_wedge(&Vector3::new(2.0, 3.0, 7.0), [&s[0], &s[1], &s[2]]).unwrap();
        assert_eq!(pr.part, Part::Plane);
        assert!((pr.point - Vector3::new(2.0, 3.0, 2.0)).norm() < 1e-12);
        assert!((pr.distance - 5.0).abs() < 1e-12);
        let pr = project_point_wedge(&Vector3::new(2.0, 3.0, -7.0), [&s[0], &s[1], &s[2]]).unwrap();
        assert!((pr.point - Vector3::new(2.0, 3.0, -2.0)).norm() < 1e-12);
        assert!((pr.normal - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-12);
    }

    #[test]
    fn tangent_planes_touch_all_three_spheres() {
        let s = [
            sphere(0.0, 0.0, 0.0, 4.0),
            sphere(20.0, 1.0, 2.0, 2.0),
            sphere(3.0, 15.0, -1.0, 3.0),
        ];
        let frame = WedgeFrame::new([&s[0], &s[1], &s[2]]);
        let tp = frame.planes.unwrap();
        for n in tp.normals {
            assert!((n.norm() - 1.0).abs() < 1e-12);
            let offset = n.dot(&s[0].center) + s[0].radius;
            for x in &s {
                assert!((n.dot(&x.center) + x.radius - offset).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn outside_the_triangle_falls_back_to_an_edge() {
        let s = [
            sphere(0.0, 0.0, 0.0, 2.0),
            sphere(10.0, 0.0, 0.0, 2.0),
            sphere(0.0, 10.0, 0.0, 2.0),
        ];
        let pr = project_point_wedge(&Vector3::new(5.0, -6.0, 0.0), [&s[0], &s[1], &s[2]]).unwrap();
        assert_eq!(pr.part, Part::Cone);
        assert_eq!(pr.spheres, [0, 1, 0]);
        assert!((pr.point - Vector3::new(5.0, -2.0, 0.0)).norm() < 1e-12);
    }
}
