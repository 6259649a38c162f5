//! Closest-point and front-facing queries on the cylinder model (thesis §2.3.1).
//!
//! The 3D fitting term (Eq. 2.2) needs, for every sensor point `x`, its correspondence
//! `y = Π_M(x, θ)` on the model. §2.3.1 "3D correspondences" defines `y` as the closest point on
//! the *front-facing* part of the model: the closest point `x_C` on every cylinder is computed in
//! closed form; if its normal faces away from the camera (`nᵀv ≥ 0`, `v` the viewing ray from the
//! camera to the point), `x` is instead projected onto the cylinder's silhouette contour, whose
//! normals are orthogonal to `v`; the closest cylinder wins.
//!
//! The queries follow parry's layout: a shape in its local frame ([`Segment`] in its bone frame:
//! [`Segment::project_local_point`]), the same with a pose ([`Segment::project_point`],
//! [`Segment::project_point_front_facing`]), and model-wide queries on a posed model
//! ([`CylinderModel::closest_point`], [`CylinderModel::front_facing_point`], and the
//! allocation-free batch [`CylinderModel::project_points`]).
//!
//! # The elliptical section: htrack's approximation
//! Only the palm is elliptical. As in htrack (`cudax/functors/ClosestPoint.h`,
//! `cylinder_distance`; ANCHOR-FACTS §3 and §5.3) the query point's local x coordinate is
//! multiplied by `ratio = ry(t)/r(t)`, taken at the axial parameter `t` of the query point's
//! projection on the axis. In that scaled space the segment is the circular tapered capsule with
//! radius profile `ry(t)`; the point is projected on it and the foot point is scaled back. This is
//! **htrack's approximation of the elliptic closest point**: the foot point lies exactly on the
//! segment's surface, but it is not in general the closest surface point of an elliptical
//! section (it is exact for circular segments). Differences from htrack, all of which vanish on
//! circular, untapered segments:
//! - in the scaled space the point is projected exactly on the tapered capsule (in the meridian
//!   half-plane, onto the two end arcs and the cone line); htrack projects on the axis and pushes
//!   out by the interpolated radius, which is not the closest point of a tapered cone;
//! - the foot point is scaled back with the ratio at its own axial parameter (htrack reuses the
//!   query's ratio), so it always lies on the surface; for circular segments and for the palm of
//!   both default models (constant thickness) the two coincide;
//! - the returned normal is the exact outward normal of the surface at the foot point (htrack
//!   scales the normal of the circular space back, which ignores the taper of the palm's width);
//!   at the creases where a cap meets a tapered cone it is the direction from the foot point to
//!   the query point (outward), a valid normal of the crease;
//! - segments compete by signed surface distance (htrack compared axis distances for circular
//!   segments and surface distances for elliptical ones).
//!
//! # Silhouette contour
//! htrack builds three candidate rim points for a back-facing foot point: the query projected on
//! a plane through the start sphere, one through the end sphere, and one through the axis
//! orthogonal to the view, each pushed out to the radius. Here the candidates are the exact
//! contour generators of the (scaled) capsule for the given view: the contour circle of each cap
//! sphere restricted to its half (for an orthographic view the great circle orthogonal to `v`;
//! for a perspective camera the circle of tangency of the cone of rays), and the two generator
//! lines of the cone whose tangent planes contain the viewing rays. The query is projected on
//! each and the closest candidate is kept, so every substituted normal is orthogonal to the
//! viewing ray. Caps are handled in their own circular space (exact); on a side whose scaling
//! ratio varies along the axis (the palm, whose width tapers but whose thickness does not), the
//! generator point is then moved around its cross-section ring by a few Newton steps onto the
//! exact contour `n·v = 0`, and dropped when that ring has no contour point.
//!
//! # Culling
//! The model-wide queries compute, once per pose (once per batch in
//! [`CylinderModel::project_points`]), each segment's frame and a bounding capsule (its axis,
//! radius the largest half-axis). Per query the segment with the nearest capsule is projected
//! first; any other is skipped when the query lies outside its capsule by more than the best
//! distance found (and, front-facing, when on a circular segment the exact closest distance
//! already exceeds it). Such a segment cannot win, so the result equals the plain scan over all
//! segments ([`CylinderModel::closest_point_brute_force`],
//! [`CylinderModel::front_facing_point_brute_force`]); ties go to the lower segment index.
//!
//! # Non-finite input
//! Queries with a non-finite point, or whose result would not be finite, return `None`; nothing
//! here panics on finite input.

use nalgebra::Vector3;

use super::model::{CylinderModel, Segment};
use crate::error::{ModelError, Result};
use crate::kinematics::PosedSkeleton;
use crate::math::Rigid3;

/// "No seed" in [`CylinderModel::project_points_seeded`].
pub const NO_SEED: u16 = u16::MAX;

/// The camera model of the front-facing test (thesis §2.3.1).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum View {
    /// The thesis' simplified orthographic camera: every viewing ray is `v = (0, 0, 1)` in the
    /// camera frame (htrack's choice, "for efficiency reasons").
    Orthographic,
    /// A pinhole camera at the origin of the camera frame: the viewing ray at a point `q` is
    /// `v = q / ‖q‖` (from the camera to the point).
    Perspective,
}

/// The part of a segment that holds a foot point.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum CylinderPart {
    /// The cap around the segment start (the bone origin).
    StartCap,
    /// The tapered elliptical cylinder between the two caps.
    Side,
    /// The cap around the segment end.
    EndCap,
    /// A point of the silhouette contour substituted for a back-facing foot point by the
    /// front-facing rule (§2.3.1); its normal is orthogonal to the viewing ray.
    Silhouette,
}

/// A correspondence `y = Π_M(x)` on the cylinder model (Eq. 2.2), with what a tracker needs to
/// differentiate it: the point is rigidly attached to `bone`, so its skeleton Jacobian is
/// [`PosedSkeleton::column`] for the DOFs of that bone's chain.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct CylinderProjection {
    /// The foot point `q` on the surface.
    pub point: Vector3<f64>,
    /// Outward unit normal `n` of the surface at `q`.
    pub normal: Vector3<f64>,
    /// Index of the segment (into [`CylinderModel::segments`]); 0 for single-segment queries.
    pub segment: usize,
    /// The bone that carries the segment.
    pub bone: usize,
    /// Signed distance: `‖x − q‖`, negative when `x` is inside the segment.
    pub distance: f64,
    /// Which part of the segment holds `q`.
    pub part: CylinderPart,
}

