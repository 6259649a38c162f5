//! Levenberg–Marquardt over a pose (thesis §2.4 "Optimization", §2.7.5, Eq. 2.11).

use nalgebra::{Cholesky, DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::cholesky::factor_lower;
use super::normal_equations::NormalEquations;
use super::term::{EnergyTerm, SkeletonCtx, TermError};
use super::terms::DampingParams;
use crate::error::ModelError;
use crate::kinematics::{DofKind, Pose, Skeleton};

/// Solver settings (STYLE practice 6): a plain, serde-deserializable struct with the thesis /
/// htrack defaults; check it with [`LmOptions::validate`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LmOptions {
    /// Total number of iterations per solve, rigid ones included (htrack
    /// `termination_max_iters = 7`; thesis §2.4 "converge within seven iterations").
    pub iterations: usize,
    /// How many of the first iterations only move the 6 global DOFs (htrack
    /// `termination_max_rigid_iters = 1`; thesis §2.4 "Rigid bias", Fig. 2.17).
    pub rigid_iterations: usize,
    /// The Levenberg damping `E_damp = δᵀ diag(λ) δ` added to the diagonal on every iteration
    /// (thesis §2.7.5: λ = 100 for every DOF). Per DOF kind, per DOF name and for the auxiliary
    /// unknowns; see [`DampingParams`].
    pub damping: DampingParams,
    /// Stop early (with [`Termination::StepTolerance`]) after a full iteration whose pose step
    /// satisfies `max |δθ_i| < step_tolerance`; 0 disables the test (the originals always run
    /// all iterations).
    pub step_tolerance: f64,
    /// After the last update, refresh the context (callback) and re-evaluate the terms once, so
    /// that [`LmReport::energy_after`] and the per-term energies describe the *returned* pose.
    /// Off, they describe the last linearization point (the pose before the last update) and
    /// one context refresh (re-pose, correspondences) is saved.
    pub final_evaluation: bool,
    /// Solve the auxiliary unknowns' part of each non-rigid step against the gradient *without*
    /// the pose-only priors ([`EnergyTerm::pose_only_prior`], e.g. the PCA pose prior), the
    /// system matrix (their curvature included) and the pose's step unchanged. In a joint
    /// pose + shape solve (honline's Eq. 4.2) a pose prior that holds the pose off the data's
    /// optimum (a motion outside its corpus) leaves a residual that the shape absorbs, so the
    /// shape's fixed point drifts from the data's; without the prior's pull in the shape's step
    /// it drifts by the prior's share of the curvature only. One more pair of triangular
    /// solves with the step's factor per non-rigid iteration; off by default (and inert without
    /// pose-only priors or auxiliary unknowns).
    pub decouple_aux: bool,
    /// With [`LmOptions::decouple_aux`]: the share (0..=1) of the pose-only priors' pull kept
    /// in the auxiliary step — the step is `s·δ_joint + (1 − s)·δ_free` over the auxiliary
    /// unknowns, both solved with the same factor (the two solutions are linear in the
    /// right-hand side, so this is the solution with the prior's gradient scaled by `s`).
    /// 0: fully decoupled; 1: the joint step (no decoupling at all, bit for bit). A caller
    /// that knows the data's noise can move it per frame ([`LmSolver::set_aux_prior_share`]):
    /// with noisy data the prior's pull is regularization rather than bias.
    pub aux_prior_share: f64,
}

impl Default for LmOptions {
    fn default() -> Self {
        Self {
            iterations: 7,
            rigid_iterations: 1,
            damping: DampingParams::default(),
            step_tolerance: 0.0,
            final_evaluation: true,
            decouple_aux: false,
            aux_prior_share: 0.0,
        }
    }
}

