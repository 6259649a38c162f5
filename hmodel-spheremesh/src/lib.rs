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
//! # Choices where the thesis is silent or the originals differ
//! - E_d2m is not divided by `|D|` (as in hmodel's code), and its ℓ1 norm is IRLS with htrack's
//!   effective gain 12.25 ([`hand_model::solver::IrlsParams`]); the residual is along `p − q`
//!   (hmodel), which for front-facing substitutes pulls the silhouette point toward the data.
//! - The front-facing test uses the sensor's pinhole ([`FrontFacingView::Perspective`], exact
//!   viewing rays); the thesis' orthographic camera is [`FrontFacingView::Orthographic`]. The
//!   object-space silhouette is orthographic either way (§3.3.1).
//! - E_m2d renders every pixel outside the sensor silhouette at the sensor resolution (QVGA);
//!   pixels are found through conservative per-element screen footprints, so the cost follows
//!   the part of the model outside the silhouette ([`hand_model::render::DepthRenderer::render_hits`]);
//!   footprint rows that keep no pixel near the element are skipped before their span.
//! - The closest points of every iteration start from each point's previous element and margin
//!   ([`hand_model::query::Coherence`]), carried across frames by pixel when the frame names its
//!   points' pixels ([`TrackingCtx::set_frame`]): bit for bit the correspondences of a fresh
//!   search, most of them without one (`honline-calib/benches/online.rs` has the timings).
//! - Collisions: finger pills only, rest-pose overlaps tolerated, hmodel's under-relaxation
//!   `fraction` left out (it makes the rows inconsistent with the energy; LM damping limits the
//!   step instead).
//! - Beyond the thesis, off by default: along-ray correspondences
//!   ([`TrackerConfig::ray_gate`], `hands track --ray-gate 20`). A depth sensor's noise moves a
//!   point along its camera ray, so a point whose ray enters the model within the gate is
//!   registered at that entry, point-to-plane (the residual is then linear in the noise and
//!   zero-mean at the true model); the closest point of a noisy point is biased outward on
//!   curved parts (≈ σ² sin²φ / 2r on a cylinder of radius r at viewing angle φ) and the
//!   front-facing rule pulls the points behind a silhouette inward. Measured
//!   (`eval/tests/ch3_acceptance.rs`, teaser, 200 frames, true template, mean keypoint error):
//!   ToF 1.512 → 0.864 mm (0.57×), structured light 0.325 → 0.316 mm, noise-free 0.178 →
//!   0.174 mm; on `eval::online`'s calibration motion (300 frames, ToF, subjects 7 / 8, last
//!   third) 2.56 → 1.81 and 2.20 → 1.62 mm. Requiring the entry on the closest point's
//!   element (a guard against misassociation) lost most of the gain (2.09 / 1.99 mm): mixing
//!   the two rules at the elements' junctions biases again. Its cost is why it is not the
//!   default: one ray per point and iteration against the prepared elements
//!   ([`hand_model::render::raycast::cast_ray_prepared`], seeded with the point's nearest
//!   element) made the online bench's correspondences ≈ 4× slower (per-frame minima 4.1 →
//!   17.9 ms, load ≈ 2), against the ≥ 200 frames/s goal of the online calibrator.
//! - Priors: τ_pose = 1e4 on the project's PCA prior, joint limits 1e7, htrack's temporal
//!   weights (3, 3; hmodel used 0.05) and uniform damping λ = 100 (shared with Ch. 2).
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

pub mod calibration;
mod context;
mod jacobian;
pub mod synthetic;
pub mod terms;
#[cfg(test)]
mod tests;
mod tracker;

pub use context::{
    intrinsics, CorrespondenceCallback, M2dMode, SilhouettePush, TrackingCtx, DEFAULT_RAY_SLIDE,
};
pub use jacobian::{FootpointJacobian, MAX_ELEMENT_DOFS};
pub use tracker::{EnabledTerms, FrontFacingView, Tracker, TrackerConfig, TrackerError};
