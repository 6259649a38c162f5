//! Solver tests against known minima, finite differences and failure cases.

use std::path::Path;

use nalgebra::{DMatrix, Vector3};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::check::{check_gradient, check_hessian, FdComparison};
use super::terms::*;
use super::*;
use crate::kinematics::{DofKind, Pose, PosedSkeleton, Skeleton};
use crate::math::euler_xyz_to_matrix;
use crate::spheremesh::{default_right_hand, SphereMeshTemplate};

const HTRACK_PCA: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../shared/reference/htrack-pose-space-pca"
);

fn htrack_prior() -> Option<PcaPrior> {
    if Path::new(HTRACK_PCA).is_dir() {
        Some(PcaPrior::load_htrack_dir(Path::new(HTRACK_PCA)).unwrap())
    } else {
        eprintln!("skipped: {HTRACK_PCA} absent");
        None
    }
}

/// A random pose with joints inside their limits (shrunk by `margin`).
fn random_pose(sk: &Skeleton, rng: &mut ChaCha8Rng, margin: f64) -> Pose {
    let mut pose = Pose::zeros(sk);
    for (v, dof) in pose.values.iter_mut().zip(sk.dofs()) {
        *v = match (dof.kind, dof.limits) {
            (_, Some([lo, hi])) => rng.random_range(lo + margin..=hi - margin),
            (DofKind::Translation, None) => rng.random_range(-30.0..30.0),
            (_, None) => rng.random_range(-1.0..1.0),
        };
    }
    pose.values[2] += 400.0;
    pose
}

/// Global rotation off by `rot` rad about a random axis, every joint by ±`joint`, translation
/// by a few mm.
fn perturbed(sk: &Skeleton, pose: &Pose, rng: &mut ChaCha8Rng, rot: f64, joint: f64) -> Pose {
    let axis = Vector3::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    )
    .normalize()
        * rot;
    let mut delta = vec![0.0; sk.num_dofs()];
    let mut r = 0;
    for (d, dof) in sk.dofs().iter().enumerate() {
        delta[d] = match dof.kind {
            DofKind::Translation => rng.random_range(-5.0..5.0),
            DofKind::GlobalRotation => {
                r += 1;
                axis[r - 1]
            }
            DofKind::Rotation => joint * if rng.random_bool(0.5) { 1.0 } else { -1.0 },
        };
    }
    pose.retract(sk, &delta)
}

fn targets_term(t: &SphereMeshTemplate, pose: &Pose) -> PointTargets {
    let points = sphere_mesh_points(t);
    let posed = PosedSkeleton::new(&t.skeleton, pose);
    let targets = points.iter().map(|p| p.position(&posed)).collect();
    PointTargets::new(points, targets, &PointTargetsParams::default()).unwrap()
}

fn max_point_error(t: &SphereMeshTemplate, term: &PointTargets, pose: &Pose) -> f64 {
    let posed = PosedSkeleton::new(&t.skeleton, pose);
    term.points()
        .iter()
        .zip(term.targets())
        .map(|(p, q)| (p.position(&posed) - q).norm())
        .fold(0.0, f64::max)
}

fn opts(iterations: usize, rigid: usize, lambda: f64) -> LmOptions {
    LmOptions {
        iterations,
        rigid_iterations: rigid,
        damping: DampingParams::uniform(lambda),
        ..LmOptions::default()
    }
}

/// A random PCA prior over the default hand's thumb (4) and finger (16) DOFs.
fn synthetic_prior(sk: &Skeleton, rng: &mut ChaCha8Rng, m: usize) -> PcaPrior {
    let thumb = [
        "thumb_cmc_abd",
        "thumb_cmc_flex",
        "thumb_mcp_flex",
        "thumb_ip_flex",
    ];
    let mut fingers = vec![];
    for f in ["index", "middle", "ring", "pinky"] {
        for j in ["mcp_abd", "mcp_flex", "pip_flex", "dip_flex"] {
            fingers.push(format!("{f}_{j}"));
        }
    }
    let groups = [
        (
            "thumb",
            thumb.iter().map(|s| s.to_string()).collect::<Vec<_>>(),
        ),
        ("fingers", fingers),
    ]
    .into_iter()
    .map(|(name, dofs)| {
        let k = dofs.len();
        assert!(dofs.iter().all(|d| sk.dof_index(d).is_some()));
        let a = DMatrix::from_fn(k, k, |_, _| rng.random_range(-1.0..1.0));
        let q = a.qr().q();
        let m = m.min(k);
        PcaGroup {
            name: name.into(),
            dofs,
            mean: (0..k).map(|_| rng.random_range(-0.2..0.6)).collect(),
            basis: q.columns(0, m).into_owned(),
            variances: (0..m).map(|i| 1.5 / (1.0 + 3.0 * i as f64)).collect(),
        }
    })
    .collect();
    PcaPrior { groups }
}

fn repose(p: &Pose, c: &mut SkeletonCtx) {
    c.set_pose(p);
}

// ---------------------------------------------------------------------------------------------
// (a) inverse kinematics to a known minimum; rigid-only iterations