/// An invalid [`LmOptions`] field.
#[derive(Copy, Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum OptionsError {
    /// `iterations` is 0.
    #[error("`iterations` must be at least 1")]
    NoIterations,
    /// More rigid iterations than iterations.
    #[error("`rigid_iterations` ({rigid}) exceeds `iterations` ({total})")]
    TooManyRigid {
        /// `rigid_iterations`.
        rigid: usize,
        /// `iterations`.
        total: usize,
    },
    /// A damping weight is negative or not finite.
    #[error("damping `{field}` must be finite and non-negative")]
    Damping {
        /// The field (`translation`, `rotation`, `joint`, `aux`, `per_dof`).
        field: &'static str,
    },
    /// `step_tolerance` is negative or not finite.
    #[error("`step_tolerance` must be finite and non-negative")]
    StepTolerance,
    /// `aux_prior_share` is outside 0..=1 (or not finite).
    #[error("`aux_prior_share` must lie in 0..=1")]
    AuxPriorShare,
}

impl LmOptions {
    /// Check every field.
    pub fn validate(&self) -> Result<(), OptionsError> {
        if self.iterations == 0 {
            return Err(OptionsError::NoIterations);
        }
        if self.rigid_iterations > self.iterations {
            return Err(OptionsError::TooManyRigid {
                rigid: self.rigid_iterations,
                total: self.iterations,
            });
        }
        self.damping.validate()?;
        if !(self.step_tolerance.is_finite() && self.step_tolerance >= 0.0) {
            return Err(OptionsError::StepTolerance);
        }
        if !(0.0..=1.0).contains(&self.aux_prior_share) {
            return Err(OptionsError::AuxPriorShare);
        }
        Ok(())
    }
}

/// Why a solve stopped. Numerical trouble is reported here, never written into the pose.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub enum Termination {
    /// All [`LmOptions::iterations`] ran.
    #[default]
    MaxIterations,
    /// A full iteration's step was below [`LmOptions::step_tolerance`].
    StepTolerance,
    /// The assembled system (or the final evaluation) held a NaN/∞ at `iteration`; no update was
    /// applied from it and the solve stopped. `term` names the first term that produced it,
    /// when one could be identified.
    NonFinite {
        /// Iteration (0-based; `iterations` for the final evaluation).
        iteration: usize,
        /// The offending term.
        term: Option<&'static str>,
    },
    /// The damped system stayed non-positive-definite even after the extra damping of the
    /// recovery (see [`LmSolver::solve`]), or its solution was not finite: zero update, stop.
    SolveFailed {
        /// Iteration (0-based).
        iteration: usize,
    },
}

impl Termination {
    /// `MaxIterations` or `StepTolerance`.
    pub fn was_successful(&self) -> bool {
        matches!(
            self,
            Termination::MaxIterations | Termination::StepTolerance
        )
    }
}

/// The energy of one term at the evaluation described by [`LmReport`].
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct TermEnergy {
    /// [`EnergyTerm::name`].
    pub name: &'static str,
    /// Its energy `Σ ω r²`.
    pub energy: f64,
    /// Its residual rows.
    pub rows: usize,
}

/// What a solve did (STYLE practice 6).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LmReport {
    /// Why it stopped.
    pub termination: Termination,
    /// Updates applied to the pose.
    pub iterations: usize,
    /// Total energy at the initial pose (first evaluation).
    pub energy_before: f64,
    /// Total energy at the last evaluation: the returned pose when [`LmReport::final_evaluated`],
    /// otherwise the last linearization point.
    pub energy_after: f64,
    /// Whether the last evaluation was made at the returned pose.
    pub final_evaluated: bool,
    /// Per-term energies of the last evaluation, in term order.
    pub terms: Vec<TermEnergy>,
    /// How many solves needed the extra damping of the non-SPD recovery.
    pub regularized_solves: usize,
    /// `max |δθ_i|` of the last applied pose step.
    pub last_step: f64,
}

/// Which iteration the callback is preparing.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct IterInfo {
    /// 0-based iteration (equals the number of iterations run for the final evaluation).
    pub iteration: usize,
    /// Whether this iteration moves only the global DOFs (htrack skips the pose prior then).
    pub rigid_only: bool,
    /// Whether this is the evaluation after the last update ([`LmOptions::final_evaluation`]).
    pub final_evaluation: bool,
}