/// A foot point in segment terms, from which the local point and the exact normal follow.
#[derive(Copy, Clone, Debug)]
enum Foot {
    /// On the start cap; `d` is a unit direction in the cap's circular space (x scaled by the
    /// start ratio).
    Start { d: Vector3<f64> },
    /// On the side at axial parameter `t` and azimuth `(ux, uz)` of the circular space.
    Side { t: f64, ux: f64, uz: f64 },
    /// On the end cap, as for `Start`.
    End { d: Vector3<f64> },
}

/// A result in the bone frame.
#[derive(Copy, Clone, Debug)]
struct Local {
    q: Vector3<f64>,
    n: Vector3<f64>,
    dist: f64,
    part: CylinderPart,
}

/// The viewing geometry in a bone frame.
#[derive(Copy, Clone, Debug)]
enum LocalView {
    /// Orthographic ray direction (camera → scene).
    Dir(Vector3<f64>),
    /// Camera center.
    Eye(Vector3<f64>),
}

impl LocalView {
    fn new(view: View, frame: &Rigid3) -> Self {
        let rt = frame.rotation.transpose();
        match view {
            View::Orthographic => LocalView::Dir(rt * Vector3::z()),
            View::Perspective => LocalView::Eye(-(rt * frame.translation)),
        }
    }

    /// The viewing ray (not normalized) at a local point.
    fn ray(&self, q: &Vector3<f64>) -> Vector3<f64> {
        match self {
            LocalView::Dir(w) => *w,
            LocalView::Eye(o) => q - o,
        }
    }
}

/// `√(a² + b²)` by one square root (libm's `hypot` costs several times more); falls back to
/// `hypot` when the squares overflow, so huge finite input keeps its finite result.
#[inline]
fn hyp(a: f64, b: f64) -> f64 {
    let s = a * a + b * b;
    if s.is_finite() {
        s.sqrt()
    } else {
        a.hypot(b)
    }
}

#[inline]
fn scale_x(v: &Vector3<f64>, k: f64) -> Vector3<f64> {
    Vector3::new(v.x * k, v.y, v.z)
}

#[inline]
fn normalize_or(v: Vector3<f64>, fallback: Vector3<f64>) -> Vector3<f64> {
    let n = v.norm();
    if n > 0.0 && n.is_finite() {
        v / n
    } else {
        fallback
    }
}

/// A unit vector orthogonal to the unit vector `m`.
fn any_orthogonal(m: &Vector3<f64>) -> Vector3<f64> {
    let helper = if m.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    normalize_or(m.cross(&helper), Vector3::z())
}

/// The closest point of the meridian profile, in the circular space.
#[derive(Copy, Clone, Debug)]
enum Foot2 {
    Start(f64, f64),
    Side(f64),
    End(f64, f64),
}

impl Segment {
    /// `ratio(t) = ry(t)/r(t)`, the elliptical-to-circular scaling of local x (1 when the
    /// section is a point).
    #[inline]
    fn ratio(&self, t: f64) -> f64 {
        let (r, ry) = self.radii_at(t);
        if r > 0.0 {
            ry / r
        } else {
            1.0
        }
    }

    /// Axial parameter of the projection of a local point on the axis.
    #[inline]
    fn axial_t(&self, y: f64) -> f64 {
        if self.length > 0.0 {
            (y / self.length).clamp(0.0, 1.0)
        } else {
            0.0
        }
    }

    /// Whether a local point lies strictly inside the segment.
    ///
    /// Exact for elliptical sections: scaling local x by the ratio at the point's own axial
    /// parameter maps the cross-section (or the cap) through the point to a circle (a sphere).
    pub fn contains_local_point(&self, p: &Vector3<f64>) -> bool {
        let k = self.ratio(self.axial_t(p.y));
        let rho = hyp(p.x * k, p.z);
        profile_inside(rho, p.y, self.r1y, self.r2y, self.length)
    }

    fn foot_point(&self, foot: &Foot) -> Vector3<f64> {
        match *foot {
            Foot::Start { d } => Vector3::new(self.r1 * d.x, self.r1y * d.y, self.r1y * d.z),
            Foot::Side { t, ux, uz } => {
                let (r, ry) = self.radii_at(t);
                Vector3::new(r * ux, t * self.length, ry * uz)
            }
            Foot::End { d } => {
                Vector3::new(self.r2 * d.x, self.length + self.r2y * d.y, self.r2y * d.z)
            }
        }
    }

    /// The exact outward unit normal at a foot point (gradient of the implicit surface, scaled
    /// so that no radius divides).
    fn foot_normal(&self, foot: &Foot) -> Vector3<f64> {
        match *foot {
            Foot::Start { d } => normalize_or(
                Vector3::new(self.r1y * d.x, self.r1 * d.y, self.r1 * d.z),
                d,
            ),
            Foot::End { d } => normalize_or(
                Vector3::new(self.r2y * d.x, self.r2 * d.y, self.r2 * d.z),
                d,
            ),
            Foot::Side { t, ux, uz } => {
                let (r, ry) = self.radii_at(t);
                let l = self.length;
                let g = Vector3::new(
                    l * ry * ux,
                    -(ry * (self.r2 - self.r1) * ux * ux + r * (self.r2y - self.r1y) * uz * uz),
                    l * r * uz,
                );
                let n = g.norm();
                if n > 0.0 && n.is_finite() {
                    g / n
                } else {
                    normalize_or(
                        Vector3::new(l * ux, self.r1y - self.r2y, l * uz),
                        Vector3::new(ux, 0.0, uz),
                    )
                }
            }
        }
    }

    fn foot_t(&self, foot: &Foot) -> f64 {
        match foot {
            Foot::Start { .. } => 0.0,
            Foot::Side { t, .. } => *t,
            Foot::End { .. } => 1.0,
        }
    }

