//! Tests of the context, the E3D term and an LM solve on a synthetic point cloud.

use hand_model::cylinder::{default_right_hand_cylinders, CylinderModel, CylinderPart, View};
use hand_model::kinematics::Pose;
use hand_model::render::Intrinsics;
use hand_model::solver::check::check_gradient;
use hand_model::solver::terms::{Damping, DampingParams, JointLimits, JointLimitsParams};
use hand_model::solver::{EnergyTerm, LmOptions, LmSolver, PoseContext};
use nalgebra::Vector3;

use crate::synthetic::visible_surface_points;
use crate::terms::E3d;
use crate::{CorrespondenceCallback, IrlsParams, TrackingCtx};

/// A 320×240 depth camera (htrack's resolution).
pub(crate) fn camera() -> Intrinsics {
    Intrinsics {
        fx: 300.0,
        fy: 300.0,
        cx: 160.0,
        cy: 120.0,
        width: 320,
        height: 240,
    }
}

/// The pose that produces the synthetic data ([`hand_model::testing::cylinder_test_pose`]).
pub(crate) fn target_pose(model: &CylinderModel) -> Pose {
    hand_model::testing::cylinder_test_pose(model)
}

/// The target perturbed: 15 mm, ~0.1 rad and 0.15–0.25 rad per finger joint.
fn perturbed_pose(model: &CylinderModel, target: &Pose) -> Pose {
    let sk = &model.skeleton;
    let mut p = target.clone();
    for (name, d) in [
        ("global_tx", 8.0),
        ("global_ty", -6.0),
        ("global_tz", 10.0),
        ("thumb_cmc_flex", 0.15),
        ("index_mcp_flex", -0.2),
        ("index_pip_flex", 0.2),
        ("middle_pip_flex", -0.25),
        ("ring_mcp_flex", -0.2),
        ("pinky_mcp_flex", 0.2),
    ] {
        let i = sk.dof_index(name).unwrap();
        p.values[i] += d;
    }
    let mut delta = vec![0.0; sk.num_dofs()];
    delta[sk.dof_index("global_rx").unwrap()] = 0.08;
    delta[sk.dof_index("global_ry").unwrap()] = -0.06;
    delta[sk.dof_index("global_rz").unwrap()] = 0.05;
    p.retract_in_place(sk, &delta);
    p
}

pub(crate) fn keypoint_error(model: &CylinderModel, a: &Pose, b: &Pose) -> (f64, f64) {
    let ka = model.keypoints(&model.posed(a).unwrap());
    let kb = model.keypoints(&model.posed(b).unwrap());
    let d: Vec<f64> = ka.iter().zip(&kb).map(|(x, y)| (x - y).norm()).collect();
    (
        d.iter().sum::<f64>() / d.len() as f64,
        d.iter().fold(0.0, |m: f64, v| m.max(*v)),
    )
}

#[test]
fn huber_weight_matches_penalty_derivative() {
    let irls = IrlsParams {
        epsilon: 0.5,
        ..IrlsParams::default()
    };
    for r in [-3.0, -0.6, -0.2, 0.0, 0.1, 0.49, 0.7, 4.0] {
        let h = 1e-6;
        let num = (irls.penalty(r + h) - irls.penalty(r - h)) / (2.0 * h);
        // ρ'(r) = 2·w·r.
        assert!((num - 2.0 * irls.weight(r) * r).abs() < 1e-6, "r = {r}");
    }
    assert_eq!(irls.penalty(-3.0), 2.0 * 12.25 * 3.0);
    assert!(irls.weight(0.0).is_finite());
    let bad = IrlsParams {
        epsilon: f64::NAN,
        ..IrlsParams::default()
    };
    assert!(bad.weight(0.0).is_finite() && bad.penalty(0.0).is_finite());
}

#[test]
fn synthetic_points_lie_on_the_visible_surface() {
    let model = default_right_hand_cylinders();
    let pose = target_pose(&model);
    let posed = model.posed(&pose).unwrap();
    let pts = visible_surface_points(&model, &posed, &camera(), 2, 1.0);
    assert!(pts.len() > 500, "{} points", pts.len());
    for p in &pts {
        let c = model.closest_point(&posed, p).unwrap();
        assert!(c.distance.abs() < 1e-6, "{p:?}: {}", c.distance);
    }
    // Non-finite pose: no points, no panic.
    let mut bad = posed.clone();
    let b = model.segments[0].bone;
    bad.globals[b].translation.x = f64::NAN;
    assert!(visible_surface_points(&model, &bad, &camera(), 2, 1.0).is_empty());
    assert!(visible_surface_points(&model, &posed, &camera(), 0, 1.0).is_empty());
}

