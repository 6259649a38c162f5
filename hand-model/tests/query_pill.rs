//! Pill projections (thesis §3.3.1, Fig. 3.7 left) against brute force and parry3d, and
//! degenerate pills.

mod common;

use common::*;
use hand_model::query::{phi_pill, project_point_pill, Part};
use hand_model::shape::Sphere;
use nalgebra::Vector3;
use parry3d::query::PointQuery;
use parry3d::shape::Capsule;
use rand::Rng;

/// Projects `p` and checks it against the brute-force distance and the surface/normal
/// invariants. Returns the projection's distance.
fn check_pill(p: &Vector3<f64>, a: &Sphere, b: &Sphere) -> f64 {
    let pr = project_point_pill(p, a, b).expect("finite input");
    check_projection(&pr, p, &[*a, *b]);
    let scale = 1.0 + p.norm() + a.center.norm() + b.center.norm() + a.radius + b.radius;
    let brute = brute_pill(p, a, b);
    assert!(
        pr.distance <= brute + 1e-9 * scale,
        "above brute force: {} vs {brute}",
        pr.distance
    );
    assert!(
        pr.distance >= brute - 1e-7 * scale,
        "below brute force: {} vs {brute}",
        pr.distance
    );
    assert_eq!(phi_pill(p, a, b), Some(pr.distance));
    // q is on the surface, with the normal of the generating sphere.
    let on_surface = phi_pill(&pr.point, a, b).unwrap();
    assert!(on_surface.abs() < 1e-9 * scale, "phi(q) = {on_surface}");
    assert!(brute_pill(&pr.point, a, b).abs() < 1e-7 * scale);
    let qs = pr.point - pr.skeleton_point;
    if qs.norm() > 1e-6 {
        assert!(
            (qs.normalize() - pr.normal).norm() < 1e-9,
            "normal != (q - s)/|q - s|"
        );
    }
    // p lies on the normal line through q.
    assert!((p - pr.point - pr.normal * pr.distance).norm() < 1e-9 * scale);
    pr.distance
}

#[test]
fn pill_matches_brute_force() {
    let mut rng = rng(42);
    let (mut inside, mut outside) = (0, 0);
    for _ in 0..300 {
        let a = random_sphere(&mut rng, 20.0, 12.0);
        let b = random_sphere(&mut rng, 20.0, 12.0);
        for k in 0..20 {
            // Half the points near the skeleton, to exercise the inside.
            let p = if k % 2 == 0 {
                random_point_near(&mut rng, &[&a, &b], 10.0)
            } else {
                let t: f64 = rng.random();
                let r = a.radius * (1.0 - t) + b.radius * t;
                a.center * (1.0 - t)
                    + b.center * t
                    + random_unit(&mut rng) * rng.random_range(0.0..1.5 * r + 1e-3)
            };
            if check_pill(&p, &a, &b) < 0.0 {
                inside += 1;
            } else {
                outside += 1;
            }
        }
    }
    assert!(
        inside > 500 && outside > 500,
        "inside {inside}, outside {outside}"
    );
}

#[test]
fn pill_parts_are_labelled() {
    let a = Sphere::new(Vector3::zeros(), 4.0);
    let b = Sphere::new(Vector3::new(20.0, 0.0, 0.0), 2.0);
    let part = |p: Vector3<f64>| project_point_pill(&p, &a, &b).unwrap().part;
    assert_eq!(part(Vector3::new(10.0, 10.0, 0.0)), Part::Cone);
    assert_eq!(part(Vector3::new(-10.0, 1.0, 0.0)), Part::Sphere);
    assert_eq!(part(Vector3::new(30.0, 1.0, 0.0)), Part::Sphere);
}

