//! Temporal smoothness of kinematic points `E_temporal` (thesis Eq. 2.9).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::kinematics::PosedSkeleton;
use crate::solver::normal_equations::{NormalEquations, TermStats};
use crate::solver::points::KinematicPoint;
use crate::solver::term::{EnergyTerm, PoseContext, TermError};

/// Weights of [`Temporal`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TemporalParams {
    /// ω₈ (velocity). Thesis §2.4 "Parameters": 3 (htrack 3; hmodel/honline 0.05).
    pub weight_velocity: f64,
    /// ω₉ (acceleration). Thesis: 3 (htrack 3; hmodel/honline 0.05).
    pub weight_acceleration: f64,
}

impl Default for TemporalParams {
    fn default() -> Self {
        Self {
            weight_velocity: 3.0,
            weight_acceleration: 3.0,
        }
    }
}

/// Velocity and acceleration of points on the kinematic chain (thesis Eq. 2.9, linearized in
/// §2.7.3 "Temporal coherence"):
///
/// `E_temporal = ω₈ Σₖ ‖k(θ) − k_{t−1}‖² + ω₉ Σₖ ‖k(θ) − 2k_{t−1} + k_{t−2}‖²`,
///
/// with residuals `r₁ = k − k_{t−1}`, `r₂ = k − 2k_{t−1} + k_{t−2}` (3 rows each) and the
/// skeleton Jacobian `J_skel(k)` for both. Both share `J`, so they are accumulated in one pass
/// as `A += (ω₈+ω₉) JᵀJ`, `b −= Jᵀ(ω₈r₁ + ω₉r₂)` (exactly the sum of the two).
///
/// The points are typically the bone origins and tips ([`crate::solver::sphere_mesh_points`],
/// [`crate::solver::cylinder_points`]); the history holds their positions in the two previous
/// frames ([`Temporal::push_frame`]). With one previous frame only the velocity part is active,
/// with none the term is empty. (htrack enables the term only once both frames exist; feeding
/// one frame is the caller's choice.) The originals recompute the history by re-posing the
/// *current* model with the stored poses — do the same when the shape changes.
#[derive(Clone, Debug, PartialEq)]
pub struct Temporal {
    params: TemporalParams,
    points: Vec<KinematicPoint>,
    prev1: Vec<Vector3<f64>>,
    prev2: Vec<Vector3<f64>>,
    history: usize,
    /// The history set aside by [`Temporal::set_history_aside`].
    aside: usize,
}

impl Temporal {
    /// A term over `points` with an empty history.
    pub fn new(points: Vec<KinematicPoint>, params: &TemporalParams) -> Self {
        let n = points.len();
        Self {
            params: params.clone(),
            points,
            prev1: vec![Vector3::zeros(); n],
            prev2: vec![Vector3::zeros(); n],
            history: 0,
            aside: 0,
        }
    }

    /// The points.
    pub fn points(&self) -> &[KinematicPoint] {
        &self.points
    }

    /// How many previous frames are stored (0, 1 or 2).
    pub fn history_len(&self) -> usize {
        self.history
    }

    /// Forget the history (after a re-initialization).
    pub fn clear_history(&mut self) {
        self.history = 0;
        self.aside = 0;
    }

    /// Set the history aside (`true`: the term is empty, the stored positions kept) or bring
    /// it back (`false`); push no frame in between.
    pub fn set_history_aside(&mut self, aside: bool) {
        if aside {
            self.aside = self.aside.max(std::mem::take(&mut self.history));
        } else {
            self.history = self.history.max(std::mem::take(&mut self.aside));
        }
    }

    /// Record a finished frame: `k_{t−2} ← k_{t−1}`, `k_{t−1} ←` the points under `posed`.
    /// Allocation-free.
    pub fn push_frame(&mut self, posed: &PosedSkeleton) -> Result<(), TermError> {
        if let Some(p) = self.points.iter().find(|p| p.bone >= posed.globals.len()) {
            return Err(TermError::BoneOutOfRange {
                bone: p.bone,
                bones: posed.globals.len(),
            });
        }
        std::mem::swap(&mut self.prev1, &mut self.prev2);
        for (dst, p) in self.prev1.iter_mut().zip(&self.points) {
            *dst = p.position(posed);
        }
        self.history = (self.history + 1).min(2);
        Ok(())
    }

    /// Set the history directly: `k_{t−1}` and optionally `k_{t−2}` (one position per point).
    pub fn set_history(
        &mut self,
        prev1: &[Vector3<f64>],
        prev2: Option<&[Vector3<f64>]>,
    ) -> Result<(), TermError> {
        let n = self.points.len();
        for len in [Some(prev1.len()), prev2.map(<[_]>::len)]
            .into_iter()
            .flatten()
        {
            if len != n {
                return Err(TermError::ShapeMismatch {
                    expected: n,
                    found: len,
                });
            }
        }
        self.prev1.copy_from_slice(prev1);
        self.history = 1;
        if let Some(p2) = prev2 {
            self.prev2.copy_from_slice(p2);
            self.history = 2;
        }
        Ok(())
    }
}

impl<C: PoseContext + ?Sized> EnergyTerm<C> for Temporal {
    fn name(&self) -> &'static str {
        "temporal"
    }

    fn accumulate(&self, ctx: &C, ne: &mut NormalEquations) -> Result<TermStats, TermError> {
        if self.history == 0 {
            return Ok(TermStats::ZERO);
        }
        let (sk, posed) = (ctx.skeleton(), ctx.posed());
        let w1 = self.params.weight_velocity;
        let w2 = if self.history >= 2 {
            self.params.weight_acceleration
        } else {
            0.0
        };
        let w = w1 + w2;
        let rows_per_point = if self.history >= 2 { 6 } else { 3 };
        let mut stats = TermStats::ZERO;
        for (i, kp) in self.points.iter().enumerate() {
            if kp.bone >= posed.globals.len() {
                return Err(TermError::BoneOutOfRange {
                    bone: kp.bone,
                    bones: posed.globals.len(),
                });
            }
            let k = kp.position(posed);
            let r1 = k - self.prev1[i];
            let r2 = k - 2.0 * self.prev1[i] + self.prev2[i];
            let energy = w1 * r1.norm_squared() + w2 * r2.norm_squared();
            if w != 0.0 {
                let r_eff = (r1 * w1 + r2 * w2) / w;
                ne.add_skeleton_point(sk, posed, kp.bone, &k, &r_eff, w)?;
            }
            stats += TermStats {
                energy,
                rows: rows_per_point,
            };
        }
        Ok(stats)
    }
}
