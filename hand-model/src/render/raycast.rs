//! Exact ray casting of sphere-mesh elements (thesis §3.3.2 "Rendering": each camera ray is
//! intersected with the planar, conical and spherical primitives of each element and the
//! closest intersection is kept).
//!
//! The hit of a ray with an element is its *entry* into the solid element. An element is convex,
//! so the line meets it in one interval; the entry is the smallest entering crossing over the
//! element's primitives (see [`PreparedElement`]), computed over the whole line, and the ray hits
//! the element when that entry lies in `[t_min, t_max]`. A ray whose segment starts inside an
//! element therefore does not hit that element (no back faces are reported).
//!
//! Everything here is allocation-free; non-finite rays or spheres give no hit.

use nalgebra::Vector3;

use super::prepared::{in_triangle, PreparedElement};
use crate::shape::{Element, Sphere};

type V3 = Vector3<f64>;

/// A ray `x(t) = origin + t·dir` restricted to `t ∈ [t_min, t_max]` (mm): the camera ray `r(x)`
/// of a pixel in thesis §3.3.2.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Ray {
    /// Origin (mm).
    pub origin: Vector3<f64>,
    /// Unit direction.
    pub dir: Vector3<f64>,
    /// Start of the segment (may be negative).
    pub t_min: f64,
    /// End of the segment (may be `+∞`).
    pub t_max: f64,
}

impl Ray {
    /// A ray over `t ∈ [0, ∞)` with `dir` normalized; `None` for non-finite input or a zero
    /// direction.
    pub fn new(origin: Vector3<f64>, dir: Vector3<f64>) -> Option<Self> {
        Self::segment(origin, dir, 0.0, f64::INFINITY)
    }

    /// A ray over `t ∈ [t_min, t_max]` with `dir` normalized; `None` for non-finite input (except
    /// `t_max = +∞`), a zero direction or `t_min > t_max`.
    pub fn segment(
        origin: Vector3<f64>,
        dir: Vector3<f64>,
        t_min: f64,
        t_max: f64,
    ) -> Option<Self> {
        let n = dir.norm();
        let ray = Self {
            origin,
            dir: dir / n,
            t_min,
            t_max,
        };
        (n > 0.0 && ray.is_valid()).then_some(ray)
    }

    /// Whether the ray can be cast: finite origin, unit direction (to 1e-6), finite `t_min`,
    /// `t_min ≤ t_max` (`t_max` may be `+∞`).
    pub fn is_valid(&self) -> bool {
        self.origin.iter().all(|x| x.is_finite())
            && self.dir.iter().all(|x| x.is_finite())
            && (self.dir.norm_squared() - 1.0).abs() < 1e-6
            && self.t_min.is_finite()
            && !self.t_max.is_nan()
            && self.t_min <= self.t_max
    }

    /// The point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f64) -> Vector3<f64> {
        self.origin + self.dir * t
    }
}

/// Where a ray enters one element (the closest intersection of §3.3.2 for that element).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SurfaceHit {
    /// Ray parameter of the hit (mm along the unit direction).
    pub t: f64,
    /// The hit point (`origin + t·dir`).
    pub point: Vector3<f64>,
    /// Outward unit normal of the element at the hit (`normal · dir ≤ 0`).
    pub normal: Vector3<f64>,
}

/// The first hit of a ray with a whole model (§3.3.2: closest intersection over all elements):
/// a [`SurfaceHit`] plus the element it belongs to.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct RayHit {
    /// Ray parameter of the hit.
    pub t: f64,
    /// The hit point.
    pub point: Vector3<f64>,
    /// Outward unit normal at the hit.
    pub normal: Vector3<f64>,
    /// Index of the element hit (in the element list given to [`cast_ray`]).
    pub element: usize,
}

