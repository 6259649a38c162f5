//! Tests of the terms against finite differences and of the tracker on rendered point clouds.

use hand_model::kinematics::Pose;
use hand_model::query::View;
use hand_model::solver::check::check_gradient;
use hand_model::solver::{EnergyTerm, IrlsParams, PcaPrior};
use hand_model::spheremesh::{default_right_hand, PosedSphereMesh, SphereMeshTemplate};
use nalgebra::Vector3;
use sensor_io::preprocess::PreprocessedFrame;
use sensor_io::{Camera, SensorView};

use crate::terms::{Collision, CollisionParams, D2m, D2mParams, M2d, M2dParams};
use crate::{M2dMode, Tracker, TrackerConfig, TrackingCtx};

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

/// Up to `n` points of the posed template's visible surface (camera frame, mm).
pub(crate) fn rendered_points(t: &SphereMeshTemplate, pose: &Pose, n: usize) -> Vec<Vector3<f64>> {
    crate::synthetic::rendered_frame(t, pose, &Camera::sr300_qvga(), n)
        .unwrap()
        .points
}

fn gradient_error<T: for<'a> EnergyTerm<TrackingCtx<'a>>>(
    term: &T,
    ctx: &mut TrackingCtx<'_>,
    pose: &Pose,
) -> f64 {
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
    let points = rendered_points(&t, &other, 600);
    for reweight in [false, true] {
        let irls = IrlsParams {
            reweight,
            ..IrlsParams::default()
        };
        let mut ctx = TrackingCtx::new(&t, View::Orthographic(Vector3::z()), irls).unwrap();
        ctx.set_front_facing(false);
        ctx.set_points(&points);
        let err = gradient_error(&D2m::new(D2mParams::default()), &mut ctx, &truth);
        assert!(
            err < 1e-4,
            "reweight {reweight}: relative gradient error {err}"
        );
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
    let mut ctx =
        TrackingCtx::new(&t, View::Orthographic(Vector3::z()), IrlsParams::default()).unwrap();
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
    let points = rendered_points(&t, &truth, 2500);
    let frame = PreprocessedFrame {
        points,
        ..PreprocessedFrame::default()
    };
    let prior = PcaPrior::project_default();
    let mut tracker = Tracker::new(&t, TrackerConfig::default(), Some(&prior)).unwrap();
    let mut start = truth.clone();
    for (name, d) in [
        ("global_tx", 6.0),
        ("global_rz", 0.1),
        ("index_mcp_flex", 0.2),
        ("middle_pip_flex", -0.2),
    ] {
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
        println!(
            "frame {f}: mean keypoint error {err:.3} mm, flags {:?}",
            rec.flags
        );
    }
    assert!(err < 1.0, "mean keypoint error {err} mm");
}

/// The sensor view whose silhouette is the template rendered at `pose`.
fn silhouette_of(t: &SphereMeshTemplate, pose: &Pose) -> SensorView {
    let frame = crate::synthetic::rendered_frame(t, pose, &Camera::sr300_qvga(), 1).unwrap();
    let mut view = SensorView::default();
    view.set_frame(&frame);
    view
}

/// With the pushes of Eq. 3.5 held fixed (their spheres, weights, normal offset and target
/// pixels), `−2b` of [`M2d`] is the gradient of `τ Σ ‖π(q(θ)) − target‖²`, checked by central
/// differences of that energy with the footpoints re-evaluated at the perturbed poses; and the
/// model rendered at a pose shifted off the silhouette yields pushes in both modes.
#[test]
fn m2d_rows_are_the_gauss_newton_linearization() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let truth = test_pose(&t);
    let mut pose = truth.clone();
    pose.values[sk.dof_index("global_tx").unwrap()] += 8.0;
    pose.values[sk.dof_index("index_mcp_abd").unwrap()] += 0.2;
    for mode in [M2dMode::Render, M2dMode::Centers] {
        let mut ctx =
            TrackingCtx::new(&t, View::Orthographic(Vector3::z()), IrlsParams::default()).unwrap();
        *ctx.sensor_mut() = silhouette_of(&t, &truth);
        ctx.set_m2d(Some(mode));
        ctx.update(&pose, false).unwrap();
        let pushes = ctx.pushes().to_vec();
        assert!(pushes.len() > 2, "{mode:?}: {} pushes", pushes.len());
        let term = M2d::new(M2dParams::default());
        let mut ne = hand_model::solver::NormalEquations::new(sk.num_dofs());
        term.accumulate(&ctx, &mut ne).unwrap();
        let cam = Camera::sr300_qvga();
        let offsets: Vec<Vector3<f64>> = pushes
            .iter()
            .map(|p| {
                let s: Vector3<f64> = (0..3)
                    .map(|i| ctx.posed_mesh().spheres[p.spheres[i] as usize].center * p.weights[i])
                    .sum();
                p.point - s
            })
            .collect();
        let energy = |q: &Pose| {
            let posed = PosedSphereMesh::new(&t, q);
            pushes
                .iter()
                .zip(&offsets)
                .map(|(p, off)| {
                    let s: Vector3<f64> = (0..3)
                        .map(|i| posed.spheres[p.spheres[i] as usize].center * p.weights[i])
                        .sum();
                    (cam.project(&(s + off)) - p.target).norm_squared()
                })
                .sum::<f64>()
                * M2dParams::default().weight
                * ctx.m2d_pixel_weight()
        };
        let h = 1e-6;
        let mut worst = 0.0f64;
        let scale = ne.rhs().amax().max(1e-3);
        for k in 0..sk.num_dofs() {
            let mut d = vec![0.0; sk.num_dofs()];
            d[k] = h;
            let plus = energy(&pose.retract(sk, &d));
            d[k] = -h;
            let minus = energy(&pose.retract(sk, &d));
            let fd = (plus - minus) / (2.0 * h);
            worst = worst.max((fd + 2.0 * ne.rhs()[k]).abs() / (2.0 * scale));
        }
        assert!(worst < 1e-5, "{mode:?}: relative gradient error {worst}");
    }
}