    /// Closest point in the bone frame. `hint` (local) chooses the azimuth when the query lies on
    /// the axis, where every azimuth is equally close.
    fn closest_local(&self, p: &Vector3<f64>, hint: Option<Vector3<f64>>) -> Local {
        let l = self.length;
        let (a, b) = (self.r1y, self.r2y);
        let t0 = self.axial_t(p.y);
        let k0 = self.ratio(t0);
        let xs = p.x * k0;
        let rho = hyp(xs, p.z);
        let (ux, uz) = if rho > 0.0 {
            (xs / rho, p.z / rho)
        } else {
            let h = hint.map(|h| (h.x * k0, h.z)).unwrap_or((1.0, 0.0));
            let hn = h.0.hypot(h.1);
            if hn > 0.0 && hn.is_finite() {
                (h.0 / hn, h.1 / hn)
            } else {
                (1.0, 0.0)
            }
        };
        let (foot2, clamped) = profile_closest(rho, p.y, a, b, l);
        let inside = profile_inside(rho, p.y, a, b, l);
        let foot = match foot2 {
            Foot2::Start(dr, dy) => Foot::Start {
                d: Vector3::new(dr * ux, dy, dr * uz),
            },
            Foot2::Side(t) => Foot::Side { t, ux, uz },
            Foot2::End(dr, dy) => Foot::End {
                d: Vector3::new(dr * ux, dy, dr * uz),
            },
        };
        let q = self.foot_point(&foot);
        let diff = p - q;
        let dn = diff.norm();
        let mut n = self.foot_normal(&foot);
        if clamped && a != b && dn > 0.0 {
            // A crease where a cap meets the tapered cone: the outward direction to the query
            // (mapped like a normal from the circular space) is a valid normal there.
            let f = profile_point(&foot2, a, b, l);
            let (pr, py) = (rho - f.0, p.y - f.1);
            let len = pr.hypot(py);
            if len > 0.0 {
                let s = if inside { -1.0 } else { 1.0 };
                let n_circ = Vector3::new(pr * ux, py, pr * uz) * (s / len);
                n = normalize_or(scale_x(&n_circ, self.ratio(self.foot_t(&foot))), n);
            }
        }
        let part = match foot {
            Foot::Start { .. } => CylinderPart::StartCap,
            Foot::Side { .. } => CylinderPart::Side,
            Foot::End { .. } => CylinderPart::EndCap,
        };
        Local {
            q,
            n,
            dist: if inside { -dn } else { dn },
            part,
        }
    }

    /// Front-facing closest point in the bone frame (§2.3.1).
    fn front_facing_local(&self, p: &Vector3<f64>, view: &LocalView) -> Local {
        let base = self.front_facing_base(p, view);
        self.front_facing_from_base(p, view, base)
    }

    /// The closest point that [`Segment::front_facing_local`] starts from (the azimuth on the
    /// axis chosen toward the camera).
    #[inline]
    fn front_facing_base(&self, p: &Vector3<f64>, view: &LocalView) -> Local {
        let toward_camera = match view {
            LocalView::Dir(w) => -w,
            LocalView::Eye(o) => o - p,
        };
        self.closest_local(p, Some(toward_camera))
    }

    /// [`Segment::front_facing_local`] given its base closest point.
    fn front_facing_from_base(&self, p: &Vector3<f64>, view: &LocalView, base: Local) -> Local {
        if base.n.dot(&view.ray(&base.q)) < 0.0 {
            return base;
        }
        let mut best: Option<(f64, Vector3<f64>, Vector3<f64>)> = None;
        let mut consider = |foot: Foot| {
            let q = self.foot_point(&foot);
            let d = (p - q).norm();
            if d.is_finite() && best.is_none_or(|(bd, _, _)| d < bd) {
                best = Some((d, q, self.foot_normal(&foot)));
            }
        };
        let l = self.length;
        if let Some(d) = self.cap_contour(p, view, true) {
            consider(Foot::Start { d });
        }
        if let Some(d) = self.cap_contour(p, view, false) {
            consider(Foot::End { d });
        }
        if l > 0.0 {
            let k0 = self.ratio(self.axial_t(p.y));
            let (a, b) = (self.r1y, self.r2y);
            // Tangency of the cone generator at azimuth u: u·m⊥ = c (see `cone_contour_azimuths`).
            let (perp, c) = match view {
                LocalView::Dir(w) => {
                    let ws = scale_x(w, k0);
                    ((ws.x, ws.z), -(a - b) * ws.y / l)
                }
                LocalView::Eye(o) => {
                    let os = scale_x(o, k0);
                    ((os.x, os.z), a - (a - b) * os.y / l)
                }
            };
            let ps = scale_x(p, k0);
            for (ux, uz) in cone_contour_azimuths(perp, c).into_iter().flatten() {
                let ea = Vector3::new(a * ux, 0.0, a * uz);
                let e = Vector3::new((b - a) * ux, l, (b - a) * uz);
                let t = ((ps - ea).dot(&e) / e.norm_squared()).clamp(0.0, 1.0);
                if let Some(foot) = self.refine_side_contour(t, ux, uz, view) {
                    consider(foot);
                }
            }
        }
        match best {
            Some((d, q, n)) => {
                let inside = self.contains_local_point(p);
                Local {
                    q,
                    n,
                    dist: if inside { -d } else { d },
                    part: CylinderPart::Silhouette,
                }
            }
            None => base,
        }
    }

