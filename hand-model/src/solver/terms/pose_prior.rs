//! The projective PCA pose prior `E_pose = E_projection + E_mean` (thesis Eq. 2.5–2.6, §2.7.1).

use nalgebra::{Cholesky, DMatrix};
use serde::{Deserialize, Serialize};

use crate::error::ModelError;
use crate::kinematics::Skeleton;
use crate::solver::normal_equations::{NormalEquations, TermStats};
use crate::solver::pca::{PcaPrior, HTRACK_LATENT_DIMS};
use crate::solver::term::{EnergyTerm, PoseContext, TermError};

/// How the latent PCA weights θ̃ of Eq. 2.5–2.6 enter the solve.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PosePriorForm {
    /// θ̃ eliminated exactly (default): `E = ω₄ yᵀ(I − P K) y` with the optimal latents
    /// `θ̃* = K y`, `K = ω₄ (ω₄ PᵀP + ω₅ Σ²)⁻¹ Pᵀ`. This is `min_θ̃ E_pose(θ, θ̃)`, so it gives
    /// exactly the θ-steps of the augmented system.
    #[default]
    Exact,
    /// The thesis' §2.7.1 expression `E = ω₄ ‖(I − P M Pᵀ) y‖²`: the projection energy at
    /// θ̃*, *without* the `E_mean(θ̃*)` part (it equals [`PosePriorForm::Exact`] only when
    /// ω₅ = 0). Kept to reproduce the thesis formula.
    Projection,
    /// The originals' formulation (ANCHOR-FACTS §4): the latents are auxiliary unknowns of the
    /// solve, linearized at θ̃* every iteration (their solved step is discarded). Needs
    /// [`PosePrior::num_aux`] auxiliary unknowns in the solver.
    Augmented,
    /// Optimization **in the PCA subspace** (the alternative of thesis Fig. 2.14): each group's
    /// DOFs are held to `θ_g = μ + P θ̃` and only the latents move, with the Mahalanobis prior
    /// `ω₅ ‖Σ θ̃‖²` on them. Realized by the penalty method rather than a reparametrization
    /// of the solver unknowns (the cheapest faithful way: no change to the solver, the term
    /// stays one constant quadratic): `E = ω⊥ ‖(I − P L) y‖² + ω₅ ‖Σ L y‖²` with the least-
    /// squares latents `θ̃ = L y`, `L = (PᵀP)⁻¹Pᵀ`, and the stiffness
    /// `ω⊥ = ω₄ · SUBSPACE_STIFFNESS` (10⁶ ω₄): with ω₄ = 10³ a pose leaves the subspace by
    /// `‖(I − PL) y‖ ~ 10⁻⁴·‖data gradient‖`, i.e. the reparametrized solve to that tolerance.
    Subspace,
}

/// `ω⊥ / ω₄` of [`PosePriorForm::Subspace`].
pub const SUBSPACE_STIFFNESS: f64 = 1e6;

/// Weights and form of [`PosePrior`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PosePriorParams {
    /// ω₄ of Eq. 2.5. Thesis §2.4: 10³. (htrack: `weight_proj` 1e4 added as `2·w·AᵀA`, i.e.
    /// ω₄ = 2e4 here; hmodel/honline 4000 → 8000.)
    pub weight_projection: f64,
    /// ω₅ of Eq. 2.6. Thesis: 1. (htrack `weight_mean` 100 → 200 here; hmodel/honline 50 → 100.)
    pub weight_mean: f64,
    /// Keep at most this many latent dimensions per group (`None`: all in the data). Default 3,
    /// htrack's `latent_size`; the hmodel files hold 2.
    pub latent_dims: Option<usize>,
    /// Exact elimination, thesis projection-only expression, or augmented latents.
    pub form: PosePriorForm,
}

