//! Tests of the silhouette term E2D (Eq. 2.3) on synthetic silhouettes: the model's own
//! rasterization at a target pose is the sensor silhouette `S_s`.

use hand_model::cylinder::{default_right_hand_cylinders, CylinderModel, CylinderRaster, View};
use hand_model::kinematics::Pose;
use hand_model::solver::terms::{Damping, DampingParams, JointLimits, JointLimitsParams};
use hand_model::solver::{EnergyTerm, LmOptions, NormalEquations, PoseContext};
use nalgebra::{DMatrix, DVector, Matrix2xX};
use sensor_io::dt::DistanceTransform;
use sensor_io::preprocess::Wristband;
use sensor_io::{Camera, Mask};

use crate::terms::E2d;
use crate::tests::{camera, target_pose};
use crate::{IrlsParams, SensorView, TrackingCtx};

/// The sensor camera of the synthetic scenes (the intrinsics of [`camera`]).
pub(crate) fn sensor_camera() -> Camera {
    let c = camera();
    Camera::new("synthetic", c.width, c.height, c.fx, c.fy, c.cx, c.cy).unwrap()
}

/// The model at `pose` rasterized from [`sensor_camera`], its silhouette and the silhouette's
/// distance transform.
pub(crate) fn rendered_silhouette(
    model: &CylinderModel,
    pose: &Pose,
) -> (CylinderRaster, Mask, DistanceTransform) {
    let mut raster = CylinderRaster::new();
    raster
        .render(model, &model.posed(pose).unwrap(), &camera())
        .unwrap();
    let cam = sensor_camera();
    let mut mask = Mask::zeros(cam.width, cam.height);
    for &i in raster.hits() {
        mask.data[i as usize] = 1;
    }
    let mut dt = DistanceTransform::default();
    dt.compute(&mask);
    (raster, mask, dt)
}

/// The sensor view whose silhouette is the rasterized model at `pose`.
fn silhouette_of(model: &CylinderModel, pose: &Pose) -> SensorView {
    let (_, _, dt) = rendered_silhouette(model, pose);
    let cam = sensor_camera();
    SensorView {
        camera: Some(cam),
        nearest: dt.nearest,
        wristband: None,
    }
}

fn shifted(model: &CylinderModel, pose: &Pose, dofs: &[(&str, f64)]) -> Pose {
    let mut p = pose.clone();
    for (name, d) in dofs {
        p.values[model.skeleton.dof_index(name).unwrap()] += d;
    }
    p
}

fn outside_count(ctx: &TrackingCtx<'_>) -> usize {
    let mut n = 0;
    E2d::for_each_push(ctx, |_| {
        n += 1;
        Ok(())
    })
    .unwrap();
    n
}

/// The E2D rows against finite differences of the projections of the same bone-attached points
/// with the same (fixed) correspondences: `A = Σ JᵀJ` and `b = −Σ Jᵀr` rebuilt from numeric
/// Jacobians `(π(x(θ ⊞ h eₖ)) − π(x(θ ⊞ −h eₖ)))/2h`.
#[test]
fn e2d_rows_match_finite_differences_of_projected_points() {
    let model = default_right_hand_cylinders();
    let sk = &model.skeleton;
    let nd = sk.num_dofs();
    let target = target_pose(&model);
    let pose = shifted(
        &model,
        &target,
        &[
            ("global_tx", 6.0),
            ("global_ty", -4.0),
            ("index_mcp_flex", -0.2),
            ("thumb_cmc_abd", 0.15),
            ("pinky_pip_flex", -0.25),
        ],
    );
    let mut ctx = TrackingCtx::new(&model, View::Orthographic, IrlsParams::default());
    *ctx.sensor_mut() = silhouette_of(&model, &target);
    ctx.update(&pose, false).unwrap();
    let cam = sensor_camera();
    let posed = ctx.posed().clone();
    let mut pushes = Vec::new();
    E2d::for_each_push(&ctx, |p| {
        pushes.push(*p);
        Ok(())
    })
    .unwrap();
    assert!(pushes.len() > 100, "{} pushes", pushes.len());
    let mut bones = std::collections::BTreeSet::new();
    let h = 1e-6;
    let (mut a_fd, mut b_fd) = (DMatrix::zeros(nd, nd), DVector::zeros(nd));
    let mut energy = 0.0;
    let plus_minus: Vec<[_; 2]> = (0..nd)
        .map(|k| {
            [h, -h].map(|s| {
                let mut delta = vec![0.0; nd];
                delta[k] = s;
                model.posed(&pose.retract(sk, &delta)).unwrap()
            })
        })
        .collect();
    for p in &pushes {
        bones.insert(p.bone);
        // The pixel-center subtlety: π(x) is the rendered pixel center at the linearization
        // point.
        let px = cam.project(&p.point);
        assert!((px.x - f64::from(p.pixel.0)).abs() < 1e-9);
        assert!((px.y - f64::from(p.pixel.1)).abs() < 1e-9);
        let local = posed.globals[p.bone].inverse().transform_point(&p.point);
        let mut j = Matrix2xX::zeros(nd);
        for (k, pm) in plus_minus.iter().enumerate() {
            let xp = pm[0].globals[p.bone].transform_point(&local);
            let xm = pm[1].globals[p.bone].transform_point(&local);
            j.set_column(k, &((cam.project(&xp) - cam.project(&xm)) / (2.0 * h)));
        }
        let r = px - p.target;
        energy += r.norm_squared();
        a_fd += j.transpose() * &j;
        b_fd -= j.transpose() * r;
    }
    assert!(bones.len() >= 3, "{bones:?}");
    let mut ne = NormalEquations::new(nd);
    let stats = E2d::default().accumulate(&ctx, &mut ne).unwrap();
    ne.symmetrize();
    assert_eq!(stats.rows, 2 * pushes.len());
    assert!((stats.energy - energy).abs() < 1e-9 * energy);
    let rel = |a: f64, m: f64| a / m.max(1e-12);
    let ea = rel((ne.lhs() - &a_fd).amax(), a_fd.amax());
    let eb = rel((ne.rhs() - &b_fd).amax(), b_fd.amax());
    eprintln!(
        "E2D vs FD: {} pushes on {} bones, relative errors A {ea:.1e}, b {eb:.1e}",
        pushes.len(),
        bones.len()
    );
    assert!(ea < 1e-6 && eb < 1e-6, "A {ea:e}, b {eb:e}");
}

