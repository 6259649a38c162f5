//! Finite-difference checks of energy terms (STYLE practice 10): every term's linearization is
//! compared with central differences of its own energy.
//!
//! With the [`NormalEquations`] convention (`E = ω‖r‖²`, `b = −ω Jᵀr`), the analytic gradient
//! is `∂E/∂θ = −2b` and the Gauss–Newton Hessian `½∂²E/∂θ² ≈ A`. Perturbations go through
//! [`Pose::retract`] (`θ ⊞ ±h eₖ`), so global-rotation derivatives are taken in the same
//! tangent space as the Jacobian columns. These helpers allocate; they are for tests.

use super::normal_equations::NormalEquations;
use super::term::{EnergyTerm, TermError};
use crate::kinematics::{Pose, Skeleton};

/// Analytic vs numeric values of a check, per pose DOF (or per DOF pair, row-major).
#[derive(Clone, Debug, PartialEq)]
pub struct FdComparison {
    /// From the term's normal equations.
    pub analytic: Vec<f64>,
    /// From central differences.
    pub numeric: Vec<f64>,
}

impl FdComparison {
    /// `max |analytic − numeric|`.
    pub fn max_abs_error(&self) -> f64 {
        self.analytic
            .iter()
            .zip(&self.numeric)
            .fold(0.0, |m, (a, n)| m.max((a - n).abs()))
    }

    /// `max |analytic − numeric| / max(‖analytic‖_∞, ‖numeric‖_∞, floor)`.
    pub fn relative_error(&self, floor: f64) -> f64 {
        let scale = self
            .analytic
            .iter()
            .chain(&self.numeric)
            .fold(floor, |m, v| m.max(v.abs()));
        self.max_abs_error() / scale
    }
}

/// Accumulate one term at `pose` (after `update` refreshed the context) into a fresh system of
/// `dim` unknowns; returns the symmetrized system and the term's energy.
pub fn linearize<Ctx: ?Sized>(
    pose: &Pose,
    dim: usize,
    term: &dyn EnergyTerm<Ctx>,
    ctx: &mut Ctx,
    update: &mut dyn FnMut(&Pose, &mut Ctx),
) -> Result<(NormalEquations, f64), TermError> {
    update(pose, ctx);
    let mut ne = NormalEquations::new(dim);
    let stats = term.accumulate(ctx, &mut ne)?;
    ne.symmetrize();
    Ok((ne, stats.energy))
}

/// Gradient check: `∂E/∂θₖ = −2bₖ` against `(E(θ ⊞ h eₖ) − E(θ ⊞ −h eₖ)) / 2h` for every pose
/// DOF k. `dim` is the system size (pose DOFs plus auxiliary unknowns).
pub fn check_gradient<Ctx: ?Sized>(
    skeleton: &Skeleton,
    pose: &Pose,
    dim: usize,
    term: &dyn EnergyTerm<Ctx>,
    ctx: &mut Ctx,
    update: &mut dyn FnMut(&Pose, &mut Ctx),
    h: f64,
) -> Result<FdComparison, TermError> {
    let nd = skeleton.num_dofs();
    let (ne, _) = linearize(pose, dim, term, ctx, update)?;
    let analytic = (0..nd).map(|k| -2.0 * ne.rhs()[k]).collect();
    let mut numeric = Vec::with_capacity(nd);
    let mut delta = vec![0.0; nd];
    for k in 0..nd {
        let mut e = [0.0; 2];
        for (s, sign) in [1.0, -1.0].into_iter().enumerate() {
            delta[k] = sign * h;
            let p = pose.retract(skeleton, &delta);
            e[s] = linearize(&p, dim, term, ctx, update)?.1;
        }
        delta[k] = 0.0;
        numeric.push((e[0] - e[1]) / (2.0 * h));
    }
    update(pose, ctx);
    Ok(FdComparison { analytic, numeric })
}

/// Gauss–Newton Hessian check over the pose DOFs: `A` against `−∂b/∂θ` by central
/// differences of the term's own `b` (row-major `nd × nd`). `A = JᵀJ` equals the true
/// `½∂²E/∂θ²` where the residuals vanish or the term is quadratic, so run it there; it then
/// checks the Jacobian itself (not only `Jᵀr`).
pub fn check_hessian<Ctx: ?Sized>(
    skeleton: &Skeleton,
    pose: &Pose,
    dim: usize,
    term: &dyn EnergyTerm<Ctx>,
    ctx: &mut Ctx,
    update: &mut dyn FnMut(&Pose, &mut Ctx),
    h: f64,
) -> Result<FdComparison, TermError> {
    let nd = skeleton.num_dofs();
    let (ne, _) = linearize(pose, dim, term, ctx, update)?;
    let mut analytic = Vec::with_capacity(nd * nd);
    for i in 0..nd {
        for j in 0..nd {
            analytic.push(ne.lhs()[(i, j)]);
        }
    }
    let mut numeric = vec![0.0; nd * nd];
    let mut delta = vec![0.0; nd];
    for k in 0..nd {
        delta[k] = h;
        let plus = linearize(&pose.retract(skeleton, &delta), dim, term, ctx, update)?.0;
        delta[k] = -h;
        let minus = linearize(&pose.retract(skeleton, &delta), dim, term, ctx, update)?.0;
        delta[k] = 0.0;
        for i in 0..nd {
            numeric[i * nd + k] = -(plus.rhs()[i] - minus.rhs()[i]) / (2.0 * h);
        }
    }
    update(pose, ctx);
    Ok(FdComparison { analytic, numeric })
}
