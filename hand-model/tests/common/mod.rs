//! Shared helpers of the `query_*` tests: seeded random shapes and independent brute-force
//! references (dense skeleton sampling refined by golden-section search, support-function
//! surface sampling).
#![allow(dead_code)]

use hand_model::query::Projection;
use hand_model::shape::Sphere;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

pub fn random_vector(rng: &mut ChaCha8Rng, half: f64) -> Vector3<f64> {
    Vector3::new(
        rng.random_range(-half..half),
        rng.random_range(-half..half),
        rng.random_range(-half..half),
    )
}

pub fn random_unit(rng: &mut ChaCha8Rng) -> Vector3<f64> {
    loop {
        let d = random_vector(rng, 1.0);
        let len = d.norm();
        if len > 0.1 && len <= 1.0 {
            return d / len;
        }
    }
}

pub fn random_sphere(rng: &mut ChaCha8Rng, half: f64, max_radius: f64) -> Sphere {
    Sphere::new(random_vector(rng, half), rng.random_range(0.0..max_radius))
}

/// A point in the box around the spheres, grown by `margin`.
pub fn random_point_near(rng: &mut ChaCha8Rng, spheres: &[&Sphere], margin: f64) -> Vector3<f64> {
    let mut lo = Vector3::repeat(f64::INFINITY);
    let mut hi = Vector3::repeat(f64::NEG_INFINITY);
    for s in spheres {
        lo = lo.inf(&(s.center.add_scalar(-s.radius)));
        hi = hi.sup(&(s.center.add_scalar(s.radius)));
    }
    Vector3::from_fn(|i, _| rng.random_range(lo[i] - margin..hi[i] + margin))
}

/// Minimum of a convex function on [lo, hi]: grid, then golden section in the bracket around
/// the best grid sample (for a convex function the minimiser lies in that bracket).
pub fn convex_min(f: impl Fn(f64) -> f64, lo: f64, hi: f64, grid: usize) -> f64 {
    if hi <= lo {
        return f(lo);
    }
    let step = (hi - lo) / grid as f64;
    let mut best_k = 0;
    let mut best = f64::INFINITY;
    for k in 0..=grid {
        let v = f(lo + step * k as f64);
        if v < best {
            best = v;
            best_k = k;
        }
    }
    let mut a = (lo + step * (best_k as f64 - 1.0)).max(lo);
    let mut b = (lo + step * (best_k as f64 + 1.0)).min(hi);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let mut x1 = b - g * (b - a);
    let mut x2 = a + g * (b - a);
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..80 {
        if f1 <= f2 {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - g * (b - a);
            f1 = f(x1);
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + g * (b - a);
            f2 = f(x2);
        }
    }
    best.min(f1).min(f2)
}

/// Brute-force signed distance to a pill: min over skeleton points of ‖p − c(t)‖ − r(t).
pub fn brute_pill(p: &Vector3<f64>, a: &Sphere, b: &Sphere) -> f64 {
    let f = |t: f64| {
        let c = a.center * (1.0 - t) + b.center * t;
        (p - c).norm() - (a.radius * (1.0 - t) + b.radius * t)
    };
    convex_min(f, 0.0, 1.0, 400)
}

/// Brute-force signed distance to a wedge: nested minimisation over the barycentric simplex
/// (the partial minimum of a convex function is convex, so both levels are convex searches).
pub fn brute_wedge(p: &Vector3<f64>, s: [&Sphere; 3]) -> f64 {
    let f = |l1: f64, l2: f64| {
        let l0 = 1.0 - l1 - l2;
        let c = s[0].center * l0 + s[1].center * l1 + s[2].center * l2;
        (p - c).norm() - (s[0].radius * l0 + s[1].radius * l1 + s[2].radius * l2)
    };
    let inner = |l1: f64| convex_min(|l2| f(l1, l2), 0.0, (1.0 - l1).max(0.0), 60);
    convex_min(inner, 0.0, 1.0, 60)
}

/// Checks the invariants every projection must satisfy: finite fields, unit normal,
/// weights forming a convex combination, and the exact identity q = Σ w c + (Σ w r) n.
pub fn check_projection(pr: &Projection, p: &Vector3<f64>, spheres: &[Sphere]) {
    let all = [
        pr.point.x,
        pr.point.y,
        pr.point.z,
        pr.normal.x,
        pr.normal.y,
        pr.normal.z,
        pr.skeleton_point.x,
        pr.skeleton_point.y,
        pr.skeleton_point.z,
        pr.distance,
        pr.weights[0],
        pr.weights[1],
        pr.weights[2],
    ];
    assert!(
        all.iter().all(|x| x.is_finite()),
        "non-finite field in {pr:?}"
    );
    assert!(
        (pr.normal.norm() - 1.0).abs() < 1e-9,
        "normal not unit: {pr:?}"
    );
    assert!(
        pr.weights.iter().all(|w| *w >= -1e-12),
        "negative weight: {pr:?}"
    );
    assert!(
        (pr.weights.iter().sum::<f64>() - 1.0).abs() < 1e-9,
        "weights: {pr:?}"
    );
    assert_eq!(
        pr.reevaluate(spheres),
        Some(pr.point),
        "identity q = Σwc + (Σwr)n"
    );
    let scale = 1.0 + p.norm();
    assert!(
        ((p - pr.point).norm() - pr.distance.abs()).abs() < 1e-9 * scale,
        "|distance| != |p - q|: {pr:?} p={p:?}"
    );
}

