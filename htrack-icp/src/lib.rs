//! # htrack-icp — robust articulated ICP with a cylinder model (thesis Ch. 2)
//!
//! The tracker of Tagliasacchi et al. 2015 (thesis Ch. 2) on the cylinder model and kinematics
//! of `hand-model`, solved by the shared Levenberg–Marquardt solver (Eq. 2.11) with a
//! rigid-first iteration.
//!
//! - [`TrackingCtx`]: the per-iteration context (posed model, sensor points, front-facing
//!   correspondences of §2.3.1, IRLS weights of §2.7.4, the model rendered from the sensor
//!   camera for §2.3.1 "2D correspondences" and the sensor silhouette's distance transform in
//!   [`SensorView`]), refreshed by [`CorrespondenceCallback`];
//! - [`terms::E3d`]: the point cloud alignment term (Eq. 2.2) as point-to-plane rows with ℓ1
//!   IRLS weights ([`IrlsParams`]);
//! - [`terms::E2d`]: the silhouette term (Eq. 2.3): every rendered pixel outside the sensor
//!   silhouette is pushed toward its nearest silhouette pixel, two pixel rows with the
//!   projection Jacobian of §2.7.2; the rendering is
//!   [`hand_model::cylinder::CylinderRaster`] (exact ray casting of the segments);
//! - [`Tracker`]: the per-frame loop of §2.4 — warm start from the previous frame, 1 rigid + 7
//!   full LM iterations over the enabled terms ([`TrackerConfig`], [`EnabledTerms`]), temporal
//!   history, loss detection and multi-hypothesis re-initialization ([`LossParams`]), one
//!   DESIGN.md record per frame (`hands track`);
//! - [`synthetic`]: ray-marched point clouds of the posed model for tests.
//!
//! Beyond the thesis: on frames whose measured depth noise is ≥ 1.5 mm
//! ([`TrackerConfig::ray_gate`], `ray_gate_noise`; `hands track --ray-gate`) the points register
//! where their camera rays enter the model ([`TrackingCtx::set_ray_gate`]), as in the sphere-mesh
//! tracker: the front-facing closest points are biased under depth noise, the entries are not,
//! and they come from the silhouette rendering extended to the points' pixels.
//! Above σ̂ = 5 mm the entry may slide 1.5 σ̂ from the closest point instead of 7.5 mm
//! ([`TrackerConfig::ray_slide_for`]), and the loss criterion's distances grow to σ̂ and
//! 2.5 σ̂ ([`hand_model::solver::LossParams::for_noise`]). Measured in session 24 (`hands
//! track`, default hand, 240 frames, Gaussian depth noise added, mean keypoint error):
//! teaser σ = 7 mm 2.74 → 1.88, σ = 10 mm 7.34 → 2.65; occlusion σ = 10 mm 17.69 → 5.41 mm;
//! the ToF teaser and occlusion unchanged (1.85, 2.26 mm).
//!
//! Re-initialization (beyond the thesis, session 26): when the best-scoring palm-on start (or
//! the pose tracked so far) leaves more than a quarter of the silhouette's area covered by the
//! model outside it, edge-on placements are tried as backups ([`DEFAULT_PLACEMENT_OUTSIDE`]). A hand first seen edge-on was
//! otherwise placed palm-on and tracked 64–71 mm off (ToF occlusion motion from a cold start).
//! Since session 38 every placement is solved with and without the rigid-only first iteration
//! of Fig. 2.17, which on a fist tilted the placed open palm to fit the curled fingers
//! (`hand_model::solver::FrameLoop`'s `place`; the 74 ToF cold starts 295.35 → 262.69 mm).
//!
//! The priors (joint limits, damping, temporal, PCA pose prior) are the shared terms of
//! [`hand_model::solver::terms`], which run on [`TrackingCtx`] through
//! [`hand_model::solver::PoseContext`].
//!
//! The kinematic and wrist priors of §2.3.2: [`terms::Collision`] (E_collision, Eq. 2.7: the
//! penetration of non-adjacent finger segments, exact Jacobian, global columns zero) and
//! [`terms::Wrist`] (E_wrist, Eq. 2.4: the projected wrist keypoint on the image line of the
//! wristband axis). [`hand_model::cylinder::CylinderModel::from_sphere_mesh`] gives the cylinder
//! model of a sphere-mesh subject, whose keypoints coincide with the synthetic ground truth
//! ([`hand_model::cylinder::CylinderModel::from_sphere_mesh_with_wrist`] adds a wrist segment,
//! what the tracker uses on synthetic sequences).
//!
//! # Example
//! ```
//! use hand_model::cylinder::default_right_hand_cylinders;
//! use hand_model::solver::PcaPrior;
//! use htrack_icp::{Tracker, TrackerConfig};
//! use sensor_io::preprocess::PreprocessedFrame;
//!
//! let model = default_right_hand_cylinders();
//! let prior = PcaPrior::project_default();
//! let mut tracker = Tracker::new(&model, TrackerConfig::default(), Some(&prior)).unwrap();
//! // A frame without a hand keeps a valid pose and is flagged.
//! let record = tracker.track(&PreprocessedFrame::default(), 0, 0.0);
//! assert_eq!(record.flags, ["no_hand"]);
//! assert!(record.is_finite() && record.keypoints.len() == 21);
//! ```

mod context;
pub mod synthetic;
pub mod terms;
mod tracker;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_e2d;
#[cfg(test)]
mod tests_placement;
#[cfg(test)]
mod tests_ray;

pub use context::{CorrespondenceCallback, TrackingCtx, DEFAULT_RAY_SLIDE};
pub use hand_model::solver::IrlsParams;
pub use hand_model::solver::{FrameStats, LossParams};
pub use sensor_io::SensorView;
pub use tracker::{EnabledTerms, Tracker, TrackerConfig, TrackerError, DEFAULT_PLACEMENT_OUTSIDE};