/// The context's seeded correspondence search (each point starts from its previous element)
/// gives bit for bit the correspondences of an unseeded search, iteration after iteration
/// of a moving pose, front-facing or plain, with noisy points off the surface too.
#[test]
fn seeded_correspondences_equal_a_fresh_search() {
    use rand::{Rng, SeedableRng};
    let t = default_right_hand();
    let pose = test_pose(&t);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
    let mut points = rendered_points(&t, &pose, 2000);
    for p in points.iter_mut().step_by(3) {
        *p += Vector3::new(
            rng.random_range(-8.0..8.0),
            rng.random_range(-8.0..8.0),
            rng.random_range(-8.0..8.0),
        );
    }
    let view = View::Perspective {
        camera_center: Vector3::zeros(),
    };
    for front_facing in [true, false] {
        let mut ctx = TrackingCtx::new(&t, view, IrlsParams::default()).unwrap();
        ctx.set_front_facing(front_facing);
        ctx.set_points(&points);
        let mut moved = pose.clone();
        for step in 0..6 {
            for v in moved.values.iter_mut() {
                *v += rng.random_range(-0.03..0.03);
            }
            ctx.update(&moved, step == 0).unwrap();
            // The unseeded search on the context's own geometry (a freshly built one has
            // another bounding tree, hence another silhouette direction under perspective).
            let geometry = ctx.geometry();
            let mut fresh = vec![None; points.len()];
            if front_facing {
                geometry.project_points_front_facing(&points, &view, &mut fresh);
            } else {
                geometry.project_points(&points, &mut fresh);
            }
            assert!(fresh.iter().all(Option::is_some));
            assert_eq!(ctx.correspondences(), &fresh[..], "step {step}");
        }
    }
}