#[test]
fn ik_recovers_random_poses_from_perturbed_starts() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let solver = LmSolver::new(sk, 0, opts(20, 1, 1.0)).unwrap();
    let mut ws = solver.workspace();
    for trial in 0..8 {
        let truth = random_pose(sk, &mut rng, 0.1);
        let fit = targets_term(&t, &truth);
        let mut pose = perturbed(sk, &truth, &mut rng, 0.3, 0.3);
        let start_err = max_point_error(&t, &fit, &pose);
        let mut ctx = SkeletonCtx::new(sk, &pose);
        let terms: [&dyn EnergyTerm<SkeletonCtx>; 1] = [&fit];
        let report = solver
            .solve(&mut ws, sk, &mut pose, &mut ctx, &terms, &mut RePose)
            .unwrap()
            .clone();
        let err = max_point_error(&t, &fit, &pose);
        eprintln!(
            "trial {trial}: keypoint error {start_err:.1} mm → {err:.2e} mm, energy {:.3e} → {:.3e}",
            report.energy_before, report.energy_after
        );
        assert!(report.termination.was_successful());
        assert!(report.final_evaluated);
        assert!(err < 1e-3, "trial {trial}: max keypoint error {err} mm");
        // The pose itself is recovered (joint angles; rotation as a matrix).
        for (d, dof) in sk.dofs().iter().enumerate() {
            if dof.kind != DofKind::GlobalRotation {
                assert!(
                    (pose.values[d] - truth.values[d]).abs() < 1e-4,
                    "{}: {} vs {}",
                    dof.name,
                    pose.values[d],
                    truth.values[d]
                );
            }
        }
        let rot = |p: &Pose| euler_xyz_to_matrix(p.values[3], p.values[4], p.values[5]);
        assert!((rot(&pose) - rot(&truth)).norm() < 1e-6);
        assert!(report.energy_after < 1e-6 * report.energy_before.max(1.0));
        assert_eq!(report.terms.len(), 1);
        assert_eq!(report.terms[0].name, "point_targets");
        assert_eq!(report.terms[0].rows, 3 * fit.points().len());
    }
}

#[test]
fn rigid_only_iterations_move_only_global_dofs() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let truth = random_pose(sk, &mut rng, 0.1);
    let fit = targets_term(&t, &truth);
    let start = perturbed(sk, &truth, &mut rng, 0.3, 0.3);
    let mut pose = start.clone();
    let mut ctx = SkeletonCtx::new(sk, &pose);
    // Damping term and joint limits too: their joint rows must be masked as well.
    let limits = JointLimits::new(sk, &JointLimitsParams::default());
    let damp = Damping::new(sk, 0, &DampingParams::default()).unwrap();
    let terms: [&dyn EnergyTerm<SkeletonCtx>; 3] = [&fit, &limits, &damp];
    let solver = LmSolver::new(sk, 0, opts(2, 2, 1.0)).unwrap();
    let mut ws = solver.workspace();
    let report = solver
        .solve(&mut ws, sk, &mut pose, &mut ctx, &terms, &mut RePose)
        .unwrap();
    assert_eq!(report.iterations, 2);
    let mut moved = 0;
    for (d, dof) in sk.dofs().iter().enumerate() {
        if dof.kind == DofKind::Rotation {
            assert_eq!(
                pose.values[d].to_bits(),
                start.values[d].to_bits(),
                "{}",
                dof.name
            );
            assert_eq!(ws.step()[d], 0.0);
        } else if (pose.values[d] - start.values[d]).abs() > 1e-6 {
            moved += 1;
        }
    }
    assert!(moved >= 4, "the global DOFs moved ({moved})");
    // The rigid fit reduced the energy.
    assert!(ws.report().energy_after < ws.report().energy_before);
}

// ---------------------------------------------------------------------------------------------
// (b) every term's gradient and Gauss–Newton Hessian against finite differences

fn assert_fd(name: &str, c: &FdComparison, tol: f64) {
    let e = c.relative_error(1e-6);
    eprintln!(
        "{name}: relative error {e:.2e} (max |analytic| {:.3e})",
        c.analytic.iter().fold(0.0f64, |m, v| m.max(v.abs()))
    );
    assert!(e < tol, "{name}: {c:?}");
}

#[test]
fn every_term_gradient_matches_finite_differences() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let nd = sk.num_dofs();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for trial in 0..3 {
        let pose = random_pose(sk, &mut rng, 0.05);
        let mut ctx = SkeletonCtx::new(sk, &pose);

        // Point targets away from the solution.
        let other = perturbed(sk, &pose, &mut rng, 0.2, 0.2);
        let fit = targets_term(&t, &other);
        let c = check_gradient(sk, &pose, nd, &fit, &mut ctx, &mut repose, 1e-6).unwrap();
        assert_fd(&format!("point_targets #{trial}"), &c, 1e-6);

        // Temporal with a two-frame history of other poses.
        let mut temporal = Temporal::new(sphere_mesh_points(&t), &TemporalParams::default());
        for _ in 0..2 {
            let p = perturbed(sk, &pose, &mut rng, 0.1, 0.1);
            temporal.push_frame(&PosedSkeleton::new(sk, &p)).unwrap();
        }
        let c = check_gradient(sk, &pose, nd, &temporal, &mut ctx, &mut repose, 1e-6).unwrap();
        assert_fd(&format!("temporal #{trial}"), &c, 1e-6);

        // Joint limits with some DOFs well outside their bounds.
        let mut violated = pose.clone();
        for (d, dof) in sk.dofs().iter().enumerate() {
            if let (Some([lo, hi]), true) = (dof.limits, d % 3 == 0) {
                violated.values[d] = if d % 2 == 0 { hi + 0.2 } else { lo - 0.1 };
            }
        }
        let limits = JointLimits::new(sk, &JointLimitsParams::default());
        let c = check_gradient(sk, &violated, nd, &limits, &mut ctx, &mut repose, 1e-6).unwrap();
        assert!(c.analytic.iter().any(|g| *g != 0.0));
        assert_fd(&format!("joint_limits #{trial}"), &c, 1e-7);
        let h = check_hessian(sk, &violated, nd, &limits, &mut ctx, &mut repose, 1e-6).unwrap();
        assert_fd(&format!("joint_limits hessian #{trial}"), &h, 1e-6);

        // Damping: a proximal term, zero gradient.
        let damp = Damping::new(sk, 0, &DampingParams::default()).unwrap();
        let c = check_gradient(sk, &pose, nd, &damp, &mut ctx, &mut repose, 1e-6).unwrap();
        assert_eq!(c.max_abs_error(), 0.0);

        // The pose prior, all forms, on a synthetic prior.
        let prior = synthetic_prior(sk, &mut rng, 4);
        for form in [
            PosePriorForm::Exact,
            PosePriorForm::Projection,
            PosePriorForm::Augmented,
            PosePriorForm::Subspace,
        ] {
            let params = PosePriorParams {
                form,
                ..PosePriorParams::default()
            };
            let term = PosePrior::new(sk, &prior, &params).unwrap();
            let dim = nd + term.num_aux();
            let c = check_gradient(sk, &pose, dim, &term, &mut ctx, &mut repose, 1e-6).unwrap();
            assert_fd(&format!("pose_prior {form:?} #{trial}"), &c, 1e-6);
            let h = check_hessian(sk, &pose, dim, &term, &mut ctx, &mut repose, 1e-5).unwrap();
            if form != PosePriorForm::Augmented {
                // Quadratic in θ: A is the exact Hessian. (The augmented A is over (θ, θ̃);
                // its θθ block is not the reduced Hessian, by design.)
                assert_fd(&format!("pose_prior {form:?} hessian #{trial}"), &h, 1e-6);
            }
        }
    }
}

