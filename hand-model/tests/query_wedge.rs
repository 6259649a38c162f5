//! Wedge projections (thesis §3.3.1, Fig. 3.7 right) against brute force, and degenerate wedges.

mod common;

use common::*;
use hand_model::query::{phi_wedge, project_point_wedge, Part};
use hand_model::shape::Sphere;
use nalgebra::Vector3;
use rand::Rng;

fn check_wedge(p: &Vector3<f64>, s: [&Sphere; 3]) -> (f64, Part) {
    let pr = project_point_wedge(p, s).expect("finite input");
    check_projection(&pr, p, &[*s[0], *s[1], *s[2]]);
    let scale = 1.0 + p.norm() + s.iter().map(|x| x.center.norm() + x.radius).sum::<f64>();
    let brute = brute_wedge(p, s);
    assert!(
        pr.distance <= brute + 1e-9 * scale,
        "above brute force: {} vs {brute} ({:?})",
        pr.distance,
        pr.part
    );
    assert!(
        pr.distance >= brute - 1e-7 * scale,
        "below brute force: {} vs {brute} ({:?})",
        pr.distance,
        pr.part
    );
    assert_eq!(phi_wedge(p, s), Some(pr.distance));
    let on_surface = phi_wedge(&pr.point, s).unwrap();
    assert!(on_surface.abs() < 1e-9 * scale, "phi(q) = {on_surface}");
    assert!(brute_wedge(&pr.point, s).abs() < 1e-7 * scale);
    let qs = pr.point - pr.skeleton_point;
    if qs.norm() > 1e-6 {
        assert!(
            (qs.normalize() - pr.normal).norm() < 1e-9,
            "normal != (q - s)/|q - s|"
        );
    }
    assert!((p - pr.point - pr.normal * pr.distance).norm() < 1e-8 * scale);
    (pr.distance, pr.part)
}

#[test]
fn wedge_matches_brute_force() {
    let mut rng = rng(11);
    let mut parts = [0usize; 3];
    let (mut inside, mut outside) = (0, 0);
    for _ in 0..200 {
        let s = [
            random_sphere(&mut rng, 20.0, 10.0),
            random_sphere(&mut rng, 20.0, 10.0),
            random_sphere(&mut rng, 20.0, 10.0),
        ];
        for k in 0..10 {
            let p = if k % 2 == 0 {
                random_point_near(&mut rng, &[&s[0], &s[1], &s[2]], 10.0)
            } else {
                let (l1, l2): (f64, f64) = (rng.random(), rng.random());
                let (l1, l2) = if l1 + l2 > 1.0 {
                    (1.0 - l1, 1.0 - l2)
                } else {
                    (l1, l2)
                };
                let l0 = 1.0 - l1 - l2;
                let c = s[0].center * l0 + s[1].center * l1 + s[2].center * l2;
                let r = s[0].radius * l0 + s[1].radius * l1 + s[2].radius * l2;
                c + random_unit(&mut rng) * rng.random_range(0.0..1.5 * r + 1e-3)
            };
            let (d, part) = check_wedge(&p, [&s[0], &s[1], &s[2]]);
            parts[match part {
                Part::Sphere => 0,
                Part::Cone => 1,
                _ => 2,
            }] += 1;
            if d < 0.0 {
                inside += 1;
            } else {
                outside += 1;
            }
        }
    }
    assert!(
        parts.iter().all(|&n| n > 100),
        "part counts (sphere, cone, plane): {parts:?}"
    );
    assert!(
        inside > 200 && outside > 200,
        "inside {inside}, outside {outside}"
    );
}

#[test]
fn palm_like_wedges_match_brute_force() {
    // Flat wedges with similar radii, as in a palm: mostly planar footpoints.
    let mut rng = rng(12);
    for _ in 0..100 {
        let r = rng.random_range(5.0..12.0);
        let s = [0, 1, 2].map(|i| {
            let c = Vector3::new(
                30.0 * (i as f64 - 1.0),
                if i == 1 { 40.0 } else { 0.0 },
                0.0,
            );
            Sphere::new(
                c + random_vector(&mut rng, 3.0),
                r + rng.random_range(-3.0..3.0),
            )
        });
        for _ in 0..10 {
            let p = random_point_near(&mut rng, &[&s[0], &s[1], &s[2]], 10.0);
            check_wedge(&p, [&s[0], &s[1], &s[2]]);
        }
    }
}