/// Solve `a·t² + 2b·t + c = 0` (numerically stable form); roots may repeat.
#[inline]
fn quadratic(a: f64, b: f64, c: f64) -> [Option<f64>; 2] {
    if a.abs() < 1e-12 {
        if b.abs() < 1e-300 {
            return [None, None];
        }
        return [Some(-c / (2.0 * b)), None];
    }
    let disc = b * b - a * c;
    if disc.is_nan() || disc < 0.0 {
        return [None, None];
    }
    let q = -(b + disc.sqrt().copysign(b));
    if q == 0.0 {
        return [Some(0.0), None];
    }
    [Some(q / a), Some(c / q)]
}

/// Entry parameter `t` of the line `o + t·d` (unit `d`) into a ball.
#[inline]
fn ball_entry(s: &Sphere, o: &V3, d: &V3) -> Option<f64> {
    if s.radius.is_nan() || s.radius <= 0.0 {
        return None;
    }
    let w = o - s.center;
    let b = w.dot(d);
    // r² − (distance from the center to the line)², stable for far origins.
    let disc = s.radius * s.radius - (w - d * b).norm_squared();
    if disc.is_nan() || disc < 0.0 {
        return None;
    }
    Some(-b - disc.sqrt())
}

/// The outward normal of a ball at the point `x` of its surface.
#[inline]
fn ball_normal(s: &Sphere, x: &V3, d: &V3) -> V3 {
    let n = x - s.center;
    let len = n.norm();
    if len > 0.0 {
        n / len
    } else {
        -d
    }
}

/// Whether the ray's segment `[t_min, t_best]` meets a (bounding) ball: the chord `[−b − √disc,
/// −b + √disc]` reaches past `t_min` and starts before `t_best`, each tested squared (no
/// square root: this test runs for every candidate element of every rendered pixel).
#[inline]
fn sphere_meets(b: &Sphere, ray: &Ray, t_best: f64) -> bool {
    let w = ray.origin - b.center;
    let bb = w.dot(&ray.dir);
    let disc = b.radius * b.radius - (w - ray.dir * bb).norm_squared();
    if disc.is_nan() || disc < 0.0 {
        return false;
    }
    // √disc ≥ x holds when x ≤ 0, else when disc ≥ x².
    let reaches = |x: f64| x <= 0.0 || disc >= x * x;
    reaches(ray.t_min + bb) && reaches(-bb - t_best)
}

impl PreparedElement {
    /// Entry `(t, outward normal)` of the whole line `o + t·d` (unit `d`) into the element, for
    /// any `t` (negative included); `None` when the line misses it.
    ///
    /// A convex body has a single entry point, and any entering crossing of a primitive that lies
    /// on the element's boundary is it: the tangent triangles of a wedge and the cone band of a
    /// pill are boundary (each lies on a supporting plane), so a hit on them ends the search.
    /// Otherwise the entry is the smallest entering crossing over all primitives.
    ///
    /// Every entering crossing comes at or after the entry, so crossings beyond `t_hi` are
    /// skipped (their normals never worked out) and an entry beyond it is `None`: a ray that
    /// already hit another element at `t_hi` needs no more.
    pub(crate) fn line_entry(&self, o: &V3, d: &V3, t_hi: f64) -> Option<(f64, V3)> {
        if let Some(faces) = &self.faces {
            let c1 = self.spheres[0].center;
            for f in faces {
                let denom = f.normal.dot(d);
                if denom.is_nan() || denom >= -1e-12 {
                    continue;
                }
                let t = (f.offset - f.normal.dot(o)) / denom;
                if in_triangle(&f.skew(&c1, &(o + d * t))) {
                    return (t <= t_hi).then_some((t, f.normal));
                }
            }
        }
        // The best crossing so far and its primitive (cone `i` or sphere `3 + i`): normals are
        // worked out for the entry alone.
        let mut best: Option<(f64, usize)> = None;
        // Whether a crossing at `t` can still be the entry.
        let wins = |best: &Option<(f64, usize)>, t: f64| match best {
            Some((bt, _)) => t < *bt,
            None => t <= t_hi,
        };
        let dd = d.norm_squared();
        for (i, cone) in self.cones.iter().enumerate() {
            let Some(cone) = cone else { continue };
            let w = o - cone.apex_side;
            let s0 = w.dot(&cone.axis);
            let ds = d.dot(&cone.axis);
            let radial0 = w - cone.axis * s0;
            let radial0_d = radial0.dot(d);
            let k = cone.cos * cone.cos;
            let q0 = cone.r_a - s0 * cone.sin;
            let a = k * (dd - ds * ds) - ds * ds * cone.sin * cone.sin;
            let b = k * radial0_d + q0 * ds * cone.sin;
            let c = k * radial0.norm_squared() - q0 * q0;
            for t in quadratic(a, b, c).into_iter().flatten() {
                let s = s0 + t * ds;
                if !(s >= cone.s_lo && s <= cone.s_hi && wins(&best, t)) {
                    continue;
                }
                // Entering: the normal `sin α·axis + cos α·radial/ρ` against `d`, times
                // `ρ cos α > 0`, where on the band `ρ cos α = r_a − s sin α` (no square root).
                let radial_d = radial0_d + t * (dd - ds * ds);
                if cone.sin * ds * (cone.r_a - s * cone.sin) + k * radial_d < 0.0 {
                    best = Some((t, i));
                }
            }
        }
        if !(self.count == 2 && best.is_some()) {
            for (i, s) in self.spheres().iter().enumerate() {
                if let Some(t) = ball_entry(s, o, d).filter(|&t| wins(&best, t)) {
                    best = Some((t, 3 + i));
                }
            }
        }
        let (t, i) = best?;
        let x = o + d * t;
        let normal = match self.cones.get(i) {
            Some(cone) => cone.as_ref()?.normal_at(&x),
            None => ball_normal(&self.spheres[i - 3], &x, d),
        };
        Some((t, normal))
    }

