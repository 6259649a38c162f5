//! Model-wide projection of 2500 points near a hand-like sphere-mesh (thesis §3.3.1 quotes
//! 250 µs/iteration for closest points and +100 µs for front-facing ones at 2500 points/frame).
//!
//! Run with `cargo bench -p hand-model --bench projection`; divide the median by 2500 for ns/point.
//!
//! Two inputs: random points around a hand-like model (about half of the plain footpoints
//! back-facing: a worst case), and `rendered_4x2500/{clean,noisy}`: the default hand rendered
//! at 4 poses (rest, fingers bent, tilted 45° about x, turned 55° about y) 400 mm from a QVGA
//! camera and back-projected to 2500 points each, without and with σ = 1 mm noise along the
//! rays; one iteration runs the 4 frames, so µs per call = median / 4. There only 0–32 of 2500
//! plain footpoints are back-facing (orthographic), 0–5 (perspective).
//!
//! # Measured (issue 5)
//! Every variant once per round, 60 interleaved rounds in one process on the shared 2-core
//! machine (criterion medians swung by up to 50 % under the concurrent builds); µs per call of
//! 2500 points, and in parentheses the minimum over the minimum of `baseline_all_elements`
//! (every element's closed-form projection, ≈ 4.2 ms) in the same run. Before = e26b258, after
//! = the seeded calls (`project_points_seeded`, `project_points_front_facing_seeded`, seeds
//! from the slightly moved pose), lazily clipped union silhouette, block culling.
//!
//! | input, query                    | before      | after, unseeded | after, seeded |
//! |---------------------------------|-------------|-----------------|---------------|
//! | clean, plain                    | 463 (0.109) | 475 (0.112)     | 348 (0.083)   |
//! | clean, front-facing ortho       | 851 (0.199) | 516 (0.122)     | 388 (0.091)   |
//! | clean, front-facing perspective | 491 (0.115) | 471 (0.111)     | 341 (0.080)   |
//! | noisy, plain                    | 474 (0.111) | 478 (0.113)     | 352 (0.083)   |
//! | noisy, front-facing ortho       | 979 (0.231) | 562 (0.132)     | 431 (0.101)   |
//! | noisy, front-facing perspective | 857 (0.201) | 530 (0.125)     | 400 (0.094)   |
//!
//! The union silhouette, built per call before (≈ 40 % of a noisy orthographic front-facing
//! call), is now clipped lazily; the remaining cost is the plain search (≈ 127 ns per point:
//! about 4 bounding-ball survivors per point for ≈ 1.05 true candidates).

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use hand_model::query::{Projection, SphereMeshGeometry, View, NO_SEED};
use hand_model::shape::{Element, Sphere};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

#[path = "support/hand_like.rs"]
mod hand_like;
use hand_like::hand_like_geometry;

#[path = "support/rendered.rs"]
mod rendered;
use rendered::{rendered_scenes, RenderedScene};

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

/// One rendered frame prepared for the benchmark.
struct Frame {
    geometry: SphereMeshGeometry,
    points: Vec<Vector3<f64>>,
    /// The elements of the answers at the previous pose ([`RenderedScene::previous`]): what a
    /// tracker's seeds hold at a new solver iteration. Plain and per view.
    seeds_plain: Vec<u32>,
    seeds_front_facing: [Vec<u32>; 2],
}

/// The views of the rendered frames: the thesis' orthographic approximation and the exact
/// pinhole camera at the origin.
const RENDERED_VIEWS: [(&str, View); 2] = [
    (
        "orthographic",
        View::Orthographic(Vector3::new(0.0, 0.0, 1.0)),
    ),
    (
        "perspective",
        View::Perspective {
            camera_center: Vector3::new(0.0, 0.0, 0.0),
        },
    ),
];

