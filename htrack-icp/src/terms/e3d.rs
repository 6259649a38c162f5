//! The point cloud alignment term E3D (thesis Eq. 2.2, linearized in §2.7.4).

use hand_model::solver::{
    EnergyTerm, NormalEquations, PackedBlocks, PoseContext, TermError, TermStats,
};
use serde::{Deserialize, Serialize};

use crate::context::TrackingCtx;

/// Settings of [`E3d`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct E3dParams {
    /// ω₁ of Eq. 2.2 (thesis and htrack: 1).
    pub weight: f64,
}

impl Default for E3dParams {
    fn default() -> Self {
        Self { weight: 1.0 }
    }
}

/// Most DOFs on one bone's chain (the cylinder skeleton has at most 6 + 4).
const MAX_CHAIN: usize = 64;

/// E3D, thesis Eq. 2.2: `E3D = ω₁ Σ_{x∈𝒳_s} ‖x − Π_M(x, θ)‖₂` (a sum of unsquared distances,
/// the mixed ℓ2/ℓ1 norm), with the front-facing correspondences `y = Π_M(x, θ)` of §2.3.1 held
/// by [`TrackingCtx`].
///
/// Linearization (§2.7.4 "Point cloud alignment"): one point-to-plane row per point,
/// `ω₁ w (nᵀ(J_skel(y) δθ + d))²` with `d = y − x`, `n` the surface normal at `y` and
/// `J_skel(y)` the skeleton Jacobian of `y` rigidly attached to its segment's bone (§2.7.2).
/// In the [`NormalEquations`] convention the residual is `r = nᵀ(y − x)` (current − target) and
/// the row `∂r/∂θ_k = nᵀ ∂y/∂θ_k`.
///
/// The per-point weight `w` is [`TrackingCtx::weights`]: on reweighted iterations the IRLS
/// weight `g/max(|r|, ε)` of the Huber-ℓ1 penalty (see [`crate::IrlsParams`] for why this
/// form), and the reported energy is `ω₁ 2g Σ ρ_ε(r)` (= `ω₁ 2g Σ‖x − y‖` for closest-point
/// correspondences, Eq. 2.2); on the rigid iteration reweighting is off (htrack, ANCHOR-FACTS
/// §5.3), `w = 1` and the energy is the point-to-plane least squares `ω₁ Σ r²`. Either way
/// `−2b` is the gradient of the reported energy wherever `n ∥ x − y`, which the tests check by
/// finite differences: on the circular segments (closest points, envelope theorem, §2.7.4's
/// `f(x)ᵀJ(x) = f(x)ᵀ`). Two exceptions, as in htrack: on the elliptical palm the foot point is
/// htrack's approximation (not the closest point, see [`hand_model::cylinder::query`]) and for
/// a silhouette substitute `y − x` is not along `n`; there the row is the Gauss–Newton row of
/// the plane through `y` held fixed, not the exact derivative of `nᵀ(y − x)`.
#[derive(Clone, Debug, PartialEq)]
pub struct E3d {
    params: E3dParams,
}

impl E3d {
    /// The term with `params`.
    pub fn new(params: E3dParams) -> Self {
        Self { params }
    }

    /// The settings.
    pub fn params(&self) -> &E3dParams {
        &self.params
    }
}

impl Default for E3d {
    fn default() -> Self {
        Self::new(E3dParams::default())
    }
}

impl EnergyTerm<TrackingCtx<'_>> for E3d {
    fn name(&self) -> &'static str {
        "e3d"
    }

    fn accumulate(
        &self,
        ctx: &TrackingCtx<'_>,
        ne: &mut NormalEquations,
    ) -> Result<TermStats, TermError> {
        let skeleton = ctx.skeleton();
        let posed = ctx.posed();
        let omega = self.params.weight;
        let reweighted = ctx.reweighted();
        let irls = ctx.irls();
        let bones = skeleton.bones().len();
        // The points of one bone share its chain: their rows are summed per bone in a packed
        // block and added once per bone; bones beyond the blocks' capacity add row by row.
        let mut blocks = PackedBlocks::new();
        let mut cols = [(0usize, 0.0f64); MAX_CHAIN];
        let mut jac = [0.0f64; MAX_CHAIN];
        let mut stats = TermStats::ZERO;
        for ((c, &r), &w) in ctx
            .correspondences()
            .iter()
            .zip(ctx.residuals())
            .zip(ctx.weights())
        {
            let Some(c) = c else { continue };
            if c.bone >= bones {
                return Err(TermError::BoneOutOfRange {
                    bone: c.bone,
                    bones,
                });
            }
            let chain = skeleton.chain(c.bone);
            let k = chain.len();
            if k > MAX_CHAIN {
                return Err(TermError::Failed("kinematic chain longer than 64 DOFs"));
            }
            for (j, &d) in jac.iter_mut().zip(chain) {
                *j = c.normal.dot(&posed.column(d, &c.point));
            }
            if PackedBlocks::fits(c.bone, k) {
                blocks.add_row(c.bone, &jac[..k], r, omega * w)?;
            } else {
                for ((slot, &d), &j) in cols.iter_mut().zip(chain).zip(&jac) {
                    *slot = (d, j);
                }
                ne.add_row(&cols[..k], r, omega * w)?;
            }
            let energy = if reweighted { irls.penalty(r) } else { r * r };
            stats += TermStats {
                energy: omega * energy,
                rows: 1,
            };
        }
        blocks.flush(ne, |bone| skeleton.chain(bone))?;
        Ok(stats)
    }
}