/// The model shifted 10 mm sideways from the pose that made the silhouette: E2D alone (with
/// damping and joint limits) pushes it back inside. E2D only pushes (pixels inside `S_s` cost
/// nothing), so alone it is ambiguous: the model can also hide its overflow by rotating,
/// flexing or moving away (with the thesis' λ = 100 on every DOF it does, the tracker relies on
/// E3D for that); the rotations and joints are therefore damped hard (λ = 1e7) so that the test
/// sees the push on the translations.
/// Model pixels where the segmentation cannot see the hand (beyond a wristband or the
/// depth-only forearm cut) are not pushed: a band whose hidden side holds the pixels with
/// camera y beyond the model's median takes exactly those pushes away.
#[test]
fn e2d_does_not_push_what_the_band_hides() {
    let model = default_right_hand_cylinders();
    let target = target_pose(&model);
    let start = shifted(&model, &target, &[("global_tx", 10.0)]);
    let mut ctx = TrackingCtx::new(&model, View::Orthographic, IrlsParams::default());
    *ctx.sensor_mut() = silhouette_of(&model, &target);
    ctx.update(&start, false).unwrap();
    let mut ys = Vec::new();
    E2d::for_each_push(&ctx, |p| {
        ys.push(p.point.y);
        Ok(())
    })
    .unwrap();
    ys.sort_by(f64::total_cmp);
    let cut = ys[ys.len() / 2];
    let kept = ys.iter().filter(|&&y| y <= cut).count();
    ctx.sensor_mut().wristband = Some(Wristband {
        center: nalgebra::Vector3::new(0.0, cut, 0.0),
        axis: nalgebra::Vector3::new(0.0, -1.0, 0.0),
        reach: 0.0,
    });
    let mut n = 0;
    E2d::for_each_push(&ctx, |p| {
        assert!(
            p.point.y <= cut,
            "a hidden pixel was pushed: y {}",
            p.point.y
        );
        n += 1;
        Ok(())
    })
    .unwrap();
    assert!(
        ys.len() > 200 && n == kept,
        "{} pushes, {n} kept of {kept}",
        ys.len()
    );
}