fn frame(scene: &RenderedScene, input: &str, points: &[Vector3<f64>]) -> Frame {
    let geometry = SphereMeshGeometry::new(&scene.spheres, &scene.elements).expect("valid hand");
    let previous = SphereMeshGeometry::new(&scene.previous, &scene.elements).expect("valid hand");
    let mut out = vec![None; points.len()];
    let mut seeds_plain = vec![NO_SEED; points.len()];
    previous.project_points_seeded(points, &mut seeds_plain, &mut out);
    let seeds_front_facing = RENDERED_VIEWS.map(|(_, view)| {
        let mut seeds = vec![NO_SEED; points.len()];
        previous.project_points_front_facing_seeded(points, &view, &mut seeds, &mut out);
        seeds
    });
    let back_facing = RENDERED_VIEWS.map(|(_, view)| {
        geometry.project_points(points, &mut out);
        out.iter()
            .flatten()
            .filter(|q| view.is_back_facing(&q.point, &q.normal))
            .count()
    });
    eprintln!(
        "rendered {:>12} ({}): {} points, back-facing plain footpoints: {} orthographic, {} perspective",
        scene.name,
        input,
        points.len(),
        back_facing[0],
        back_facing[1]
    );
    Frame {
        geometry,
        points: points.to_vec(),
        seeds_plain,
        seeds_front_facing,
    }
}

/// The realistic case: the rendered frames of `support/rendered.rs` (4 poses, 2500 points
/// each), clean and with noise along the rays; one iteration projects every frame once, so a
/// call costs the median / 4. Seeded variants start from the answers at a slightly different
/// pose (a previous solver iteration); the seed buffers are reset outside the timing.
fn bench_rendered(c: &mut Criterion) {
    let scenes = rendered_scenes();
    let inputs = [
        (
            "clean",
            scenes
                .iter()
                .map(|s| frame(s, "clean", &s.points))
                .collect::<Vec<_>>(),
        ),
        (
            "noisy",
            scenes.iter().map(|s| frame(s, "noisy", &s.noisy)).collect(),
        ),
    ];
    let mut group = c.benchmark_group("rendered_4x2500");
    for (input, frames) in inputs {
        let mut outs: Vec<Vec<Option<Projection>>> =
            frames.iter().map(|f| vec![None; f.points.len()]).collect();
        let total: usize = frames.iter().map(|f| f.points.len()).sum();
        group.throughput(Throughput::Elements(total as u64));
        group.bench_function(format!("{input}/baseline_all_elements"), |b| {
            b.iter(|| {
                for (f, out) in frames.iter().zip(outs.iter_mut()) {
                    let g = &f.geometry;
                    for (p, o) in black_box(&f.points).iter().zip(out.iter_mut()) {
                        *o = (0..g.elements().len())
                            .filter_map(|e| g.project_on_element(e, p))
                            .min_by(|a, b| a.distance.total_cmp(&b.distance));
                    }
                }
            })
        });
        group.bench_function(format!("{input}/plain"), |b| {
            b.iter(|| {
                for (f, out) in frames.iter().zip(outs.iter_mut()) {
                    f.geometry.project_points(black_box(&f.points), out);
                }
            })
        });
        group.bench_function(format!("{input}/plain_seeded"), |b| {
            b.iter_batched_ref(
                || {
                    frames
                        .iter()
                        .map(|f| f.seeds_plain.clone())
                        .collect::<Vec<_>>()
                },
                |seeds| {
                    for ((f, s), out) in frames.iter().zip(seeds.iter_mut()).zip(outs.iter_mut()) {
                        f.geometry
                            .project_points_seeded(black_box(&f.points), s, out);
                    }
                },
                BatchSize::SmallInput,
            )
        });
        for (v, (name, view)) in RENDERED_VIEWS.iter().enumerate() {
            group.bench_function(format!("{input}/front_facing_{name}"), |b| {
                b.iter(|| {
                    for (f, out) in frames.iter().zip(outs.iter_mut()) {
                        f.geometry
                            .project_points_front_facing(black_box(&f.points), view, out);
                    }
                })
            });
            group.bench_function(format!("{input}/front_facing_{name}_seeded"), |b| {
                b.iter_batched_ref(
                    || {
                        let seeds = frames.iter().map(|f| f.seeds_front_facing[v].clone());
                        seeds.collect::<Vec<_>>()
                    },
                    |seeds| {
                        for ((f, s), out) in
                            frames.iter().zip(seeds.iter_mut()).zip(outs.iter_mut())
                        {
                            f.geometry.project_points_front_facing_seeded(
                                black_box(&f.points),
                                view,
                                s,
                                out,
                            );
                        }
                    },
                    BatchSize::SmallInput,
                )
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench_projection, bench_rendered);
criterion_main!(benches);