    /// Move a side point along its cross-section ring (fixed `t`) onto the exact contour,
    /// `n(t, φ)·v(q(t, φ)) = 0`. The generator lines of the circular space are exact for circular
    /// segments; on an elliptical segment whose ratio varies along the axis (the palm, whose
    /// width tapers) they are off by the taper, which a few Newton steps in `φ` remove. `None`
    /// when the ring at `t` has no contour point (a tapered side seen nearly along its axis).
    fn refine_side_contour(&self, t: f64, ux: f64, uz: f64, view: &LocalView) -> Option<Foot> {
        let (r, ry) = self.radii_at(t);
        let l = self.length;
        let (dr, dry) = (self.r2 - self.r1, self.r2y - self.r1y);
        let g_at = |s: f64, c: f64| {
            let n = Vector3::new(l * ry * c, -(ry * dr * c * c + r * dry * s * s), l * r * s);
            let q = Vector3::new(r * c, t * l, ry * s);
            let v = view.ray(&q);
            n.dot(&v) / (n.norm() * v.norm()).max(f64::MIN_POSITIVE)
        };
        let g = |phi: f64| {
            let (s, c) = phi.sin_cos();
            g_at(s, c)
        };
        // Exact generators (circular segments, untapered ratio) need no trigonometry.
        if g_at(uz, ux).abs() <= 1e-12 {
            return Some(Foot::Side { t, ux, uz });
        }
        let phi0 = uz.atan2(ux);
        let g0 = g(phi0);
        if g0.abs() <= 1e-12 {
            return Some(Foot::Side { t, ux, uz });
        }
        let (mut phi, mut gphi) = (phi0, g0);
        for _ in 0..16 {
            if gphi.abs() <= 1e-14 {
                break;
            }
            let h = 1e-6;
            let slope = (g(phi + h) - g(phi - h)) / (2.0 * h);
            if !slope.is_finite() || slope.abs() <= 1e-12 {
                break;
            }
            let next = phi - (gphi / slope).clamp(-0.5, 0.5);
            let gn = g(next);
            if gn.is_nan() || gn.abs() >= gphi.abs() {
                break;
            }
            phi = next;
            gphi = gn;
        }
        if gphi.abs() <= 1e-12 {
            let (s, c) = phi.sin_cos();
            Some(Foot::Side { t, ux: c, uz: s })
        } else {
            None
        }
    }

    /// The point of a cap's contour closest to `p`, as a unit direction from the cap center in
    /// the cap's circular space; `None` when the cap has no contour on its half (camera inside
    /// the sphere, or the contour circle entirely on the other half).
    fn cap_contour(&self, p: &Vector3<f64>, view: &LocalView, start: bool) -> Option<Vector3<f64>> {
        let (k, rho, cy) = if start {
            (self.ratio(0.0), self.r1y, 0.0)
        } else {
            (self.ratio(1.0), self.r2y, self.length)
        };
        let center = Vector3::new(0.0, cy, 0.0);
        let ps = scale_x(p, k) - center;
        // Contour circle: center `cc`, radius `rs`, plane normal `m` (relative to the center).
        let (cc, rs, m) = match view {
            LocalView::Dir(w) => {
                let m = scale_x(w, k);
                let mn = m.norm();
                if mn.is_nan() || mn <= 0.0 {
                    return None;
                }
                (Vector3::zeros(), rho, m / mn)
            }
            LocalView::Eye(o) => {
                let e = scale_x(o, k) - center;
                let dd = e.norm();
                if dd.is_nan() || dd <= rho {
                    return None;
                }
                let f = rho / dd;
                (e * (f * f), rho * (1.0 - f * f).sqrt(), -e / dd)
            }
        };
        let proj = ps - m * (ps - cc).dot(&m);
        let dir = normalize_or(proj - cc, any_orthogonal(&m));
        let cand = cc + dir * rs;
        let tol = 1e-12 * (rho + 1.0);
        let ok = if start { cand.y <= tol } else { cand.y >= -tol };
        let point = if ok {
            cand
        } else {
            // The closest point of the allowed arc is one of its end points (the circle meets the
            // cap's boundary plane there).
            let axis = Vector3::y();
            let e1 = axis - m * axis.dot(&m);
            let sigma = e1.norm();
            if sigma.is_nan() || sigma <= 1e-12 || rs.is_nan() || rs <= 0.0 {
                return None;
            }
            let e1 = e1 / sigma;
            let e2 = m.cross(&e1);
            let kappa = -cc.y / (rs * sigma);
            if !(-1.0..=1.0).contains(&kappa) {
                return None;
            }
            let s = (1.0 - kappa * kappa).sqrt();
            let c1 = cc + (e1 * kappa + e2 * s) * rs;
            let c2 = cc + (e1 * kappa - e2 * s) * rs;
            if (c1 - ps).norm_squared() <= (c2 - ps).norm_squared() {
                c1
            } else {
                c2
            }
        };
        Some(normalize_or(point, dir))
    }

    /// Closest point of the segment surface to a point given in the bone frame, in the bone
    /// frame (segment 0, bone [`Segment::bone`]); `None` for a non-finite point.
    pub fn project_local_point(&self, p: &Vector3<f64>) -> Option<CylinderProjection> {
        if !p.iter().all(|v| v.is_finite()) {
            return None;
        }
        finish(self.closest_local(p, None), self, 0, &Rigid3::identity())
    }

    /// Closest point of the segment surface to a world point when the bone frame is `frame`
    /// (segment 0, bone [`Segment::bone`]); `None` for non-finite input.
    pub fn project_point(&self, frame: &Rigid3, p: &Vector3<f64>) -> Option<CylinderProjection> {
        if !p.iter().all(|v| v.is_finite()) {
            return None;
        }
        let pl = frame.rotation.transpose() * (p - frame.translation);
        finish(self.closest_local(&pl, None), self, 0, frame)
    }

    /// Front-facing closest point (§2.3.1): the closest point, or — when its normal faces away
    /// from the camera (`n·v ≥ 0`) — the closest point of the segment's silhouette contour
    /// (part [`CylinderPart::Silhouette`]). `frame` maps the bone frame to the camera frame.
    pub fn project_point_front_facing(
        &self,
        frame: &Rigid3,
        p: &Vector3<f64>,
        view: View,
    ) -> Option<CylinderProjection> {
        if !p.iter().all(|v| v.is_finite()) {
            return None;
        }
        let pl = frame.rotation.transpose() * (p - frame.translation);
        let lv = LocalView::new(view, frame);
        finish(self.front_facing_local(&pl, &lv), self, 0, frame)
    }
}

/// Map a local result to the world and check it is finite.
fn finish(l: Local, seg: &Segment, index: usize, frame: &Rigid3) -> Option<CylinderProjection> {
    let out = CylinderProjection {
        point: frame.transform_point(&l.q),
        normal: frame.transform_vector(&l.n),
        segment: index,
        bone: seg.bone,
        distance: l.dist,
        part: l.part,
    };
    let finite = out
        .point
        .iter()
        .chain(out.normal.iter())
        .all(|v| v.is_finite())
        && out.distance.is_finite();
    finite.then_some(out)
}