/// `points` moved along their camera rays by Gaussian depth noise of `sigma` mm (a depth
/// sensor's noise model).
fn with_depth_noise(points: &[Vector3<f64>], sigma: f64, seed: u64) -> Vec<Vector3<f64>> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    hand_model::testing::with_depth_noise(points, sigma, || {
        (rng.random_range(1e-12..1.0), rng.random())
    })
}

/// A context seen through the sensor's pinhole at the origin, default IRLS.
fn pinhole_ctx(t: &SphereMeshTemplate) -> TrackingCtx<'_> {
    let view = View::Perspective {
        camera_center: Vector3::zeros(),
    };
    TrackingCtx::new(t, view, IrlsParams::default()).unwrap()
}

/// Mean over the points with a correspondence of the residual along the footpoint's normal
/// (`> 0`: the points lie outside the model on average).
fn mean_normal_residual(ctx: &TrackingCtx<'_>) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for (c, u, r, _) in ctx.d2m_rows() {
        sum -= u.dot(&c.normal) * r;
        n += 1;
    }
    sum / n as f64
}

/// At the true pose under depth noise the along-ray residuals average to zero where the
/// closest points' do not; limiting how far the footpoint may slide from the closest point
/// ([`TrackingCtx::set_ray_slide`], against misassociation) keeps most of the gain.
#[test]
fn along_ray_correspondences_are_unbiased_under_depth_noise() {
    let t = default_right_hand();
    let truth = test_pose(&t);
    let exact = rendered_points(&t, &truth, 4000);
    let mut ctx = pinhole_ctx(&t);
    // (slide, least gain in mm)
    for (slide, gain) in [(f64::INFINITY, 0.1), (crate::DEFAULT_RAY_SLIDE, 0.05)] {
        ctx.set_ray_slide(slide);
        let (mut closest, mut along_ray) = (0.0, 0.0);
        for seed in 0..4 {
            ctx.set_points(&with_depth_noise(&exact, 4.0, seed));
            ctx.set_ray_gate(None);
            ctx.update(&truth, false).unwrap();
            closest += mean_normal_residual(&ctx) / 4.0;
            ctx.set_ray_gate(Some(20.0));
            ctx.update(&truth, false).unwrap();
            along_ray += mean_normal_residual(&ctx) / 4.0;
        }
        println!(
            "mean residual at the true pose, σ = 4 mm, slide {slide} mm: closest {closest:.3} mm, \
             along rays {along_ray:.3} mm"
        );
        // The mean of 16 000 residuals of σ ≈ 3 mm varies by ≈ 0.03 mm.
        assert!(along_ray.abs() < 0.08, "along rays: {along_ray}");
        assert!(
            closest - along_ray > gain,
            "slide {slide}: closest points {closest}, along rays {along_ray}"
        );
    }
}

