//! Plumbing shared by the trackers around one LM solve: the pose prior with its solver, the
//! mean pose, a term that adds nothing (to fill fixed term arrays) and a timed solve.

use std::time::Instant;

use super::lm::{IterInfo, LmCallback, LmError, LmOptions, LmSolver, LmWorkspace};
use super::normal_equations::{NormalEquations, TermStats};
use super::pca::PcaPrior;
use super::term::{EnergyTerm, TermError};
use super::terms::{PosePrior, PosePriorParams};
use crate::error::ModelError;
use crate::kinematics::{Pose, Skeleton};

/// A term that adds nothing: fills the unused slots of a fixed-size term list (no allocation
/// per frame for the list of enabled terms).
#[derive(Copy, Clone, Debug, Default)]
pub struct NoTerm;

impl<Ctx: ?Sized> EnergyTerm<Ctx> for NoTerm {
    fn name(&self) -> &'static str {
        "none"
    }
    fn accumulate(&self, _: &Ctx, _: &mut NormalEquations) -> Result<TermStats, TermError> {
        Ok(TermStats::ZERO)
    }
}

/// What a tracker builds once per sequence around its prior: the pose-prior term (`None`
/// without a prior), the LM solver sized for the prior's auxiliary unknowns, and the prior's
/// mean pose at the identity global transform (zeros without a prior; the initial finger pose
/// of §2.3.2).
pub struct PriorSetup {
    /// E_pose (Eq. 2.5–2.6).
    pub prior: Option<PosePrior>,
    /// The solver.
    pub solver: LmSolver,
    /// The PCA mean pose.
    pub mean_pose: Pose,
}

impl PriorSetup {
    /// Build the prior term with `params`, the solver with `lm`, and the mean pose.
    pub fn new<E: From<LmError> + From<ModelError>>(
        skeleton: &Skeleton,
        prior: Option<&PcaPrior>,
        params: &PosePriorParams,
        lm: &LmOptions,
    ) -> Result<Self, E> {
        let term = prior
            .map(|p| PosePrior::new(skeleton, p, params))
            .transpose()?;
        let num_aux = term.as_ref().map_or(0, PosePrior::num_aux);
        let solver = LmSolver::new(skeleton, num_aux, lm.clone())?;
        let mut mean_pose = Pose::zeros(skeleton);
        for g in prior.iter().flat_map(|p| &p.groups) {
            for (name, &m) in g.dofs.iter().zip(&g.mean) {
                mean_pose.set(skeleton, name, m)?;
            }
        }
        Ok(Self {
            prior: term,
            solver,
            mean_pose,
        })
    }
}

/// Wall time of one [`timed_solve`] (µs): inside the callback (correspondences) and the rest.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct SolveTiming {
    /// Time in the callback's `prepare` (re-pose, correspondences, rendering).
    pub callback_us: f64,
    /// Everything else of the solve (terms, factorization).
    pub solve_us: f64,
}

impl std::ops::AddAssign for SolveTiming {
    fn add_assign(&mut self, o: Self) {
        self.callback_us += o.callback_us;
        self.solve_us += o.solve_us;
    }
}

struct Timed<'c, Ctx: ?Sized> {
    inner: &'c mut dyn LmCallback<Ctx>,
    us: f64,
}

impl<Ctx: ?Sized> LmCallback<Ctx> for Timed<'_, Ctx> {
    fn prepare(&mut self, pose: &Pose, ctx: &mut Ctx, info: IterInfo) -> Result<(), TermError> {
        let t = Instant::now();
        let r = self.inner.prepare(pose, ctx, info);
        self.us += t.elapsed().as_secs_f64() * 1e6;
        r
    }
    fn apply_aux(&mut self, ctx: &mut Ctx, delta_aux: &[f64]) {
        self.inner.apply_aux(ctx, delta_aux);
    }
}

/// One LM solve from `pose` in place, timed; true when it succeeded and left a finite pose.
#[allow(clippy::too_many_arguments)]
pub fn timed_solve<Ctx: ?Sized>(
    solver: &LmSolver,
    ws: &mut LmWorkspace,
    skeleton: &Skeleton,
    pose: &mut Pose,
    ctx: &mut Ctx,
    terms: &[&dyn EnergyTerm<Ctx>],
    callback: &mut dyn LmCallback<Ctx>,
    timing: &mut SolveTiming,
) -> bool {
    let mut timed = Timed {
        inner: callback,
        us: 0.0,
    };
    let t = Instant::now();
    let result = solver.solve(ws, skeleton, pose, ctx, terms, &mut timed);
    let total = t.elapsed().as_secs_f64() * 1e6;
    *timing += SolveTiming {
        callback_us: timed.us,
        solve_us: total - timed.us,
    };
    let finite = pose.values.iter().all(|v| v.is_finite());
    matches!(result, Ok(r) if r.termination.was_successful()) && finite
}