#[test]
fn equal_radii_pill_matches_parry_capsule() {
    let mut rng = rng(7);
    let f = |v: &Vector3<f64>| parry3d::math::Vector::new(v.x as f32, v.y as f32, v.z as f32);
    for _ in 0..500 {
        let r = rng.random_range(0.5..10.0);
        let a = Sphere::new(random_vector(&mut rng, 20.0), r);
        let b = Sphere::new(random_vector(&mut rng, 20.0), r);
        let capsule = Capsule::new(f(&a.center), f(&b.center), r as f32);
        for _ in 0..10 {
            let p = random_point_near(&mut rng, &[&a, &b], 8.0);
            let ours = project_point_pill(&p, &a, &b).unwrap();
            let theirs = capsule.project_local_point(f(&p), false);
            let q = Vector3::new(
                theirs.point.x as f64,
                theirs.point.y as f64,
                theirs.point.z as f64,
            );
            let signed = if theirs.is_inside {
                -(p - q).norm()
            } else {
                (p - q).norm()
            };
            let tol = 2e-5 * (1.0 + p.norm() + a.center.norm() + b.center.norm() + r);
            assert!(
                (ours.distance - signed).abs() < tol,
                "{} vs parry {signed}",
                ours.distance
            );
            // Footpoints agree except where the closest point is not unique (p on the axis).
            if (p - ours.skeleton_point).norm() > 1e-2 {
                assert!(
                    (ours.point - q).norm() < 1e2 * tol,
                    "{:?} vs parry {q:?}",
                    ours.point
                );
            }
        }
    }
}

#[test]
fn degenerate_pills_never_give_nan() {
    let mut rng = rng(3);
    let c = Vector3::new(1.0, 2.0, 3.0);
    let cases = [
        // Equal radii.
        (
            Sphere::new(c, 3.0),
            Sphere::new(c + Vector3::new(10.0, 0.0, 0.0), 3.0),
        ),
        // Coincident centers, different and equal radii.
        (Sphere::new(c, 3.0), Sphere::new(c, 5.0)),
        (Sphere::new(c, 3.0), Sphere::new(c, 3.0)),
        // A sphere inside its neighbour: strictly, exactly touching from inside, and barely out.
        (
            Sphere::new(c, 8.0),
            Sphere::new(c + Vector3::new(3.0, 0.0, 0.0), 2.0),
        ),
        (
            Sphere::new(c, 8.0),
            Sphere::new(c + Vector3::new(6.0, 0.0, 0.0), 2.0),
        ),
        (
            Sphere::new(c, 8.0),
            Sphere::new(c + Vector3::new(6.0 + 1e-13, 0.0, 0.0), 2.0),
        ),
        (
            Sphere::new(c + Vector3::new(0.0, 4.0, 0.0), 2.0),
            Sphere::new(c, 9.0),
        ),
        // Zero radii: a segment, a point.
        (
            Sphere::new(c, 0.0),
            Sphere::new(c + Vector3::new(0.0, 0.0, 7.0), 0.0),
        ),
        (Sphere::new(c, 0.0), Sphere::new(c, 0.0)),
        (
            Sphere::new(c, 0.0),
            Sphere::new(c + Vector3::new(5.0, 5.0, 0.0), 4.0),
        ),
        // Tiny and huge scales.
        (
            Sphere::new(c, 1e-9),
            Sphere::new(c + Vector3::new(1e-9, 0.0, 0.0), 2e-9),
        ),
        (
            Sphere::new(c * 1e5, 1e4),
            Sphere::new(c * 1e5 + Vector3::new(3e4, 0.0, 0.0), 2e4),
        ),
    ];
    for (a, b) in cases {
        let mut points = vec![
            a.center,
            b.center,
            (a.center + b.center) * 0.5,
            a.center * 0.25 + b.center * 0.75,
        ];
        for _ in 0..200 {
            points.push(random_point_near(&mut rng, &[&a, &b], 5.0));
        }
        for p in &points {
            let pr = project_point_pill(p, &a, &b).unwrap();
            check_projection(&pr, p, &[a, b]);
            let scale = 1.0 + p.norm() + a.center.norm() + b.center.norm() + a.radius + b.radius;
            let brute = brute_pill(p, &a, &b);
            assert!(
                (pr.distance - brute).abs() < 1e-7 * scale,
                "{a:?} {b:?} {p:?}: {} vs {brute}",
                pr.distance
            );
        }
    }
}
