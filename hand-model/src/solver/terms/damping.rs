//! Constant (Levenberg) damping `E_damp = Σᵢ λᵢ δᵢ²` (thesis §2.7.5).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::error::ModelError;
use crate::kinematics::{DofKind, Skeleton};
use crate::solver::lm::OptionsError;
use crate::solver::normal_equations::{NormalEquations, TermStats};
use crate::solver::term::{EnergyTerm, TermError};

/// Damping weights λ per kind of unknown, with per-DOF overrides.
///
/// Used twice: as [`crate::solver::LmOptions::damping`] (applied by the solver every
/// iteration) and by the [`Damping`] term (extra damping reported as a term). Use one or the
/// other for a given weight — both add to the diagonal.
///
/// Defaults: the thesis' uniform λ = 100 (§2.7.5, "λ = 100") for translations (per mm²),
/// global rotations and joints (per rad²); 0 for auxiliary unknowns (the PCA latents must stay
/// undamped for the augmented prior to equal the closed form). The originals differ: htrack
/// damps translations 1, rotations 300; hmodel/honline translations 1, rotations 3000,
/// abductions 1.5e6, tip flexions 1e4 (ANCHOR-FACTS §5.2) — express those with `per_dof`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DampingParams {
    /// λ for the global translations (`DofKind::Translation`).
    pub translation: f64,
    /// λ for the global rotations (`DofKind::GlobalRotation`, tangent-space steps).
    pub rotation: f64,
    /// λ for the joint rotations (`DofKind::Rotation`).
    pub joint: f64,
    /// λ for the auxiliary unknowns appended after the pose.
    pub aux: f64,
    /// Per-DOF overrides by name (replace the kind's value), e.g.
    /// `{"index_mcp_abd": 1.5e6}`.
    pub per_dof: BTreeMap<String, f64>,
}

impl Default for DampingParams {
    fn default() -> Self {
        Self::uniform(100.0)
    }
}

impl DampingParams {
    /// λ for every DOF, 0 for auxiliary unknowns.
    pub fn uniform(lambda: f64) -> Self {
        Self {
            translation: lambda,
            rotation: lambda,
            joint: lambda,
            aux: 0.0,
            per_dof: BTreeMap::new(),
        }
    }

    /// No damping at all.
    pub fn none() -> Self {
        Self::uniform(0.0)
    }

    /// Every weight finite and non-negative.
    pub fn validate(&self) -> Result<(), OptionsError> {
        let ok = |v: f64| v.is_finite() && v >= 0.0;
        for (field, v) in [
            ("translation", self.translation),
            ("rotation", self.rotation),
            ("joint", self.joint),
            ("aux", self.aux),
        ] {
            if !ok(v) {
                return Err(OptionsError::Damping { field });
            }
        }
        if !self.per_dof.values().all(|&v| ok(v)) {
            return Err(OptionsError::Damping { field: "per_dof" });
        }
        Ok(())
    }

    /// The diagonal `λᵢ` for the unknowns `[θ of skeleton | num_aux auxiliaries]`; unknown
    /// names in `per_dof` are an error.
    pub fn diagonal(&self, skeleton: &Skeleton, num_aux: usize) -> Result<Vec<f64>, ModelError> {
        let mut d: Vec<f64> = skeleton
            .dofs()
            .iter()
            .map(|dof| match dof.kind {
                DofKind::Translation => self.translation,
                DofKind::GlobalRotation => self.rotation,
                DofKind::Rotation => self.joint,
            })
            .collect();
        d.resize(skeleton.num_dofs() + num_aux, self.aux);
        for (name, &v) in &self.per_dof {
            let i = skeleton
                .dof_index(name)
                .ok_or_else(|| ModelError::InvalidArgument {
                    name: "damping.per_dof",
                    reason: format!("unknown DOF `{name}`"),
                })?;
            d[i] = v;
        }
        Ok(d)
    }
}

/// Constant damping as an energy term: `E_damp = Σᵢ λᵢ δᵢ²` (thesis §2.7.5).
///
/// A proximal term on the *step*: at the linearization point (δ = 0) its energy and gradient
/// are zero; it only adds `λᵢ` to the diagonal (`A += diag λ`, `b += 0`), one "row" per damped
/// unknown. Prefer [`crate::solver::LmOptions::damping`] for the solver's λ; this term is for
/// extra, separately reported damping.
#[derive(Clone, Debug, PartialEq)]
pub struct Damping {
    diagonal: Vec<f64>,
}

impl Damping {
    /// Resolve `params` on a skeleton with `num_aux` auxiliary unknowns.
    pub fn new(
        skeleton: &Skeleton,
        num_aux: usize,
        params: &DampingParams,
    ) -> Result<Self, ModelError> {
        params.validate().map_err(|e| ModelError::InvalidArgument {
            name: "damping",
            reason: e.to_string(),
        })?;
        Ok(Self {
            diagonal: params.diagonal(skeleton, num_aux)?,
        })
    }

    /// The resolved `λᵢ`.
    pub fn diagonal(&self) -> &[f64] {
        &self.diagonal
    }
}

impl<Ctx: ?Sized> EnergyTerm<Ctx> for Damping {
    fn name(&self) -> &'static str {
        "damping"
    }

    fn accumulate(&self, _ctx: &Ctx, ne: &mut NormalEquations) -> Result<TermStats, TermError> {
        if self.diagonal.len() > ne.dim() {
            return Err(TermError::ShapeMismatch {
                expected: ne.dim(),
                found: self.diagonal.len(),
            });
        }
        let mut rows = 0;
        for (i, &l) in self.diagonal.iter().enumerate() {
            if l != 0.0 {
                ne.add_diagonal(i, l)?;
                rows += 1;
            }
        }
        Ok(TermStats { energy: 0.0, rows })
    }
}
