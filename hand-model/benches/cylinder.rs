//! Model-wide cylinder queries (thesis §2.3.1) for 2500 points near the posed default cylinder
//! hand: the closest point and the front-facing correspondence, each with the brute-force
//! baseline (every segment projected, no culling) measured in the same run.
//!
//! Run with `cargo bench -p hand-model --bench cylinder`; divide the median by 2500 for ns/point.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use hand_model::cylinder::{default_right_hand_cylinders, CylinderProjection, View};
use hand_model::kinematics::Pose;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

const POINTS: usize = 2500;

fn bench_cylinder(c: &mut Criterion) {
    let model = default_right_hand_cylinders();
    // 40 cm in front of the camera, turned a little, fingers half flexed.
    let mut values = vec![0.0; model.skeleton.dofs().len()];
    for (v, d) in values.iter_mut().zip(model.skeleton.dofs()) {
        *v = match d.name.as_str() {
            "global_tz" => 400.0,
            "global_rx" => 0.3,
            "global_ry" => -0.4,
            n if n.ends_with("_flex") => 0.5,
            _ => 0.0,
        };
    }
    let pose = Pose::from_values(&model.skeleton, values).expect("valid pose");
    let posed = model.posed(&pose).expect("valid pose");

    // Points within a few mm of the segments, in their bone frames.
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let points: Vec<Vector3<f64>> = (0..POINTS)
        .map(|_| {
            let s = &model.segments[rng.random_range(0..model.segments.len())];
            let local = Vector3::new(
                rng.random_range(-1.5..1.5) * (s.r1.max(s.r2) + 4.0),
                rng.random_range(-8.0..s.length + 8.0),
                rng.random_range(-1.5..1.5) * (s.r1y.max(s.r2y) + 4.0),
            );
            posed.point(s.bone, &local)
        })
        .collect();
    let mut out: Vec<Option<CylinderProjection>> = vec![None; POINTS];

    let mut group = c.benchmark_group("cylinder_2500");
    group.throughput(Throughput::Elements(POINTS as u64));
    group.bench_function("closest_brute_force", |b| {
        b.iter(|| {
            for (p, o) in black_box(&points).iter().zip(out.iter_mut()) {
                *o = model.closest_point_brute_force(&posed, p);
            }
        })
    });
    group.bench_function("closest", |b| {
        b.iter(|| model.project_points(&posed, black_box(&points), None, black_box(&mut out)))
    });
    for (name, view) in [
        ("orthographic", View::Orthographic),
        ("perspective", View::Perspective),
    ] {
        group.bench_function(format!("front_facing_{name}_brute_force"), |b| {
            b.iter(|| {
                for (p, o) in black_box(&points).iter().zip(out.iter_mut()) {
                    *o = model.front_facing_point_brute_force(&posed, p, view);
                }
            })
        });
        group.bench_function(format!("front_facing_{name}"), |b| {
            b.iter(|| {
                model.project_points(&posed, black_box(&points), Some(view), black_box(&mut out))
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_cylinder);
criterion_main!(benches);
