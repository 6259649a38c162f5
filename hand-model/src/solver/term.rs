//! The one trait every energy term implements, its error, and the shared per-iteration context.

use super::normal_equations::{NormalEquations, TermStats};
use crate::kinematics::{Pose, PosedSkeleton, Skeleton};

/// Why a term (or the per-iteration callback) could not contribute. Small and `Copy`: terms run
/// in the solver's hot loop. A term returning an error aborts the solve (see
/// [`super::LmSolver::solve`]); numerical trouble (NaN, non-SPD systems) is *not* an error but a
/// [`super::Termination`].
#[derive(Copy, Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TermError {
    /// An unknown index outside the system.
    #[error("unknown {index} is outside the system of {dim} unknowns")]
    IndexOutOfRange {
        /// The offending index.
        index: usize,
        /// The number of unknowns of the system.
        dim: usize,
    },
    /// A bone index outside the skeleton.
    #[error("bone {bone} is outside the skeleton of {bones} bones")]
    BoneOutOfRange {
        /// The offending bone.
        bone: usize,
        /// The number of bones.
        bones: usize,
    },
    /// The pose, a history or a matrix does not have the size the term was built for.
    #[error("size mismatch: expected {expected}, found {found}")]
    ShapeMismatch {
        /// Expected size.
        expected: usize,
        /// Actual size.
        found: usize,
    },
    /// Anything else (for trackers' own terms and callbacks).
    #[error("{0}")]
    Failed(&'static str),
}

/// One energy term of the tracking objective (thesis Eq. 2.1 / 2.11; STYLE practice 4).
///
/// `accumulate` linearizes the term at the current context and **adds** its contribution to the
/// normal equations through the [`NormalEquations`] helpers (terms cannot assign), returning its
/// energy at the linearization point. Sign and weight conventions are those of
/// [`NormalEquations`]: `A += ω JᵀJ`, `b −= ω Jᵀr`, energy `ω‖r‖²`.
///
/// `Ctx` is the per-iteration precompute shared by all terms (posed model, correspondences, …;
/// STYLE practice 5), refreshed by the solver's [`super::LmCallback`] before the terms run.
pub trait EnergyTerm<Ctx: ?Sized> {
    /// Short name used in reports (`"joint_limits"`, `"pose_prior"`, …).
    fn name(&self) -> &'static str;

    /// Add this term's linearization to `ne`.
    fn accumulate(&self, ctx: &Ctx, ne: &mut NormalEquations) -> Result<TermStats, TermError>;

    /// Whether this term is a prior on the pose DOFs alone (the PCA pose prior): under
    /// [`super::LmOptions::decouple_aux`] its pull moves the pose but not the auxiliary
    /// unknowns.
    fn pose_only_prior(&self) -> bool {
        false
    }
}

/// What the reusable prior terms of [`super::terms`] need from a context: the skeleton, the
/// current pose and its forward kinematics. Trackers implement it on their own context.
pub trait PoseContext {
    /// The kinematic tree.
    fn skeleton(&self) -> &Skeleton;
    /// The current pose θ.
    fn pose(&self) -> &Pose;
    /// Forward kinematics of [`PoseContext::pose`].
    fn posed(&self) -> &PosedSkeleton;
}

/// A ready-made [`PoseContext`]: a skeleton, the current pose and its posed skeleton.
#[derive(Clone, Debug)]
pub struct SkeletonCtx<'a> {
    /// The kinematic tree.
    pub skeleton: &'a Skeleton,
    /// The current pose.
    pub pose: Pose,
    /// Its forward kinematics.
    pub posed: PosedSkeleton,
}

impl<'a> SkeletonCtx<'a> {
    /// A context posed at `pose`.
    ///
    /// # Panics
    /// When `pose` does not have one value per DOF of `skeleton` (the precondition of
    /// [`PosedSkeleton::update`]); [`crate::solver::LmSolver::solve`] checks the pose it is
    /// given before re-posing.
    pub fn new(skeleton: &'a Skeleton, pose: &Pose) -> Self {
        Self {
            skeleton,
            pose: pose.clone(),
            posed: PosedSkeleton::new(skeleton, pose),
        }
    }

    /// Re-pose (allocation-free once sized): copy `pose` and run forward kinematics. Same
    /// precondition as [`SkeletonCtx::new`].
    pub fn set_pose(&mut self, pose: &Pose) {
        self.pose.values.clone_from(&pose.values);
        self.posed.update(self.skeleton, &self.pose);
    }
}

impl PoseContext for SkeletonCtx<'_> {
    fn skeleton(&self) -> &Skeleton {
        self.skeleton
    }
    fn pose(&self) -> &Pose {
        &self.pose
    }
    fn posed(&self) -> &PosedSkeleton {
        &self.posed
    }
}