#[test]
fn along_ray_correspondences_are_the_rays_first_entry() {
    use hand_model::render::raycast::{cast_ray, Ray};
    let t = default_right_hand();
    let truth = test_pose(&t);
    let points = with_depth_noise(&rendered_points(&t, &truth, 1500), 4.0, 5);
    let mut ctx = pinhole_ctx(&t);
    ctx.set_ray_gate(Some(20.0));
    ctx.set_ray_slide(f64::INFINITY);
    ctx.set_points(&points);
    let mut pose = truth.clone();
    pose.set(&t.skeleton, "global_tx", 2.0).unwrap();
    ctx.update(&pose, false).unwrap();
    let mut thesis = pinhole_ctx(&t);
    thesis.set_points(&points);
    thesis.update(&pose, false).unwrap();
    let posed = PosedSphereMesh::new(&t, &pose);
    let elements: Vec<_> = t.elements.iter().map(|e| e.element).collect();
    let mut along = 0;
    for ((c, p), front) in ctx
        .correspondences()
        .iter()
        .zip(ctx.points())
        .zip(thesis.correspondences())
    {
        let c = c.expect("every point has a correspondence");
        let hit = cast_ray(
            &Ray::new(Vector3::zeros(), *p).unwrap(),
            &posed.spheres,
            &elements,
        );
        match hit {
            Some(h) if (h.point - p).norm() <= 20.0 => {
                along += 1;
                assert!(
                    (c.point - h.point).norm() < 1e-6,
                    "{:?} vs {:?}",
                    c.point,
                    h.point
                );
                // Where two elements meet at the hit either may hold it; else the same normal.
                if c.element as usize == h.element {
                    assert!((c.normal - h.normal).norm() < 1e-6);
                }
            }
            _ => assert_eq!(
                Some(c),
                *front,
                "a point off its ray keeps its front-facing point"
            ),
        }
    }
    assert!(
        along > 1000,
        "{along} of 1500 points registered along their rays"
    );
    // With the default slide limit a point takes its ray's entry only within that distance
    // of its front-facing point, else keeps the latter.
    ctx.set_ray_slide(crate::DEFAULT_RAY_SLIDE);
    ctx.update(&pose, false).unwrap();
    let mut slid = 0;
    for (c, front) in ctx.correspondences().iter().zip(thesis.correspondences()) {
        let (c, front) = (c.unwrap(), front.unwrap());
        if c != front {
            slid += 1;
            assert!((c.point - front.point).norm() <= crate::DEFAULT_RAY_SLIDE + 1e-9);
        }
    }
    assert!(slid > 700 && slid < along, "{slid} of {along} slid");
}

/// The tracker measures the depth noise and registers along the rays only on noisy data (the
/// default `ray_gate_noise`), at the configured gate.
#[test]
fn along_ray_correspondences_follow_the_measured_noise() {
    let t = default_right_hand();
    let camera = Camera::sr300_qvga();
    let exact = crate::synthetic::rendered_frame(&t, &test_pose(&t), &camera, 1500).unwrap();
    let mut noisy = exact.clone();
    for (i, d) in noisy.depth.data.iter_mut().enumerate() {
        if *d != 0 {
            *d = if i % 2 == 0 { *d + 3 } else { *d - 3 };
        }
    }
    let config = TrackerConfig::default();
    assert_eq!(config.ray_gate_for(None), None, "not measured yet");
    assert_eq!(config.ray_gate_for(Some(0.5)), None);
    assert_eq!(config.ray_gate_for(Some(5.0)), config.ray_gate);
    for (frame, on) in [(&exact, false), (&noisy, true)] {
        let mut tracker = Tracker::new(&t, config.clone(), None).unwrap();
        tracker.track(frame, 0, 0.0);
        assert_eq!(tracker.context().ray_gate(), config.ray_gate.filter(|_| on));
    }
}