/// The per-iteration hook of a solve (Ceres `EvaluationCallback`, STYLE practice 5).
pub trait LmCallback<Ctx: ?Sized> {
    /// Refresh the shared context for `pose` (re-pose the model, search correspondences, render)
    /// before the terms run. Called once per iteration and once for the final evaluation.
    fn prepare(&mut self, pose: &Pose, ctx: &mut Ctx, info: IterInfo) -> Result<(), TermError>;

    /// Receive the solved step of the auxiliary unknowns (`δ[num_dofs..]`) after each applied
    /// update. The default discards it, which is right for unknowns that terms re-derive at every
    /// linearization (the PCA latents of [`super::terms::PosePrior`]); a tracker with persistent
    /// auxiliary state (e.g. shape parameters) applies it here.
    fn apply_aux(&mut self, ctx: &mut Ctx, delta_aux: &[f64]) {
        let _ = (ctx, delta_aux);
    }
}

/// An [`LmCallback`] made of a closure for [`LmCallback::prepare`] (see [`callback_fn`]).
pub struct FnCallback<F>(pub F);

impl<Ctx: ?Sized, F> LmCallback<Ctx> for FnCallback<F>
where
    F: FnMut(&Pose, &mut Ctx, IterInfo) -> Result<(), TermError>,
{
    fn prepare(&mut self, pose: &Pose, ctx: &mut Ctx, info: IterInfo) -> Result<(), TermError> {
        (self.0)(pose, ctx, info)
    }
}

/// Wrap a closure `|pose, ctx, info| …` as an [`LmCallback`] (the bound lets the compiler infer
/// the closure's argument types).
pub fn callback_fn<Ctx: ?Sized, F>(f: F) -> FnCallback<F>
where
    F: FnMut(&Pose, &mut Ctx, IterInfo) -> Result<(), TermError>,
{
    FnCallback(f)
}

/// The callback for a [`SkeletonCtx`]: re-pose it (forward kinematics) and nothing else.
#[derive(Copy, Clone, Debug, Default)]
pub struct RePose;

impl LmCallback<SkeletonCtx<'_>> for RePose {
    fn prepare(
        &mut self,
        pose: &Pose,
        ctx: &mut SkeletonCtx<'_>,
        _info: IterInfo,
    ) -> Result<(), TermError> {
        ctx.set_pose(pose);
        Ok(())
    }
}