    /// The first hit of `ray` with the element (§3.3.2), or `None` (also for an invalid ray, and when the
    /// ray's segment starts inside the element).
    pub fn cast(&self, ray: &Ray) -> Option<SurfaceHit> {
        if !ray.is_valid() {
            return None;
        }
        self.cast_unchecked(ray, ray.t_max)
    }

    /// [`PreparedElement::cast`] for a valid ray, with `t_max` lowered to `t_best`; bounding-sphere
    /// culling first (bounding sphere, then the bounding box or prism).
    #[inline]
    pub(crate) fn cast_unchecked(&self, ray: &Ray, t_best: f64) -> Option<SurfaceHit> {
        if !sphere_meets(&self.bounds, ray, t_best) {
            return None;
        }
        if !self.hull.meets(&ray.origin, &ray.dir, ray.t_min, t_best) {
            return None;
        }
        let (t, normal) = self.line_entry(&ray.origin, &ray.dir, t_best)?;
        (t >= ray.t_min && t <= t_best).then(|| SurfaceHit {
            t,
            point: ray.at(t),
            normal,
        })
    }
}

/// First hit of a ray with a pill (two spheres and their tangent cone, Fig. 3.3, §3.3.2); see
/// [`PreparedElement::cast`].
pub fn cast_ray_pill(ray: &Ray, a: &Sphere, b: &Sphere) -> Option<SurfaceHit> {
    PreparedElement::pill(a, b)?.cast(ray)
}

/// First hit of a ray with a wedge (three spheres, three tangent cones, two tangent triangles:
/// the spherical, conical and planar primitives of Fig. 3.3, §3.3.2); see [`PreparedElement::cast`].
pub fn cast_ray_wedge(ray: &Ray, a: &Sphere, b: &Sphere, c: &Sphere) -> Option<SurfaceHit> {
    PreparedElement::wedge(a, b, c)?.cast(ray)
}

/// First hit of a ray with one element (§3.3.2) whose indices refer to `spheres`; `None` also
/// when an index is out of range or a sphere is invalid.
pub fn cast_ray_element(ray: &Ray, spheres: &[Sphere], element: &Element) -> Option<SurfaceHit> {
    PreparedElement::new(spheres, element)?.cast(ray)
}

