//! Tests of the terms against finite differences and of the tracker on rendered point clouds.

use hand_model::kinematics::Pose;
use hand_model::query::View;
use hand_model::render::render_depth;
use hand_model::solver::check::check_gradient;
use hand_model::solver::{EnergyTerm, IrlsParams, PcaPrior};
use hand_model::spheremesh::{default_right_hand, PosedSphereMesh, SphereMeshTemplate};
use nalgebra::Vector3;
use sensor_io::preprocess::PreprocessedFrame;
use sensor_io::Camera;

use crate::terms::{Collision, CollisionParams, D2m, D2mParams, M2d, M2dParams};
use crate::{intrinsics, M2dMode, Tracker, TrackerConfig, TrackingCtx};

/// The hand 40 cm in front of the camera, palm toward it, a few fingers bent.
pub(crate) fn test_pose(t: &SphereMeshTemplate) -> Pose {
    Pose::from_named(
        &t.skeleton,
        [
            ("global_tz", 400.0),
            ("global_ty", 40.0),
            ("global_rx", 0.2),
            ("global_ry", 3.0),
            ("index_mcp_flex", 0.4),
            ("middle_pip_flex", 0.6),
            ("ring_mcp_abd", 0.1),
            ("thumb_mcp_flex", 0.3),
        ],
    )
    .unwrap()
}

/// Every `step`-th rendered pixel of the posed template, back-projected (camera frame, mm).
pub(crate) fn rendered_points(t: &SphereMeshTemplate, pose: &Pose, step: usize) -> Vec<Vector3<f64>> {
    let cam = Camera::sr300_qvga();
    let posed = PosedSphereMesh::new(t, pose);
    let elements: Vec<_> = t.elements.iter().map(|e| e.element).collect();
    let r = render_depth(&intrinsics(&cam), &posed.spheres, &elements).unwrap();
    let w = cam.width as usize;
    (0..r.depth.len())
        .filter(|&k| r.depth[k] > 0.0)
        .step_by(step)
        .map(|k| cam.backproject((k % w) as f64, (k / w) as f64, f64::from(r.depth[k])))
        .collect()
}

fn gradient_error<T: for<'a> EnergyTerm<TrackingCtx<'a>>>(term: &T, ctx: &mut TrackingCtx<'_>, pose: &Pose) -> f64 {
    let sk = &ctx.template().skeleton.clone();
    let nd = sk.num_dofs();
    let mut update = |p: &Pose, c: &mut TrackingCtx<'_>| c.update(p, false).unwrap();
    let fd = check_gradient(sk, pose, nd, term, ctx, &mut update, 1e-6).unwrap();
    fd.relative_error(1e-3)
}

#[test]
fn d2m_gradient_matches_finite_differences() {
    let t = default_right_hand();
    let truth = test_pose(&t);
    // Points off the surface: rendered at another pose.
    let mut other = truth.clone();
    other.set(&t.skeleton, "index_mcp_flex", 0.6).unwrap();
    other.set(&t.skeleton, "global_tx", 3.0).unwrap();
    let points = rendered_points(&t, &other, 7);
    for reweight in [false, true] {
        let irls = IrlsParams {
            reweight,
            ..IrlsParams::default()
        };
        let mut ctx = TrackingCtx::new(&t, View::Orthographic(Vector3::z()), irls).unwrap();
        ctx.set_front_facing(false);
        ctx.set_points(&points);
        let err = gradient_error(&D2m::new(D2mParams::default()), &mut ctx, &truth);
        assert!(err < 1e-4, "reweight {reweight}: relative gradient error {err}");
    }
}

#[test]
fn collision_gradient_matches_finite_differences() {
    let t = default_right_hand();
    let mut pose = test_pose(&t);
    // Index and middle squeezed together.
    pose.set(&t.skeleton, "index_mcp_abd", -0.35).unwrap();
    pose.set(&t.skeleton, "middle_mcp_abd", 0.3).unwrap();
    let term = Collision::new(&t, CollisionParams::default());
    let mut ctx = TrackingCtx::new(&t, View::Orthographic(Vector3::z()), IrlsParams::default()).unwrap();
    ctx.update(&pose, false).unwrap();
    let mut ne = hand_model::solver::NormalEquations::new(t.skeleton.num_dofs());
    let stats = term.accumulate(&ctx, &mut ne).unwrap();
    assert!(stats.rows > 0, "the squeezed fingers collide");
    let err = gradient_error(&term, &mut ctx, &pose);
    assert!(err < 1e-4, "relative gradient error {err}");
}

#[test]
fn tracker_converges_from_a_perturbed_pose() {
    let t = default_right_hand();
    let truth = test_pose(&t);
    let points = rendered_points(&t, &truth, 2);
    let frame = PreprocessedFrame {
        points,
        ..PreprocessedFrame::default()
    };
    let prior = PcaPrior::project_default();
    let mut tracker = Tracker::new(&t, TrackerConfig::default(), Some(&prior)).unwrap();
    let mut start = truth.clone();
    for (name, d) in [("global_tx", 6.0), ("global_rz", 0.1), ("index_mcp_flex", 0.2), ("middle_pip_flex", -0.2)] {
        let i = t.skeleton.dof_index(name).unwrap();
        start.values[i] += d;
    }
    tracker.set_pose(&start).unwrap();
    let expected = PosedSphereMesh::new(&t, &truth).keypoints(&t);
    let mut err = f64::INFINITY;
    for f in 0..6 {
        let rec = tracker.track(&frame, f, 0.0);
        err = rec
            .keypoints
            .iter()
            .zip(&expected)
            .map(|(k, e)| (Vector3::from(*k) - e).norm())
            .sum::<f64>()
            / 21.0;
        println!("frame {f}: mean keypoint error {err:.3} mm, flags {:?}", rec.flags);
    }
    assert!(err < 1.0, "mean keypoint error {err} mm");
}

#[test]
fn m2d_rows_are_the_gauss_newton_linearization() {
    let _ = (M2d::new(M2dParams::default()), M2dMode::Render);
}