#[test]
fn gauss_newton_hessians_match_at_zero_residual() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let nd = sk.num_dofs();
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let pose = random_pose(sk, &mut rng, 0.05);
    let mut ctx = SkeletonCtx::new(sk, &pose);
    // Point targets at their solution: A = JᵀJ is the exact half Hessian.
    let fit = targets_term(&t, &pose);
    let h = check_hessian(sk, &pose, nd, &fit, &mut ctx, &mut repose, 1e-5).unwrap();
    assert_fd("point_targets hessian", &h, 1e-6);
    // Temporal with a history equal to the current points.
    let mut temporal = Temporal::new(sphere_mesh_points(&t), &TemporalParams::default());
    let posed = PosedSkeleton::new(sk, &pose);
    temporal.push_frame(&posed).unwrap();
    temporal.push_frame(&posed).unwrap();
    let h = check_hessian(sk, &pose, nd, &temporal, &mut ctx, &mut repose, 1e-5).unwrap();
    assert_fd("temporal hessian", &h, 1e-6);
}

// ---------------------------------------------------------------------------------------------
// Term order: terms only add

#[test]
fn shuffled_term_order_gives_the_same_system() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let pose = random_pose(sk, &mut rng, 0.0);
    let mut violated = pose.clone();
    violated.values[sk.dof_index("index_pip_flex").unwrap()] = 2.5;
    let ctx = SkeletonCtx::new(sk, &violated);
    let fit = targets_term(&t, &perturbed(sk, &pose, &mut rng, 0.2, 0.2));
    let limits = JointLimits::new(sk, &JointLimitsParams::default());
    let damp = Damping::new(sk, 6, &DampingParams::default()).unwrap();
    let mut temporal = Temporal::new(sphere_mesh_points(&t), &TemporalParams::default());
    temporal
        .push_frame(&PosedSkeleton::new(
            sk,
            &perturbed(sk, &pose, &mut rng, 0.1, 0.1),
        ))
        .unwrap();
    temporal
        .push_frame(&PosedSkeleton::new(
            sk,
            &perturbed(sk, &pose, &mut rng, 0.1, 0.1),
        ))
        .unwrap();
    let prior = synthetic_prior(sk, &mut rng, 3);
    let pca = PosePrior::new(
        sk,
        &prior,
        &PosePriorParams {
            form: PosePriorForm::Augmented,
            ..PosePriorParams::default()
        },
    )
    .unwrap();
    assert_eq!(pca.num_aux(), 6);
    let mut terms: Vec<&dyn EnergyTerm<SkeletonCtx>> = vec![&fit, &limits, &damp, &temporal, &pca];
    let n = sk.num_dofs() + 6;
    let (reference, e0) = assemble(&ctx, &terms, n);
    let scale = reference.lhs().amax();
    for _ in 0..10 {
        terms.shuffle(&mut rng);
        let (ne, e) = assemble(&ctx, &terms, n);
        assert!((ne.lhs() - reference.lhs()).amax() <= 1e-12 * scale);
        assert!((ne.rhs() - reference.rhs()).amax() <= 1e-12 * reference.rhs().amax());
        assert!((e - e0).abs() <= 1e-12 * e0);
    }
}

/// A history set aside leaves the temporal term empty and comes back as it was; a cleared one
/// does not come back.
#[test]
fn temporal_history_set_aside_comes_back_unchanged() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let pose = random_pose(sk, &mut rng, 0.0);
    let ctx = SkeletonCtx::new(sk, &pose);
    let mut temporal = Temporal::new(sphere_mesh_points(&t), &TemporalParams::default());
    for _ in 0..2 {
        let past = perturbed(sk, &pose, &mut rng, 0.1, 0.1);
        temporal.push_frame(&PosedSkeleton::new(sk, &past)).unwrap();
    }
    let n = sk.num_dofs();
    let (before, e0) = assemble(&ctx, &[&temporal], n);
    assert!(e0 > 0.0);
    temporal.set_history_aside(true);
    assert_eq!(temporal.history_len(), 0);
    assert_eq!(assemble(&ctx, &[&temporal], n).1, 0.0);
    temporal.set_history_aside(false);
    let (after, e1) = assemble(&ctx, &[&temporal], n);
    assert_eq!(
        (e1, after.lhs(), after.rhs()),
        (e0, before.lhs(), before.rhs())
    );
    temporal.set_history_aside(true);
    temporal.clear_history();
    temporal.set_history_aside(false);
    assert_eq!(temporal.history_len(), 0);
}

fn assemble<'a>(
    ctx: &SkeletonCtx<'a>,
    terms: &[&dyn EnergyTerm<SkeletonCtx<'a>>],
    n: usize,
) -> (NormalEquations, f64) {
    let mut ne = NormalEquations::new(n);
    let e: f64 = terms
        .iter()
        .map(|t| t.accumulate(ctx, &mut ne).unwrap().energy)
        .sum();
    ne.symmetrize();
    (ne, e)
}

// ---------------------------------------------------------------------------------------------
// (c) joint limits