/// [`cast_ray`] over elements prepared once (`None`: an element that could not be prepared, skipped),
/// trying element `seed` first so that the others are culled against its hit: the form for
/// many rays per pose (e.g. one per sensor point, seeded with the point's nearest element).
/// The same hit as [`cast_ray`] except on exact ties in `t`, which go to `seed`.
pub fn cast_ray_prepared(
    ray: &Ray,
    elements: &[Option<PreparedElement>],
    seed: usize,
) -> Option<RayHit> {
    if !ray.is_valid() {
        return None;
    }
    let hit = |i: usize, t_best: f64| {
        let e = elements.get(i)?.as_ref()?;
        e.cast_unchecked(ray, t_best).map(|h| RayHit {
            t: h.t,
            point: h.point,
            normal: h.normal,
            element: i,
        })
    };
    let mut best = hit(seed, ray.t_max);
    for i in (0..elements.len()).filter(|&i| i != seed) {
        if let Some(h) = hit(i, best.map_or(ray.t_max, |b| b.t)) {
            if best.is_none_or(|b| h.t < b.t) {
                best = Some(h);
            }
        }
    }
    best
}

/// First hit of a ray with a whole sphere-mesh model (Eq. 3.6's union of elements), with
/// bounding-sphere culling; ties go to the lower element index.
///
/// Elements with an out-of-range index, a non-finite sphere or a negative radius are skipped.
/// Allocation-free: elements are prepared on the stack one at a time (the depth renderer prepares
/// them once per frame instead).
pub fn cast_ray(ray: &Ray, spheres: &[Sphere], elements: &[Element]) -> Option<RayHit> {
    if !ray.is_valid() {
        return None;
    }
    let mut best: Option<RayHit> = None;
    for (i, e) in elements.iter().enumerate() {
        let t_best = best.map_or(ray.t_max, |h| h.t);
        // Cull with the bounding sphere before paying for the preparation.
        let mut own = [Sphere::new(V3::zeros(), 0.0); 3];
        let idx = e.spheres();
        if idx.iter().any(|&k| k as usize >= spheres.len()) {
            continue;
        }
        for (slot, &k) in own.iter_mut().zip(idx) {
            *slot = spheres[k as usize];
        }
        if !sphere_meets(&PreparedElement::bounds_of(&own[..idx.len()]), ray, t_best) {
            continue;
        }
        let Some(p) = PreparedElement::new(spheres, e) else {
            continue;
        };
        if let Some(h) = p.cast_unchecked(ray, t_best) {
            if best.is_none_or(|b| h.t < b.t) {
                best = Some(RayHit {
                    t: h.t,
                    point: h.point,
                    normal: h.normal,
                    element: i,
                });
            }
        }
    }
    best
}

