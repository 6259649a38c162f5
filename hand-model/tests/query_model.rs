//! Model-wide projection `Π_M` and implicit function `φ_M` (thesis Eq. 3.6) on a hand-like
//! sphere-mesh: culled argmin equals the brute-force argmin over elements.

mod common;

#[path = "../benches/support/hand_like.rs"]
mod hand_like;

use common::*;
use hand_like::hand_like_geometry;
use hand_model::query::{GeometryError, Projection, SphereMeshGeometry};
use hand_model::shape::{Element, Sphere};
use nalgebra::Vector3;
use rand::Rng;

fn hand() -> (Vec<Sphere>, Vec<Element>, SphereMeshGeometry) {
    let (spheres, elements) = hand_like_geometry();
    let g = SphereMeshGeometry::new(&spheres, &elements).unwrap();
    (spheres, elements, g)
}

/// Random points in the model's bounding box (grown by 20 mm) and near its surface.
fn test_points(g: &SphereMeshGeometry, n: usize, seed: u64) -> Vec<Vector3<f64>> {
    let mut rng = rng(seed);
    let refs: Vec<&Sphere> = g.spheres().iter().collect();
    (0..n)
        .map(|k| {
            if k % 2 == 0 {
                random_point_near(&mut rng, &refs, 20.0)
            } else {
                let s = &g.spheres()[rng.random_range(0..g.spheres().len())];
                s.center + random_unit(&mut rng) * rng.random_range(0.0..s.radius + 10.0)
            }
        })
        .collect()
}

fn brute_over_elements(g: &SphereMeshGeometry, p: &Vector3<f64>) -> Projection {
    (0..g.elements().len())
        .map(|e| g.project_on_element(e, p).unwrap())
        .min_by(|a, b| a.distance.total_cmp(&b.distance))
        .unwrap()
}

#[test]
fn model_projection_equals_brute_force_over_elements() {
    let (spheres, elements, g) = hand();
    for p in test_points(&g, 20_000, 1) {
        let pr = g.project(&p).unwrap();
        let brute = brute_over_elements(&g, &p);
        assert_eq!(pr.distance, brute.distance, "p = {p:?}");
        // Ties go to the lower element index, as for the brute force's first minimum.
        assert_eq!(pr.element, brute.element, "p = {p:?}");
        assert_eq!(g.phi(&p), Some(pr.distance));
        check_projection(&pr, &p, &spheres);
        // The footpoint lies on the surface of its element.
        let on = g.phi_element(pr.element as usize, &pr.point).unwrap();
        assert!(on.abs() < 1e-9, "phi_e(q) = {on}");
        let own = elements[pr.element as usize].spheres();
        assert!(pr.spheres.iter().all(|i| own.contains(i)), "{pr:?}");
    }
}

#[test]
fn model_projection_of_random_meshes_equals_brute_force() {
    // Random meshes, also beyond the stack buffer of lower bounds (> 64 elements).
    let mut rng = rng(2);
    for n_elements in [1, 2, 5, 30, 80] {
        let spheres: Vec<Sphere> = (0..40)
            .map(|_| random_sphere(&mut rng, 60.0, 12.0))
            .collect();
        let elements: Vec<Element> = (0..n_elements)
            .map(|_| {
                let ids: [u32; 3] = std::array::from_fn(|_| rng.random_range(0..40u32));
                if rng.random_bool(0.5) {
                    Element::Pill([ids[0], ids[1]])
                } else {
                    Element::Wedge(ids)
                }
            })
            .collect();
        let g = SphereMeshGeometry::new(&spheres, &elements).unwrap();
        for p in test_points(&g, 2000, 3) {
            let pr = g.project(&p).unwrap();
            assert_eq!(pr.distance, brute_over_elements(&g, &p).distance);
            check_projection(&pr, &p, &spheres);
        }
    }
}

#[test]
fn update_reposes_without_changing_topology() {
    let (spheres, elements, mut g) = hand();
    let mut rng = rng(4);
    let moved: Vec<Sphere> = spheres
        .iter()
        .map(|s| {
            Sphere::new(
                s.center + random_vector(&mut rng, 5.0),
                s.radius * rng.random_range(0.8..1.2),
            )
        })
        .collect();
    g.update(&moved).unwrap();
    let fresh = SphereMeshGeometry::new(&moved, &elements).unwrap();
    for p in test_points(&g, 2000, 5) {
        assert_eq!(g.project(&p), fresh.project(&p));
        check_projection(&g.project(&p).unwrap(), &p, &moved);
    }
    assert_eq!(
        g.update(&moved[1..]),
        Err(GeometryError::SphereCountMismatch {
            expected: moved.len(),
            got: moved.len() - 1
        })
    );
    let mut bad = moved.clone();
    bad[3].radius = -1.0;
    assert_eq!(
        g.update(&bad),
        Err(GeometryError::InvalidSphere { index: 3 })
    );
    bad[3].radius = f64::NAN;
    assert_eq!(
        g.update(&bad),
        Err(GeometryError::InvalidSphere { index: 3 })
    );
    // A failed update leaves the geometry as it was.
    assert_eq!(g.spheres(), &moved[..]);
}