#[test]
fn joint_limits_pull_a_violated_dof_back_inside() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let d = sk.dof_index("index_mcp_flex").unwrap();
    let [lo, hi] = sk.dofs()[d].limits.unwrap();
    let limits = JointLimits::new(sk, &JointLimitsParams::default());
    let solver = LmSolver::new(sk, 0, opts(2, 0, 100.0)).unwrap();
    let mut ws = solver.workspace();
    for (start, bound) in [(hi + 0.4, hi), (lo - 0.3, lo)] {
        let mut pose = Pose::zeros(sk);
        pose.values[d] = start;
        let before = pose.clone();
        let mut ctx = SkeletonCtx::new(sk, &pose);
        let terms: [&dyn EnergyTerm<SkeletonCtx>; 1] = [&limits];
        let report = solver
            .solve(&mut ws, sk, &mut pose, &mut ctx, &terms, &mut RePose)
            .unwrap();
        // One step lands within λ/(ω+λ) of the bound; the second inside to rounding.
        assert!((pose.values[d] - bound).abs() < 1e-8, "{}", pose.values[d]);
        assert!(report.energy_before > 0.0 && report.energy_after < 1e-9);
        // Approached from outside: at most a rounding-size violation is left.
        assert!(report.terms[0].rows <= 1);
        for (i, (a, b)) in pose.values.iter().zip(&before.values).enumerate() {
            if i != d {
                assert_eq!(a, b);
            }
        }
    }
    // Inside the limits the term is empty.
    let ctx = SkeletonCtx::new(sk, &Pose::zeros(sk));
    let mut ne = NormalEquations::new(sk.num_dofs());
    let s = EnergyTerm::<SkeletonCtx>::accumulate(&limits, &ctx, &mut ne).unwrap();
    assert_eq!(s, TermStats::ZERO);
}

// ---------------------------------------------------------------------------------------------
// (d) the PCA pose prior

fn pose_with(sk: &Skeleton, values: &[(&str, f64)]) -> Pose {
    Pose::from_named(sk, values.iter().copied()).unwrap()
}

fn set_group(sk: &Skeleton, pose: &mut Pose, g: &PcaGroup, y: &[f64]) {
    for ((name, mu), v) in g.dofs.iter().zip(&g.mean).zip(y) {
        pose.values[sk.dof_index(name).unwrap()] = mu + v;
    }
}

#[test]
fn pose_prior_is_zero_at_the_mean_and_grows_off_the_subspace() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let prior = synthetic_prior(sk, &mut rng, 3);
    for form in [
        PosePriorForm::Exact,
        PosePriorForm::Projection,
        PosePriorForm::Augmented,
    ] {
        let params = PosePriorParams {
            form,
            ..PosePriorParams::default()
        };
        let term = PosePrior::new(sk, &prior, &params).unwrap();
        // At μ: zero energy and zero gradient.
        let mut pose = random_pose(sk, &mut rng, 0.0);
        for g in &prior.groups {
            set_group(sk, &mut pose, g, &vec![0.0; g.num_dofs()]);
        }
        let ctx = SkeletonCtx::new(sk, &pose);
        let mut ne = NormalEquations::new(sk.num_dofs() + term.num_aux());
        let s = term.accumulate(&ctx, &mut ne).unwrap();
        assert!(s.energy.abs() < 1e-20, "{form:?}: {}", s.energy);
        assert!(ne.rhs().amax() < 1e-12);
        assert!(term.energy(&pose.values).unwrap().abs() < 1e-20);

        // Along a direction orthogonal to the subspace the energy is ω₄‖y⊥‖², increasing.
        let g = &prior.groups[1];
        let p = &g.basis;
        let raw = nalgebra::DVector::from_fn(g.num_dofs(), |_, _| rng.random_range(-1.0..1.0));
        let perp = &raw - p * (p.transpose() * &raw);
        let mut last = 0.0;
        for step in 1..=4 {
            let y = &perp * (0.1 * step as f64);
            let mut q = pose.clone();
            set_group(sk, &mut q, g, y.as_slice());
            let e = term.energy(&q.values).unwrap();
            assert!((e - 1e3 * y.norm_squared()).abs() < 1e-9 * e, "{form:?}");
            assert!(e > last);
            last = e;
        }
        // Inside the subspace the cost is far lower than the same distance across it.
        let inside = p.column(0) * (0.1 * 4.0 * perp.norm());
        let mut q = pose.clone();
        set_group(sk, &mut q, g, inside.as_slice());
        assert!(term.energy(&q.values).unwrap() < 0.01 * last, "{form:?}");
    }
}

#[test]
fn exact_and_augmented_pose_priors_give_the_same_steps() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let nd = sk.num_dofs();
    let mut rng = ChaCha8Rng::seed_from_u64(22);
    let prior = synthetic_prior(sk, &mut rng, 3);
    let truth = random_pose(sk, &mut rng, 0.1);
    let fit = targets_term(&t, &truth);
    let start = perturbed(sk, &truth, &mut rng, 0.2, 0.3);
    let run = |form: PosePriorForm| {
        let params = PosePriorParams {
            form,
            weight_projection: 50.0,
            weight_mean: 5.0,
            ..PosePriorParams::default()
        };
        let pca = PosePrior::new(sk, &prior, &params).unwrap();
        let solver = LmSolver::new(sk, pca.num_aux(), opts(6, 1, 10.0)).unwrap();
        let mut ws = solver.workspace();
        let mut pose = start.clone();
        let mut ctx = SkeletonCtx::new(sk, &pose);
        let terms: [&dyn EnergyTerm<SkeletonCtx>; 2] = [&fit, &pca];
        let mut aux_calls = 0;
        let report = {
            let len = pca.num_aux();
            let mut cb = RePoseAnd(|delta: &[f64]| {
                assert_eq!(delta.len(), len);
                aux_calls += 1;
            });
            solver
                .solve(&mut ws, sk, &mut pose, &mut ctx, &terms, &mut cb)
                .unwrap()
                .clone()
        };
        (pose, report, aux_calls, ws.step()[..nd].to_vec())
    };
    let (p_exact, r_exact, calls_exact, _) = run(PosePriorForm::Exact);
    let (p_aug, r_aug, calls_aug, _) = run(PosePriorForm::Augmented);
    for (a, b) in p_exact.values.iter().zip(&p_aug.values) {
        assert!((a - b).abs() < 1e-9, "{a} vs {b}");
    }
    assert!((r_exact.energy_before - r_aug.energy_before).abs() < 1e-9 * r_exact.energy_before);
    assert!((r_exact.energy_after - r_aug.energy_after).abs() < 1e-7 * r_exact.energy_before);
    for (a, b) in r_exact.terms.iter().zip(&r_aug.terms) {
        assert!((a.energy - b.energy).abs() <= 1e-8 * a.energy.max(1.0));
    }
    assert_eq!((calls_exact, calls_aug), (6, 6));
    assert!(r_exact.energy_after < r_exact.energy_before);
}

