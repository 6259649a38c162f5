//! Tests of the along-ray correspondences ([`TrackingCtx::set_ray_gate`]).

use hand_model::cylinder::{default_right_hand_cylinders, CylinderModel, View};
use hand_model::kinematics::Pose;
use hand_model::solver::LmOptions;
use nalgebra::Vector3;
use sensor_io::preprocess::{HandSegment, PreprocessedFrame};
use sensor_io::DepthImage;

use crate::terms::E3d;
use crate::tests::{keypoint_error, solve_terms, target_pose};
use crate::tests_e2d::{rendered_silhouette, sensor_camera};
use crate::{IrlsParams, Tracker, TrackerConfig, TrackingCtx};

/// The frame the sensor sees of `model` at `pose`: every rendered pixel a point with its pixel,
/// moved along its ray by Gaussian depth noise of `sigma` mm, and the depth image of those
/// points (mm, rounded); the silhouette is the rendering's.
pub(crate) fn noisy_frame(
    model: &CylinderModel,
    pose: &Pose,
    sigma: f64,
    seed: u64,
) -> PreprocessedFrame {
    use rand::{Rng, SeedableRng};
    let (raster, mask, dt) = rendered_silhouette(model, pose);
    let cam = sensor_camera();
    let exact: Vec<Vector3<f64>> = raster
        .hits()
        .iter()
        .map(|&i| raster.hit(i as usize).unwrap().point)
        .collect();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let points = hand_model::testing::with_depth_noise(&exact, sigma, || {
        (rng.random_range(1e-12..1.0), rng.random())
    });
    let mut depth = DepthImage {
        width: cam.width,
        height: cam.height,
        data: vec![0; cam.width as usize * cam.height as usize],
    };
    for (&k, p) in raster.hits().iter().zip(&points) {
        depth.data[k as usize] = p.z.round().clamp(1.0, 65535.0) as u16;
    }
    PreprocessedFrame {
        points,
        pixels: raster.hits().to_vec(),
        depth,
        camera: Some(cam),
        dt,
        hand: HandSegment {
            count: raster.hits().len(),
            mask,
            ..HandSegment::default()
        },
        ..PreprocessedFrame::default()
    }
}

/// Under depth noise along the rays the front-facing closest points are biased (a noisy point in
/// front of a finger finds its foot point on the finger's side, one behind it is pulled to the
/// finger's silhouette), the rays' entries are not: E3D solved from the true pose on noisy
/// frames drifts less with them.
#[test]
fn along_ray_correspondences_drift_less_under_depth_noise() {
    let model = default_right_hand_cylinders();
    let truth = target_pose(&model);
    let options = LmOptions {
        iterations: 8,
        rigid_iterations: 1,
        ..LmOptions::default()
    };
    let mut ctx = TrackingCtx::new(&model, View::Orthographic, IrlsParams::default());
    let e3d = E3d::default();
    let (mut closest, mut along_ray) = (0.0, 0.0);
    for seed in 0..3 {
        ctx.set_frame(&noisy_frame(&model, &truth, 4.0, seed));
        for (gate, drift) in [(None, &mut closest), (Some(20.0), &mut along_ray)] {
            ctx.set_ray_gate(gate);
            let (pose, _) = solve_terms(&mut ctx, &[&e3d], options.clone(), &truth);
            *drift += keypoint_error(&model, &pose, &truth).0 / 3.0;
        }
    }
    println!(
        "E3D from the true pose, σ = 4 mm: mean keypoint drift closest {closest:.3} mm, along \
         rays {along_ray:.3} mm"
    );
    assert!(
        along_ray < 0.8 * closest,
        "closest {closest}, along rays {along_ray}"
    );
}

/// The entries read from the rendering of the points' pixels are the single-ray casts of points
/// that name no pixel, and each replaces its closest point only within the gate and the slide.
#[test]
fn rendered_entries_equal_single_ray_casts_within_gate_and_slide() {
    let model = default_right_hand_cylinders();
    let truth = target_pose(&model);
    let mut pose = truth.clone();
    pose.values[model.skeleton.dof_index("global_tx").unwrap()] += 2.0;
    let frame = noisy_frame(&model, &truth, 4.0, 9);
    let ctx_with = |frame_pixels: bool, gate: Option<f64>| {
        let mut ctx = TrackingCtx::new(&model, View::Orthographic, IrlsParams::default());
        if frame_pixels {
            ctx.set_frame(&frame);
        } else {
            ctx.set_points(&frame.points);
            ctx.sensor_mut().camera = frame.camera.clone();
        }
        ctx.set_ray_gate(gate);
        ctx.update(&pose, false).unwrap();
        ctx
    };
    let (rendered, cast, thesis) = (
        ctx_with(true, Some(20.0)),
        ctx_with(false, Some(20.0)),
        ctx_with(true, None),
    );
    let mut moved = 0;
    for (i, x) in frame.points.iter().enumerate() {
        let (r, c, t) = (
            rendered.correspondences()[i].unwrap(),
            cast.correspondences()[i].unwrap(),
            thesis.correspondences()[i].unwrap(),
        );
        assert!(
            (r.point - c.point).norm() < 1e-9,
            "point {i}: {r:?} vs {c:?}"
        );
        assert!((r.normal - c.normal).norm() < 1e-9, "point {i}");
        assert!(
            (rendered.residuals()[i] - cast.residuals()[i]).abs() < 1e-9,
            "point {i}"
        );
        if (r.point - t.point).norm() > 1e-9 {
            moved += 1;
            assert!(
                (r.point - x).norm() <= 20.0 + 1e-9,
                "point {i} beyond the gate"
            );
            assert!(
                (r.point - t.point).norm() <= crate::DEFAULT_RAY_SLIDE + 1e-9,
                "point {i} slid beyond the limit"
            );
        }
    }
    println!(
        "{moved} of {} points registered along their rays",
        frame.points.len()
    );
    assert!(moved * 2 > frame.points.len(), "{moved} points moved");
}

/// The tracker registers along the rays on the frames whose measured depth noise reaches
/// [`TrackerConfig::ray_gate_noise`] and keeps the thesis' rule on exact (rounded) depth.
#[test]
fn along_ray_correspondences_follow_the_measured_noise() {
    let model = default_right_hand_cylinders();
    let truth = target_pose(&model);
    let config = TrackerConfig::default();
    assert_eq!(config.ray_gate_for(None), None, "not measured yet");
    assert_eq!(config.ray_gate_for(Some(0.5)), None);
    assert_eq!(config.ray_gate_for(Some(5.0)), config.ray_gate);
    for (sigma, on) in [(0.0, false), (4.0, true)] {
        let mut tracker = Tracker::new(&model, config.clone(), None).unwrap();
        tracker.set_pose(&truth).unwrap();
        let record = tracker.track(&noisy_frame(&model, &truth, sigma, 3), 0, 0.0);
        assert!(record.is_finite());
        assert_eq!(
            tracker.context().ray_gate(),
            config.ray_gate.filter(|_| on),
            "σ = {sigma}"
        );
    }
}