#[test]
fn degenerate_wedges_never_give_nan() {
    let mut rng = rng(5);
    let o = Vector3::new(-2.0, 1.0, 4.0);
    let x = Vector3::x();
    let y = Vector3::y();
    let sp = |c: Vector3<f64>, r: f64| Sphere::new(c, r);
    let cases = [
        // Equal radii.
        [sp(o, 3.0), sp(o + x * 10.0, 3.0), sp(o + y * 10.0, 3.0)],
        // Collinear centers (third in the middle, bulging and not; third outside the segment).
        [sp(o, 3.0), sp(o + x * 10.0, 2.0), sp(o + x * 5.0, 6.0)],
        [sp(o, 3.0), sp(o + x * 10.0, 2.0), sp(o + x * 5.0, 1.0)],
        [sp(o, 3.0), sp(o + x * 10.0, 2.0), sp(o + x * 15.0, 4.0)],
        // Nearly collinear.
        [
            sp(o, 3.0),
            sp(o + x * 10.0, 2.0),
            sp(o + x * 5.0 + y * 1e-9, 4.0),
        ],
        // One sphere swallowed by another.
        [sp(o, 9.0), sp(o + x * 3.0, 2.0), sp(o + y * 20.0, 3.0)],
        [sp(o, 9.0), sp(o + x * 7.0, 2.0), sp(o + y * 20.0, 3.0)],
        // Two swallowed.
        [sp(o, 12.0), sp(o + x * 3.0, 2.0), sp(o + y * 4.0, 3.0)],
        // Coincident centers.
        [sp(o, 3.0), sp(o, 5.0), sp(o + y * 10.0, 2.0)],
        [sp(o, 3.0), sp(o, 3.0), sp(o, 3.0)],
        // Zero radii: a flat triangle; a point.
        [sp(o, 0.0), sp(o + x * 10.0, 0.0), sp(o + y * 10.0, 0.0)],
        [sp(o, 0.0), sp(o, 0.0), sp(o, 0.0)],
        // Radius gradient of exactly 1 along an edge (tangent planes degenerate).
        [sp(o, 1.0), sp(o + x * 10.0, 11.0), sp(o + y * 10.0, 1.0)],
    ];
    for s in &cases {
        let refs = [&s[0], &s[1], &s[2]];
        let mut points = vec![
            s[0].center,
            s[1].center,
            s[2].center,
            (s[0].center + s[1].center + s[2].center) / 3.0,
        ];
        for _ in 0..100 {
            points.push(random_point_near(&mut rng, &refs, 5.0));
        }
        for p in &points {
            let pr = project_point_wedge(p, refs).unwrap();
            check_projection(&pr, p, s);
            let scale = 1.0 + p.norm() + s.iter().map(|x| x.center.norm() + x.radius).sum::<f64>();
            let brute = brute_wedge(p, refs);
            assert!(
                (pr.distance - brute).abs() < 1e-7 * scale,
                "{s:?} {p:?}: {} vs {brute}",
                pr.distance
            );
        }
    }
}

#[test]
fn non_finite_input_is_rejected() {
    let s = [
        Sphere::new(Vector3::zeros(), 1.0),
        Sphere::new(Vector3::x(), 1.0),
        Sphere::new(Vector3::y(), 1.0),
    ];
    let refs = [&s[0], &s[1], &s[2]];
    assert!(project_point_wedge(&Vector3::new(f64::NAN, 0.0, 0.0), refs).is_none());
    assert!(phi_wedge(&Vector3::new(0.0, f64::NEG_INFINITY, 0.0), refs).is_none());
    let bad = Sphere::new(Vector3::new(0.0, 0.0, f64::NAN), 1.0);
    assert!(project_point_wedge(&Vector3::zeros(), [&s[0], &s[1], &bad]).is_none());
}