#[test]
fn subspace_pose_prior_holds_the_solve_in_the_pca_subspace() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let mut rng = ChaCha8Rng::seed_from_u64(23);
    let prior = synthetic_prior(sk, &mut rng, 3);
    let params = PosePriorParams {
        form: PosePriorForm::Subspace,
        ..PosePriorParams::default()
    };
    let term = PosePrior::new(sk, &prior, &params).unwrap();
    assert_eq!(term.num_aux(), 0);
    // Energy: ω₄·10⁶ across the subspace, the Mahalanobis ω₅ Σ z²/σ² inside it.
    let g = &prior.groups[1];
    let p = &g.basis;
    let mut pose = random_pose(sk, &mut rng, 0.0);
    for g in &prior.groups {
        set_group(sk, &mut pose, g, &vec![0.0; g.num_dofs()]);
    }
    let raw = nalgebra::DVector::from_fn(g.num_dofs(), |_, _| rng.random_range(-1.0..1.0));
    let perp = (&raw - p * (p.transpose() * &raw)) * 0.01;
    let z = [0.3, -0.2, 0.1];
    let inside = p * nalgebra::DVector::from_column_slice(&z);
    let mut q = pose.clone();
    set_group(sk, &mut q, g, (&inside + &perp).as_slice());
    let e = term.energy(&q.values).unwrap();
    let mahalanobis: f64 = z.iter().zip(&g.variances).map(|(z, v)| z * z / v).sum();
    let expected = 1e3 * SUBSPACE_STIFFNESS * perp.norm_squared() + mahalanobis;
    assert!((e - expected).abs() < 1e-6 * expected, "{e} vs {expected}");
    // A solve toward targets off the subspace ends (numerically) inside it.
    let truth = random_pose(sk, &mut rng, 0.1);
    let fit = targets_term(&t, &truth);
    let start = perturbed(sk, &truth, &mut rng, 0.1, 0.2);
    let solver = LmSolver::new(sk, 0, opts(10, 1, 1.0)).unwrap();
    let mut ws = solver.workspace();
    let mut pose = start.clone();
    let mut ctx = SkeletonCtx::new(sk, &pose);
    let terms: [&dyn EnergyTerm<SkeletonCtx>; 2] = [&fit, &term];
    solver
        .solve(&mut ws, sk, &mut pose, &mut ctx, &terms, &mut RePose)
        .unwrap();
    for (gi, g) in prior.groups.iter().enumerate() {
        let y: Vec<f64> = g
            .dofs
            .iter()
            .zip(&g.mean)
            .map(|(n, m)| pose.values[sk.dof_index(n).unwrap()] - m)
            .collect();
        let y = nalgebra::DVector::from_vec(y);
        let lat = nalgebra::DVector::from_vec(term.latent(&pose.values, gi).unwrap());
        let off = (&y - &g.basis * lat).norm();
        assert!(off < 1e-3, "group {gi}: {off} rad off the subspace");
    }
}

/// [`RePose`], and each auxiliary step handed to a closure.
struct RePoseAnd<F>(F);

impl<F: FnMut(&[f64])> LmCallback<SkeletonCtx<'_>> for RePoseAnd<F> {
    fn prepare(
        &mut self,
        pose: &Pose,
        ctx: &mut SkeletonCtx,
        info: IterInfo,
    ) -> Result<(), TermError> {
        RePose.prepare(pose, ctx, info)
    }
    fn apply_aux(&mut self, _ctx: &mut SkeletonCtx, delta: &[f64]) {
        (self.0)(delta)
    }
}

#[test]
fn pose_prior_alone_pulls_toward_the_mean() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let mut rng = ChaCha8Rng::seed_from_u64(23);
    let prior = synthetic_prior(sk, &mut rng, 3);
    let pca = PosePrior::new(sk, &prior, &PosePriorParams::default()).unwrap();
    let mut pose = random_pose(sk, &mut rng, 0.0);
    let mut ctx = SkeletonCtx::new(sk, &pose);
    let terms: [&dyn EnergyTerm<SkeletonCtx>; 1] = [&pca];
    let solver = LmSolver::new(sk, 0, opts(1, 0, 0.01)).unwrap();
    let mut ws = solver.workspace();
    let mut last = pca.energy(&pose.values).unwrap();
    for _ in 0..10 {
        let r = solver
            .solve(&mut ws, sk, &mut pose, &mut ctx, &terms, &mut RePose)
            .unwrap();
        assert!(r.energy_after < last);
        last = r.energy_after;
    }
    assert!(last < 1e-6, "{last}");
}

