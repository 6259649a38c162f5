//! STYLE practice 7: after a warm-up solve, Levenberg–Marquardt iterations allocate nothing —
//! re-posing, every prior term (point targets, joint limits, temporal, the augmented PCA prior,
//! damping), assembly, the Cholesky solve and the pose update. Counted by a global allocator
//! (per thread, so the test harness does not interfere).

#![allow(unsafe_code)] // the counting allocator of the included file

#[path = "support/counting_alloc.rs"]
mod counting_alloc;

use hand_model::kinematics::{Pose, PosedSkeleton};
use hand_model::solver::terms::{
    Damping, DampingParams, JointLimits, JointLimitsParams, PointTargets, PointTargetsParams,
    PosePrior, PosePriorForm, PosePriorParams, Temporal, TemporalParams,
};
use hand_model::solver::{
    callback_fn, sphere_mesh_points, EnergyTerm, IterInfo, LmOptions, LmSolver, PcaGroup, PcaPrior,
    SkeletonCtx,
};
use hand_model::spheremesh::default_right_hand;
use nalgebra::DMatrix;

/// Allocations made by `f` on this thread.
fn count(f: impl FnOnce()) -> usize {
    counting_alloc::count(f).0
}

/// A deterministic 3+3-latent prior over the default hand's thumb and finger DOFs.
fn prior() -> PcaPrior {
    let thumb: Vec<String> = [
        "thumb_cmc_abd",
        "thumb_cmc_flex",
        "thumb_mcp_flex",
        "thumb_ip_flex",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let fingers: Vec<String> = ["index", "middle", "ring", "pinky"]
        .iter()
        .flat_map(|f| {
            ["mcp_abd", "mcp_flex", "pip_flex", "dip_flex"]
                .iter()
                .map(move |j| format!("{f}_{j}"))
        })
        .collect();
    let groups = [("thumb", thumb), ("fingers", fingers)]
        .into_iter()
        .map(|(name, dofs)| {
            let k = dofs.len();
            let a = DMatrix::from_fn(k, k, |i, j| {
                ((i * 7 + j * 3) % 11) as f64 - 5.0 + (i == j) as u8 as f64 * 9.0
            });
            let q = a.qr().q();
            PcaGroup {
                name: name.into(),
                dofs,
                mean: (0..k).map(|i| 0.1 * (i % 4) as f64).collect(),
                basis: q.columns(0, 3).into_owned(),
                variances: vec![1.5, 0.4, 0.2],
            }
        })
        .collect();
    PcaPrior { groups }
}

#[test]
fn lm_iterations_allocate_nothing_after_warm_up() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let mut target = Pose::zeros(sk);
    for (name, v) in [
        ("index_mcp_flex", 0.5),
        ("global_tz", 400.0),
        ("thumb_ip_flex", 0.3),
    ] {
        target.set(sk, name, v).unwrap();
    }
    let points = sphere_mesh_points(&t);
    let posed = PosedSkeleton::new(sk, &target);
    let targets = points.iter().map(|p| p.position(&posed)).collect();
    let fit = PointTargets::new(points.clone(), targets, &PointTargetsParams::default()).unwrap();
    let limits = JointLimits::new(sk, &JointLimitsParams::default());
    let mut temporal = Temporal::new(points, &TemporalParams::default());
    temporal.push_frame(&posed).unwrap();
    temporal.push_frame(&posed).unwrap();
    let pca = PosePrior::new(
        sk,
        &prior(),
        &PosePriorParams {
            form: PosePriorForm::Augmented,
            ..PosePriorParams::default()
        },
    )
    .unwrap();
    let damping = Damping::new(sk, pca.num_aux(), &DampingParams::uniform(1.0)).unwrap();
    let terms: [&dyn EnergyTerm<SkeletonCtx>; 5] = [&fit, &limits, &temporal, &pca, &damping];

    let solver = LmSolver::new(sk, pca.num_aux(), LmOptions::default()).unwrap();
    assert_eq!(solver.dim(), 34);
    let mut ws = solver.workspace();
    let mut pose = Pose::zeros(sk);
    pose.set(sk, "global_tz", 390.0).unwrap();
    pose.set(sk, "index_pip_flex", 2.5).unwrap(); // violates its limit
    let mut ctx = SkeletonCtx::new(sk, &pose);
    let mut iterations = 0;
    let mut cb = callback_fn(|p: &Pose, c: &mut SkeletonCtx, _: IterInfo| {
        iterations += 1;
        c.set_pose(p);
        Ok(())
    });

    assert!(
        count(|| {
            std::hint::black_box(vec![1u8; 16]);
        }) >= 1,
        "the counter counts"
    );

    // Warm-up: sizes the report's per-term list.
    let start = pose.clone();
    solver
        .solve(&mut ws, sk, &mut pose, &mut ctx, &terms, &mut cb)
        .unwrap();
    pose.values.copy_from_slice(&start.values);

    let mut ok = false;
    let n = count(|| {
        let r = solver
            .solve(&mut ws, sk, &mut pose, &mut ctx, &terms, &mut cb)
            .unwrap();
        ok = r.termination.was_successful() && r.iterations == 7;
    });
    assert!(ok);
    assert_eq!(n, 0, "allocations during a 7-iteration solve");
    // The temporal history update between frames.
    let n = count(|| temporal.push_frame(&ctx.posed).unwrap());
    assert_eq!(n, 0, "allocations in Temporal::push_frame");
    assert_eq!(iterations, 2 * 8, "7 iterations + final evaluation, twice");
}
