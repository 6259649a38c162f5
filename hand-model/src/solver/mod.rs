//! Solver plumbing shared by the Ch. 2 (cylinder) and Ch. 3 (sphere-mesh) trackers.
//!
//! The tracking objective (thesis Eq. 2.1) is a sum of energy terms minimized over the pose θ by
//! Levenberg–Marquardt (§2.7.5): each iteration linearizes every term at the current pose,
//! `E_i(θ ⊞ δ) ≈ ωᵢ‖rᵢ + Jᵢδ‖²` (Eq. 2.10), and solves the damped normal equations
//!
//! `(Σ ωᵢ JᵢᵀJᵢ + diag λ) δ = −Σ ωᵢ Jᵢᵀ rᵢ`   (Eq. 2.11),
//!
//! then updates `θ ← θ ⊞ δ` ([`crate::kinematics::Pose::retract_in_place`]: additive except the
//! multiplicative global rotation).
//!
//! - [`NormalEquations`]: the dense system with structured accumulation helpers
//!   (`add_row`, `add_rank1`, `add_point_rows`, `add_diagonal`, `add_quadratic_form`), upper
//!   triangle only, symmetrized once. **Sign convention**: `b = −½∂E/∂θ` (the thesis' `Jᵀe`
//!   with `e = target − current`); **weight convention**: ω multiplies `JᵀJ` and `Jᵀr` once.
//! - [`EnergyTerm`]: the one trait of every term; terms only add. [`PoseContext`] is what the
//!   shared prior terms read from the per-iteration context; [`SkeletonCtx`] a ready one.
//! - [`LmSolver`] / [`LmWorkspace`] / [`LmOptions`] / [`LmReport`]: the solver (rigid-only first
//!   iterations, per-DOF damping, Cholesky with a documented non-SPD/NaN recovery, auxiliary
//!   unknowns after the pose DOFs), allocation-free after the first solve; [`factor_lower`],
//!   its in-place Cholesky (nalgebra's factor bit for bit, ≈ 2× faster at 106 unknowns).
//! - [`terms`]: joint limits (Eq. 2.8), damping, temporal (Eq. 2.9), the PCA pose prior
//!   (Eq. 2.5–2.6, §2.7.1), point targets.
//! - [`PcaPrior`]: pose-space PCA data and the loader of the original binary files.
//! - [`FrameLoop`] / [`TrackingProblem`] / [`LossParams`]: the per-frame control flow of the
//!   trackers (warm start, loss detection, re-initialization), and [`IrlsParams`], the robust ℓ1
//!   reweighting of their data terms.
//! - [`check`]: finite-difference checks of a term's gradient and Gauss–Newton Hessian.
//!
//! # Example
//! ```
//! use hand_model::kinematics::Pose;
//! use hand_model::solver::{
//!     sphere_mesh_points,
//!     terms::{DampingParams, JointLimits, JointLimitsParams, PointTargets, PointTargetsParams},
//!     EnergyTerm, LmOptions, LmSolver, RePose, SkeletonCtx,
//! };
//! use hand_model::spheremesh::{default_right_hand, PosedSphereMesh};
//!
//! let template = default_right_hand();
//! let sk = &template.skeleton;
//! // Targets: the kinematic points of a bent index finger.
//! let mut target_pose = Pose::zeros(sk);
//! target_pose.set(sk, "index_pip_flex", 0.8).unwrap();
//! let points = sphere_mesh_points(&template);
//! let posed = PosedSphereMesh::new(&template, &target_pose).skeleton;
//! let targets = points.iter().map(|p| p.position(&posed)).collect();
//! let fit = PointTargets::new(points, targets, &PointTargetsParams::default()).unwrap();
//! let limits = JointLimits::new(sk, &JointLimitsParams::default());
//!
//! // 23 points only: the thesis' λ = 100 (sized for thousands of data rows) would be slow here.
//! let options = LmOptions {
//!     iterations: 10,
//!     rigid_iterations: 0,
//!     damping: DampingParams::uniform(1.0),
//!     ..LmOptions::default()
//! };
//! let solver = LmSolver::new(sk, 0, options).unwrap();
//! let mut ws = solver.workspace();
//! let mut pose = Pose::zeros(sk);
//! let mut ctx = SkeletonCtx::new(sk, &pose);
//! let terms: [&dyn EnergyTerm<SkeletonCtx>; 2] = [&fit, &limits];
//! let report = solver.solve(&mut ws, sk, &mut pose, &mut ctx, &terms, &mut RePose).unwrap();
//! assert!(report.termination.was_successful());
//! assert!((pose.values[sk.dof_index("index_pip_flex").unwrap()] - 0.8).abs() < 1e-6);
//! assert!(report.energy_after < 1e-9 * report.energy_before);
//! ```

mod blocks;
pub mod check;
mod cholesky;
mod digits;
mod frame_loop;
mod irls;
mod lm;
mod loss;
mod normal_equations;
mod pca;
mod points;
mod setup;
mod term;
pub mod terms;

#[cfg(test)]
mod tests;

pub use blocks::{PackedBlocks, BLOCK_DOFS, MAX_BLOCKS};
pub use cholesky::{cholesky_checked, factor_lower};
pub use digits::{digit_variants, DIGITS, DIGIT_FLEXION_LEVELS};
pub use frame_loop::{
    FrameLoop, FrameOutcome, Hypothesis, ScoreTrigger, TrackingProblem, CONFIRM_FRAMES,
    PLACEMENT_SOLVES, RECHECK_FRAMES,
};
pub use irls::IrlsParams;
pub use lm::{
    callback_fn, FnCallback, IterInfo, LmCallback, LmError, LmOptions, LmReport, LmSolver,
    LmWorkspace, OptionsError, RePose, TermEnergy, Termination,
};
pub use loss::{
    placed_rotation, placement_directions, placement_hypotheses, placement_rotation, FrameStats,
    LossParams, ARM_MIN_COSINE, PLACEMENT_ROLLS, POOR_PLACEMENT_OUTSIDE,
};
pub use normal_equations::{NormalEquations, TermStats};
pub use pca::{
    htrack_groups, parse_htrack_matrix, parse_htrack_vector, read_htrack_matrix,
    read_htrack_vector, PcaGroup, PcaPrior, HMODEL_LATENT_DIMS, HTRACK_LATENT_DIMS,
    PCA_PRIOR_FORMAT, PCA_PRIOR_VERSION, PCA_VARIANCE_FLOOR,
};
pub use points::{cylinder_points, skeleton_points, sphere_mesh_points, KinematicPoint};
pub use setup::{timed_solve, NoTerm, PriorSetup, SolveTiming};
pub use term::{EnergyTerm, PoseContext, SkeletonCtx, TermError};
