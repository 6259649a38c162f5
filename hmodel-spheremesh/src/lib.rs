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
//! - Beyond the thesis, on noisy data: along-ray correspondences ([`TrackerConfig::ray_gate`],
//!   `hands track --ray-gate 20|off`). A depth sensor's noise moves a point along its camera
//!   ray, so a point whose ray enters the model within the gate (20 mm) is registered at that
//!   entry, point-to-plane (the residual is then linear in the noise and zero-mean at the true
//!   model); the closest point of a noisy point is biased outward on curved parts (≈ σ² sin²φ /
//!   2r on a cylinder of radius r at viewing angle φ) and the front-facing rule pulls the
//!   points behind a silhouette inward. Measured on every frame
//!   (`eval/tests/ch3_acceptance.rs`, teaser, 200 frames, true template, mean keypoint error,
//!   closest points → along rays): ToF 1.512 → 0.910 mm (0.60×; 0.995 with the 5 mm slide
//!   limit of sessions 16–17, 0.864 without the limit below), structured light 0.325 → 0.321
//!   mm, noise-free 0.178 → 0.178 mm (0.183 with 5 mm).
//!   - The entry must lie within 7.5 mm of the point's closest point
//!     ([`TrackerConfig::ray_slide`], [`DEFAULT_RAY_SLIDE`]): a ray that first enters another
//!     part of the model (a finger the pose put in front of the palm's points) otherwise pulls
//!     that part onto data of the one behind it. Without the limit, `hands track` from the
//!     default template lost the hand on a structured-light `occlusion` sequence (mean keypoint
//!     error 7.9 → 18.1 mm, with online calibration 1.8 → 15.5 mm); with it 7.9 / 1.8 mm (5 mm
//!     until session 18; 7.5 mm tracks ToF sequences slightly better, see
//!     [`DEFAULT_RAY_SLIDE`]). Requiring the entry on the closest point's element instead lost
//!     most of the gain (mixing the two rules at the elements' junctions biases again).
//!   - The rays are rendered before any closest point is sought, and a point whose entry lies
//!     within half the slide of it is registered there at once: its closest point, whatever
//!     it is, lies within the slide of the entry (triangle inequality), so the search is
//!     skipped ([`hand_model::query::SphereMeshGeometry::project_points_coherent_skipping`]).
//!     Under ToF noise ≈ 89 % of the points are settled so after a frame's first iteration,
//!     and the closest points cost 3.86 → 2.19 ms a frame (`hands bench`, ToF teaser, the
//!     whole frame 11.45 → 9.88 ms; online calibration 10.78 → 9.49 ms). Only a point whose
//!     closest point is a front-facing substitute (a point behind a finger's middle) can be
//!     registered differently than before (at its entry, where the substitute lay more than
//!     the slide away): the 74 ToF cold starts track as before (152.60 → 152.57 mm summed;
//!     the library's 16 ToF motions 20.01 → 20.02 mm).
//!   - Above σ̂ = 5 mm the slide grows as 1.5 σ̂ ([`TrackerConfig::ray_slide_for`]; 7.5 mm was
//!     chosen at the ToF model's σ̂ ≈ 5 mm), and the loss criterion's distances as σ̂ and 2.5 σ̂
//!     ([`hand_model::solver::LossParams::for_noise`]; a hand at its true pose is ≈ 0.62 σ from
//!     its points, so from σ ≈ 10 mm every frame failed the fixed 6 mm and the tracker
//!     re-initialized every third frame). With the fixed slide, the points that the noise
//!     put behind a finger's axis kept their silhouette substitutes while those in front pulled
//!     the finger toward the camera (pinky tip −4.6 mm in depth at σ = 10 mm). Measured in
//!     session 24 with `hands track` on library sequences with Gaussian depth noise added (240
//!     frames default hand, 480 frames random subjects; mean keypoint error, before → after,
//!     this tracker / online calibration):
//!
//!     | σ | teaser, default hand | occlusion, default hand | teaser, random subject |
//!     |---|---|---|---|
//!     | 5 mm | 1.01 → 1.00 / 1.29 → 1.29 | 1.48 → 1.47 / 1.73 → 1.73 | 5.21 → 5.21 / 1.52 → 1.51 |
//!     | 7 mm | 1.53 → 1.24 / 1.91 → 1.45 | 2.35 → 1.91 / 3.44 → 2.22 | 5.18 → 5.16 / 2.03 → 1.77 |
//!     | 10 mm | 3.05 → 1.78 / 10.55 → 2.51 | 5.84 → 4.20 / 6.67 → 6.57 | 6.68 → 5.64 / 15.92 → 2.88 |
//!
//!     On ToF over a random subject (`random`, seed 4), 10 mm added: 9.49 → 7.85 / 12.93 →
//!     4.57 mm. The 16 ToF library sequences and ten ToF random-subject runs track as before
//!     (σ̂ ≤ 5.2 mm: bit for bit except the teaser, online 1.11 → 1.10 mm, this tracker
//!     0.97 mm both). A slide of 3 σ̂ tracked heavy noise better still (σ = 10 mm: occlusion
//!     1.86 / 2.48 mm) but made online calibration worse on 15 of the 16 ToF sequences (teaser
//!     1.11 → 1.29 mm at 15 mm), and widening the 20 mm gate with the noise too was mixed
//!     (occlusion 4.23 → 6.00 mm).
//!   - They run on the frames whose measured depth noise ([`sensor_io::preprocess::NoiseMonitor`])
//!     is at least 1.5 mm ([`TrackerConfig::ray_gate_noise`]): on exact or quantized depth
//!     they gain nothing (0.178 → 0.178 mm above) and cost about four times the closest
//!     points' correspondence time. The pixels of the frame's points are rendered once per iteration
//!     ([`hand_model::render::DepthRenderer::render_hits`], per-element footprints) rather than
//!     cast one ray per point against all elements: 1.1 against 2.1 ms per context update for
//!     2045 points (the closest points alone: 0.3 ms). Per frame on the ToF teaser (`hands
//!     track`, default template, quiet machine, median of 240 frames, two runs each): 22 →
//!     29–37 ms, with online calibration 18 → 30 ms — still above 30 frames/s on one core.
//!   - Measured from the default template with `hands track` (240 frames, subject 21, mean
//!     keypoint error, thesis' rule → default): ToF teaser 3.80 → 3.70 mm (online calibration
//!     2.72 → 1.75), ToF fist 3.91 → 3.77 (3.07 → 2.45), ToF `rotation_fast` 5.74 → 5.40 (4.57
//!     → 4.08); noise-free and structured-light sequences unchanged (the gate stays off).
//!     With the 7.5 mm slide: teaser 3.69 (1.57), fist 3.77 (2.38), `rotation_fast` 5.19
//!     (4.12).
//! - Priors: τ_pose = 1e4 on the project's PCA prior, joint limits 1e7, htrack's temporal
//!   weights (3, 3; hmodel used 0.05) and uniform damping λ = 100 (shared with Ch. 2).
//!   τ_pose measured in session 24 (`hands track --model spheremesh`, default hand, 240
//!   frames, seed 7, mean keypoint error, τ_pose 1e4 / 3e3 / 1e3 / no prior). Under ToF the
//!   prior pays on the motions that real hands make: occlusion 1.65 / 2.07 / 2.75 / 3.27 mm,
//!   rotating fist 1.65 / 1.69 / – / 2.51, pinch 0.79 / 0.84 / – / 1.04. Each of the 16
//!   motions but one is best at 1e4 or within 0.03 mm of it. The exception is `random`, whose
//!   joints move independently: 1.40 / 1.09 / 1.04 / 1.09. Noise-free the same holds on 14
//!   (fist 0.33 / 0.41 / – / 0.75), against `random` (0.28 / 0.19 / – / 0.19) and the
//!   rotating fist (0.71 / 0.60 / – / 0.66). The prior's energy does
//!   not tell the two kinds of motion apart: the teaser's 90th percentile, 7.5·10³, lies above
//!   `random`'s median, 5.9·10³. So a robust (saturating) prior would give up the one to win
//!   the other.
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
    intrinsics, CorrespondenceCallback, M2dMode, SilhouettePush, TrackingCtx, UpdateTiming,
    DEFAULT_RAY_SLIDE,
};
pub use jacobian::{FootpointJacobian, MAX_ELEMENT_DOFS};
pub use tracker::{EnabledTerms, FrontFacingView, Tracker, TrackerConfig, TrackerError};