/// Points of the target cloud whose correspondence at `pose` is a genuine closest point on a
/// circular segment: not a silhouette substitute (whose point-to-plane residual has a kink where
/// the substitution switches) and not on the elliptical palm (whose foot point is htrack's
/// approximation, not the closest point, so `nᵀ(y − x)` is not the distance and its gradient is
/// not `nᵀJ_skel(y)`).
fn closest_point_cloud(model: &CylinderModel, pose: &Pose) -> Vec<Vector3<f64>> {
    let target = target_pose(model);
    let all = visible_surface_points(model, &model.posed(&target).unwrap(), &camera(), 2, 1.0);
    let posed = model.posed(pose).unwrap();
    all.into_iter()
        .filter(|p| {
            model
                .front_facing_point(&posed, p, View::Orthographic)
                .is_some_and(|c| {
                    c.part != CylinderPart::Silhouette
                        && c.distance.abs() > 0.05
                        && model.segments[c.segment].is_circular()
                })
        })
        .collect()
}

#[test]
fn e3d_gradient_matches_finite_differences() {
    let model = default_right_hand_cylinders();
    let sk = &model.skeleton;
    let target = target_pose(&model);
    // A small perturbation so that the correspondences stay on the same parts under FD steps.
    let mut pose = target.clone();
    for (name, d) in [
        ("global_tx", 2.0),
        ("global_tz", -3.0),
        ("index_mcp_flex", 0.05),
        ("ring_pip_flex", -0.04),
        ("thumb_cmc_abd", 0.03),
    ] {
        pose.values[sk.dof_index(name).unwrap()] += d;
    }
    let points = closest_point_cloud(&model, &pose);
    assert!(points.len() > 200, "{} points", points.len());
    let term = E3d::default();
    for rigid in [false, true] {
        let mut ctx = TrackingCtx::new(&model, View::Orthographic, IrlsParams::default());
        ctx.set_points(&points);
        let mut update = |p: &Pose, c: &mut TrackingCtx<'_>| c.update(p, rigid).unwrap();
        let cmp =
            check_gradient(sk, &pose, sk.num_dofs(), &term, &mut ctx, &mut update, 1e-6).unwrap();
        let rel = cmp.relative_error(1e-9);
        eprintln!(
            "E3D gradient, rigid = {rigid}, {} points: relative error {rel:.2e}",
            points.len()
        );
        assert!(ctx.reweighted() != rigid);
        assert!(
            rel < 1e-4,
            "rigid = {rigid}: relative error {rel:e}\n{cmp:?}"
        );
    }
}

#[test]
fn rigid_iteration_is_not_reweighted_and_energy_is_l1() {
    let model = default_right_hand_cylinders();
    let target = target_pose(&model);
    let pose = perturbed_pose(&model, &target);
    let points = closest_point_cloud(&model, &pose);
    let mut ctx = TrackingCtx::new(&model, View::Orthographic, IrlsParams::default());
    ctx.set_points(&points);
    ctx.update(&pose, true).unwrap();
    assert!(ctx.rigid_only() && !ctx.reweighted());
    assert!(ctx.weights().iter().all(|&w| w == 1.0));
    ctx.update(&pose, false).unwrap();
    assert!(!ctx.rigid_only() && ctx.reweighted());
    // Closest-point correspondences: the Huber-ℓ1 energy is 2g Σ‖x − y‖ (Eq. 2.2).
    let l1: f64 = 2.0
        * IrlsParams::default().gain
        * ctx
            .correspondences()
            .iter()
            .map(|c| c.unwrap().distance.abs())
            .sum::<f64>();
    let mut ne = hand_model::solver::NormalEquations::new(model.skeleton.num_dofs());
    let stats = E3d::default().accumulate(&ctx, &mut ne).unwrap();
    assert_eq!(stats.rows, points.len());
    assert!(
        (stats.energy - l1).abs() < 1e-6 * l1,
        "{} vs {l1}",
        stats.energy
    );
}