#[test]
fn htrack_prior_prefers_natural_poses() {
    let Some(prior) = htrack_prior() else {
        return;
    };
    let t = default_right_hand();
    let sk = &t.skeleton;
    let pca = PosePrior::new(sk, &prior, &PosePriorParams::default()).unwrap();
    let e = |p: &Pose| pca.energy(&p.values).unwrap();
    let mut half_fist: Vec<(String, f64)> = [
        ("thumb_cmc_flex", 0.4),
        ("thumb_mcp_flex", 0.3),
        ("thumb_ip_flex", 0.3),
    ]
    .iter()
    .map(|(n, v)| (n.to_string(), *v))
    .collect();
    for f in ["index", "middle", "ring", "pinky"] {
        half_fist.push((format!("{f}_mcp_flex"), 0.6));
        half_fist.push((format!("{f}_pip_flex"), 0.7));
        half_fist.push((format!("{f}_dip_flex"), 0.4));
    }
    let natural = Pose::from_named(sk, half_fist.iter().map(|(n, v)| (n.as_str(), *v))).unwrap();
    let unnatural = pose_with(
        sk,
        &[
            ("index_mcp_flex", 1.5),
            ("index_pip_flex", 1.6),
            ("index_dip_flex", 1.2),
            ("middle_mcp_flex", -0.4),
            ("middle_pip_flex", -0.1),
            ("middle_dip_flex", -0.2),
            ("ring_mcp_flex", -0.4),
            ("ring_pip_flex", -0.1),
            ("ring_dip_flex", -0.2),
            ("pinky_mcp_flex", -0.4),
            ("pinky_pip_flex", -0.1),
            ("pinky_dip_flex", -0.2),
        ],
    );
    let mut mean = Pose::zeros(sk);
    for g in &prior.groups {
        set_group(sk, &mut mean, g, &vec![0.0; g.num_dofs()]);
    }
    let (en, eu, em) = (e(&natural), e(&unnatural), e(&mean));
    eprintln!("htrack prior: mean {em:.3e}, half fist {en:.3e}, index-only fist {eu:.3e}");
    assert!(em.abs() < 1e-9);
    assert!(en < eu, "natural {en} vs unnatural {eu}");
    assert!(eu > 5.0 * en);
    // Same ordering with the thesis projection-only expression and the augmented form.
    for form in [PosePriorForm::Projection, PosePriorForm::Augmented] {
        let p = PosePrior::new(
            sk,
            &prior,
            &PosePriorParams {
                form,
                ..PosePriorParams::default()
            },
        )
        .unwrap();
        assert!(p.energy(&natural.values).unwrap() < p.energy(&unnatural.values).unwrap());
    }
    // The latent "bending" coordinate of the fingers grows with the fist.
    let l0 = pca.latent(&mean.values, 1).unwrap()[0];
    let l1 = pca.latent(&natural.values, 1).unwrap()[0];
    assert!(l0.abs() < 1e-9 && l1.abs() > 0.1, "{l0} {l1}");
}

#[test]
fn pose_prior_refuses_unknown_dofs_and_bad_weights() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let mut rng = ChaCha8Rng::seed_from_u64(24);
    let mut prior = synthetic_prior(sk, &mut rng, 2);
    assert!(PosePrior::new(
        sk,
        &prior,
        &PosePriorParams {
            weight_projection: 0.0,
            ..PosePriorParams::default()
        }
    )
    .is_err());
    prior.groups[0].dofs[0] = "no_such_dof".into();
    let err = PosePrior::new(sk, &prior, &PosePriorParams::default()).unwrap_err();
    assert!(err.to_string().contains("no_such_dof"), "{err}");
}

// ---------------------------------------------------------------------------------------------
// (e) NaN safety and the non-SPD recovery

struct BadTerm {
    residual: f64,
    jacobian: f64,
    diagonal: f64,
}

impl EnergyTerm<SkeletonCtx<'_>> for BadTerm {
    fn name(&self) -> &'static str {
        "bad"
    }
    fn accumulate(
        &self,
        _: &SkeletonCtx,
        ne: &mut NormalEquations,
    ) -> Result<TermStats, TermError> {
        ne.add_diagonal(7, self.diagonal)?;
        ne.add_row(&[(7, self.jacobian), (8, 1.0)], self.residual, 1.0)
    }
}

#[test]
fn non_finite_terms_never_reach_the_pose() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let mut rng = ChaCha8Rng::seed_from_u64(31);
    let truth = random_pose(sk, &mut rng, 0.1);
    let fit = targets_term(&t, &truth);
    let solver = LmSolver::new(sk, 0, LmOptions::default()).unwrap();
    let mut ws = solver.workspace();
    for (residual, jacobian) in [(f64::NAN, 1.0), (1.0, f64::NAN), (f64::INFINITY, 1.0)] {
        let bad = BadTerm {
            residual,
            jacobian,
            diagonal: 0.0,
        };
        let start = perturbed(sk, &truth, &mut rng, 0.1, 0.1);
        let mut pose = start.clone();
        let mut ctx = SkeletonCtx::new(sk, &pose);
        let terms: [&dyn EnergyTerm<SkeletonCtx>; 2] = [&fit, &bad];
        let report = solver
            .solve(&mut ws, sk, &mut pose, &mut ctx, &terms, &mut RePose)
            .unwrap();
        assert_eq!(
            report.termination,
            Termination::NonFinite {
                iteration: 0,
                term: Some("bad")
            }
        );
        assert!(!report.termination.was_successful());
        assert_eq!(report.iterations, 0);
        assert_eq!(pose, start, "pose untouched");
        assert!(ws.step().iter().all(|v| *v == 0.0));
    }
}

#[test]
fn indefinite_systems_are_recovered_with_extra_damping() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let mut rng = ChaCha8Rng::seed_from_u64(32);
    let truth = random_pose(sk, &mut rng, 0.1);
    let fit = targets_term(&t, &truth);
    // A negative diagonal makes the system indefinite.
    let bad = BadTerm {
        residual: 0.5,
        jacobian: 1.0,
        diagonal: -1e6,
    };
    let solver = LmSolver::new(sk, 0, opts(3, 0, 1.0)).unwrap();
    let mut ws = solver.workspace();
    let mut pose = perturbed(sk, &truth, &mut rng, 0.1, 0.1);
    let mut ctx = SkeletonCtx::new(sk, &pose);
    let terms: [&dyn EnergyTerm<SkeletonCtx>; 2] = [&fit, &bad];
    let report = solver
        .solve(&mut ws, sk, &mut pose, &mut ctx, &terms, &mut RePose)
        .unwrap();
    assert!(
        report.termination.was_successful(),
        "{:?}",
        report.termination
    );
    assert_eq!(report.regularized_solves, 3);
    assert!(pose.values.iter().all(|v| v.is_finite()));
    // Without damping and with no terms the system is singular: extra damping gives δ = 0.
    let empty: [&dyn EnergyTerm<SkeletonCtx>; 0] = [];
    let solver = LmSolver::new(sk, 0, opts(1, 0, 0.0)).unwrap();
    let mut ws = solver.workspace();
    let before = pose.clone();
    let report = solver
        .solve(&mut ws, sk, &mut pose, &mut ctx, &empty, &mut RePose)
        .unwrap();
    assert!(report.termination.was_successful());
    assert_eq!(report.regularized_solves, 1);
    assert_eq!(pose, before);
}

