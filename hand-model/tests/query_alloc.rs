//! The per-iteration queries allocate nothing: `update`, `project_points` and
//! `project_points_front_facing` (seeded, coherent or neither) and the per-frame
//! `Coherence::carry_to_pixels` run under a counting global allocator.
#![allow(unsafe_code)] // the counting allocator of the included file

#[path = "support/counting_alloc.rs"]
mod counting_alloc;

#[path = "../benches/support/hand_like.rs"]
mod hand_like;

use hand_like::hand_like_geometry;
use hand_model::query::{SphereMeshGeometry, View};
use nalgebra::Vector3;

#[test]
fn per_iteration_queries_do_not_allocate() {
    let (spheres, elements) = hand_like_geometry();
    let mut g = SphereMeshGeometry::new(&spheres, &elements).unwrap();
    let moved: Vec<_> = spheres
        .iter()
        .map(|s| hand_model::shape::Sphere::new(s.center + Vector3::new(1.0, -2.0, 0.5), s.radius))
        .collect();
    let mut points: Vec<Vector3<f64>> = (0..500)
        .map(|i| {
            let t = i as f64 * 0.37;
            Vector3::new(
                60.0 * t.sin(),
                60.0 + 70.0 * (0.7 * t).cos(),
                25.0 * (1.3 * t).sin(),
            )
        })
        .collect();
    // And points behind each sphere (+z, away from both views): back-facing footpoints.
    points.extend(
        spheres
            .iter()
            .map(|s| s.center + Vector3::new(0.0, 0.0, s.radius + 3.0)),
    );
    let mut out = vec![None; points.len()];
    let mut seeds = vec![hand_model::query::NO_SEED; points.len()];
    // A coherent state sized by a first call (the only one that allocates).
    let mut coherence = hand_model::query::Coherence::default();
    let pixels: Vec<u32> = (0..points.len() as u32).map(|i| 2 * i).collect();
    coherence.carry_to_pixels(&pixels, 64, 4 * points.len() as u32 / 64 + 1);
    g.project_points_coherent(&points, &mut coherence, &mut out);
    // Carried once, so that its scratch is sized.
    coherence.carry_to_pixels(&pixels, 64, 4 * points.len() as u32 / 64 + 1);
    g.project_points_coherent(&points, &mut coherence, &mut out);
    let views = [
        View::Orthographic(Vector3::z()),
        View::Perspective {
            camera_center: Vector3::new(0.0, 50.0, -400.0),
        },
    ];
    // The coherent state keeps the silhouette of the front-facing calls (allocated once).
    g.project_points_front_facing_coherent(&points, &views[0], &mut coherence, &mut out);

    let (allocations, single) = counting_alloc::count(|| {
        g.update(&moved).unwrap();
        coherence.carry_to_pixels(&pixels, 64, 4 * points.len() as u32 / 64 + 1);
        g.project_points(&points, &mut out);
        g.project_points_seeded(&points, &mut seeds, &mut out);
        g.project_points_coherent(&points, &mut coherence, &mut out);
        for view in &views {
            g.project_points_front_facing(&points, view, &mut out);
            g.project_points_front_facing_seeded(&points, view, &mut seeds, &mut out);
            g.project_points_front_facing_coherent(&points, view, &mut coherence, &mut out);
        }
        g.project_front_facing(&points[0], &views[0])
    });
    // Some footpoints were back-facing (the silhouette was built): substitutes differ from the
    // plain projections.
    let mut plain = vec![None; points.len()];
    g.project_points(&points, &mut plain);
    assert!(out.iter().zip(&plain).any(|(a, b)| a != b));
    assert!(single.is_some() && out.iter().all(Option::is_some));
    assert_eq!(allocations, 0, "allocations during per-iteration queries");
}