#[test]
fn context_reuses_its_buffers_and_survives_bad_input() {
    let model = default_right_hand_cylinders();
    let pose = target_pose(&model);
    let mut points =
        visible_surface_points(&model, &model.posed(&pose).unwrap(), &camera(), 4, 1.0);
    let mut ctx = TrackingCtx::new(&model, View::Perspective, IrlsParams::default());
    ctx.set_points(&points);
    ctx.update(&pose, false).unwrap();
    let ptrs = (
        ctx.points().as_ptr(),
        ctx.correspondences().as_ptr(),
        ctx.weights().as_ptr(),
        ctx.posed().globals.as_ptr(),
    );
    points[0].x = f64::NAN;
    ctx.set_points(&points);
    ctx.update(&perturbed_pose(&model, &pose), false).unwrap();
    assert_eq!(
        ptrs,
        (
            ctx.points().as_ptr(),
            ctx.correspondences().as_ptr(),
            ctx.weights().as_ptr(),
            ctx.posed().globals.as_ptr(),
        )
    );
    assert!(ctx.correspondences()[0].is_none() && ctx.weights()[0] == 0.0);
    let mut ne = hand_model::solver::NormalEquations::new(model.skeleton.num_dofs());
    let stats = E3d::default().accumulate(&ctx, &mut ne).unwrap();
    assert!(stats.energy.is_finite() && ne.is_finite());
    // Wrong pose length: an error; non-finite pose: no correspondences.
    assert!(ctx
        .update(
            &Pose {
                values: vec![0.0; 3]
            },
            false
        )
        .is_err());
    let mut nan = pose.clone();
    nan.values[0] = f64::NAN;
    ctx.update(&nan, false).unwrap();
    assert!(ctx.correspondences().iter().all(Option::is_none));
}

