//! The data→model term E_d2m (thesis Eq. 3.4).

use hand_model::solver::{EnergyTerm, NormalEquations, PackedBlocks, TermError, TermStats};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::context::TrackingCtx;
use crate::jacobian::MAX_ELEMENT_DOFS;

/// Settings of [`D2m`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct D2mParams {
    /// τ_d2m (thesis §3.6 "Reproducibility": 1).
    pub weight: f64,
}

impl Default for D2mParams {
    fn default() -> Self {
        Self { weight: 1.0 }
    }
}

/// E_d2m, thesis Eq. 3.4: `τ_d2m Σ_{p∈D} ‖p − Π_M(θ)(p)‖₂¹` — every data point explained by
/// the model, with the closed-form pill/wedge projections of §3.3.1 (Fig. 3.7) and the
/// monocular front-facing rule (Fig. 3.9) computed by [`TrackingCtx`]. The thesis' `|D|⁻¹`
/// normalization is left out, as in hmodel's code: it would make the data term's pull depend on
/// the number of points against fixed prior weights.
///
/// The robust ℓ1 norm by IRLS with the tracker's [`hand_model::solver::IrlsParams`] (hmodel
/// reweights like htrack, ANCHOR-FACTS §5.3): one row per point, residual `r = −‖p − q‖`,
/// weight `w`, Jacobian `∂r/∂θ = uᵀ ∂q/∂θ` with `u = (p − q)/‖p − q‖` and `∂q/∂θ` the exact
/// footpoint Jacobian of [`crate::FootpointJacobian`] (`w`, `n` held fixed). Where `p − q` is
/// along the surface normal (every plain closest point) this is the exact gradient of
/// `‖p − q(θ)‖` (the motion of the footpoint along the surface is second order); for a
/// silhouette substitute it is the Gauss–Newton row of the point-to-point distance with the
/// correspondence held fixed (hmodel's choice, ANCHOR-FACTS §5.3). Energy reported: `τ Σ
/// 2g·ρ_ε(r)` on reweighted iterations, `τ Σ r²` on the rigid one.
///
/// The rows of one element share its DOF set and are summed in a [`PackedBlocks`] block.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct D2m {
    params: D2mParams,
}

impl D2m {
    /// The term with `params`.
    pub fn new(params: D2mParams) -> Self {
        Self { params }
    }
}

impl EnergyTerm<TrackingCtx<'_>> for D2m {
    fn name(&self) -> &'static str {
        "d2m"
    }

    fn accumulate(
        &self,
        ctx: &TrackingCtx<'_>,
        ne: &mut NormalEquations,
    ) -> Result<TermStats, TermError> {
        let tau = self.params.weight;
        let jac = ctx.jacobian();
        let posed = ctx.posed_mesh();
        let irls = ctx.irls();
        let reweighted = ctx.reweighted();
        let mut blocks = PackedBlocks::new();
        let mut cols = [Vector3::zeros(); MAX_ELEMENT_DOFS];
        let mut row = [0.0f64; MAX_ELEMENT_DOFS];
        let mut pairs = [(0usize, 0.0f64); MAX_ELEMENT_DOFS];
        let mut stats = TermStats::ZERO;
        for (c, u, r, w) in ctx.d2m_rows() {
            let e = c.element as usize;
            let dofs = jac.columns(posed, e, &c.spheres, &c.weights, &mut cols);
            let k = dofs.len();
            for (x, col) in row.iter_mut().zip(&cols[..k]) {
                *x = u.dot(col);
            }
            if PackedBlocks::fits(e, k) {
                blocks.add_row(e, &row[..k], r, tau * w)?;
            } else {
                for ((slot, &d), &j) in pairs.iter_mut().zip(dofs).zip(&row) {
                    *slot = (d, j);
                }
                ne.add_row(&pairs[..k], r, tau * w)?;
            }
            let energy = if reweighted { irls.penalty(r) } else { r * r };
            stats += TermStats {
                energy: tau * energy,
                rows: 1,
            };
        }
        blocks.flush(ne, |e| jac.dofs(e))?;
        Ok(stats)
    }
}
