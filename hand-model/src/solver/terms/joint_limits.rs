//! Joint-angle bounds `E_bounds` (thesis Eq. 2.8).

use serde::{Deserialize, Serialize};

use crate::kinematics::Skeleton;
use crate::solver::normal_equations::{NormalEquations, TermStats};
use crate::solver::term::{EnergyTerm, PoseContext, TermError};

/// Weight of [`JointLimits`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct JointLimitsParams {
    /// ω₇ of Eq. 2.8, applied once to `JᵀJ` and `Jᵀr` (ANCHOR-FACTS §5.2 convention). Default
    /// 1e7 as in htrack/hmodel/honline (`jointlimits_weight = 10000000`); the thesis text lists
    /// ω₇ = 1e8 for its own weight convention.
    pub weight: f64,
}

impl Default for JointLimitsParams {
    fn default() -> Self {
        Self { weight: 1e7 }
    }
}

/// Joint-angle bounds (thesis Eq. 2.8, linearized in §2.7.3 "Joint bounds"):
///
/// `E_bounds = ω₇ Σᵢ χ̲(i)(θᵢ − θ̲ᵢ)² + χ̄(i)(θᵢ − θ̄ᵢ)²`,
///
/// for every DOF with [`crate::kinematics::Dof::limits`] `[θ̲ᵢ, θ̄ᵢ]`. Only violated DOFs
/// produce a row: residual `rᵢ = θᵢ − θ̄ᵢ` when `θᵢ > θ̄ᵢ`, `rᵢ = θᵢ − θ̲ᵢ` when `θᵢ < θ̲ᵢ`,
/// Jacobian `∂rᵢ/∂θᵢ = 1`. So it adds `ω` to `A[i][i]` and `−ω rᵢ` to `bᵢ` (the originals' dense
/// `LᵀL` product reduced to its diagonal).
#[derive(Clone, Debug, PartialEq)]
pub struct JointLimits {
    weight: f64,
    /// `(dof, lower, upper)`.
    bounds: Vec<(usize, f64, f64)>,
}

impl JointLimits {
    /// The bounded DOFs of `skeleton`.
    pub fn new(skeleton: &Skeleton, params: &JointLimitsParams) -> Self {
        let bounds = skeleton
            .dofs()
            .iter()
            .enumerate()
            .filter_map(|(i, d)| d.limits.map(|[lo, hi]| (i, lo, hi)))
            .collect();
        Self {
            weight: params.weight,
            bounds,
        }
    }

    /// `(dof, lower, upper)` of every bounded DOF.
    pub fn bounds(&self) -> &[(usize, f64, f64)] {
        &self.bounds
    }
}

impl<C: PoseContext + ?Sized> EnergyTerm<C> for JointLimits {
    fn name(&self) -> &'static str {
        "joint_limits"
    }

    fn accumulate(&self, ctx: &C, ne: &mut NormalEquations) -> Result<TermStats, TermError> {
        let theta = &ctx.pose().values;
        let mut stats = TermStats::ZERO;
        for &(i, lo, hi) in &self.bounds {
            let Some(&v) = theta.get(i) else {
                return Err(TermError::ShapeMismatch {
                    expected: i + 1,
                    found: theta.len(),
                });
            };
            let r = if v > hi {
                v - hi
            } else if v < lo {
                v - lo
            } else if v.is_nan() {
                // A NaN angle is reported, never silently skipped.
                v
            } else {
                continue;
            };
            stats += ne.add_row(&[(i, 1.0)], r, self.weight)?;
        }
        Ok(stats)
    }
}
