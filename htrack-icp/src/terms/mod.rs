//! The energy terms of the Ch. 2 tracker (thesis Eq. 2.1), each an
//! [`hand_model::solver::EnergyTerm`] over [`crate::TrackingCtx`]. The shared priors (joint
//! limits Eq. 2.8, damping, temporal Eq. 2.9, PCA pose prior Eq. 2.5–2.6) come from
//! [`hand_model::solver::terms`] and run on the same context through
//! [`hand_model::solver::PoseContext`].

mod collision;
mod e3d;
mod wrist;

pub use collision::{contact, Collision, CollisionPair, CollisionParams, PairContact};
pub use e3d::{E3d, E3dParams};
pub use wrist::{Wrist, WristParams};