/// Under heavy depth noise (σ = 12 mm, twice the ToF model's) a hand held at its true pose
/// is ≈ 0.62 σ from its points. With the fixed loss thresholds every frame failed and the
/// tracker re-initialized every third frame; with the fixed 7.5 mm along-ray slide the points
/// behind a finger's axis kept their silhouette substitutes, so the fingers were pulled toward
/// the camera. Both now follow the measured noise ([`hand_model::solver::LossParams::for_noise`],
/// [`TrackerConfig::ray_slide_for`]).
#[test]
fn heavy_depth_noise_fails_no_frame_and_tracks_closer() {
    use hand_model::solver::LossParams;
    let t = default_right_hand();
    let truth = test_pose(&t);
    let exact = crate::synthetic::rendered_frame(&t, &truth, &Camera::sr300_qvga(), 2500).unwrap();
    let frames: Vec<_> = (0..12)
        .map(|seed| crate::synthetic::noisy_frame(&exact, 12.0, seed))
        .collect();
    let prior = PcaPrior::project_default();
    let expected = PosedSphereMesh::new(&t, &truth).keypoints(&t);
    let run = |config: TrackerConfig| {
        let mut tracker = Tracker::new(&t, config, Some(&prior)).unwrap();
        tracker.set_pose(&truth).unwrap();
        let (mut err, mut lost) = (0.0, 0);
        for (f, frame) in frames.iter().enumerate() {
            let rec = tracker.track(frame, f as u64, 0.0);
            lost += rec.flags.iter().filter(|x| *x == "lost").count();
            let e: f64 = rec
                .keypoints
                .iter()
                .zip(&expected)
                .map(|(k, e)| (Vector3::from(*k) - e).norm())
                .sum();
            err += e / (21.0 * frames.len() as f64);
        }
        (err, lost, tracker.context().ray_gate())
    };
    let fixed = TrackerConfig {
        ray_slide_noise: 0.0,
        loss: LossParams {
            noise_scaled: false,
            ..LossParams::default()
        },
        ..TrackerConfig::default()
    };
    let (e_fixed, lost_fixed, _) = run(fixed);
    let (e, lost, gate) = run(TrackerConfig::default());
    println!(
        "σ = 12 mm at the true pose: mean keypoint error {e:.2} mm, {lost} frames lost; with \
         the fixed thresholds and slide {e_fixed:.2} mm, {lost_fixed} lost"
    );
    assert!(gate.is_some(), "the along-ray registration runs");
    assert_eq!(lost, 0);
    assert!(lost_fixed >= frames.len() / 2, "{lost_fixed} lost");
    assert!(e < 0.8 * e_fixed, "{e} against {e_fixed} mm");
}

/// A hand first seen edge-on (turned 88° about its fingers) is placed edge-on from a cold
/// start: the re-initialization also rolls the placed mean pose by ±90° about the fingers
/// ([`hand_model::solver::PLACEMENT_ROLLS`]). Placed palm-on only, the ToF occlusion motion
/// started at such a frame stayed 80–98 mm off for 45 frames. The fingers behind the nearest
/// one are hidden, so only the palm's placement is checked: its rotation and the wrist and
/// knuckle keypoints.
#[test]
fn a_hand_first_seen_edge_on_is_placed_edge_on() {
    use hand_model::math::euler_xyz_to_matrix;
    let t = default_right_hand();
    let truth = Pose::from_named(
        &t.skeleton,
        [
            ("global_tz", 400.0),
            ("global_ty", 40.0),
            ("global_ry", 1.54),
            ("global_rz", 3.16),
            ("index_mcp_flex", 0.3),
            ("thumb_mcp_flex", 0.3),
        ],
    )
    .unwrap();
    let frame = crate::synthetic::rendered_frame(&t, &truth, &Camera::sr300_qvga(), 2500).unwrap();
    let prior = PcaPrior::project_default();
    let mut tracker = Tracker::new(&t, TrackerConfig::default(), Some(&prior)).unwrap();
    let rec = tracker.track(&frame, 0, 0.0);
    assert_eq!(rec.flags, ["reinitialized"]);
    let rotation = |p: &Pose| {
        let g = |k: &str| p.values[t.skeleton.dof_index(k).unwrap()];
        euler_xyz_to_matrix(g("global_rx"), g("global_ry"), g("global_rz"))
    };
    let turn = rotation(tracker.pose()).transpose() * rotation(&truth);
    let angle = ((turn.trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos();
    let expected = PosedSphereMesh::new(&t, &truth).keypoints(&t);
    // The wrist and the four finger knuckles (DESIGN.md keypoint order).
    let palm: f64 = [0, 5, 9, 13, 17]
        .iter()
        .map(|&k| (Vector3::from(rec.keypoints[k]) - expected[k]).norm())
        .sum::<f64>()
        / 5.0;
    println!("edge-on start: rotation off by {angle:.3} rad, wrist and knuckles {palm:.2} mm");
    assert!(angle < 0.1 && palm < 4.0, "{angle} rad, {palm} mm");
}
