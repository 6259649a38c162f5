//! The per-iteration queries allocate nothing: `update`, `project_points` and
//! `project_points_front_facing` (seeded, coherent or neither) and the per-frame
//! `Coherence::carry_to_pixels` run under a counting global allocator.
// Implementing `GlobalAlloc` needs `unsafe`; it only forwards to the system allocator.
#![allow(unsafe_code)]

#[path = "../benches/support/hand_like.rs"]
mod hand_like;

use hand_like::hand_like_geometry;
use hand_model::query::{SphereMeshGeometry, View};
use nalgebra::Vector3;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

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

    // This file holds a single test, so nothing else allocates while it runs.
    let before = ALLOCATIONS.load(Ordering::SeqCst);
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
    let single = g.project_front_facing(&points[0], &views[0]);
    let after = ALLOCATIONS.load(Ordering::SeqCst);
    // Some footpoints were back-facing (the silhouette was built): substitutes differ from the
    // plain projections.
    let mut plain = vec![None; points.len()];
    g.project_points(&points, &mut plain);
    assert!(out.iter().zip(&plain).any(|(a, b)| a != b));
    assert!(single.is_some() && out.iter().all(Option::is_some));
    assert_eq!(
        after - before,
        0,
        "allocations during per-iteration queries"
    );
}