/// Azimuths `u` (unit, in the (x, z) plane) with `u·m = c` for `m = perp`: the generator lines
/// of a cone whose tangent planes contain the viewing rays. With `w` the (scaled) orthographic
/// ray, the cone normal `N ∝ (L·u, a − b)` is orthogonal to it when `u·w⊥ = −(a − b)·w_y / L`;
/// with a camera at `o`, the tangent plane contains `o` when `u·o⊥ = a − (a − b)·o_y / L`.
fn cone_contour_azimuths(perp: (f64, f64), c: f64) -> [Option<(f64, f64)>; 2] {
    let m = perp.0.hypot(perp.1);
    if !m.is_finite() || m <= 1e-12 {
        return [None, None];
    }
    let cg = c / m;
    if !(-1.0..=1.0).contains(&cg) {
        return [None, None];
    }
    let sg = (1.0 - cg * cg).sqrt();
    let (wx, wz) = (perp.0 / m, perp.1 / m);
    let (px, pz) = (-wz, wx);
    [
        Some((cg * wx + sg * px, cg * wz + sg * pz)),
        Some((cg * wx - sg * px, cg * wz - sg * pz)),
    ]
}

/// The point of the meridian profile named by a foot.
fn profile_point(f: &Foot2, a: f64, b: f64, l: f64) -> (f64, f64) {
    match *f {
        Foot2::Start(dr, dy) => (a * dr, a * dy),
        Foot2::Side(t) => (a + t * (b - a), t * l),
        Foot2::End(dr, dy) => (b * dr, l + b * dy),
    }
}

/// Closest point of the meridian profile of a circular capsule (start arc of radius `a` around
/// `(0, 0)`, cone line from `(a, 0)` to `(b, l)`, end arc of radius `b` around `(0, l)`) to the
/// point `(rho ≥ 0, y)`. Returns the foot and whether it was clamped to a rim.
fn profile_closest(rho: f64, y: f64, a: f64, b: f64, l: f64) -> (Foot2, bool) {
    let mut best: Option<(f64, Foot2, bool)> = None;
    let (er, ey) = (b - a, l);
    let len2 = er * er + ey * ey;
    if len2 > 0.0 {
        let raw = ((rho - a) * er + y * ey) / len2;
        let t = raw.clamp(0.0, 1.0);
        let (fr, fy) = (a + t * er, t * ey);
        let d2 = (rho - fr).powi(2) + (y - fy).powi(2);
        best = Some((d2, Foot2::Side(t), raw != t));
    }
    for start in [true, false] {
        let (cy, r) = if start { (0.0, a) } else { (l, b) };
        let dy = y - cy;
        let outside_half = if start { dy > 0.0 } else { dy < 0.0 };
        let (d, clamped) = if outside_half {
            ((1.0, 0.0), true)
        } else {
            let len = hyp(rho, dy);
            if len > 0.0 {
                ((rho / len, dy / len), false)
            } else {
                ((1.0, 0.0), true)
            }
        };
        let d2 = (rho - r * d.0).powi(2) + (dy - r * d.1).powi(2);
        if best.is_none_or(|(bd, _, _)| d2 < bd) {
            let f = if start {
                Foot2::Start(d.0, d.1)
            } else {
                Foot2::End(d.0, d.1)
            };
            best = Some((d2, f, clamped));
        }
    }
    let (_, f, c) = best.unwrap_or((0.0, Foot2::Start(1.0, 0.0), true));
    (f, c)
}

/// Whether `(rho, y)` is strictly inside the circular capsule of [`profile_closest`].
fn profile_inside(rho: f64, y: f64, a: f64, b: f64, l: f64) -> bool {
    if y < 0.0 {
        rho * rho + y * y < a * a
    } else if y > l {
        rho * rho + (y - l) * (y - l) < b * b
    } else {
        let r = if l > 0.0 {
            a + (b - a) * (y / l)
        } else {
            a.max(b)
        };
        rho < r
    }
}

/// Per-pose data of one segment for the model-wide queries: its frame and a bounding capsule
/// (the axis from `start` to `start + axis`, radius `reach`) that contains the whole segment.
#[derive(Copy, Clone, Debug)]
struct PosedSeg {
    /// Index into [`CylinderModel::segments`].
    index: usize,
    /// The bone frame.
    frame: Rigid3,
    /// World start of the axis (the bone origin).
    start: Vector3<f64>,
    /// World axis vector (start → end).
    axis: Vector3<f64>,
    /// `1 / ‖axis‖²`, or 0 for a degenerate axis.
    inv_len2: f64,
    /// The largest half-axis: every surface point is within `reach` of the axis segment.
    reach: f64,
    /// Whether the segment is circular (its closest point is then exact).
    circular: bool,
    /// For elliptical segments, the bone-frame box holding the segment: `|x| ≤ box_max.x`,
    /// `box_min.y ≤ y ≤ box_max.y`, `|z| ≤ box_max.z` (a flat palm is much thinner than its
    /// bounding capsule, whose radius is its half-width).
    box_min_y: f64,
    box_max: Vector3<f64>,
}

/// Slack of the culling tests, far above the rounding of the distances they compare.
#[inline]
fn margin(d: f64) -> f64 {
    1e-9 * (1.0 + d.abs())
}

/// Segments whose per-pose data fits on the stack (more fall back to a heap buffer).
const STACK_SEGMENTS: usize = 32;

impl PosedSeg {
    fn new(seg: &Segment, index: usize, frame: &Rigid3) -> Self {
        let axis = frame.rotation.column(1) * seg.length;
        let len2 = axis.norm_squared();
        PosedSeg {
            index,
            frame: *frame,
            start: frame.translation,
            axis,
            inv_len2: if len2 > 0.0 { 1.0 / len2 } else { 0.0 },
            reach: seg.r1.max(seg.r2).max(seg.r1y).max(seg.r2y),
            circular: seg.is_circular(),
            // Cross-sections have half-axes r(t) ≤ max(r1, r2) along x and ry(t) ≤ max(r1y, r2y)
            // along z; the end caps reach r1y below the start and r2y beyond the end along y.
            box_min_y: -seg.r1y,
            box_max: Vector3::new(
                seg.r1.max(seg.r2),
                seg.length + seg.r2y,
                seg.r1y.max(seg.r2y),
            ),
        }
    }

