//! Per-frame costs of the input side (issue 3 "Speed"): rendering a QVGA synthetic frame, and
//! preprocessing one QVGA frame (segment, normals, distance transform, 2500-point subsample),
//! with the depth-only and the wristband segmentations and both subsamplings.
//!
//! `cargo bench -p datasets --bench frame_pipeline`

use criterion::{criterion_group, criterion_main, Criterion};
use datasets::noise::SensorModel;
use datasets::synth::{SceneConfig, Synthesizer};
use datasets::MotionLibrary;
use hand_model::spheremesh::default_right_hand;
use sensor_io::preprocess::{
    DepthOnlyParams, PreprocessConfig, PreprocessedFrame, Preprocessor, Segmentation, Subsampling,
    WristbandParams,
};
use sensor_io::Camera;

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
