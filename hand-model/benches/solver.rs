//! Cost of the shared solver plumbing on the default sphere-mesh hand (28 DOFs) with the
//! augmented PCA prior (3 + 3 latents): a 34×34 system.
//!
//! - `lm_iteration_34`: one Levenberg–Marquardt iteration — re-pose (FK), assemble five terms
//!   (point targets on 23 kinematic points, joint limits, temporal, augmented PCA prior,
//!   damping), symmetrize, damp, Cholesky-solve, retract;
//! - `lm_solve_7_iterations_34`: a default solve (1 rigid + 6 full iterations + final
//!   evaluation);
//! - `assemble_5_terms_34`: the assembly alone;
//! - `cholesky_34`: copy + factor + solve of a 34×34 SPD system (nalgebra, preallocated);
//! - `factor_lower_34` / `factor_lower_106` against `cholesky_106`: copy + factor by the
//!   solvers' own Cholesky (nalgebra's factor bit for bit) and by nalgebra's, at 106 unknowns
//!   (online calibration; a synthetic SPD matrix);
//! - `point_rows_1000x12`: 1000 data-term point rows with 12 Jacobian columns each (the cost a
//!   tracker's data term adds per 1000 correspondences).
//!
//! `cargo bench -p hand-model --bench solver`

use criterion::{criterion_group, criterion_main, Criterion};
use hand_model::kinematics::{Pose, PosedSkeleton};
use hand_model::solver::terms::{
    Damping, DampingParams, JointLimits, JointLimitsParams, PointTargets, PointTargetsParams,
    PosePrior, PosePriorForm, PosePriorParams, Temporal, TemporalParams,
};
use hand_model::solver::{
    factor_lower, sphere_mesh_points, EnergyTerm, LmOptions, LmSolver, NormalEquations, PcaGroup,
    PcaPrior, RePose, SkeletonCtx,
};
use hand_model::spheremesh::default_right_hand;
use nalgebra::{Cholesky, DMatrix, DVector, Vector3};

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
                ((i * 7 + j * 3) % 11) as f64 - 5.0 + if i == j { 9.0 } else { 0.0 }
            });
            PcaGroup {
                name: name.into(),
                dofs,
                mean: (0..k).map(|i| 0.1 * (i % 4) as f64).collect(),
                basis: a.qr().q().columns(0, 3).into_owned(),
                variances: vec![1.5, 0.4, 0.2],
            }
        })
        .collect();
    PcaPrior { groups }
}

fn bench(c: &mut Criterion) {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let mut target = Pose::zeros(sk);
    for (name, v) in [
        ("global_tz", 400.0),
        ("global_rx", 0.2),
        ("index_mcp_flex", 0.5),
        ("middle_pip_flex", 0.7),
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

    let mut start = Pose::zeros(sk);
    start.set(sk, "global_tz", 390.0).unwrap();
    start.set(sk, "index_pip_flex", 2.2).unwrap();
    let mut pose = start.clone();
    let mut ctx = SkeletonCtx::new(sk, &pose);
    let n = sk.num_dofs() + pca.num_aux();

    let one = LmOptions {
        iterations: 1,
        rigid_iterations: 0,
        final_evaluation: false,
        ..LmOptions::default()
    };
    let solver = LmSolver::new(sk, pca.num_aux(), one).unwrap();
    let mut ws = solver.workspace();
    c.bench_function("lm_iteration_34", |b| {
        b.iter(|| {
            pose.values.copy_from_slice(&start.values);
            solver
                .solve(&mut ws, sk, &mut pose, &mut ctx, &terms, &mut RePose)
                .unwrap()
                .energy_after
        })
    });

    let full = LmSolver::new(sk, pca.num_aux(), LmOptions::default()).unwrap();
    let mut ws = full.workspace();
    c.bench_function("lm_solve_7_iterations_34", |b| {
        b.iter(|| {
            pose.values.copy_from_slice(&start.values);
            full.solve(&mut ws, sk, &mut pose, &mut ctx, &terms, &mut RePose)
                .unwrap()
                .energy_after
        })
    });

    ctx.set_pose(&start);
    let mut ne = NormalEquations::new(n);
    c.bench_function("assemble_5_terms_34", |b| {
        b.iter(|| {
            ne.clear();
            for term in &terms {
                term.accumulate(&ctx, &mut ne).unwrap();
            }
            ne.symmetrize();
            ne.rhs()[0]
        })
    });

    let mut a = ne.lhs().clone();
    for i in 0..n {
        a[(i, i)] += 1.0;
    }
    let rhs = ne.rhs().clone();
    let mut factor = Some(DMatrix::zeros(n, n));
    let mut x = DVector::zeros(n);
    c.bench_function("cholesky_34", |b| {
        b.iter(|| {
            let mut m = factor.take().unwrap();
            m.copy_from(&a);
            x.copy_from(&rhs);
            let chol = Cholesky::new_unchecked(m);
            chol.solve_mut(&mut x);
            factor = Some(chol.unpack_dirty());
            x[0]
        })
    });
    // The same factor, bit for bit, by the solver's own routine; and both at the online
    // calibrator's size (a synthetic SPD matrix of 106 unknowns).
    let b106 = DMatrix::from_fn(106, 106, |i, j| ((i * 7 + j * 13) % 17) as f64 - 8.0);
    let a106 = &b106 * b106.transpose() + DMatrix::identity(106, 106) * 1000.0;
    for (name, a) in [("34", &a), ("106", &a106)] {
        let mut m = a.clone();
        if name == "106" {
            c.bench_function("cholesky_106", |b| {
                b.iter(|| {
                    m.copy_from(a);
                    let l = Cholesky::new_unchecked(std::mem::take(&mut m)).unpack_dirty();
                    m = l;
                    m[(0, 0)]
                })
            });
        }
        c.bench_function(&format!("factor_lower_{name}"), |b| {
            b.iter(|| {
                m.copy_from(a);
                factor_lower(&mut m);
                m[(0, 0)]
            })
        });
    }

    let cols: Vec<(usize, Vector3<f64>)> = (0..12)
        .map(|k| (k * 2, Vector3::new(1.0 + k as f64, -0.5, 0.25 * k as f64)))
        .collect();
    let r = Vector3::new(0.1, -0.2, 0.3);
    c.bench_function("point_rows_1000x12", |b| {
        b.iter(|| {
            ne.clear();
            for _ in 0..1000 {
                ne.add_point_rows(&cols, &r, 1.0).unwrap();
            }
            ne.rhs()[0]
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
