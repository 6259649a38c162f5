//! Kinematic chains shared by the sphere-mesh and cylinder models (thesis Eq. 3.7, §2.2).
//!
//! A [`Skeleton`] is a tree of bones with rest frames `T̄_k` (relative to the parent) and per-bone
//! degrees of freedom; a [`Pose`] is the vector θ of their values; [`PosedSkeleton`] evaluates
//! forward kinematics and the skeleton Jacobian `∂p/∂θ` of any point attached to a bone.

pub mod names;
mod pose;
mod posed;
mod skeleton;

pub use pose::Pose;
pub use posed::PosedSkeleton;
pub use skeleton::{Bone, Dof, DofKind, Skeleton};
