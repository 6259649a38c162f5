//! Iteratively re-weighted least squares for the robust ℓ1 data terms of both trackers
//! (thesis §2.7.4 "Point cloud alignment"; Eq. 3.4 uses the same robust norm, §3.3).

use serde::{Deserialize, Serialize};

/// How the ℓ1 norm of the data terms (Eq. 2.2, Eq. 3.4) is approximated by iteratively re-weighted least squares
/// (thesis §2.7.4: `ω_re = 1/‖d‖`; htrack reweights with `3.5/√(d + 1e−3)` baked into both `J`
/// and `e`, an effective weight `3.5²/d`, ANCHOR-FACTS §5.3).
///
/// With the point-to-plane residual `r = nᵀ(y − x)` the term minimizes the Huber-smoothed ℓ1
/// energy `2g·ρ_ε(r)`, `ρ_ε(r) = |r|` for `|r| ≥ ε`, `r²/(2ε) + ε/2` below, whose IRLS weight is
/// `w = (2g·ρ_ε)'(r)/(2r) = g / max(|r|, ε)`. With that weight the quadratic surrogate
/// `w·(r + Jδ)² + const` has exactly the value and the gradient of `2g·ρ_ε` at the linearization
/// point, so the linearization is finite-difference checkable and the reported energy is
/// `2g Σ‖x − y‖` (Eq. 2.2 scaled) whenever `n ∥ x − y` (every closest-point correspondence).
///
/// The gain `g` sets how strongly the reweighted data term pulls against the damping λ = 100
/// and the priors. The default `g = 3.5² = 12.25` is htrack's effective weight (the thesis'
/// `ω_re = 1/‖d‖` is `g = 1`: with it the data term is ~12× weaker than in the code whose
/// numbers the thesis reports, and a perturbed pose converges several times slower against
/// λ = 100 — measured in `tests/tracker.rs`). On non-reweighted iterations the weight is 1,
/// as in htrack. `ε` avoids the division by zero (htrack skips reweighting below
/// `d = 1e−3` mm).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IrlsParams {
    /// Reweight at all (false: plain point-to-plane least squares `Σ r²` on every iteration).
    pub reweight: bool,
    /// Also reweight on rigid-only iterations (htrack `fit3D_reweight_rigid`, off: "allows fast
    /// rigid motion", ANCHOR-FACTS §5.3).
    pub reweight_rigid: bool,
    /// Huber threshold ε (mm) below which the ℓ1 norm is replaced by a quadratic.
    pub epsilon: f64,
    /// Gain `g` of the reweighted term (htrack 12.25; thesis formula 1).
    pub gain: f64,
}

impl Default for IrlsParams {
    fn default() -> Self {
        Self {
            reweight: true,
            reweight_rigid: false,
            epsilon: 1e-3,
            gain: 12.25,
        }
    }
}

impl IrlsParams {
    /// The penalty `2g·ρ_ε(r)` whose IRLS weight is [`IrlsParams::weight`].
    #[inline]
    pub fn penalty(&self, r: f64) -> f64 {
        let a = r.abs();
        let eps = self.eps();
        let rho = if a >= eps {
            a
        } else {
            r * r / (2.0 * eps) + eps / 2.0
        };
        2.0 * self.gain() * rho
    }

    /// The IRLS weight `w = g / max(|r|, ε)` of [`IrlsParams::penalty`].
    #[inline]
    pub fn weight(&self, r: f64) -> f64 {
        self.gain() / r.abs().max(self.eps())
    }

    /// ε, made positive and finite so that no weight divides by zero.
    #[inline]
    fn eps(&self) -> f64 {
        if self.epsilon.is_finite() && self.epsilon > 1e-12 {
            self.epsilon
        } else {
            1e-12
        }
    }

    /// g, made positive and finite (1 otherwise).
    #[inline]
    fn gain(&self) -> f64 {
        if self.gain.is_finite() && self.gain > 0.0 {
            self.gain
        } else {
            1.0
        }
    }
}