#[test]
fn e2d_alone_moves_a_shifted_model_back_into_the_silhouette() {
    let model = default_right_hand_cylinders();
    let sk = &model.skeleton;
    let target = target_pose(&model);
    let start = shifted(&model, &target, &[("global_tx", 10.0)]);
    let tx = sk.dof_index("global_tx").unwrap();
    let e2d = E2d::default();
    let limits = JointLimits::new(sk, &JointLimitsParams::default());
    let strong = DampingParams {
        rotation: 1e7,
        joint: 1e7,
        ..DampingParams::default()
    };
    let damping = Damping::new(sk, 0, &strong).unwrap();
    let terms: [&dyn EnergyTerm<TrackingCtx<'_>>; 3] = [&e2d, &limits, &damping];
    let options = LmOptions {
        iterations: 10,
        rigid_iterations: 1,
        damping: DampingParams::none(),
        ..LmOptions::default()
    };
    let mut ctx = TrackingCtx::new(&model, View::Orthographic, IrlsParams::default());
    *ctx.sensor_mut() = silhouette_of(&model, &target);
    ctx.update(&start, false).unwrap();
    let before = outside_count(&ctx);
    let (pose, report) = crate::tests::solve_terms(&mut ctx, &terms, options, &start);
    ctx.update(&pose, false).unwrap();
    let after = outside_count(&ctx);
    let (e0, e1) = (
        (start.values[tx] - target.values[tx]).abs(),
        (pose.values[tx] - target.values[tx]).abs(),
    );
    eprintln!(
        "E2D LM: outside pixels {before} -> {after}, |Δtx| {e0:.2} -> {e1:.2} mm, energy \
         {:.1} -> {:.1}, {:?}",
        report.energy_before, report.energy_after, report.termination
    );
    assert!(report.termination.was_successful());
    assert!(before > 200, "{before}");
    assert!(after * 20 < before, "{before} -> {after}");
    assert!(e1 < 0.1 * e0, "{e0} -> {e1}");
    assert!(report.energy_after < 0.01 * report.energy_before);
}

#[test]
fn e2d_adds_nothing_without_silhouette_camera_or_finite_pose() {
    let model = default_right_hand_cylinders();
    let nd = model.skeleton.num_dofs();
    let target = target_pose(&model);
    let pose = shifted(&model, &target, &[("global_tx", 10.0)]);
    let term = E2d::default();
    let rows = |ctx: &TrackingCtx<'_>| {
        let mut ne = NormalEquations::new(nd);
        let s = term.accumulate(ctx, &mut ne).unwrap();
        assert!(ne.is_finite());
        s.rows
    };
    // No camera: no rendering, no rows.
    let mut ctx = TrackingCtx::new(&model, View::Orthographic, IrlsParams::default());
    ctx.update(&pose, false).unwrap();
    assert!(ctx.raster().hits().is_empty());
    assert_eq!(rows(&ctx), 0);
    // Empty silhouette: rendered, but no nearest silhouette pixel anywhere.
    let cam = sensor_camera();
    let mut dt = DistanceTransform::default();
    dt.compute(&Mask::zeros(cam.width, cam.height));
    *ctx.sensor_mut() = SensorView {
        camera: Some(cam.clone()),
        nearest: dt.nearest.clone(),
        wristband: None,
    };
    ctx.update(&pose, false).unwrap();
    assert!(!ctx.raster().hits().is_empty());
    assert_eq!(rows(&ctx), 0);
    // A real silhouette: rows; disabled: none; NaN pose: none.
    *ctx.sensor_mut() = silhouette_of(&model, &target);
    ctx.update(&pose, false).unwrap();
    assert!(rows(&ctx) > 0);
    ctx.set_silhouette(false);
    ctx.update(&pose, false).unwrap();
    assert!(!ctx.silhouette() && ctx.raster().hits().is_empty());
    assert_eq!(rows(&ctx), 0);
    ctx.set_silhouette(true);
    let mut nan = pose.clone();
    nan.values[3] = f64::NAN;
    ctx.update(&nan, false).unwrap();
    assert!(ctx.raster().hits().is_empty());
    assert_eq!(rows(&ctx), 0);
    // A camera swapped without an update: an error, not a panic.
    ctx.update(&pose, false).unwrap();
    ctx.sensor_mut().camera = Some(cam.downsampled(2));
    let mut ne = NormalEquations::new(nd);
    assert!(term.accumulate(&ctx, &mut ne).is_err());
}

/// Prints the cost of the silhouette rendering inside `TrackingCtx::update` and of one E2D
/// accumulate at 320×240 (model shifted 10 mm from the silhouette's pose).
#[test]
fn e2d_timing() {
    let model = default_right_hand_cylinders();
    let target = target_pose(&model);
    let pose = shifted(&model, &target, &[("global_tx", 10.0)]);
    let mut ctx = TrackingCtx::new(&model, View::Orthographic, IrlsParams::default());
    *ctx.sensor_mut() = silhouette_of(&model, &target);
    ctx.update(&pose, false).unwrap();
    let runs = 30;
    let time = |f: &mut dyn FnMut()| {
        let t = std::time::Instant::now();
        for _ in 0..runs {
            f();
        }
        t.elapsed().as_secs_f64() * 1e6 / f64::from(runs)
    };
    let with = time(&mut || ctx.update(&pose, false).unwrap());
    ctx.set_silhouette(false);
    let without = time(&mut || ctx.update(&pose, false).unwrap());
    ctx.set_silhouette(true);
    ctx.update(&pose, false).unwrap();
    let term = E2d::default();
    let mut ne = NormalEquations::new(model.skeleton.num_dofs());
    let mut rows = 0;
    let acc = time(&mut || {
        ne.clear();
        rows = term.accumulate(&ctx, &mut ne).unwrap().rows;
    });
    eprintln!(
        "320×240: rendering in update {:.0} µs ({} pixels), E2D accumulate {acc:.0} µs \
         ({rows} rows)",
        with - without,
        ctx.raster().hits().len()
    );
}