/// Fibonacci sphere directions.
pub fn fibonacci_directions(n: usize) -> Vec<Vector3<f64>> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let a = golden * i as f64;
            Vector3::new(r * a.cos(), r * a.sin(), z)
        })
        .collect()
}

fn orthonormal(u: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let h = if u.x.abs() < 0.6 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let a = u.cross(&h).normalize();
    (a, u.cross(&a))
}

/// Dense samples (point, outward normal) of the boundary of the convex hull of 2 or 3 spheres,
/// generated from the support function alone: the boundary point with normal n is cᵢ + rᵢn for
/// the sphere with the largest n·cᵢ + rᵢ, a generator segment on a tie of two spheres, the
/// tangent triangle on a tie of three.
pub fn sample_hull_surface(
    spheres: &[Sphere],
    density: usize,
) -> Vec<(Vector3<f64>, Vector3<f64>)> {
    let mut out = Vec::new();
    let support = |n: &Vector3<f64>, i: usize| n.dot(&spheres[i].center) + spheres[i].radius;
    let max_support = |n: &Vector3<f64>| {
        (0..spheres.len())
            .map(|i| support(n, i))
            .fold(f64::NEG_INFINITY, f64::max)
    };
    for n in fibonacci_directions(density * density) {
        let m = max_support(&n);
        for (i, s) in spheres.iter().enumerate() {
            if support(&n, i) >= m - 1e-12 {
                out.push((s.center + n * s.radius, n));
            }
        }
    }
    for i in 0..spheres.len() {
        for j in (i + 1)..spheres.len() {
            let (a, b) = (&spheres[i], &spheres[j]);
            let d = b.center - a.center;
            let len = d.norm();
            if len <= 0.0 {
                continue;
            }
            let k = (b.radius - a.radius) / len;
            if k.abs() >= 1.0 {
                continue;
            }
            let u = d / len;
            let h = (1.0 - k * k).sqrt();
            let (e1, e2) = orthonormal(&u);
            for ti in 0..(4 * density) {
                let th = 2.0 * std::f64::consts::PI * ti as f64 / (4 * density) as f64;
                let n = -u * k + (e1 * th.cos() + e2 * th.sin()) * h;
                if support(&n, i) < max_support(&n) - 1e-9 {
                    continue;
                }
                for si in 0..=density {
                    let t = si as f64 / density as f64;
                    let c = a.center * (1.0 - t) + b.center * t;
                    let r = a.radius * (1.0 - t) + b.radius * t;
                    out.push((c + n * r, n));
                }
            }
        }
    }
    if spheres.len() == 3 {
        let e1 = spheres[1].center - spheres[0].center;
        let e2 = spheres[2].center - spheres[0].center;
        let m = e1.cross(&e2);
        if m.norm() > 1e-9 * e1.norm() * e2.norm() {
            let m = m.normalize();
            // n·e1 = r0 − r1, n·e2 = r0 − r2: in-plane part from the 2×2 Gram system.
            let (g11, g12, g22) = (e1.dot(&e1), e1.dot(&e2), e2.dot(&e2));
            let (y1, y2) = (
                spheres[0].radius - spheres[1].radius,
                spheres[0].radius - spheres[2].radius,
            );
            let det = g11 * g22 - g12 * g12;
            let a1 = (y1 * g22 - y2 * g12) / det;
            let a2 = (y2 * g11 - y1 * g12) / det;
            let inplane = e1 * a1 + e2 * a2;
            let rest = 1.0 - inplane.norm_squared();
            if rest > 1e-12 {
                for sign in [1.0, -1.0] {
                    let n = inplane + m * (sign * rest.sqrt());
                    for a in 0..=density {
                        for b in 0..=(density - a) {
                            let l1 = a as f64 / density as f64;
                            let l2 = b as f64 / density as f64;
                            let l0 = 1.0 - l1 - l2;
                            let c = spheres[0].center * l0
                                + spheres[1].center * l1
                                + spheres[2].center * l2;
                            let r = spheres[0].radius * l0
                                + spheres[1].radius * l1
                                + spheres[2].radius * l2;
                            out.push((c + n * r, n));
                        }
                    }
                }
            }
        }
    }
    out
}