// ---------------------------------------------------------------------------------------------
// Errors, options, callbacks

#[test]
fn errors_and_options() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    assert_eq!(
        LmOptions {
            iterations: 0,
            ..LmOptions::default()
        }
        .validate(),
        Err(OptionsError::NoIterations)
    );
    assert!(matches!(
        LmSolver::new(sk, 0, opts(1, 2, 1.0)),
        Err(LmError::Options(OptionsError::TooManyRigid { .. }))
    ));
    assert!(LmSolver::new(sk, 0, opts(1, 0, -1.0)).is_err());
    let mut bad_name = LmOptions::default();
    bad_name.damping.per_dof.insert("nope".into(), 1.0);
    assert!(matches!(
        LmSolver::new(sk, 0, bad_name),
        Err(LmError::Model(_))
    ));

    // Serde: partial JSON takes the defaults.
    let o: LmOptions = serde_json::from_str(
        r#"{"iterations": 5, "damping": {"per_dof": {"index_mcp_abd": 1.5e6}}}"#,
    )
    .unwrap();
    assert_eq!((o.iterations, o.rigid_iterations), (5, 1));
    assert_eq!(o.damping.rotation, 100.0);
    let solver = LmSolver::new(sk, 2, o).unwrap();
    assert_eq!(solver.dim(), sk.num_dofs() + 2);
    let p: PosePriorParams = serde_json::from_str(r#"{"form": "augmented"}"#).unwrap();
    assert_eq!(p.form, PosePriorForm::Augmented);
    assert_eq!(p.weight_projection, 1e3);
    let tp: TemporalParams = serde_json::from_str("{}").unwrap();
    assert_eq!(tp.weight_velocity, 3.0);
    let jl: JointLimitsParams = serde_json::from_str("{}").unwrap();
    assert_eq!(jl.weight, 1e7);

    // Size mismatches and term errors are errors, not panics.
    let solver = LmSolver::new(sk, 0, LmOptions::default()).unwrap();
    let mut ws = LmWorkspace::new(3);
    let mut pose = Pose::zeros(sk);
    let mut ctx = SkeletonCtx::new(sk, &pose);
    let none: [&dyn EnergyTerm<SkeletonCtx>; 0] = [];
    assert!(matches!(
        solver.solve(&mut ws, sk, &mut pose, &mut ctx, &none, &mut RePose),
        Err(LmError::Dimension { .. })
    ));
    let mut ws = solver.workspace();
    let stray = PointTargets::new(
        vec![KinematicPoint {
            bone: 999,
            local: Vector3::zeros(),
        }],
        vec![Vector3::zeros()],
        &PointTargetsParams::default(),
    )
    .unwrap();
    let terms: [&dyn EnergyTerm<SkeletonCtx>; 1] = [&stray];
    let err = solver
        .solve(&mut ws, sk, &mut pose, &mut ctx, &terms, &mut RePose)
        .unwrap_err();
    assert!(
        matches!(
            err,
            LmError::Term {
                name: "point_targets",
                ..
            }
        ),
        "{err}"
    );
    // A failing callback.
    let mut cb = callback_fn(|_: &Pose, _: &mut SkeletonCtx, _| Err(TermError::Failed("no data")));
    assert!(matches!(
        solver.solve(&mut ws, sk, &mut pose, &mut ctx, &none, &mut cb),
        Err(LmError::Callback(TermError::Failed("no data")))
    ));
}

#[test]
fn step_tolerance_stops_early_and_callback_sees_iterations() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    let truth = random_pose(sk, &mut rng, 0.1);
    let fit = targets_term(&t, &truth);
    let options = LmOptions {
        iterations: 50,
        step_tolerance: 1e-9,
        damping: DampingParams::uniform(1.0),
        ..LmOptions::default()
    };
    let solver = LmSolver::new(sk, 0, options).unwrap();
    let mut ws = solver.workspace();
    let mut pose = perturbed(sk, &truth, &mut rng, 0.1, 0.1);
    let mut ctx = SkeletonCtx::new(sk, &pose);
    let mut seen = vec![];
    let mut cb = callback_fn(|p: &Pose, c: &mut SkeletonCtx, info: IterInfo| {
        seen.push(info);
        c.set_pose(p);
        Ok(())
    });
    let terms: [&dyn EnergyTerm<SkeletonCtx>; 1] = [&fit];
    let report = solver
        .solve(&mut ws, sk, &mut pose, &mut ctx, &terms, &mut cb)
        .unwrap()
        .clone();
    assert_eq!(report.termination, Termination::StepTolerance);
    assert!(report.iterations < 50);
    assert!(report.last_step < 1e-9);
    assert_eq!(
        seen.len(),
        report.iterations + 1,
        "one prepare per iteration + final"
    );
    assert!(seen[0].rigid_only && !seen[1].rigid_only);
    assert!(seen.last().unwrap().final_evaluation);
}

// (f) LmOptions::decouple_aux

/// Residuals `θ_j + β − 1` and `θ_j − 2β + 0.5` over one joint DOF and one auxiliary unknown β
/// (optimum θ_j = β = 0.5), β read from the shared cell.
struct Coupled<'a> {
    dof: usize,
    beta: &'a std::cell::Cell<f64>,
}