    /// A lower bound of the distance from `p` to the segment surface when `p` is outside the
    /// bounding capsule (the bound is then positive); ≤ 0 when `p` may be inside the segment.
    /// Elliptical segments also use the distance to their bone-frame box (the larger of two
    /// lower bounds is one).
    #[inline]
    fn lower_bound(&self, p: &Vector3<f64>) -> f64 {
        let d = p - self.start;
        let t = (d.dot(&self.axis) * self.inv_len2).clamp(0.0, 1.0);
        let capsule = (d - self.axis * t).norm() - self.reach;
        if self.circular {
            return capsule;
        }
        let l = self.frame.rotation.transpose() * d;
        let out = Vector3::new(
            (l.x.abs() - self.box_max.x).max(0.0),
            (self.box_min_y - l.y).max(l.y - self.box_max.y).max(0.0),
            (l.z.abs() - self.box_max.z).max(0.0),
        );
        capsule.max(out.norm())
    }

    /// Whether `p` lies outside the bounding capsule by more than `best + margin(best)`, i.e.
    /// `lower_bound(p) > 0` and `lower_bound(p) > best + margin(best)` (then no surface point of
    /// the segment is within `best` of `p`), tested on squared lengths without a square root.
    #[inline]
    fn beyond(&self, p: &Vector3<f64>, best: f64) -> bool {
        let d = p - self.start;
        let t = (d.dot(&self.axis) * self.inv_len2).clamp(0.0, 1.0);
        let r = self.reach + (best + margin(best)).max(0.0);
        (d - self.axis * t).norm_squared() > r * r
    }
}

/// The bounding capsules of up to [`STACK_SEGMENTS`] posed segments in f32 structure-of-arrays
/// form, relative to `origin` (the first segment's start), for a vectorized candidate test.
/// Only a conservative pre-filter: a segment it rejects lies farther than the threshold by more
/// than a slack far above the f32 rounding; survivors are tested again exactly
/// ([`PosedSeg::beyond`]), so results do not change.
#[derive(Clone, Debug)]
struct CapsuleSoa {
    origin: Vector3<f64>,
    /// Sum over the axes of the largest |start| and |end| coordinate (relative to `origin`),
    /// the scale of the rounding.
    extent: f64,
    start: [[f32; STACK_SEGMENTS]; 3],
    axis: [[f32; STACK_SEGMENTS]; 3],
    inv_len2: [f32; STACK_SEGMENTS],
    reach: [f32; STACK_SEGMENTS],
}

impl CapsuleSoa {
    /// `None` for more than [`STACK_SEGMENTS`] segments or an empty list. Unused slots sit far
    /// away and are never candidates.
    fn new(segs: &[PosedSeg]) -> Option<Self> {
        if segs.len() > STACK_SEGMENTS || segs.is_empty() {
            return None;
        }
        let origin = segs[0].start;
        let mut soa = CapsuleSoa {
            origin,
            extent: 0.0,
            start: [[1e18; STACK_SEGMENTS]; 3],
            axis: [[0.0; STACK_SEGMENTS]; 3],
            inv_len2: [0.0; STACK_SEGMENTS],
            reach: [0.0; STACK_SEGMENTS],
        };
        for (j, sg) in segs.iter().enumerate() {
            let rel = sg.start - origin;
            for k in 0..3 {
                soa.start[k][j] = rel[k] as f32;
                soa.axis[k][j] = sg.axis[k] as f32;
            }
            soa.inv_len2[j] = sg.inv_len2 as f32;
            soa.reach[j] = sg.reach as f32;
            soa.extent = soa
                .extent
                .max(rel.abs().sum() + (rel + sg.axis).abs().sum() + sg.reach);
        }
        soa.extent.is_finite().then_some(soa)
    }

    /// Bit `j` set unless `p` lies outside capsule `j` by clearly more than
    /// `best + margin(best)` (so that [`PosedSeg::beyond`] would hold).
    #[inline]
    fn candidates(&self, p: &Vector3<f64>, best: f64) -> u32 {
        let rel = p - self.origin;
        let base = (best + margin(best)).max(0.0);
        // f32 rounding of coordinates, products and squares stays below 1e-6 of this scale.
        let slack = 1e-5 * (1.0 + rel.abs().sum() + self.extent + base);
        let (px, py, pz) = (rel.x as f32, rel.y as f32, rel.z as f32);
        let base = (base + slack) as f32;
        let mut mask = 0u32;
        for j in 0..STACK_SEGMENTS {
            let (dx, dy, dz) = (
                px - self.start[0][j],
                py - self.start[1][j],
                pz - self.start[2][j],
            );
            let (ax, ay, az) = (self.axis[0][j], self.axis[1][j], self.axis[2][j]);
            let t = ((dx * ax + dy * ay + dz * az) * self.inv_len2[j]).clamp(0.0, 1.0);
            let (ex, ey, ez) = (dx - ax * t, dy - ay * t, dz - az * t);
            let d2 = ex * ex + ey * ey + ez * ez;
            let thr = self.reach[j] + base;
            // Only a clear comparison culls: NaN (overflow) keeps the segment.
            let far = d2 > thr * thr;
            mask |= u32::from(!far) << j;
        }
        mask
    }
}