impl Default for PosePriorParams {
    fn default() -> Self {
        Self {
            weight_projection: 1e3,
            weight_mean: 1.0,
            latent_dims: Some(HTRACK_LATENT_DIMS),
            form: PosePriorForm::Exact,
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
struct Group {
    /// Pose DOFs (k), then auxiliary unknowns (m) for the augmented form.
    indices: Vec<usize>,
    k: usize,
    mean: Vec<f64>,
    /// Symmetric Hessian over `indices` (both triangles).
    hessian: DMatrix<f64>,
    /// `K` (m × k): optimal latents `θ̃* = K y`.
    latent_map: DMatrix<f64>,
}

/// The projective PCA pose prior (thesis Eq. 2.5–2.6, closed form §2.7.1, linearization
/// §2.7.3 "Data-driven (PCA)").
///
/// Per PCA group with DOFs `θ_g`, mean μ, basis `P = Π_𝒫` (k × m), latent variances `σ²`
/// (`Σ = diag(1/σ)` of Eq. 2.6, `Σ² = diag(1/σ²)`) and `y = θ_g − μ`:
///
/// `E_pose(θ, θ̃) = ω₄ ‖y − P θ̃‖² + ω₅ ‖Σ θ̃‖²`  (Eq. 2.5 + Eq. 2.6).
///
/// It is quadratic in `(y, θ̃)`; minimizing over θ̃ gives `θ̃* = K y` with
/// `K = ω₄ G⁻¹ Pᵀ`, `G = ω₄ PᵀP + ω₅ Σ²` (§2.7.1: `θ̃* = M Pᵀ y`, `M = ω₄(ω₅Σ² + ω₄I)⁻¹` for
/// orthonormal P), and the exact reduced energy
///
/// `E(θ) = ω₄ yᵀ (I − P K) y`,
///
/// a quadratic with constant Hessian `H = ω₄(I − P K)` (precomputed): the term adds `A += H`,
/// `b −= H y` over the group's DOFs (`add_quadratic_form`), with no linearization error. In
/// the eigenbasis, a latent direction with variance σ² is penalized by
/// `ω₄ω₅/(ω₅ + ω₄σ²)`·(coordinate)² ≈ `ω₅/σ²` (a Mahalanobis prior) and directions
/// orthogonal to the subspace by ω₄. See [`PosePriorForm`] for the thesis projection-only
/// expression and the originals' augmented system; all share this code path (the augmented
/// form is the same quadratic over `(y, θ̃)` with `θ̃` at `θ̃*`).
///
/// Acts on the DOF names of a [`PcaPrior`]; the skeleton must have all of them.
#[derive(Clone, Debug, PartialEq)]
pub struct PosePrior {
    form: PosePriorForm,
    groups: Vec<Group>,
    num_aux: usize,
}

impl PosePrior {
    /// Build the term for `skeleton`; for [`PosePriorForm::Augmented`] the latents are the
    /// auxiliary unknowns right after the pose DOFs (offset `skeleton.num_dofs()`).
    pub fn new(
        skeleton: &Skeleton,
        prior: &PcaPrior,
        params: &PosePriorParams,
    ) -> Result<Self, ModelError> {
        Self::with_aux_offset(skeleton, prior, params, skeleton.num_dofs())
    }

    /// As [`PosePrior::new`], with the augmented latents at unknowns `aux_offset ..
    /// aux_offset + num_aux()` (must be ≥ the number of DOFs).
    pub fn with_aux_offset(
        skeleton: &Skeleton,
        prior: &PcaPrior,
        params: &PosePriorParams,
        aux_offset: usize,
    ) -> Result<Self, ModelError> {
        let bad = |reason: String| ModelError::InvalidArgument {
            name: "pose_prior",
            reason,
        };
        let (w4, w5) = (params.weight_projection, params.weight_mean);
        if !(w4.is_finite() && w4 > 0.0 && w5.is_finite() && w5 >= 0.0) {
            return Err(bad(format!(
                "weights must satisfy ω₄ > 0, ω₅ ≥ 0 (got {w4}, {w5})"
            )));
        }
        if aux_offset < skeleton.num_dofs() {
            return Err(bad(format!(
                "auxiliary offset {aux_offset} overlaps the {} pose DOFs",
                skeleton.num_dofs()
            )));
        }
        let prior = match params.latent_dims {
            Some(m) => prior.truncated(m),
            None => prior.clone(),
        };
        prior.validate(std::path::Path::new("<pose prior>"))?;
        let mut groups = Vec::with_capacity(prior.groups.len());
        let mut next_aux = aux_offset;
        for g in &prior.groups {
            let (k, m) = (g.num_dofs(), g.num_latent());
            let mut indices = Vec::with_capacity(k + m);
            for name in &g.dofs {
                indices.push(skeleton.dof_index(name).ok_or_else(|| {
                    bad(format!(
                        "the skeleton has no DOF `{name}` (group `{}`)",
                        g.name
                    ))
                })?);
            }
            let p = &g.basis;
            let sigma2 = DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(
                m,
                g.variances.iter().map(|v| 1.0 / v),
            ));
            let gram = p.transpose() * p * w4 + &sigma2 * w5;
            let chol = Cholesky::new(gram.clone())
                .ok_or_else(|| bad(format!("group `{}`: ω₄PᵀP + ω₅Σ² is singular", g.name)))?;
            let mut latent_map = chol.solve(&p.transpose()) * w4;
            let eye = DMatrix::<f64>::identity(k, k);
            let r = &eye - p * &latent_map;
            let hessian = match params.form {
                PosePriorForm::Subspace => {
                    let ptp = Cholesky::new(p.transpose() * p)
                        .ok_or_else(|| bad(format!("group `{}`: PᵀP is singular", g.name)))?;
                    latent_map = ptp.solve(&p.transpose());
                    let r = &eye - p * &latent_map;
                    let h = r.transpose() * &r * (w4 * SUBSPACE_STIFFNESS)
                        + latent_map.transpose() * &sigma2 * &latent_map * w5;
                    (&h + h.transpose()) * 0.5
                }
                PosePriorForm::Exact => {
                    let h = &r * w4;
                    (&h + h.transpose()) * 0.5
                }
                PosePriorForm::Projection => r.transpose() * &r * w4,
                PosePriorForm::Augmented => {
                    let mut h = DMatrix::zeros(k + m, k + m);
                    h.view_mut((0, 0), (k, k)).copy_from(&(eye * w4));
                    h.view_mut((0, k), (k, m)).copy_from(&(p * -w4));
                    h.view_mut((k, 0), (m, k)).copy_from(&(p.transpose() * -w4));
                    h.view_mut((k, k), (m, m)).copy_from(&gram);
                    indices.extend(next_aux..next_aux + m);
                    next_aux += m;
                    h
                }
            };
            groups.push(Group {
                indices,
                k,
                mean: g.mean.clone(),
                hessian,
                latent_map,
            });
        }
        Ok(Self {
            form: params.form,
            groups,
            num_aux: next_aux - aux_offset,
        })
    }

    /// The form.
    pub fn form(&self) -> PosePriorForm {
        self.form
    }

    /// Auxiliary unknowns the solver must provide (Σ m for the augmented form, else 0).
    pub fn num_aux(&self) -> usize {
        self.num_aux
    }

    /// Number of groups.
    pub fn num_groups(&self) -> usize {
        self.groups.len()
    }

    /// The optimal latent coordinates `θ̃* = K (θ_g − μ)` of group `group` (the least-squares
    /// `L (θ_g − μ)` for [`PosePriorForm::Subspace`]; e.g. honline's
    /// "fingers bending" latent is `latent(θ, 1)[0]`); `None` when out of range.
    pub fn latent(&self, theta: &[f64], group: usize) -> Option<Vec<f64>> {
        let g = self.groups.get(group)?;
        let y = self.y(g, theta)?;
        Some(
            (&g.latent_map * nalgebra::DVector::from_vec(y))
                .as_slice()
                .to_vec(),
        )
    }

    /// `E_pose(θ)` evaluated directly (allocates; for scoring and tests).
    pub fn energy(&self, theta: &[f64]) -> Option<f64> {
        let mut e = 0.0;
        for g in &self.groups {
            let mut z = self.y(g, theta)?;
            if self.form == PosePriorForm::Augmented {
                let y = nalgebra::DVector::from_column_slice(&z);
                z.extend((&g.latent_map * y).iter());
            }
            let z = nalgebra::DVector::from_vec(z);
            e += z.dot(&(&g.hessian * &z));
        }
        Some(e)
    }

    fn y(&self, g: &Group, theta: &[f64]) -> Option<Vec<f64>> {
        g.indices[..g.k]
            .iter()
            .zip(&g.mean)
            .map(|(&i, mu)| theta.get(i).map(|t| t - mu))
            .collect()
    }
}

impl<C: PoseContext + ?Sized> EnergyTerm<C> for PosePrior {
    fn name(&self) -> &'static str {
        "pose_prior"
    }

    /// The augmented form reaches its latents (auxiliary unknowns), so it is not pose-only.
    fn pose_only_prior(&self) -> bool {
        self.form != PosePriorForm::Augmented
    }

    fn accumulate(&self, ctx: &C, ne: &mut NormalEquations) -> Result<TermStats, TermError> {
        let theta = &ctx.pose().values;
        let mut stats = TermStats::ZERO;
        for g in &self.groups {
            let k = g.k;
            if let Some(&i) = g.indices[..k].iter().find(|&&i| i >= theta.len()) {
                return Err(TermError::ShapeMismatch {
                    expected: i + 1,
                    found: theta.len(),
                });
            }
            stats += ne.add_quadratic_form(&g.indices, &g.hessian, |z| {
                for a in 0..k {
                    z[a] = theta[g.indices[a]] - g.mean[a];
                }
                // Augmented: the latents sit at their optimum θ̃* = K y.
                let (y, x) = z.split_at_mut(k);
                for (j, xj) in x.iter_mut().enumerate() {
                    *xj = g
                        .latent_map
                        .row(j)
                        .iter()
                        .zip(y.iter())
                        .map(|(a, b)| a * b)
                        .sum();
                }
            })?;
        }
        Ok(stats)
    }
}