/// [`cast_ray`] over elements prepared once, restricted to the listed element indices (any
/// order: front-to-back is fastest; ties still go to the lower index, so the result does not
/// depend on the order); used by the depth renderer.
#[inline]
pub(crate) fn cast_prepared(
    ray: &Ray,
    prepared: &[PreparedElement],
    indices: impl Iterator<Item = usize>,
) -> Option<RayHit> {
    let mut best: Option<RayHit> = None;
    for i in indices {
        let t_best = best.map_or(ray.t_max, |h| h.t);
        if let Some(h) = prepared[i].cast_unchecked(ray, t_best) {
            if best.is_none_or(|b| h.t < b.t || (h.t == b.t && i < b.element)) {
                best = Some(RayHit {
                    t: h.t,
                    point: h.point,
                    normal: h.normal,
                    element: i,
                });
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::testutil::*;
    use rand::Rng;

    fn s(x: f64, y: f64, z: f64, r: f64) -> Sphere {
        Sphere::new(V3::new(x, y, z), r)
    }

    fn axis_ray(x: f64, y: f64) -> Ray {
        Ray::new(V3::new(x, y, 0.0), V3::z()).unwrap()
    }

    #[test]
    fn sphere_at_known_distance() {
        let c = s(0.0, 0.0, 500.0, 20.0);
        // A pill of two coincident spheres, and one whose second sphere is swallowed, are spheres.
        let pills = [
            PreparedElement::pill(&c, &c).unwrap(),
            PreparedElement::pill(&c, &s(0.0, 3.0, 505.0, 1.0)).unwrap(),
        ];
        for p in &pills {
            let h = p.cast(&Ray::new(V3::zeros(), V3::z()).unwrap()).unwrap();
            assert_eq!(h.t, 480.0);
            assert!((h.normal + V3::z()).norm() < 1e-12);
            let ray = Ray::new(V3::zeros(), V3::new(0.02, -0.01, 1.0)).unwrap();
            let b = ray.dir.dot(&c.center);
            let t = b - (b * b - c.center.norm_squared() + 400.0).sqrt();
            let h = p.cast(&ray).unwrap();
            assert!((h.t - t).abs() < 1e-9, "{} vs {t}", h.t);
            assert!(((h.point - c.center).norm() - 20.0).abs() < 1e-9);
            assert!(p
                .cast(&Ray::new(V3::zeros(), V3::new(0.05, 0.0, 1.0)).unwrap())
                .is_none());
            // Segment limits: ends before the sphere, or starts inside it.
            assert!(p
                .cast(&Ray::segment(V3::zeros(), V3::z(), 0.0, 479.0).unwrap())
                .is_none());
            assert!(p
                .cast(&Ray::segment(V3::zeros(), V3::z(), 490.0, 1e9).unwrap())
                .is_none());
        }
    }

    #[test]
    fn pill_seen_side_on() {
        let (a, b) = (s(-30.0, 0.0, 300.0, 12.0), s(30.0, 0.0, 300.0, 8.0));
        let p = PreparedElement::pill(&a, &b).unwrap();
        let (sin, l) = (4.0 / 60.0, 60.0);
        let cos = (1.0f64 - sin * sin).sqrt();
        for i in 0..=160 {
            let x = -45.0 + 0.5625 * i as f64;
            let sx = x + 30.0;
            let expect = if sx >= 12.0 * sin && sx <= l + 8.0 * sin {
                300.0 - (12.0 - sx * sin) / cos
            } else if sx < 12.0 * sin {
                let dx: f64 = x + 30.0;
                if dx.abs() > 12.0 {
                    continue;
                } else {
                    300.0 - (144.0 - dx * dx).sqrt()
                }
            } else {
                let dx: f64 = x - 30.0;
                if dx.abs() > 8.0 {
                    continue;
                } else {
                    300.0 - (64.0 - dx * dx).sqrt()
                }
            };
            let h = p
                .cast(&axis_ray(x, 0.0))
                .unwrap_or_else(|| panic!("miss at x = {x}"));
            assert!((h.t - expect).abs() < 1e-9, "x = {x}: {} vs {expect}", h.t);
            assert!((h.normal.norm() - 1.0).abs() < 1e-12);
        }
        assert!(p.cast(&axis_ray(0.0, 10.5)).is_none());
        // Equal radii: a cylinder, flat at z = 290 between the spheres.
        let cyl =
            PreparedElement::pill(&s(-30.0, 0.0, 300.0, 10.0), &s(30.0, 0.0, 300.0, 10.0)).unwrap();
        for x in [-29.0, -5.0, 0.0, 17.3, 29.9] {
            assert_eq!(cyl.cast(&axis_ray(x, 0.0)).unwrap().t, 290.0);
        }
    }

    #[test]
    fn wedge_planar_face_has_exact_depth() {
        let (a, b, c) = (
            s(-30.0, -20.0, 300.0, 10.0),
            s(30.0, -20.0, 300.0, 10.0),
            s(0.0, 30.0, 300.0, 10.0),
        );
        for w in [
            PreparedElement::wedge(&a, &b, &c).unwrap(),
            PreparedElement::wedge(&c, &b, &a).unwrap(),
        ] {
            assert!(w.has_planar_faces());
            for (x, y) in [
                (0.0, 0.0),
                (-25.0, -19.0),
                (25.0, -19.0),
                (0.0, 28.0),
                (10.0, 5.0),
            ] {
                let h = w.cast(&axis_ray(x, y)).unwrap();
                assert!((h.t - 290.0).abs() < 1e-9, "({x}, {y}): {}", h.t);
                assert!((h.normal + V3::z()).norm() < 1e-9);
                // Perspective rays from the camera center: depth z is exactly 290 too.
                let h = w
                    .cast(&Ray::new(V3::zeros(), V3::new(x, y, 290.0)).unwrap())
                    .unwrap();
                assert!((h.point.z - 290.0).abs() < 1e-9);
            }
        }
        // Unequal radii: the hit lies on the plane tangent to the three spheres.
        let (a, b, c) = (
            s(-30.0, -20.0, 300.0, 10.0),
            s(30.0, -20.0, 300.0, 13.0),
            s(0.0, 30.0, 300.0, 7.0),
        );
        let w = PreparedElement::wedge(&a, &b, &c).unwrap();
        let h = w.cast(&axis_ray(0.0, 0.0)).unwrap();
        let n = h.normal;
        let offsets = [&a, &b, &c].map(|s| n.dot(&s.center) + s.radius);
        assert!((offsets[0] - offsets[1]).abs() < 1e-9 && (offsets[0] - offsets[2]).abs() < 1e-9);
        assert!((n.dot(&h.point) - offsets[0]).abs() < 1e-9);
    }

    fn random_sphere(rng: &mut rand_chacha::ChaCha8Rng) -> Sphere {
        let r = if rng.random_bool(0.1) {
            0.0
        } else {
            rng.random_range(0.5..15.0)
        };
        Sphere::new(point_in_cube(rng, &V3::zeros(), 25.0), r)
    }

    /// Elements worth testing: random ones plus every degenerate case.
    fn test_elements(rng: &mut rand_chacha::ChaCha8Rng) -> Vec<(Vec<Sphere>, Element)> {
        let mut out = vec![];
        for _ in 0..25 {
            out.push((
                vec![random_sphere(rng), random_sphere(rng)],
                Element::Pill([0, 1]),
            ));
            out.push((
                vec![random_sphere(rng), random_sphere(rng), random_sphere(rng)],
                Element::Wedge([0, 1, 2]),
            ));
        }
        let degenerate = [
            vec![s(-20.0, 0.0, 0.0, 8.0), s(20.0, 0.0, 0.0, 8.0)], // equal radii
            vec![s(3.0, 1.0, 2.0, 8.0), s(3.0, 1.0, 2.0, 12.0)],   // coincident centers
            vec![s(0.0, 0.0, 0.0, 15.0), s(5.0, 3.0, 0.0, 6.0)],   // swallowed
            vec![s(0.0, 0.0, 0.0, 15.0), s(10.0, 0.0, 0.0, 5.0)],  // internally tangent
            vec![s(-20.0, 0.0, 0.0, 0.0), s(20.0, 0.0, 0.0, 9.0)], // zero radius (true cone)
            vec![s(-20.0, 0.0, 0.0, 0.0), s(20.0, 0.0, 0.0, 0.0)], // zero radii (a segment)
        ];
        for d in degenerate {
            out.push((d, Element::Pill([0, 1])));
        }
        let wedges = [
            vec![
                s(-20.0, 0.0, 0.0, 8.0),
                s(20.0, 0.0, 0.0, 8.0),
                s(0.0, 25.0, 0.0, 8.0),
            ],
            vec![
                s(-20.0, 0.0, 0.0, 8.0),
                s(0.0, 0.0, 0.0, 5.0),
                s(20.0, 0.0, 0.0, 10.0),
            ], // collinear
            vec![
                s(-20.0, 0.0, 0.0, 8.0),
                s(-20.0, 0.0, 0.0, 8.0),
                s(20.0, 5.0, 0.0, 6.0),
            ], // coincident
            vec![
                s(0.0, 0.0, 0.0, 20.0),
                s(5.0, 3.0, 1.0, 4.0),
                s(30.0, 0.0, 0.0, 6.0),
            ], // swallowed
            vec![
                s(0.0, 0.0, 0.0, 20.0),
                s(5.0, 3.0, 1.0, 4.0),
                s(-4.0, 2.0, 3.0, 6.0),
            ], // two swallowed
            vec![
                s(-20.0, 0.0, 0.0, 0.0),
                s(20.0, 0.0, 0.0, 0.0),
                s(0.0, 25.0, 0.0, 0.0),
            ], // zero radii
            vec![
                s(-20.0, 0.0, 0.0, 0.0),
                s(20.0, 0.0, 0.0, 3.0),
                s(0.0, 25.0, 0.0, 9.0),
            ], // one zero
            vec![
                s(-20.0, 0.0, 0.0, 30.0),
                s(20.0, 0.0, 0.0, 2.0),
                s(0.0, 25.0, 0.0, 2.0),
            ], // no plane
        ];
        for w in wedges {
            out.push((w, Element::Wedge([0, 1, 2])));
        }
        out
    }

    #[test]
    fn matches_dense_sampling_brute_force() {
        let mut rng = rng(42);
        let (step, tol) = (0.2, 0.05);
        let mut hits = 0;
        for (spheres, element) in test_elements(&mut rng) {
            let prepared = PreparedElement::new(&spheres, &element).unwrap();
            let samples = skeleton_samples(&spheres, &element, step);
            // Point-like samples (all radii 0: a flat triangle or a segment) leave gaps of the
            // order of the step itself.
            let tol = if spheres.iter().all(|s| s.radius == 0.0) {
                step
            } else {
                tol
            };
            let target = prepared.bounds();
            for _ in 0..300 {
                let origin = target.center + unit_vector(&mut rng) * (target.radius + 60.0);
                let aim = point_in_cube(&mut rng, &target.center, target.radius);
                let ray = Ray::new(origin, aim - origin).unwrap();
                let exact = prepared.cast(&ray);
                let brute = brute_first_hit(&samples, &ray);
                if let Some(tb) = brute {
                    let h = exact.unwrap_or_else(|| {
                        panic!("{element:?} {spheres:?}: brute hit at {tb}, exact miss")
                    });
                    // No sample of the surface lies in front of the exact hit.
                    assert!(h.t <= tb + 1e-9, "exact {} behind brute {tb}", h.t);
                    if -h.normal.dot(&ray.dir) > 0.3 {
                        assert!(tb - h.t < tol / 0.3, "exact {} brute {tb}", h.t);
                    }
                }
                if let Some(h) = exact {
                    hits += 1;
                    let d = brute_sdf(&samples, &h.point);
                    assert!(
                        (-1e-9..tol).contains(&d),
                        "{element:?} {spheres:?}: sdf {d} at the hit"
                    );
                    assert!((h.normal.norm() - 1.0).abs() < 1e-9 && h.normal.dot(&ray.dir) <= 0.0);
                    assert!((h.point - ray.at(h.t)).norm() < 1e-9);
                }
            }
            // The implicit function agrees with the sampled one.
            for _ in 0..300 {
                let p = point_in_cube(&mut rng, &target.center, target.radius + 5.0);
                let (phi, b) = (prepared.phi(&p), brute_sdf(&samples, &p));
                if phi >= 0.0 {
                    assert!(b >= phi - 1e-9 && b - phi < tol, "phi {phi} brute {b}");
                } else {
                    assert!(b < tol, "phi {phi} brute {b}");
                }
                if b < -tol {
                    assert!(prepared.contains(&p));
                }
            }
        }
        assert!(hits > 5000, "{hits}");
    }

    #[test]
    fn degenerate_elements_never_give_nan() {
        let mut rng = rng(7);
        for (spheres, element) in test_elements(&mut rng) {
            let p = PreparedElement::new(&spheres, &element).unwrap();
            for _ in 0..2000 {
                let origin = point_in_cube(&mut rng, &V3::zeros(), 80.0);
                let ray = Ray::new(origin, unit_vector(&mut rng)).unwrap();
                if let Some(h) = p.cast(&ray) {
                    assert!(h.t.is_finite() && h.point.iter().all(|x| x.is_finite()));
                    assert!(
                        (h.normal.norm() - 1.0).abs() < 1e-9,
                        "{element:?} {spheres:?}"
                    );
                }
                assert!(p.phi(&origin).is_finite());
            }
            // Rays aimed exactly at centers and along the axis of the first pair.
            let axis = Ray::new(
                spheres[0].center - (spheres[1].center - spheres[0].center) * 3.0,
                spheres[1].center - spheres[0].center,
            );
            for ray in [
                axis,
                Ray::new(
                    V3::new(0.0, 0.0, -100.0),
                    spheres[0].center - V3::new(0.0, 0.0, -100.0),
                ),
            ]
            .into_iter()
            .flatten()
            {
                if let Some(h) = p.cast(&ray) {
                    assert!(h.t.is_finite() && (h.normal.norm() - 1.0).abs() < 1e-9);
                }
            }
        }
    }

    #[test]
    fn invalid_input_gives_no_hit() {
        let a = s(0.0, 0.0, 100.0, 10.0);
        let nan = s(f64::NAN, 0.0, 100.0, 10.0);
        assert!(PreparedElement::pill(&a, &nan).is_none());
        assert!(PreparedElement::pill(&a, &s(0.0, 0.0, 120.0, -1.0)).is_none());
        assert!(Ray::new(V3::new(f64::NAN, 0.0, 0.0), V3::z()).is_none());
        assert!(Ray::new(V3::zeros(), V3::zeros()).is_none());
        assert!(Ray::segment(V3::zeros(), V3::z(), 5.0, 1.0).is_none());
        let bad = Ray {
            origin: V3::zeros(),
            dir: V3::new(0.0, 0.0, 2.0),
            t_min: 0.0,
            t_max: 1e9,
        };
        assert!(cast_ray_pill(&bad, &a, &a).is_none());
        let spheres = [a, nan];
        let elements = [
            Element::Pill([0, 1]),
            Element::Pill([0, 7]),
            Element::Pill([0, 0]),
        ];
        let ray = Ray::new(V3::zeros(), V3::z()).unwrap();
        // The invalid elements are skipped; the valid one is found.
        assert_eq!(cast_ray(&ray, &spheres, &elements).unwrap().element, 2);
        assert!(cast_ray_element(&ray, &spheres, &elements[1]).is_none());
    }

    #[test]
    fn model_cast_is_the_closest_element_hit() {
        use crate::kinematics::Pose;
        use crate::spheremesh::{default_right_hand, PosedSphereMesh};
        let template = default_right_hand();
        let mut pose = Pose::zeros(&template.skeleton);
        pose.set(&template.skeleton, "global_tz", 400.0).unwrap();
        pose.set(&template.skeleton, "index_pip_flex", 0.8).unwrap();
        pose.set(&template.skeleton, "global_ry", 0.4).unwrap();
        let posed = PosedSphereMesh::new(&template, &pose);
        let elements: Vec<Element> = template.elements.iter().map(|e| e.element).collect();
        let prepared: Vec<_> = elements
            .iter()
            .map(|e| PreparedElement::new(&posed.spheres, e))
            .collect();
        let mut rng = rng(3);
        let mut hits = 0;
        for _ in 0..3000 {
            let aim = point_in_cube(&mut rng, &V3::new(0.0, 40.0, 400.0), 70.0);
            let ray = Ray::new(V3::zeros(), aim).unwrap();
            let best = elements
                .iter()
                .enumerate()
                .filter_map(|(i, e)| cast_ray_element(&ray, &posed.spheres, e).map(|h| (i, h)))
                .min_by(|a, b| a.1.t.total_cmp(&b.1.t));
            let got = cast_ray(&ray, &posed.spheres, &elements);
            assert_eq!(got.map(|h| h.t), best.map(|b| b.1.t));
            // Seeded with any element, the prepared form finds the same first hit.
            let seed = rng.random_range(0..elements.len());
            let seeded = cast_ray_prepared(&ray, &prepared, seed);
            assert_eq!(seeded.map(|h| h.t), got.map(|h| h.t));
            if let (Some(g), Some((i, h))) = (got, best) {
                hits += 1;
                assert!(g.element == i || h.t == g.t);
            }
        }
        assert!(hits > 300, "{hits}");
    }
}