/// Why a solve could not run; numerical trouble is a [`Termination`] instead.
#[derive(Debug, thiserror::Error)]
pub enum LmError {
    /// Invalid options.
    #[error("invalid solver options: {0}")]
    Options(#[from] OptionsError),
    /// The damping names a DOF the skeleton does not have.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// Skeleton, pose or workspace sizes disagree with the solver.
    #[error("{what}: expected {expected}, found {found}")]
    Dimension {
        /// What disagrees (`"skeleton DOFs"`, `"pose values"`, `"workspace unknowns"`).
        what: &'static str,
        /// What the solver was built for.
        expected: usize,
        /// What it was given.
        found: usize,
    },
    /// A term returned an error; the pose keeps the updates of the iterations before it.
    #[error("term `{name}`: {source}")]
    Term {
        /// The term.
        name: &'static str,
        /// Its error.
        #[source]
        source: TermError,
    },
    /// The callback returned an error; the pose keeps the updates applied before it.
    #[error("solver callback: {0}")]
    Callback(#[source] TermError),
}

/// Preallocated buffers of a solve (STYLE practice 7): the normal equations, the factor, the
/// step and the report. Make one per solver with [`LmSolver::workspace`] and reuse it every
/// frame; after the first solve nothing allocates.
#[derive(Clone, Debug)]
pub struct LmWorkspace {
    ne: NormalEquations,
    factor: DMatrix<f64>,
    diag: Vec<f64>,
    step: DVector<f64>,
    /// [`LmOptions::decouple_aux`]: `b` without the pose-only priors, then its solution.
    free_rhs: DVector<f64>,
    saved_pose: Vec<f64>,
    report: LmReport,
}

impl LmWorkspace {
    /// Buffers for a system of `dim` unknowns.
    pub fn new(dim: usize) -> Self {
        Self {
            ne: NormalEquations::new(dim),
            factor: DMatrix::zeros(dim, dim),
            diag: vec![0.0; dim],
            step: DVector::zeros(dim),
            free_rhs: DVector::zeros(dim),
            saved_pose: Vec::with_capacity(dim),
            report: LmReport::default(),
        }
    }

    /// Number of unknowns.
    pub fn dim(&self) -> usize {
        self.ne.dim()
    }

    /// The system of the last evaluation: the sum of the terms only (no LM damping, no rigid
    /// mask), symmetrized — e.g. the measured Hessian honline's Kalman filter reads.
    pub fn normal_equations(&self) -> &NormalEquations {
        &self.ne
    }

    /// The last solved step `δ` (pose DOFs, then auxiliary unknowns); zero after a failed solve.
    pub fn step(&self) -> &[f64] {
        self.step.as_slice()
    }

    /// The report of the last solve.
    pub fn report(&self) -> &LmReport {
        &self.report
    }
}

/// Relative pivot threshold of the Cholesky factorization: a pivot `l_jj` is accepted when
/// `l_jj² ≥ PIVOT_TOLERANCE · A_jj` (the fraction of the diagonal left after elimination).
const PIVOT_TOLERANCE: f64 = 1e-12;
/// Extra-damping attempts of the non-SPD recovery: `s·10^(k−9)`, k = 1 … 10, `s = ‖A‖_∞`.
const RECOVERY_ATTEMPTS: i32 = 10;

/// Levenberg–Marquardt with constant damping over a [`Pose`] and optional auxiliary unknowns
/// (thesis §2.7.5, Eq. 2.11).
///
/// # Unknowns
/// `δ = [δθ (num_dofs, tangent layout of Pose::retract) | δaux (num_aux)]`. Auxiliary unknowns
/// are appended after the pose DOFs (e.g. the PCA latents of the augmented pose prior, which
/// [`super::terms::PosePrior::with_aux_offset`] places at a given offset ≥ `num_dofs`); the solver
/// solves for them jointly and hands their step to [`LmCallback::apply_aux`].
///
/// # One iteration (STYLE practices 4–9)
/// 1. `callback.prepare(θ, ctx)`: shared precompute;
/// 2. clear the [`NormalEquations`] and let every term add itself (order irrelevant);
///    symmetrize once;
/// 3. `A + diag(λ)` (per-DOF damping of [`LmOptions::damping`]); on rigid-only iterations every
///    row and column but the 6 global DOFs is replaced by the identity (their δ is exactly 0);
/// 4. Cholesky ([`factor_lower`], in the preallocated matrix) and solve `(A + diag λ) δ = b`;
/// 5. `θ ← θ ⊞ δθ` through [`Pose::retract_in_place`] (multiplicative global rotation).
///
/// # Numerical recovery
/// - A non-finite system (a term produced NaN/∞): no update, stop with
///   [`Termination::NonFinite`] naming the term.
/// - A non-positive-definite system (a pivot `l_jj ≤ 0`, non-finite, or
///   `l_jj² < 1e-12·A_jj`): retry with extra damping `s·10^(k−9)·I`, k = 1…10,
///   `s = ‖A‖_∞ ≥ ρ(A)`, so the last attempt is SPD for any finite symmetric `A`; counted in
///   [`LmReport::regularized_solves`]. If all fail, or the solution is not finite: zero update,
///   stop with [`Termination::SolveFailed`].
/// - The pose is saved before the update and restored if the retraction produced a non-finite
///   value. A NaN is never written into the pose.
///
/// There is no step rejection (the originals' fixed damping): the context changes between
/// iterations (new correspondences), so energies of successive iterations are not comparable.
#[derive(Clone, Debug)]
pub struct LmSolver {
    options: LmOptions,
    /// The [`LmOptions::rigid_iterations`] the solver was built with
    /// ([`LmSolver::set_rigid_first`]).
    rigid_iterations: usize,
    num_dofs: usize,
    num_aux: usize,
    damping: Vec<f64>,
    global: Vec<bool>,
}

impl LmSolver {
    /// A solver for poses of `skeleton` plus `num_aux` auxiliary unknowns. Validates the
    /// options and resolves the per-DOF damping names.
    pub fn new(skeleton: &Skeleton, num_aux: usize, options: LmOptions) -> Result<Self, LmError> {
        options.validate()?;
        let damping = options.damping.diagonal(skeleton, num_aux)?;
        let global = skeleton
            .dofs()
            .iter()
            .map(|d| d.kind != DofKind::Rotation)
            .chain(std::iter::repeat_n(false, num_aux))
            .collect();
        Ok(Self {
            num_dofs: skeleton.num_dofs(),
            num_aux,
            damping,
            global,
            rigid_iterations: options.rigid_iterations,
            options,
        })
    }

    /// The options.
    pub fn options(&self) -> &LmOptions {
        &self.options
    }

    /// Set [`LmOptions::aux_prior_share`] for the next solves (clamped to 0..=1; a non-finite
    /// share keeps the joint step, 1).
    pub fn set_aux_prior_share(&mut self, share: f64) {
        self.options.aux_prior_share = if share.is_finite() {
            share.clamp(0.0, 1.0)
        } else {
            1.0
        };
    }

    /// Turn the rigid-only first iterations of the next solves off (`false`) or back to the
    /// count the solver was built with (`true`); whether it was built with any (the trackers'
    /// [`super::TrackingProblem::set_rigid_first`]).
    pub fn set_rigid_first(&mut self, on: bool) -> bool {
        self.options.rigid_iterations = if on { self.rigid_iterations } else { 0 };
        self.rigid_iterations > 0
    }

    /// Number of pose DOFs.
    pub fn num_dofs(&self) -> usize {
        self.num_dofs
    }

    /// Number of auxiliary unknowns.
    pub fn num_aux(&self) -> usize {
        self.num_aux
    }

    /// Total unknowns `num_dofs + num_aux`.
    pub fn dim(&self) -> usize {
        self.num_dofs + self.num_aux
    }

    /// A workspace sized for this solver.
    pub fn workspace(&self) -> LmWorkspace {
        LmWorkspace::new(self.dim())
    }

    /// Run [`LmOptions::iterations`] iterations from `pose`, updating it in place; returns the
    /// report stored in `ws`.
    ///
    /// Errors (options are validated at construction) are size mismatches and term or
    /// callback errors; in the latter case `pose` keeps the updates applied before. Nothing
    /// allocates once `ws` has run one solve with the same number of terms.
    pub fn solve<'w, Ctx: ?Sized>(
        &self,
        ws: &'w mut LmWorkspace,
        skeleton: &Skeleton,
        pose: &mut Pose,
        ctx: &mut Ctx,
        terms: &[&dyn EnergyTerm<Ctx>],
        callback: &mut dyn LmCallback<Ctx>,
    ) -> Result<&'w LmReport, LmError> {
        let dim_check = |what, expected, found| {
            if expected == found {
                Ok(())
            } else {
                Err(LmError::Dimension {
                    what,
                    expected,
                    found,
                })
            }
        };
        dim_check("skeleton DOFs", self.num_dofs, skeleton.num_dofs())?;
        dim_check("pose values", self.num_dofs, pose.values.len())?;
        dim_check("workspace unknowns", self.dim(), ws.dim())?;

        let opts = &self.options;
        ws.report.termination = Termination::MaxIterations;
        ws.report.iterations = 0;
        ws.report.regularized_solves = 0;
        ws.report.final_evaluated = false;
        ws.report.last_step = 0.0;
        ws.report.energy_before = 0.0;
        ws.report.energy_after = 0.0;
        ws.step.fill(0.0);

        let mut updated_since_eval = false;
        for it in 0..opts.iterations {
            let rigid = it < opts.rigid_iterations;
            let info = IterInfo {
                iteration: it,
                rigid_only: rigid,
                final_evaluation: false,
            };
            callback
                .prepare(pose, ctx, info)
                .map_err(LmError::Callback)?;
            let decouple = self.decouples(rigid, terms);
            let total = assemble(ws, ctx, terms, decouple)?;
            updated_since_eval = false;
            if it == 0 {
                ws.report.energy_before = total;
            }
            ws.report.energy_after = total;
            if !ws.ne.is_finite() {
                ws.report.termination = Termination::NonFinite {
                    iteration: it,
                    term: find_non_finite(ws, ctx, terms),
                };
                break;
            }
            if !self.solve_step(ws, rigid) {
                ws.report.termination = Termination::SolveFailed { iteration: it };
                break;
            }
            if decouple {
                self.decoupled_aux_step(ws);
            }
            // Apply δθ; never leave a non-finite pose behind.
            ws.saved_pose.clone_from(&pose.values);
            pose.retract_in_place(skeleton, &ws.step.as_slice()[..self.num_dofs]);
            if !pose.values.iter().all(|v| v.is_finite()) {
                pose.values.clone_from(&ws.saved_pose);
                ws.step.fill(0.0);
                ws.report.termination = Termination::SolveFailed { iteration: it };
                break;
            }
            updated_since_eval = true;
            callback.apply_aux(ctx, &ws.step.as_slice()[self.num_dofs..]);
            ws.report.iterations += 1;
            let step = ws.step.as_slice()[..self.num_dofs]
                .iter()
                .fold(0.0f64, |m, v| m.max(v.abs()));
            ws.report.last_step = step;
            if !rigid && step < opts.step_tolerance {
                ws.report.termination = Termination::StepTolerance;
                break;
            }
        }

        if opts.final_evaluation && updated_since_eval {
            let info = IterInfo {
                iteration: ws.report.iterations,
                rigid_only: false,
                final_evaluation: true,
            };
            callback
                .prepare(pose, ctx, info)
                .map_err(LmError::Callback)?;
            ws.report.energy_after = assemble(ws, ctx, terms, false)?;
            ws.report.final_evaluated = true;
            if !ws.ne.is_finite() {
                ws.report.termination = Termination::NonFinite {
                    iteration: ws.report.iterations,
                    term: find_non_finite(ws, ctx, terms),
                };
            }
        }
        Ok(&ws.report)
    }

