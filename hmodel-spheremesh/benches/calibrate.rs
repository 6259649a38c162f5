//! Offline calibration speed (issue 6 "Speed"): the whole calibration of 8 frames × 2500 points
//! on one core (goal < 1 s), one linearization of all energies, and the damped solve of the
//! normal equations alone. The iteration count and milliseconds per iteration of a run are
//! printed once.

use criterion::{criterion_group, criterion_main, Criterion};
use hand_model::spheremesh::default_right_hand;
use hmodel_spheremesh::calibration::{calibrate, CalibrationConfig, LinearSolver};
use hmodel_spheremesh::synthetic::CalibrationScene;
use sensor_io::Camera;

fn bench_calibration(c: &mut Criterion) {
    let base = default_right_hand();
    let scene = CalibrationScene::new(&base, 1, 8, 2500, 0.15, &Camera::sr300_qvga()).unwrap();
    let config = CalibrationConfig::default();
    let run = calibrate(&base, &scene.frames, &scene.initial, &config).unwrap();
    let ms: Vec<f64> = run.iterations.iter().map(|r| r.ms).collect();
    println!(
        "calibration: {} iterations ({} accepted) in {:.3} s, {:.1} ms per iteration (mean)",
        run.iterations.len(),
        run.iterations.iter().filter(|r| r.accepted).count(),
        run.seconds,
        ms.iter().sum::<f64>() / ms.len().max(1) as f64
    );
    let mut group = c.benchmark_group("calibration");
    group.sample_size(10);
    group.bench_function("8 frames x 2500 points", |b| {
        b.iter(|| calibrate(&base, &scene.frames, &scene.initial, &config).unwrap())
    });
    // Many frames (Offline-Hard/Soft sub-sample ~1/20 of a sequence): the block-arrow solve
    // against the dense Cholesky, a few iterations each.
    let many = CalibrationScene::new(&base, 2, 32, 1000, 0.15, &Camera::sr300_qvga()).unwrap();
    for solver in [LinearSolver::BlockArrow, LinearSolver::Dense] {
        let config = CalibrationConfig {
            iterations: 3,
            solver,
            ..CalibrationConfig::default()
        };
        group.bench_function(
            format!("32 frames x 1000 points, 3 iterations, {solver:?}"),
            |b| b.iter(|| calibrate(&base, &many.frames, &many.initial, &config).unwrap()),
        );
    }
    group.finish();
}

criterion_group!(benches, bench_calibration);
criterion_main!(benches);
