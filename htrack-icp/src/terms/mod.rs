//! The energy terms of the Ch. 2 tracker (thesis Eq. 2.1), each an
//! [`hand_model::solver::EnergyTerm`] over [`crate::TrackingCtx`]:
//!
//! - [`E3d`]: point cloud alignment (Eq. 2.2, front-facing correspondences of §2.3.1,
//!   linearized as in §2.7.4);
//! - [`E2d`]: silhouette alignment (Eq. 2.3, §2.3.1 "2D correspondences", projection Jacobian
//!   of §2.7.2): rendered pixels outside the sensor silhouette pushed to their nearest
//!   silhouette pixel;
//! - [`Wrist`]: the wristband line (Eq. 2.4);
//! - [`Collision`]: finger segment interpenetration (Eq. 2.7, Fig. 2.25).
//!
//! The shared priors (joint limits Eq. 2.8, damping, temporal Eq. 2.9, PCA pose prior
//! Eq. 2.5–2.6) come from [`hand_model::solver::terms`] and run on the same context through
//! [`hand_model::solver::PoseContext`].

mod collision;
mod e2d;
mod e3d;
mod wrist;

pub use collision::{contact, Collision, CollisionPair, CollisionParams, PairContact};
pub use e2d::{E2d, E2dParams, SilhouettePush};
pub use e3d::{E3d, E3dParams};
pub use wrist::{Wrist, WristParams};