/// LM from the perturbed pose on the ray-marched cloud of the target pose (4282 points at
/// stride 1): thesis defaults — 1 rigid + `iterations − 1` full iterations (§2.4), λ = 100
/// (§2.7.5) as the Damping term, joint limits ω₇ = 1e7, ω₁ = 1, orthographic front-facing test
/// (§2.3.1). Returns the pose, the report and the mean/max keypoint errors before and after.
fn solve_synthetic(
    iterations: usize,
) -> (Pose, hand_model::solver::LmReport, (f64, f64), (f64, f64)) {
    let model = default_right_hand_cylinders();
    let sk = &model.skeleton;
    let target = target_pose(&model);
    let points = visible_surface_points(&model, &model.posed(&target).unwrap(), &camera(), 1, 0.5);
    assert!(points.len() > 3000, "{} points", points.len());
    let start = perturbed_pose(&model, &target);
    let e3d = E3d::default();
    let limits = JointLimits::new(sk, &JointLimitsParams::default());
    let damping = Damping::new(sk, 0, &DampingParams::default()).unwrap();
    let options = LmOptions {
        iterations,
        rigid_iterations: 1,
        damping: DampingParams::none(),
        ..LmOptions::default()
    };
    let mut ctx = TrackingCtx::new(&model, View::Orthographic, IrlsParams::default());
    ctx.set_points(&points);
    let terms: [&dyn EnergyTerm<TrackingCtx<'_>>; 3] = [&e3d, &limits, &damping];
    let (pose, report) = solve_terms(&mut ctx, &terms, options, &start);
    let before = keypoint_error(&model, &start, &target);
    let after = keypoint_error(&model, &pose, &target);
    eprintln!(
        "{iterations} iterations, {} points: keypoint error mean/max before {:.2}/{:.2} mm, \
         after {:.4}/{:.4} mm; energy {:.1} -> {:.3}; {:?}",
        points.len(),
        before.0,
        before.1,
        after.0,
        after.1,
        report.energy_before,
        report.energy_after,
        report.termination
    );
    assert!(report.termination.was_successful());
    assert_eq!(report.iterations, iterations);
    (pose, report, before, after)
}

#[test]
fn lm_recovers_a_perturbed_pose_from_a_synthetic_cloud() {
    // One frame's solve with the thesis' 7 iterations: most of the way (the distal pinky
    // phalanx, caught by wrong correspondences at the start, lags behind).
    let (_, _, before, after) = solve_synthetic(7);
    assert!(before.0 > 15.0);
    assert!(after.0 < 0.1 * before.0 && after.0 < 2.0, "{after:?}");
    // Iterated further, the pose is recovered exactly (the data are noise-free).
    let (_, _, _, after) = solve_synthetic(30);
    assert!(after.1 < 1e-3, "{after:?}");
}

/// Prints the cost of one `TrackingCtx::update` (front-facing correspondences of the whole
/// ray-marched cloud, IRLS weights) at the perturbed pose; the results must not depend on
/// whether the correspondences were culled.
#[test]
fn update_timing_on_the_full_cloud() {
    let model = default_right_hand_cylinders();
    let target = target_pose(&model);
    let points = visible_surface_points(&model, &model.posed(&target).unwrap(), &camera(), 1, 0.5);
    let pose = perturbed_pose(&model, &target);
    let mut ctx = TrackingCtx::new(&model, View::Orthographic, IrlsParams::default());
    ctx.set_points(&points);
    ctx.update(&pose, false).unwrap();
    let runs = 10;
    let start = std::time::Instant::now();
    for _ in 0..runs {
        ctx.update(&pose, false).unwrap();
    }
    let ms = start.elapsed().as_secs_f64() * 1e3 / f64::from(runs);
    eprintln!(
        "TrackingCtx::update: {ms:.2} ms for {} points",
        points.len()
    );
    let posed = model.posed(&pose).unwrap();
    for (p, c) in points.iter().zip(ctx.correspondences()) {
        assert_eq!(
            *c,
            model.front_facing_point_brute_force(&posed, p, View::Orthographic)
        );
    }
}

/// One LM solve of `terms` from `start` (the context refreshed before every iteration);
/// returns the solved pose and the report. Shared by the term modules' tests.
pub(crate) fn solve_terms<'m>(
    ctx: &mut TrackingCtx<'m>,
    terms: &[&dyn EnergyTerm<TrackingCtx<'m>>],
    options: LmOptions,
    start: &Pose,
) -> (Pose, hand_model::solver::LmReport) {
    let sk = &ctx.model().skeleton;
    let solver = LmSolver::new(sk, 0, options).unwrap();
    let mut ws = solver.workspace();
    let mut pose = start.clone();
    let report = solver
        .solve(
            &mut ws,
            sk,
            &mut pose,
            ctx,
            terms,
            &mut CorrespondenceCallback,
        )
        .unwrap()
        .clone();
    (pose, report)
}

/// E3D sums the rows of each bone in a packed block before adding it: the system equals the
/// row-by-row [`NormalEquations::add_row`] assembly up to the order of the additions.
#[test]
fn e3d_blocks_equal_row_by_row_assembly() {
    use hand_model::solver::NormalEquations;
    let model = default_right_hand_cylinders();
    let target = target_pose(&model);
    let points = visible_surface_points(&model, &model.posed(&target).unwrap(), &camera(), 3, 0.5);
    let pose = perturbed_pose(&model, &target);
    let mut ctx = TrackingCtx::new(&model, View::Orthographic, IrlsParams::default());
    ctx.set_points(&points);
    ctx.update(&pose, false).unwrap();
    let n = model.skeleton.num_dofs();
    let mut blocked = NormalEquations::new(n);
    let stats = E3d::default().accumulate(&ctx, &mut blocked).unwrap();
    let mut rows = NormalEquations::new(n);
    let (sk, posed) = (ctx.skeleton(), ctx.posed());
    for ((c, &r), &w) in ctx
        .correspondences()
        .iter()
        .zip(ctx.residuals())
        .zip(ctx.weights())
    {
        let Some(c) = c else { continue };
        let cols: Vec<(usize, f64)> = sk
            .chain(c.bone)
            .iter()
            .map(|&d| (d, c.normal.dot(&posed.column(d, &c.point))))
            .collect();
        rows.add_row(&cols, r, w).unwrap();
    }
    assert!(stats.rows > 100);
    blocked.symmetrize();
    rows.symmetrize();
    let scale = rows.lhs().amax().max(rows.rhs().amax());
    let diff = (blocked.lhs() - rows.lhs())
        .amax()
        .max((blocked.rhs() - rows.rhs()).amax());
    assert!(diff <= 1e-12 * scale, "{diff} vs {scale}");
}