    /// `‖A + diag λ‖_∞` over the unknowns that move (≥ the spectral radius): the scale of the
    /// recovery damping. Failure path only.
    fn recovery_scale(&self, ne: &NormalEquations, rigid: bool) -> f64 {
        let n = self.dim();
        let lhs = ne.lhs();
        let mut scale = 0.0f64;
        for i in 0..n {
            if rigid && !self.global[i] {
                continue;
            }
            let mut row = self.damping[i];
            for j in 0..n {
                if !rigid || self.global[j] {
                    row += lhs[(i, j)].abs();
                }
            }
            scale = scale.max(row);
        }
        scale.max(f64::MIN_POSITIVE)
    }

    /// Build `A + diag(λ)` (rigid-masked), factor and solve into `ws.step`; extra damping on
    /// failure. Returns false (with a zero step) when no attempt succeeded.
    /// Whether this iteration solves the auxiliary step apart ([`LmOptions::decouple_aux`]).
    fn decouples<Ctx: ?Sized>(&self, rigid: bool, terms: &[&dyn EnergyTerm<Ctx>]) -> bool {
        self.options.decouple_aux
            && self.options.aux_prior_share < 1.0
            && !rigid
            && self.num_aux > 0
            && terms.iter().any(|t| t.pose_only_prior())
    }

