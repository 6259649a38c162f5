//! Model-wide projection of 2500 points near a hand-like sphere-mesh (thesis §3.3.1 quotes
//! 250 µs/iteration for closest points and +100 µs for front-facing ones at 2500 points/frame).
//!
//! Run with `cargo bench -p hand-model --bench projection`; divide the median by 2500 for ns/point.

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use hand_model::query::{Projection, SphereMeshGeometry, View};
use hand_model::shape::{Element, Sphere};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

#[path = "support/hand_like.rs"]
mod hand_like;
use hand_like::hand_like_geometry;

const POINTS: usize = 2500;

/// Points within a few mm of the surface: a random skeleton point of a random element, pushed
/// out along a random direction to its interpolated radius plus an offset in [−4, 12] mm.
fn points_near(spheres: &[Sphere], elements: &[Element], n: usize, seed: u64) -> Vec<Vector3<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let el = &elements[rng.random_range(0..elements.len())];
            let ids = el.spheres();
            let mut w: Vec<f64> = ids
                .iter()
                .map(|_| -rng.random::<f64>().max(1e-12).ln())
                .collect();
            let sum: f64 = w.iter().sum();
            w.iter_mut().for_each(|x| *x /= sum);
            let mut c = Vector3::zeros();
            let mut r = 0.0;
            for (i, wi) in ids.iter().zip(&w) {
                c += spheres[*i as usize].center * *wi;
                r += spheres[*i as usize].radius * *wi;
            }
            let dir = loop {
                let d = Vector3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                );
                let len: f64 = d.norm();
                if len > 0.1 && len <= 1.0 {
                    break d / len;
                }
            };
            c + dir * (r + rng.random_range(-4.0..12.0))
        })
        .collect()
}

fn bench_projection(c: &mut Criterion) {
    let (spheres, elements) = hand_like_geometry();
    let geometry = SphereMeshGeometry::new(&spheres, &elements).expect("valid hand-like model");
    let points = points_near(&spheres, &elements, POINTS, 7);
    let ortho = View::Orthographic(Vector3::z());
    let perspective = View::Perspective {
        camera_center: Vector3::new(0.0, 50.0, -400.0),
    };
    let mut out: Vec<Option<Projection>> = vec![None; POINTS];

    let back_facing = points
        .iter()
        .filter_map(|p| geometry.project(p))
        .filter(|q| ortho.is_back_facing(&q.point, &q.normal))
        .count();
    eprintln!(
        "hand-like model: {} spheres, {} elements; {back_facing}/{POINTS} plain footpoints back-facing (orthographic +z)",
        spheres.len(),
        elements.len()
    );

    let mut group = c.benchmark_group("projection_2500");
    group.throughput(Throughput::Elements(POINTS as u64));
    // Baseline measured in the same run: every element's closed-form projection, no culling
    // (the thesis' "brute force" over the 30 elements).
    group.bench_function("baseline_all_elements", |b| {
        b.iter(|| {
            for (p, o) in black_box(&points).iter().zip(out.iter_mut()) {
                *o = (0..elements.len())
                    .filter_map(|e| geometry.project_on_element(e, p))
                    .min_by(|a, b| a.distance.total_cmp(&b.distance));
            }
        })
    });
    group.bench_function("plain", |b| {
        b.iter(|| geometry.project_points(black_box(&points), black_box(&mut out)))
    });
    group.bench_function("front_facing_orthographic", |b| {
        b.iter(|| {
            geometry.project_points_front_facing(black_box(&points), &ortho, black_box(&mut out))
        })
    });
    group.bench_function("front_facing_perspective", |b| {
        b.iter(|| {
            geometry.project_points_front_facing(
                black_box(&points),
                &perspective,
                black_box(&mut out),
            )
        })
    });
    group.finish();

    // Re-posing (tangent planes, bounding balls, tree refit) once per solver iteration.
    c.bench_function("update_pose", |b| {
        b.iter_batched_ref(
            || geometry.clone(),
            |g| g.update(black_box(&spheres)),
            BatchSize::SmallInput,
        )
    });
}

criterion_group!(benches, bench_projection);
criterion_main!(benches);
