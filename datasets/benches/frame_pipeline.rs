//! Per-frame costs of the input side (issue 3 "Speed"): rendering a QVGA synthetic frame (and,
//! beside it, a 10 000-triangle mesh with `datasets::mesh`, the size of a hand scan), and
//! preprocessing one QVGA frame (segment, normals, distance transform, 2500-point subsample),
//! with the depth-only and the wristband segmentations and both subsamplings.
//!
//! `cargo bench -p datasets --bench frame_pipeline`

use criterion::{criterion_group, criterion_main, Criterion};
use datasets::mesh::{render_mesh_depth, TriangleMesh};
use datasets::noise::SensorModel;
use datasets::synth::{SceneConfig, Synthesizer};
use datasets::MotionLibrary;
use hand_model::spheremesh::default_right_hand;
use nalgebra::Vector3;
use sensor_io::preprocess::{
    DepthOnlyParams, PreprocessConfig, PreprocessedFrame, Preprocessor, Segmentation, Subsampling,
    WristbandParams,
};
use sensor_io::Camera;

/// A latitude-longitude sphere of `2 · stacks · slices` triangles (poles included as
/// degenerate ones, which the renderer skips).
fn uv_sphere(center: Vector3<f64>, radius: f64, stacks: u32, slices: u32) -> TriangleMesh {
    let mut mesh = TriangleMesh::default();
    for i in 0..=stacks {
        let polar = std::f64::consts::PI * f64::from(i) / f64::from(stacks);
        for j in 0..slices {
            let azimuth = std::f64::consts::TAU * f64::from(j) / f64::from(slices);
            let d = Vector3::new(
                polar.sin() * azimuth.cos(),
                polar.cos(),
                polar.sin() * azimuth.sin(),
            );
            mesh.vertices.push(center + d * radius);
        }
    }
    let at = |i: u32, j: u32| i * slices + j % slices;
    for i in 0..stacks {
        for j in 0..slices {
            mesh.triangles
                .push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            mesh.triangles
                .push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    mesh
}

fn bench(c: &mut Criterion) {
    let template = default_right_hand();
    let motion = MotionLibrary::by_name_for("teaser", 7, &template.skeleton).expect("motion");
    let config = SceneConfig {
        sensor: SensorModel::by_name("tof").expect("tof"),
        ..Default::default()
    };
    let mut synth = Synthesizer::new(&template, &[], config).expect("synth");
    let pose = motion.pose_at(2.0);
    c.bench_function("synth_render_qvga_tof", |b| {
        b.iter(|| synth.render(0, 2.0, &pose).expect("render"))
    });
    let frame = synth.render(0, 2.0, &pose).expect("render").frame;
    let cam = Camera::sr300_qvga();
    let sphere = uv_sphere(Vector3::new(0.0, 0.0, 400.0), 80.0, 50, 100);
    c.bench_function("mesh_render_qvga_10k_triangles", |b| {
        b.iter(|| render_mesh_depth(&sphere, &cam))
    });
    let mut out = PreprocessedFrame::default();
    for (name, seg, sub) in [
        (
            "preprocess_qvga_depth_only_uniform",
            Segmentation::DepthOnly(DepthOnlyParams::default()),
            Subsampling::Uniform,
        ),
        (
            "preprocess_qvga_depth_only_farthest",
            Segmentation::DepthOnly(DepthOnlyParams::default()),
            Subsampling::Farthest,
        ),
        (
            "preprocess_qvga_wristband_uniform",
            Segmentation::Wristband(WristbandParams::default()),
            Subsampling::Uniform,
        ),
    ] {
        let mut pre = Preprocessor::new(PreprocessConfig {
            segmentation: seg,
            subsampling: sub,
            num_points: 2500,
            ..Default::default()
        });
        c.bench_function(name, |b| {
            b.iter(|| pre.process(&frame, &cam, &mut out).expect("process"))
        });
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