impl EnergyTerm<SkeletonCtx<'_>> for Coupled<'_> {
    fn name(&self) -> &'static str {
        "coupled"
    }
    fn accumulate(
        &self,
        c: &SkeletonCtx,
        ne: &mut NormalEquations,
    ) -> Result<TermStats, TermError> {
        let (t, b, aux) = (c.pose.values[self.dof], self.beta.get(), ne.dim() - 1);
        let s = ne.add_row(&[(self.dof, 1.0), (aux, 1.0)], t + b - 1.0, 1.0)?;
        Ok(s + ne.add_row(&[(self.dof, 1.0), (aux, -2.0)], t - 2.0 * b + 0.5, 1.0)?)
    }
}

/// `4 θ_j²`: a prior on the pose alone, holding θ_j off the data's optimum.
struct ToZero(usize);

impl EnergyTerm<SkeletonCtx<'_>> for ToZero {
    fn name(&self) -> &'static str {
        "to_zero"
    }
    fn accumulate(
        &self,
        c: &SkeletonCtx,
        ne: &mut NormalEquations,
    ) -> Result<TermStats, TermError> {
        ne.add_row(&[(self.0, 1.0)], c.pose.values[self.0], 4.0)
    }
    fn pose_only_prior(&self) -> bool {
        true
    }
}

/// Solve the coupled problem (with the prior or not) from θ = β = 0; returns (θ_j, β).
fn solve_coupled(decouple: bool, with_prior: bool) -> (f64, f64) {
    solve_shared(decouple, with_prior, 0.0)
}

/// [`solve_coupled`] with [`LmOptions::aux_prior_share`] set through the solver.
fn solve_shared(decouple: bool, with_prior: bool, share: f64) -> (f64, f64) {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let dof = sk
        .dofs()
        .iter()
        .position(|d| d.kind == DofKind::Rotation)
        .unwrap();
    let beta = std::cell::Cell::new(0.0);
    let data = Coupled { dof, beta: &beta };
    let prior = ToZero(dof);
    let mut terms: Vec<&dyn EnergyTerm<SkeletonCtx>> = vec![&data];
    if with_prior {
        terms.push(&prior);
    }
    let options = LmOptions {
        decouple_aux: decouple,
        ..opts(60, 0, 1e-3)
    };
    let mut solver = LmSolver::new(sk, 1, options).unwrap();
    solver.set_aux_prior_share(share);
    let mut ws = solver.workspace();
    let mut pose = Pose::zeros(sk);
    let mut ctx = SkeletonCtx::new(sk, &pose);
    solver
        .solve(
            &mut ws,
            sk,
            &mut pose,
            &mut ctx,
            &terms,
            &mut RePoseAnd(|delta: &[f64]| beta.set(beta.get() + delta[0])),
        )
        .unwrap();
    (pose.values[dof], beta.get())
}

#[test]
fn decoupled_aux_step_keeps_the_pose_prior_out_of_the_shape() {
    // Jointly, the prior's pull on θ (to 0) is absorbed by β: the fixed point minimizes
    // (θ+β−1)² + (θ−2β+0.5)² + 4θ², β = 25/58, off the data's 0.5.
    let (t_joint, b_joint) = solve_coupled(false, true);
    assert!((b_joint - 25.0 / 58.0).abs() < 1e-9, "β = {b_joint}");
    // Decoupled, β's step sees the prior's curvature but not its pull: in the normal
    // equations [[a+p, c], [c, b]] (a = 2, b = 5, c = −1, p = 4) the bias shrinks by
    // b·p / ((a+p)·b − c²) = 20/29 — with the data's curvature far above the prior's (a
    // frame's thousands of points) it vanishes.
    let (t_dec, b_dec) = solve_coupled(true, true);
    let expected = 0.5 - (0.5 - 25.0 / 58.0) * 20.0 / 29.0;
    // (The LM damping, 1e-3, moves this fixed point by ≈ 4e-6.)
    assert!(
        (b_dec - expected).abs() < 2e-5,
        "β: {b_dec}, expected {expected}"
    );
    // The pose keeps the prior's regularization.
    assert!(
        t_dec < 0.45 && t_joint < 0.45,
        "θ: joint {t_joint}, decoupled {t_dec}"
    );
    // Without pose-only priors the option changes nothing, bit for bit.
    assert_eq!(solve_coupled(true, false), solve_coupled(false, false));
    let (t, b) = solve_coupled(false, false);
    assert!((t - 0.5).abs() < 1e-6 && (b - 0.5).abs() < 1e-6, "{t} {b}");
}

#[test]
fn a_share_of_the_prior_in_the_aux_step_moves_the_fixed_point_linearly() {
    // With the prior's gradient scaled by s in β's step, the fixed point is θ = 9/58 whatever
    // s (from θ's row: 5·∂E/∂θ = −∂E/∂β) and β = 25/58 + (1 − s)·18/841 (from β's row:
    // ∂E_data/∂β = 20 (1 − s) θ / 29): s = 0 is the decoupled point above, s = 1 the joint.
    for share in [0.25, 0.75] {
        let (t, b) = solve_shared(true, true, share);
        let expected = 25.0 / 58.0 + (1.0 - share) * 18.0 / 841.0;
        assert!((t - 9.0 / 58.0).abs() < 2e-5, "θ: {t}");
        assert!(
            (b - expected).abs() < 2e-5,
            "β at s = {share}: {b}, expected {expected}"
        );
    }
    // s = 1 is the joint step bit for bit; out-of-range shares are clamped, NaN means joint.
    assert_eq!(solve_shared(true, true, 1.0), solve_coupled(false, true));
    assert_eq!(
        solve_shared(true, true, f64::NAN),
        solve_coupled(false, true)
    );
    assert_eq!(solve_shared(true, true, -3.0), solve_coupled(true, true));
    let bad = LmOptions {
        aux_prior_share: 1.5,
        ..LmOptions::default()
    };
    assert_eq!(bad.validate(), Err(OptionsError::AuxPriorShare));
}