    /// After [`LmSolver::solve_step`] (whose factor `ws.factor` holds): the auxiliary part of
    /// the step from `ws.free_rhs`, blended with the joint step by
    /// [`LmOptions::aux_prior_share`]; the step is kept as it is if that solution is not finite.
    fn decoupled_aux_step(&self, ws: &mut LmWorkspace) {
        let chol = Cholesky::pack_dirty(std::mem::replace(&mut ws.factor, DMatrix::zeros(0, 0)));
        chol.solve_mut(&mut ws.free_rhs);
        ws.factor = chol.unpack_dirty();
        let n = self.num_dofs;
        let aux = &ws.free_rhs.as_slice()[n..];
        if aux.iter().all(|v| v.is_finite()) {
            let s = self.options.aux_prior_share;
            for (joint, free) in ws.step.as_mut_slice()[n..].iter_mut().zip(aux) {
                *joint = s * *joint + (1.0 - s) * free;
            }
        }
    }

    fn solve_step(&self, ws: &mut LmWorkspace, rigid: bool) -> bool {
        let n = self.dim();
        let mut scale = 0.0;
        for attempt in 0..=RECOVERY_ATTEMPTS {
            let extra = if attempt == 0 {
                0.0
            } else {
                if attempt == 1 {
                    scale = self.recovery_scale(&ws.ne, rigid);
                }
                scale * 10f64.powi(attempt - 9)
            };
            ws.factor.copy_from(ws.ne.lhs());
            ws.step.copy_from(ws.ne.rhs());
            for i in 0..n {
                ws.factor[(i, i)] += self.damping[i] + extra;
            }
            if rigid {
                for i in 0..n {
                    if !self.global[i] {
                        ws.factor.row_mut(i).fill(0.0);
                        ws.factor.column_mut(i).fill(0.0);
                        ws.factor[(i, i)] = 1.0;
                        ws.step[i] = 0.0;
                    }
                }
            }
            for i in 0..n {
                ws.diag[i] = ws.factor[(i, i)];
            }
            factor_lower(&mut ws.factor);
            let spd = (0..n).all(|j| {
                let d = ws.factor[(j, j)];
                d.is_finite() && d > 0.0 && d * d >= PIVOT_TOLERANCE * ws.diag[j]
            });
            if spd {
                let l = std::mem::replace(&mut ws.factor, DMatrix::zeros(0, 0));
                let chol = Cholesky::pack_dirty(l);
                chol.solve_mut(&mut ws.step);
                ws.factor = chol.unpack_dirty();
                if ws.step.iter().all(|v| v.is_finite()) {
                    if attempt > 0 {
                        ws.report.regularized_solves += 1;
                    }
                    return true;
                }
                break;
            }
        }
        ws.step.fill(0.0);
        false
    }
}

