//! The energy terms of the sphere-mesh tracker (thesis Eq. 3.3), each an
//! [`hand_model::solver::EnergyTerm`] over [`crate::TrackingCtx`]:
//!
//! - [`D2m`]: data→model (Eq. 3.4) with closed-form and front-facing correspondences;
//! - [`M2d`]: model→data (Eq. 3.5), the model pushed into the sensor silhouette;
//! - [`Collision`]: finger pills must not interpenetrate.
//!
//! The pose prior (Eq. 2.5–2.6), joint limits (Eq. 2.8) and temporal smoothness (Eq. 2.9) are
//! the shared terms of [`hand_model::solver::terms`], running on the same context through
//! [`hand_model::solver::PoseContext`].

mod collision;
mod d2m;
mod m2d;

pub use collision::{pill_contact, Collision, CollisionParams, PillContact, PillPair};
pub use d2m::{D2m, D2mParams};
pub use m2d::{M2d, M2dParams};
