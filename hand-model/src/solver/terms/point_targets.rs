//! Point-to-point targets for kinematic points (inverse kinematics; tests and initialization).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::solver::normal_equations::{NormalEquations, TermStats};
use crate::solver::points::KinematicPoint;
use crate::solver::term::{EnergyTerm, PoseContext, TermError};

/// Weight of [`PointTargets`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PointTargetsParams {
    /// ω (per mm²). Default 1, like the data terms of the originals.
    pub weight: f64,
}

impl Default for PointTargetsParams {
    fn default() -> Self {
        Self { weight: 1.0 }
    }
}

/// `E = ω Σⱼ ‖pⱼ(θ) − tⱼ‖²`: kinematic points pulled onto 3D targets (the point-to-point form of
/// the thesis' point cloud alignment, §2.7.4, with known correspondences). Residual
/// `rⱼ = pⱼ(θ) − tⱼ` (3 rows), Jacobian `J_skel(pⱼ)` from
/// [`crate::kinematics::PosedSkeleton::for_each_column`]. Non-finite targets are skipped (a
/// missing marker), so only the pose can make the term non-finite.
#[derive(Clone, Debug, PartialEq)]
pub struct PointTargets {
    weight: f64,
    points: Vec<KinematicPoint>,
    targets: Vec<Vector3<f64>>,
}

impl PointTargets {
    /// One target per point.
    pub fn new(
        points: Vec<KinematicPoint>,
        targets: Vec<Vector3<f64>>,
        params: &PointTargetsParams,
    ) -> Result<Self, TermError> {
        if points.len() != targets.len() {
            return Err(TermError::ShapeMismatch {
                expected: points.len(),
                found: targets.len(),
            });
        }
        Ok(Self {
            weight: params.weight,
            points,
            targets,
        })
    }

    /// Replace the targets (same count); allocation-free.
    pub fn set_targets(&mut self, targets: &[Vector3<f64>]) -> Result<(), TermError> {
        if targets.len() != self.targets.len() {
            return Err(TermError::ShapeMismatch {
                expected: self.targets.len(),
                found: targets.len(),
            });
        }
        self.targets.copy_from_slice(targets);
        Ok(())
    }

    /// The points.
    pub fn points(&self) -> &[KinematicPoint] {
        &self.points
    }

    /// The targets.
    pub fn targets(&self) -> &[Vector3<f64>] {
        &self.targets
    }
}

impl<C: PoseContext + ?Sized> EnergyTerm<C> for PointTargets {
    fn name(&self) -> &'static str {
        "point_targets"
    }

    fn accumulate(&self, ctx: &C, ne: &mut NormalEquations) -> Result<TermStats, TermError> {
        let (sk, posed) = (ctx.skeleton(), ctx.posed());
        let mut stats = TermStats::ZERO;
        for (kp, t) in self.points.iter().zip(&self.targets) {
            if !t.iter().all(|v| v.is_finite()) {
                continue;
            }
            if kp.bone >= posed.globals.len() {
                return Err(TermError::BoneOutOfRange {
                    bone: kp.bone,
                    bones: posed.globals.len(),
                });
            }
            let p = kp.position(posed);
            stats += ne.add_skeleton_point(sk, posed, kp.bone, &p, &(p - t), self.weight)?;
        }
        Ok(stats)
    }
}