impl CylinderModel {
    /// Frame of segment `i` in `posed`, when both exist.
    fn frame<'a>(
        &'a self,
        posed: &'a PosedSkeleton,
        i: usize,
    ) -> Option<(&'a Segment, &'a Rigid3)> {
        let s = self.segments.get(i)?;
        Some((s, posed.globals.get(s.bone)?))
    }

    /// Run `f` on the per-pose data of every segment whose bone exists in `posed` (in segment
    /// order), without allocating for models of up to [`STACK_SEGMENTS`] segments.
    fn with_posed_segments<R>(&self, posed: &PosedSkeleton, f: impl FnOnce(&[PosedSeg]) -> R) -> R {
        let posed_seg = |(i, s): (usize, &Segment)| {
            posed
                .globals
                .get(s.bone)
                .map(|frame| PosedSeg::new(s, i, frame))
        };
        if self.segments.len() <= STACK_SEGMENTS {
            let empty = PosedSeg::new(&self.segments[0], 0, &Rigid3::identity());
            let mut buf = [empty; STACK_SEGMENTS];
            let mut n = 0;
            for ps in self.segments.iter().enumerate().filter_map(posed_seg) {
                buf[n] = ps;
                n += 1;
            }
            f(&buf[..n])
        } else {
            let v: Vec<PosedSeg> = self
                .segments
                .iter()
                .enumerate()
                .filter_map(posed_seg)
                .collect();
            f(&v)
        }
    }

    /// The model-wide query on precomputed segments: the segment with the smallest signed
    /// distance wins (ties go to the lowest segment index, as in a plain scan). The `seed`
    /// segment (temporal coherence: the winner of the previous iteration), or without one the
    /// segment whose bounding capsule is nearest, is projected first; any other is skipped when
    /// the query lies outside its bounding capsule farther than the best distance found, which
    /// cannot change the result. Falls back to the plain scan in the (overflow) case where the
    /// winner's world result is not finite.
    fn best_of(
        &self,
        segs: &[PosedSeg],
        posed: &PosedSkeleton,
        p: &Vector3<f64>,
        view: Option<View>,
        seed: Option<usize>,
        soa: Option<&CapsuleSoa>,
    ) -> Option<CylinderProjection> {
        // `segs` lists the segments in order, so segment `i` sits at `i` unless a bone is
        // missing from `posed`.
        let seeded = seed.filter(|&i| segs.get(i).is_some_and(|s| s.index == i));
        let mut first = seeded;
        let mut lbs = [0.0; STACK_SEGMENTS];
        if seeded.is_none() {
            let mut min_lb = f64::INFINITY;
            for (j, s) in segs.iter().enumerate() {
                let lb = s.lower_bound(p);
                if let Some(slot) = lbs.get_mut(j) {
                    *slot = lb;
                }
                if lb < min_lb {
                    min_lb = lb;
                    first = Some(j);
                }
            }
        }
        let mut best: Option<(f64, usize, Local)> = None;
        let eval = |s: &PosedSeg, best: &mut Option<(f64, usize, Local)>| {
            let seg = &self.segments[s.index];
            let frame = &s.frame;
            let pl = frame.rotation.transpose() * (p - frame.translation);
            let l = match view {
                Some(v) => {
                    let lv = LocalView::new(v, frame);
                    let base = seg.front_facing_base(&pl, &lv);
                    // On a circular segment the base is the exact closest point, so for a query
                    // outside it no front-facing result (a surface point) is closer.
                    if let Some((bd, _, _)) = *best {
                        if s.circular && base.dist > 0.0 && base.dist > bd + margin(bd) {
                            return;
                        }
                    }
                    seg.front_facing_from_base(&pl, &lv, base)
                }
                None => seg.closest_local(&pl, None),
            };
            let finite = l.dist.is_finite() && l.q.iter().chain(l.n.iter()).all(|v| v.is_finite());
            if finite
                && best.is_none_or(|(bd, bi, _)| l.dist < bd || (l.dist == bd && s.index < bi))
            {
                *best = Some((l.dist, s.index, l));
            }
        };
        if let Some(f) = first {
            eval(&segs[f], &mut best);
        }
        // Seeded, the best distance after the first segment is usually final: pre-filter every
        // other capsule against it at once.
        let mask = match (seeded, soa, best) {
            (Some(_), Some(soa), Some((bd, _, _))) => soa.candidates(p, bd),
            _ => u32::MAX,
        };
        for (j, s) in segs.iter().enumerate() {
            if j < 32 && mask & (1 << j) == 0 {
                continue;
            }
            if Some(j) == first {
                continue;
            }
            if let Some((bd, _, _)) = best {
                let culled = match lbs.get(j) {
                    Some(&lb) if seeded.is_none() => lb > 0.0 && lb > bd + margin(bd),
                    _ => s.beyond(p, bd),
                };
                if culled {
                    continue;
                }
            }
            eval(s, &mut best);
        }
        let (_, index, l) = best?;
        let s = segs.iter().find(|s| s.index == index)?;
        finish(l, &self.segments[index], index, &s.frame).or_else(|| self.scan(posed, p, view))
    }

    /// The plain scan over every segment (the reference of [`CylinderModel::closest_point`]
    /// and [`CylinderModel::front_facing_point`]).
    fn scan(
        &self,
        posed: &PosedSkeleton,
        p: &Vector3<f64>,
        view: Option<View>,
    ) -> Option<CylinderProjection> {
        let mut best: Option<CylinderProjection> = None;
        for i in 0..self.segments.len() {
            let Some((s, frame)) = self.frame(posed, i) else {
                continue;
            };
            let pl = frame.rotation.transpose() * (p - frame.translation);
            let l = match view {
                Some(v) => s.front_facing_local(&pl, &LocalView::new(v, frame)),
                None => s.closest_local(&pl, None),
            };
            if let Some(r) = finish(l, s, i, frame) {
                if best.is_none_or(|b| r.distance < b.distance) {
                    best = Some(r);
                }
            }
        }
        best
    }

    /// The closest point of the model surface to `p` (the projection `Π_M` of Eq. 2.2 without
    /// the front-facing rule): the segment with the smallest signed distance wins.
    /// `posed` must come from this model's skeleton; `None` for a non-finite point.
    pub fn closest_point(
        &self,
        posed: &PosedSkeleton,
        p: &Vector3<f64>,
    ) -> Option<CylinderProjection> {
        if !p.iter().all(|v| v.is_finite()) || self.segments.is_empty() {
            return None;
        }
        self.with_posed_segments(posed, |segs| self.best_of(segs, posed, p, None, None, None))
    }

    /// The closest point computed by projecting `p` on every segment, without the culling of
    /// [`CylinderModel::closest_point`] (same result; a baseline for benchmarks and tests).
    pub fn closest_point_brute_force(
        &self,
        posed: &PosedSkeleton,
        p: &Vector3<f64>,
    ) -> Option<CylinderProjection> {
        if !p.iter().all(|v| v.is_finite()) {
            return None;
        }
        self.scan(posed, p, None)
    }

    /// The front-facing correspondence of §2.3.1 ("3D correspondences"): on every segment the
    /// closest point, replaced by the closest silhouette-contour point when back-facing
    /// (`n·v ≥ 0`); the segment with the smallest signed distance `±‖p − q‖` wins (the sign is
    /// negative when `p` is inside that segment).
    pub fn front_facing_point(
        &self,
        posed: &PosedSkeleton,
        p: &Vector3<f64>,
        view: View,
    ) -> Option<CylinderProjection> {
        if !p.iter().all(|v| v.is_finite()) || self.segments.is_empty() {
            return None;
        }
        self.with_posed_segments(posed, |segs| {
            self.best_of(segs, posed, p, Some(view), None, None)
        })
    }

    /// [`CylinderModel::front_facing_point`] computed on every segment, without culling (same
    /// result; a baseline for benchmarks and tests).
    pub fn front_facing_point_brute_force(
        &self,
        posed: &PosedSkeleton,
        p: &Vector3<f64>,
        view: View,
    ) -> Option<CylinderProjection> {
        if !p.iter().all(|v| v.is_finite()) {
            return None;
        }
        self.scan(posed, p, Some(view))
    }

    /// Batch form: `out[i]` receives [`CylinderModel::front_facing_point`] of `points[i]` (with
    /// `Some(view)`) or [`CylinderModel::closest_point`] (with `None`). The per-pose segment
    /// data is computed once for the whole batch. Allocates nothing for models of up to 32
    /// segments. Returns how many points got a correspondence; `out` must be as long as
    /// `points`.
    pub fn project_points(
        &self,
        posed: &PosedSkeleton,
        points: &[Vector3<f64>],
        view: Option<View>,
        out: &mut [Option<CylinderProjection>],
    ) -> Result<usize> {
        self.project_points_impl(posed, points, view, None, out)
    }

    /// [`CylinderModel::project_points`] with temporal coherence: `seeds[i]` names the segment
    /// to project `points[i]` on first (the one it matched at the previous iteration or frame;
    /// [`NO_SEED`] or an out-of-range index for none), so that the culling bound is tight from
    /// the start; on return it holds the segment of `out[i]` ([`NO_SEED`] for `None`). The seed
    /// only orders the search: the result is the same as without it. `seeds` must be as long as
    /// `points`.
    pub fn project_points_seeded(
        &self,
        posed: &PosedSkeleton,
        points: &[Vector3<f64>],
        view: Option<View>,
        seeds: &mut [u16],
        out: &mut [Option<CylinderProjection>],
    ) -> Result<usize> {
        if seeds.len() != points.len() {
            return Err(ModelError::InvalidArgument {
                name: "seeds",
                reason: format!("{} seeds for {} points", seeds.len(), points.len()),
            });
        }
        self.project_points_impl(posed, points, view, Some(seeds), out)
    }

    fn project_points_impl(
        &self,
        posed: &PosedSkeleton,
        points: &[Vector3<f64>],
        view: Option<View>,
        mut seeds: Option<&mut [u16]>,
        out: &mut [Option<CylinderProjection>],
    ) -> Result<usize> {
        if out.len() != points.len() {
            return Err(ModelError::InvalidArgument {
                name: "out",
                reason: format!("{} slots for {} points", out.len(), points.len()),
            });
        }
        if self.segments.is_empty() {
            out.fill(None);
            if let Some(s) = seeds {
                s.fill(NO_SEED);
            }
            return Ok(0);
        }
        Ok(self.with_posed_segments(posed, |segs| {
            let soa = seeds.as_ref().and_then(|_| CapsuleSoa::new(segs));
            let mut count = 0;
            for (i, (o, p)) in out.iter_mut().zip(points).enumerate() {
                let seed = seeds.as_deref_mut().and_then(|s| s.get_mut(i));
                *o = if p.iter().all(|v| v.is_finite()) {
                    let first = seed.as_deref().map(|&s| usize::from(s));
                    self.best_of(segs, posed, p, view, first, soa.as_ref())
                } else {
                    None
                };
                if let Some(s) = seed {
                    *s = o
                        .as_ref()
                        .and_then(|c| u16::try_from(c.segment).ok())
                        .unwrap_or(NO_SEED);
                }
                count += usize::from(o.is_some());
            }
            count
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(length: f64, r1: f64, r2: f64, r1y: f64, r2y: f64) -> Segment {
        Segment {
            bone: 0,
            length,
            r1,
            r2,
            r1y,
            r2y,
        }
    }

    #[test]
    fn profile_closest_basic_cases() {
        // Cylinder of radius 2, length 10.
        let (f, c) = profile_closest(5.0, 4.0, 2.0, 2.0, 10.0);
        assert!(matches!(f, Foot2::Side(t) if (t - 0.4).abs() < 1e-12) && !c);
        let (f, _) = profile_closest(0.0, -5.0, 2.0, 2.0, 10.0);
        assert!(matches!(f, Foot2::Start(dr, dy) if dr == 0.0 && dy == -1.0));
        let (f, _) = profile_closest(3.0, 14.0, 2.0, 2.0, 10.0);
        assert!(
            matches!(f, Foot2::End(dr, dy) if (dr - 0.6).abs() < 1e-12 && (dy - 0.8).abs() < 1e-12)
        );
    }

    #[test]
    fn inside_test_matches_ellipse() {
        let s = seg(20.0, 10.0, 12.0, 3.0, 3.0);
        // Mid-height: half-axes r = 11, ry = 3.
        assert!(s.contains_local_point(&Vector3::new(10.9, 10.0, 0.0)));
        assert!(!s.contains_local_point(&Vector3::new(11.1, 10.0, 0.0)));
        assert!(s.contains_local_point(&Vector3::new(0.0, 10.0, 2.9)));
        assert!(!s.contains_local_point(&Vector3::new(0.0, 10.0, 3.1)));
        // Start cap: half-axes (10, 3, 3).
        assert!(s.contains_local_point(&Vector3::new(0.0, -2.9, 0.0)));
        assert!(!s.contains_local_point(&Vector3::new(0.0, -3.1, 0.0)));
    }

    #[test]
    fn foot_points_lie_on_the_surface() {
        let s = seg(30.0, 9.0, 6.0, 4.0, 5.0);
        for i in 0..200 {
            let f = i as f64;
            let p = Vector3::new(
                (f * 0.37).sin() * 20.0,
                (f * 0.21).cos() * 30.0 + 15.0,
                (f * 0.13).sin() * 15.0,
            );
            let r = s.project_local_point(&p).unwrap();
            // On the surface: a tiny step along the normal leaves, a tiny step back enters.
            assert!(
                !s.contains_local_point(&(r.point + r.normal * 1e-6)),
                "{p:?}"
            );
            assert!(
                s.contains_local_point(&(r.point - r.normal * 1e-6)),
                "{p:?}"
            );
        }
    }
}
