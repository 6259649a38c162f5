//! # hmodel-spheremesh — sphere-mesh tracking (thesis Ch. 3)
//!
//! The real-time tracker of Tkach et al. 2016 (thesis §3.3) on the sphere-mesh template,
//! geometry queries and solver of `hand-model`:
//!
//! - [`TrackingCtx`]: the per-iteration context — posed template, monocular front-facing
//!   correspondences (§3.3.1, Fig. 3.9–3.10) with IRLS weights, and the model→data push
//!   constraints ([`M2dMode`]: the model rendered from the sensor camera by tiled CPU ray
//!   casting, §3.3.2, or the projected sphere centers of §3.6);
//! - [`FootpointJacobian`]: exact skeleton Jacobians of surface points (Eq. 3.7 through the
//!   sphere weights of Eq. 3.1), including multi-bone elements;
//! - [`terms`]: [`terms::D2m`] (Eq. 3.4), [`terms::M2d`] (Eq. 3.5), [`terms::Collision`]; the
//!   pose prior, joint limits and temporal terms are the shared ones of
//!   [`hand_model::solver::terms`];
//! - [`Tracker`]: warm start, 1 rigid + 7 LM iterations with the §3.6 weights
//!   ([`TrackerConfig`]), loss detection and re-initialization
//!   ([`hand_model::solver::FrameLoop`]), one DESIGN.md record per frame;
//! - [`synthetic`]: frames rendered from a posed template for tests and benchmarks.
//!
//! # Example
//! ```
//! use hand_model::solver::PcaPrior;
//! use hand_model::spheremesh::default_right_hand;
//! use hmodel_spheremesh::{Tracker, TrackerConfig};
//! use sensor_io::preprocess::PreprocessedFrame;
//!
//! let template = default_right_hand();
//! let prior = PcaPrior::project_default();
//! let mut tracker = Tracker::new(&template, TrackerConfig::default(), Some(&prior)).unwrap();
//! // A frame without a hand keeps a valid pose and is flagged.
//! let record = tracker.track(&PreprocessedFrame::default(), 0, 0.0);
//! assert_eq!(record.flags, ["no_hand"]);
//! assert!(record.is_finite() && record.keypoints.len() == 21);
//! ```

mod context;
mod jacobian;
pub mod synthetic;
pub mod terms;
#[cfg(test)]
mod tests;
mod tracker;

pub use context::{intrinsics, CorrespondenceCallback, M2dMode, SilhouettePush, TrackingCtx};
pub use jacobian::{FootpointJacobian, MAX_ELEMENT_DOFS};
pub use tracker::{EnabledTerms, FrontFacingView, Tracker, TrackerConfig, TrackerError};
