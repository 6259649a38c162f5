//! Brute-force references for the render tests: an element is the union of the balls
//! `B(c(λ), r(λ))` over its skeleton (Eq. 3.1); sampling λ densely gives a union of balls that
//! lies inside the element and approaches it to `O(h²/r)`.

use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::raycast::Ray;
use crate::shape::{Element, Sphere};

type V3 = Vector3<f64>;

/// Balls on the skeleton of `element`, spaced by at most `step` mm along every edge.
pub(crate) fn skeleton_samples(spheres: &[Sphere], element: &Element, step: f64) -> Vec<Sphere> {
    let lerp = |a: &Sphere, b: &Sphere, t: f64| {
        Sphere::new(
            a.center * (1.0 - t) + b.center * t,
            a.radius * (1.0 - t) + b.radius * t,
        )
    };
    let mut out = Vec::new();
    match *element {
        Element::Pill([a, b]) => {
            let (a, b) = (&spheres[a as usize], &spheres[b as usize]);
            let n = ((a.center - b.center).norm() / step).ceil().max(1.0) as usize;
            for i in 0..=n {
                out.push(lerp(a, b, i as f64 / n as f64));
            }
        }
        Element::Wedge([a, b, c]) => {
            let (a, b, c) = (
                &spheres[a as usize],
                &spheres[b as usize],
                &spheres[c as usize],
            );
            let longest = (a.center - b.center)
                .norm()
                .max((b.center - c.center).norm())
                .max((c.center - a.center).norm());
            let n = (longest / step).ceil().max(1.0) as usize;
            for i in 0..=n {
                for j in 0..=n - i {
                    let (l2, l3) = (i as f64 / n as f64, j as f64 / n as f64);
                    let l1 = 1.0 - l2 - l3;
                    out.push(Sphere::new(
                        a.center * l1 + b.center * l2 + c.center * l3,
                        a.radius * l1 + b.radius * l2 + c.radius * l3,
                    ));
                }
            }
        }
    }
    out
}

/// `min over samples ‖p − c‖ − r`.
pub(crate) fn brute_sdf(samples: &[Sphere], p: &V3) -> f64 {
    samples
        .iter()
        .map(|s| (p - s.center).norm() - s.radius)
        .fold(f64::INFINITY, f64::min)
}

/// First entry of the ray into the union of the sampled balls (origin assumed outside).
pub(crate) fn brute_first_hit(samples: &[Sphere], ray: &Ray) -> Option<f64> {
    let mut best: Option<f64> = None;
    for s in samples {
        let w = ray.origin - s.center;
        let b = w.dot(&ray.dir);
        let disc = s.radius * s.radius - (w - ray.dir * b).norm_squared();
        if disc < 0.0 {
            continue;
        }
        let t = -b - disc.sqrt();
        if t >= ray.t_min && t <= ray.t_max && best.is_none_or(|x| t < x) {
            best = Some(t);
        }
    }
    best
}

/// A seeded generator (the same stream on every run).
pub(crate) fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// A uniform point in the cube `[-half, half]³` around `center`.
pub(crate) fn point_in_cube(rng: &mut ChaCha8Rng, center: &V3, half: f64) -> V3 {
    center
        + V3::new(
            rng.random_range(-half..half),
            rng.random_range(-half..half),
            rng.random_range(-half..half),
        )
}

/// A uniform unit vector.
pub(crate) fn unit_vector(rng: &mut ChaCha8Rng) -> V3 {
    loop {
        let v = point_in_cube(rng, &V3::zeros(), 1.0);
        let n = v.norm();
        if n > 0.1 && n <= 1.0 {
            return v / n;
        }
    }
}