/// Clear, accumulate every term, symmetrize; record per-term energies; return the total.
/// `decouple`: the pose-only priors go last, and `b` before them is kept in `ws.free_rhs`.
fn assemble<Ctx: ?Sized>(
    ws: &mut LmWorkspace,
    ctx: &Ctx,
    terms: &[&dyn EnergyTerm<Ctx>],
    decouple: bool,
) -> Result<f64, LmError> {
    ws.ne.clear();
    ws.report.terms.clear();
    let mut total = 0.0;
    let mut add = |ws: &mut LmWorkspace, term: &dyn EnergyTerm<Ctx>| {
        let stats = term
            .accumulate(ctx, &mut ws.ne)
            .map_err(|source| LmError::Term {
                name: term.name(),
                source,
            })?;
        total += stats.energy;
        ws.report.terms.push(TermEnergy {
            name: term.name(),
            energy: stats.energy,
            rows: stats.rows,
        });
        Ok::<_, LmError>(())
    };
    if decouple {
        for term in terms.iter().filter(|t| !t.pose_only_prior()) {
            add(ws, *term)?;
        }
        ws.free_rhs.copy_from(ws.ne.rhs());
        for term in terms.iter().filter(|t| t.pose_only_prior()) {
            add(ws, *term)?;
        }
    } else {
        for term in terms {
            add(ws, *term)?;
        }
    }
    ws.ne.symmetrize();
    Ok(total)
}

/// Failure path only: re-accumulate term by term to name the first one that makes the system
/// non-finite (terms are deterministic, so the system ends up as before).
fn find_non_finite<Ctx: ?Sized>(
    ws: &mut LmWorkspace,
    ctx: &Ctx,
    terms: &[&dyn EnergyTerm<Ctx>],
) -> Option<&'static str> {
    ws.ne.clear();
    let mut culprit = None;
    for term in terms {
        let stats = term.accumulate(ctx, &mut ws.ne);
        let bad = match stats {
            Ok(s) => !s.energy.is_finite(),
            Err(_) => false,
        };
        if culprit.is_none() && (bad || !ws.ne.is_finite()) {
            culprit = Some(term.name());
        }
    }
    ws.ne.symmetrize();
    culprit
}