#[test]
fn construction_errors() {
    let s = [
        Sphere::new(Vector3::zeros(), 1.0),
        Sphere::new(Vector3::x(), 1.0),
    ];
    assert_eq!(
        SphereMeshGeometry::new(&s, &[Element::Wedge([0, 1, 2])]).unwrap_err(),
        GeometryError::SphereIndexOutOfRange {
            element: 0,
            sphere: 2,
            count: 2
        }
    );
    let empty = SphereMeshGeometry::new(&s, &[]).unwrap();
    assert!(empty.project(&Vector3::zeros()).is_none());
    assert!(empty.phi(&Vector3::zeros()).is_none());
}

#[test]
fn non_finite_points_give_none_and_batches_match_single_queries() {
    let (_, _, g) = hand();
    for bad in [
        Vector3::new(f64::NAN, 0.0, 0.0),
        Vector3::new(0.0, f64::INFINITY, 0.0),
        Vector3::new(0.0, 0.0, f64::NEG_INFINITY),
    ] {
        assert!(g.project(&bad).is_none());
        assert!(g.phi(&bad).is_none());
        assert!(g.project_on_element(0, &bad).is_none());
    }
    let mut points = test_points(&g, 500, 6);
    points[17] = Vector3::new(f64::NAN, 1.0, 2.0);
    let mut out = vec![None; points.len()];
    g.project_points(&points, &mut out);
    for (p, o) in points.iter().zip(&out) {
        assert_eq!(*o, g.project(p));
    }
    assert!(out[17].is_none());
}

#[test]
fn phi_sign_matches_inside_outside() {
    let (_, _, g) = hand();
    // Sphere centers are inside, far points outside.
    for s in g.spheres() {
        if s.radius > 0.0 {
            assert!(g.phi(&s.center).unwrap() < 0.0);
        }
    }
    // The hand sits around z = 400 mm: a point 500 mm behind the camera is far outside.
    assert!(g.phi(&Vector3::new(0.0, 0.0, -500.0)).unwrap() > 400.0);
    // Bounding balls contain their elements: the bound never exceeds φ_e.
    let mut rng = rng(8);
    for _ in 0..5000 {
        let p = random_vector(&mut rng, 150.0);
        for (e, b) in g.bounding_balls().iter().enumerate() {
            assert!((p - b.center).norm() - b.radius <= g.phi_element(e, &p).unwrap() + 1e-12);
        }
    }
}

#[test]
fn extreme_accepted_magnitudes_never_give_nan() {
    use hand_model::query::{View, MAX_COORDINATE};
    let (spheres, elements, _) = hand();
    let mut rng = rng(9);
    for scale in [1e-40, 1e-12, 1e12, 1e40, MAX_COORDINATE / 500.0] {
        let scaled: Vec<Sphere> = spheres
            .iter()
            .map(|s| Sphere::new(s.center * scale, s.radius * scale))
            .collect();
        let g = SphereMeshGeometry::new(&scaled, &elements).unwrap();
        let view = View::Perspective {
            camera_center: Vector3::new(0.0, 50.0, -400.0) * scale,
        };
        for _ in 0..300 {
            let p = random_vector(&mut rng, 200.0) * scale;
            for pr in [g.project(&p), g.project_front_facing(&p, &view)] {
                let pr = pr.expect("accepted input");
                let v = [
                    pr.point.x,
                    pr.point.y,
                    pr.point.z,
                    pr.normal.norm(),
                    pr.distance,
                    pr.weights[1],
                ];
                assert!(v.iter().all(|x| x.is_finite()), "scale {scale}: {pr:?}");
            }
        }
    }
    let g = SphereMeshGeometry::new(&spheres, &elements).unwrap();
    assert!(g
        .project(&Vector3::new(2.0 * MAX_COORDINATE, 0.0, 0.0))
        .is_none());
    let mut big = spheres.clone();
    big[0].radius = 2.0 * MAX_COORDINATE;
    assert!(SphereMeshGeometry::new(&big, &elements).is_err());
}
