//! The online calibrator: per frame, the joint pose+shape LM (Eq. 4.2–4.4), the Laplace
//! approximation of its posterior (Eq. 4.5–4.6) and the estimator's update.

use std::time::Instant;

use hand_model::kinematics::Pose;
use hand_model::solver::terms::Temporal;
use hand_model::solver::{
    sphere_mesh_points, EnergyTerm, FrameStats, IterInfo, LmCallback, LmError, LmSolver,
    LmWorkspace, NormalEquations, PcaPrior, ScoreTrigger, TermError, CONFIRM_FRAMES,
};
use hand_model::spheremesh::{PosedSphereMesh, ShapeBasis, SphereMeshTemplate};
use hand_model::ModelError;
use hmodel_spheremesh::{TrackerConfig, TrackingCtx};
use nalgebra::{DMatrix, DVector, Vector3};
use sensor_io::preprocess::{noise_scale, NoiseMonitor, PreprocessedFrame};
use sensor_io::record::HandRecord;
use serde::{Deserialize, Serialize};

use crate::filter::{marginal_certainty_into, Estimator, InfoScratch, ShapeBelief};
use crate::frame::FrameProblem;
use crate::gate::Gate;
use crate::shape::ShapeSubset;
use crate::terms::{IekfPrior, Layout, OnlineCtx};
use crate::watch::Shadow;

/// Settings of the online calibration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OnlineConfig {
    /// The estimator (default: the joint cumulative IEKF).
    pub estimator: Estimator,
    /// The β entries in the state (default [`ShapeSubset::All`]; see its docs).
    pub subset: ShapeSubset,
    /// The tracker's terms, weights and LM schedule (default: the Ch. 3 tracker's terms with
    /// honline's schedule, [`honline_schedule`]; β moves on the non-rigid iterations).
    pub tracker: TrackerConfig,
    /// ω_shape-space (Eq. 4.14) per mm² for lengths and positions. Default 2.5, half honline's
    /// `weight_uniform` (5, ANCHOR-FACTS §7.4). The term sits in every frame's solve and its
    /// pull is not absorbed into the belief, so the estimate's fixed point is the per-frame
    /// balance of data and belief against this prior: a phalanx the data sees weakly stays
    /// biased toward the template in proportion to ω over the belief's information. Measured
    /// on the Fig. 4.7 draws (`eval/tests/ch4_acceptance.rs`, 15 draws, 20 s, noise-free, with
    /// the earlier measurement weight 1/20), mean E_β of the IEKF at σ = 0.3: ω = 10 → 1.16 mm,
    /// 5 → 0.91, 1 → 0.72, 0.1 → 0.74; but ω ≤ 1 lets noise and mis-tracked frames through
    /// (ToF σ = 0.1, one draw: 2.4 mm at ω = 1 against 1.6 at ω = 5; the per-frame estimator
    /// diverges). With the measurement weight 1/2 and every entry estimated, tracking random
    /// subjects 7 / 8 / 9 noise-free (last-third keypoint error over the true template's):
    /// ω = 5 → 1.11 / 1.13 / 0.90, 2.5 → 1.08 / 1.09 / 0.83; ω = 1 with the radii's at 2
    /// diverged on subject 9 (its thumb's middle phalanx 8 mm long, ratio 4.6): the radii's
    /// prior is what holds a thumb whose radii and lengths trade off.
    pub shape_prior: f64,
    /// ω_shape-space per mm² for radii.
    pub radius_prior: f64,
    /// Weight of the β bounds (per mm²).
    pub limits: f64,
    /// Weight of the shape-validity barriers (Eq. 4.15, per mm²).
    pub valid: f64,
    /// LM damping of β per mm² on every non-rigid iteration (default 300; 10 until session
    /// 30): a trust region on each frame's shape step. An entry the data see well carries
    /// thousands per mm² of information and steps almost freely; one that a frame barely shows
    /// (the phalanges of a fist, a palm's width along the camera's rays) cannot jump. While the
    /// belief is still vague (the [`Self::measurement_ramp`]) nothing else held such an entry:
    /// on an edge-on fist placed at its true pose (`tests/hard_poses.rs`) the shape swung by up
    /// to 30 mm from one frame to the next and the keypoints went 20 mm off; with 300, 5 mm and
    /// 1.7 mm. Measured 10 → 300 (with [`Self::outside_gate`] at 3):
    /// - `hands track --calibrate online`, cold starts (the library's default-hand motions and
    ///   random subjects cut at frames 45–250, mean keypoint error summed): 74 ToF cuts 253.86
    ///   → 233.83 mm (the Ch. 3 tracker alone: 236.49), 64 noise-free cuts 175.39 → 156.49 mm;
    /// - the library's 34 sequences from frame 0: 253.18 → 248.27 mm;
    /// - the random subjects 7–12 (last-third keypoint error over the true template's),
    ///   noise-free 1.09 / 1.12 / 0.85 / 1.25 / 1.08 / 1.12 → 1.07 / 1.09 / 0.83 / 1.18 / 1.06
    ///   / 1.11, ToF 1.31 / 1.09 / 1.04 / 1.36 / 1.13 / 1.35 → 1.31 / 1.10 / 1.05 / 1.36 / 1.13
    ///   / 1.36;
    /// - Fig. 4.7's hardest draws (20 s, noise-free; E_β at the end): σ = 0.3 draw 12 0.190 →
    ///   0.188 mm, σ = 0.4 draw 5 0.990 → 0.957 mm.
    ///
    /// 100 and 1000 did worse (without the gate): the ToF cuts 241.38 mm at 100; at 1000 the
    /// slow steps let a phalanx drift for longer and random subject 10 went to 1.38 noise-free.
    pub beta_damping: f64,
    /// The per-frame data information is scaled by this before it enters the estimate: the
    /// rows of consecutive frames are far from independent (the same surface seen again), so
    /// counting each frame's information in full makes the estimate overconfident after a few
    /// frames. Default 1/2; honline took a measurement every 20th frame (1/20, the default
    /// until session 14). The belief's information is what outweighs the shape-space prior's
    /// pull toward the template in each frame's solve, so too small a weight leaves the
    /// estimate at that per-frame balance. Measured (`eval/tests/ch4_acceptance.rs` tracking
    /// scenario, 300 frames, last-third keypoint error over the true template's, every entry
    /// estimated, no ramp): noise-free subject 7 1/20 → 1.62, 1/5 → 1.17, 1/2 → 1.11 (with
    /// ω_shape-space 5); started at the truth with the null-space subset, 1/100 → 2.83, 1/20 →
    /// 1.68, 1/5 → 1.23, 1 → 1.27. Under ToF (subjects 7 / 8, ω 2.5) 1/20 → 1.32 / 1.25, 1/2 →
    /// 1.33 / 1.18.
    pub measurement_weight: f64,
    /// Measurements over which the weight grows linearly to [`Self::measurement_weight`]
    /// (the n-th solved frame since the last [`OnlineCalibrator::set_shape`] counts
    /// `min(n / ramp, 1)` of it). The first frames are tracked with the template, which may be
    /// far off, and linearized there: at full weight their information locks a wrong shape in
    /// before the tracking has settled. Measured on the Fig. 4.7 draws (20 s, noise-free): σ =
    /// 0.3 draw 12 (a ring proximal phalanx started 24 mm short) ends at E_β 1.69 mm with no
    /// ramp — the phalanx still 17 mm short, certain — and 0.20 mm with 50 frames; σ = 0.4 draw
    /// 5 1.10 → 0.99 mm (100 frames: 1.53, 300: 0.96). Tracking subjects 7 / 8 (noise-free,
    /// last-third keypoints over the true template's) 1.08 / 1.09 → 1.09 / 1.12 (100 frames:
    /// 1.12 / 1.12; 300: 1.14 / 1.18). Default 50 (≈ 1.7 s at 30 Hz); 1 turns it off.
    pub measurement_ramp: usize,
    /// Information of the initial belief (per mm², honline: 0.001).
    pub initial_information: f64,
    /// Frames with fewer points are not solved (flag `no_hand`): the estimate is kept.
    pub min_points: usize,
    /// Express ω_shape-space (both weights) per unit of the data's noise: times
    /// `max(σ̂ / 1 mm, 1)^p` ([`Self::noise_prior_exponent`]), σ̂ the depth noise measured on
    /// the hand every `NOISE_INTERVAL` (15) frames (`sensor_io::preprocess::depth_noise`,
    /// smoothed). The data terms count millimetres as if the noise were 1 mm, so noisy frames
    /// outvote the prior and the estimate follows the noise; noise-free data (σ̂ < 1 mm) keep
    /// ω as given. Measured with p = 2 (`eval/tests/ch4_acceptance.rs` tracking scenario, ToF,
    /// σ̂ ≈ 5 mm, subjects 7 / 8 / 9): E_β at the end 1.44 / 1.38 / 1.37 mm and last-third
    /// keypoints 1.41 / 1.43 / 1.49× the true template's without; 0.72 / 0.98 / 0.92 mm and
    /// 1.30 / 1.28 / 1.30× with.
    pub noise_scaled_prior: bool,
    /// The exponent `p` of [`Self::noise_scaled_prior`]'s factor (default 1.5; 2 until session
    /// 20). Least-squares data outvote a prior by σ̂², but the d2m term is ℓ1-like under noise
    /// (IRLS weight ∝ 1/√|r|: its curvature falls as 1/σ̂, its Laplace likelihood wants a
    /// further 1/σ̂), which asks for σ̂¹, while the m2d and prior terms are least squares.
    /// Measured under ToF (σ̂ ≈ 5 mm; with [`Self::innovation_gate`] at 6), p = 2 / 1.5 / 1:
    /// - the random subjects 7–12 (calibration motion, 300 frames, last-third keypoint
    ///   error over the true template's): 1.40 / 1.08 / 1.08 / 1.44 / 1.19 / 1.44 → 1.31 / 1.09
    ///   / 1.04 / 1.36 / 1.12 / 1.36 → 1.25 / 1.13 / 1.04 / 1.33 / 1.10 / 1.35;
    /// - `hands track --calibrate online` on the library's nine 240-frame ToF sequences, sum of
    ///   mean keypoint errors 24.69 → 23.56 → 24.57 mm (p = 1: `crossing` 3.91 → 4.48,
    ///   `rotation_fast` 4.08 → 4.69, fist 2.38 → 2.68; p = 1.5 within +0.09 mm of p = 2 on
    ///   every sequence, `random` 3.65 → 2.71, `calibration` 2.60 → 2.40, flexion 2.07 →
    ///   1.82);
    /// - noise-free and structured-light data: unchanged (σ̂ < 1 mm).
    pub noise_prior_exponent: f64,
    /// Innovation gate of the joint estimator (beyond the thesis; 0 turns it off; default 6):
    /// a frame whose E_iekf after the solve (Eq. 4.11, the belief's Mahalanobis penalty on the
    /// step β took) exceeds this multiple of the median E_iekf of the last
    /// 60 accepted frames keeps the previous β and adds no information
    /// (flag `shape_rejected`); its pose is kept. A mis-tracked frame (fingers crossing or
    /// hidden, a pose the LM did not reach) otherwise fits the shape to the wrong pose: on the
    /// ToF `crossing` sequence without the noise-scaled prior, E_iekf rose to 30× its median
    /// over frames 63–73 while the thumb's proximal phalanx went 17 mm short. After
    /// 60 rejections in a row the next frame is accepted, so a lasting
    /// change of the data is not refused forever. Measured (`hands track --calibrate online`,
    /// the library's 240-frame sequences, mean keypoint error, gate off → 6):
    /// - noise-free: teaser 0.42 → 0.47 mm, fist 1.79 → 1.00, occlusion 1.31 → 1.01, pinch
    ///   1.63 → 0.64, `rotation_fast` 1.55 → 1.81; structured light: occlusion 1.77 → 1.41,
    ///   pinch 1.80 → 1.80; the seven sum 10.27 → 8.14 mm (gate 4: 7.58, but 71 of
    ///   `rotation_fast`'s frames rejected and teaser 0.51);
    /// - ToF, nine sequences: sum 24.89 → 24.69 mm (`random` 3.82 → 3.65, the others within
    ///   ±0.04), the gate firing on 0–17 frames;
    /// - the random subjects 7–12 (calibration motion, noise-free and ToF) and the
    ///   Fig. 4.7 draws of `eval/tests/ch4_acceptance.rs`: unchanged, the gate never fires.
    ///
    /// It does not make the noise-scaled prior unnecessary: without that scaling, ToF
    /// `crossing` 8.25 → 5.63 mm with the gate (3.92 with the scaling).
    pub innovation_gate: f64,
    /// Outside gate (beyond the thesis; 0 turns it off; default 3): a frame whose model lies
    /// outside the sensor silhouette over more than this multiple of the median share of the
    /// last 60 frames it let through (and over [`OUTSIDE_FLOOR`] of the silhouette's area,
    /// [`hand_model::solver::FrameStats::outside`]) keeps the previous β and adds no
    /// information (flag `shape_rejected`), as the innovation gate's frames. A finger the
    /// tracker has lost behind the others is free to grow: nothing in the data holds a hidden
    /// phalanx, and E_iekf rises too slowly to notice, frame by frame. Measured (with
    /// [`Self::beta_damping`] at 300; gate off → 3): the noise-free `occlusion` motion from its
    /// 105th frame 6.11 → 2.51 mm (a ring middle phalanx had grown 34 mm while the model's
    /// share outside rose from 0.01 to 0.13); the other 63 noise-free cold starts and all 74 ToF
    /// ones unchanged (±0.3 mm; under ToF the edges leave ≈ 0.035 outside and the gate never
    /// fires there); the library's 34 sequences 247.80 → 248.27 mm (`leave_reenter` only);
    /// random subjects 7–12 noise-free 1.07 / 1.08 / 0.83 / 1.22 / 1.07 / 1.11 → 1.07 / 1.09 /
    /// 0.83 / 1.18 / 1.06 / 1.11.
    pub outside_gate: f64,
    /// Penetration (mm) that the joint solve's collision term tolerates between two fingers
    /// beyond their rest overlap (`hmodel_spheremesh::terms::CollisionParams::tolerance`;
    /// the Ch. 3 tracker that places the hand, settles it and searches its digits keeps
    /// [`Self::tracker`]'s). Default 2 mm (session 39; 0 before: the tracker's collisions as
    /// they are).
    ///
    /// Why: in a fist the pills of neighbouring fingers overlap more than at rest (0.1–1.3 mm
    /// at the library's `fist`; real fingers pressed together flatten). The collision term
    /// pushes them apart, the pose gives way, and with the shape free the data pull the finger
    /// bases back under the fingers: on the library's noise-free `fist` cut from frame 45,
    /// online calibration started at the true shape walked `pinky_base_x` 27 → 17 mm and
    /// `index_middle_length` 23 → 29 mm (mean keypoint error 2.06 mm against 0.47 for the Ch. 3
    /// tracker; 0.52 mm at 2 mm tolerance; `tests/hard_poses.rs`). On another hand's
    /// `rotating_fist` (ToF, random subject 50) the estimate started at the subject's own shape
    /// drifted the same way (index proximal phalanx 4–6 mm short): 5.18 mm against 2.20 for
    /// the Ch. 3 tracker on that shape; from the default template 5.64 → 2.64 mm at 2 mm.
    ///
    /// Measured in session 39 (`hands track --calibrate online`, mean keypoint error summed;
    /// better / worse by more than 0.05 mm), 0 → 2 mm, and then with the digit search's
    /// trigger holding a lasting bad fit out of its window (`hand_model::solver::ScoreTrigger`)
    /// and keeping the fits from before a loss after the search mends it:
    /// - the library's 16 motions from frame 0, ToF: 21.43 → 19.07 mm (10 / 0; `crossing` 3.92
    ///   → 3.07) → 18.48 (10 / 0 against 0 mm; `axis_interaction` 2.36 → 1.23);
    /// - structured light: 18.40 → 14.87 mm (9 / 0) → 12.27 (9 / 0; `crossing` 6.34 → 2.99,
    ///   `fist` 1.01 → 0.55);
    /// - the same motions by random subjects 41–56, ToF: 37.16 → 33.80 mm (8 / 3;
    ///   `rotating_fist` 5.66 → 2.64, `crossing` 5.11 → 2.66, `fist` 2.56 → 1.49, but
    ///   `axis_interaction` 3.51 → 8.34: crossed fingers lost over frames 465–485 and not
    ///   found again, the trigger having taken the lost fit as its normal) → 27.55 (9 / 2;
    ///   `axis_interaction` 2.10; `pinch` 1.18 → 1.23 and `rotation_fast` 1.53 → 1.61 worse);
    /// - 74 cold starts of 90 frames: ToF 141.28 → 135.19 mm (20 / 1) → 135.19, noise-free
    ///   96.04 → 83.29 (22 / 2);
    /// - the random subjects 7–12 (`eval/tests/ch4_acceptance.rs`, last-third keypoint
    ///   error over the true template's): noise-free 1.07 / 1.09 / 0.83 / 1.18 / 1.06 / 1.11 →
    ///   1.07 / 1.10 / 0.85 / 1.17 / 1.06 / 1.05, ToF 1.59 / 1.18 / 1.03 / 1.67 / 1.24 / 1.45 →
    ///   1.60 / 1.18 / 1.03 / 1.65 / 1.23 / 1.41 (both unchanged by the trigger).
    ///
    /// Session 35 measured the same switch before the placements were solved both ways
    /// (`hand_model::solver::FrameLoop`) and kept 0: the cold starts gained then too, but fast
    /// finger crossings lost (both settings lost the crossed index and middle finger for ≈ 60
    /// frames, and with the tolerance they passed through each other and stayed exchanged for
    /// ≈ 150 frames more: `crossing` ToF 4.07 → 5.92, structured light 1.72 → 5.56), and
    /// `axis_interaction` ToF 2.50 → 8.29. Tolerating only nearly parallel pills lost the
    /// fist's gain (1.92–2.48 mm); a tolerance that fades for deep penetration
    /// (`(p² − t²)/p`) kept the fist (0.52 mm) but not the structured-light crossing (5.56 mm);
    /// refusing the shape step on frames in contact (collision energy above 0.3 / 1 mm of
    /// penetration) refused 545 / 200 of the library's 2 626 ToF teaser frames and fixed one
    /// fist cut of two.
    pub collision_tolerance: f64,
    /// On how many of the last iterations of each frame's joint solve (and its evaluation after
    /// the last update) the correspondences are registered along the camera rays, on the frames
    /// where [`Self::tracker`]'s `ray_gate` runs (noisy depth); the earlier iterations take the
    /// thesis' closest points. 0: along the rays on every iteration, as the Ch. 3 tracker
    /// (default 1; the Ch. 3 tracker that places the hand and searches its digits keeps its
    /// own rule).
    ///
    /// Why (beyond the thesis, session 37): registered along the rays, a point is pulled onto the
    /// part of the model its ray enters first, and while a frame's solve is still converging
    /// that is often the wrong part (a finger in front of another, a shape still far off). The
    /// closest points converge the pose; the along-ray registration on the last iteration then
    /// takes the closest points' noise bias out of the final pose and out of the Laplace
    /// measurement (Eq. 4.5), which is linearized there. Measured under ToF (`hands track
    /// --calibrate online`, mean keypoint error summed; every iteration → the last one):
    /// - the library's 16 motions from frame 0: 23.15 → 21.39 mm (15 better, none worse by
    ///   more than 0.05 mm); the same motions performed by random subjects (seeds 41–56): 47.16
    ///   → 42.06 mm (12 better, none worse);
    /// - the random subjects 7–12 (`eval/tests/ch4_acceptance.rs`, last-third keypoint
    ///   error over the true template's): 1.56 / 1.24 / 1.10 / 1.78 / 1.21 / 1.56 → 1.60 / 1.19
    ///   / 1.05 / 1.69 / 1.23 / 1.48, E_β at the end 0.31–0.41 → 0.29–0.37 mm;
    /// - the 74 ToF cold starts (the library's motions and random subjects cut at frames
    ///   45–250, 90 frames each): 154.96 → 145.27 mm (55 better, 3 worse);
    /// - the frame: 9.1 → 6.6 ms (`hands bench --model online`, ToF teaser).
    ///
    /// On the last two: the library 21.94 mm, the random subjects' motions 44.89 mm (`crossing`
    /// 5.11 → 9.47). On no iteration (closest points only): the library 21.11 mm and the random
    /// subjects' motions 34.03 mm (a fragile `axis_interaction` 8.14 → 2.27), 6.0 ms a frame,
    /// but the shape came out worse (E_β 0.50–0.55 mm; ratios 1.73 / 1.28 / 1.08 / 1.91 / 1.35
    /// / 1.53) and the cold starts too (158.76 mm, 41 worse). The rule is the calibrator's alone:
    /// the Ch. 3 tracker with a fixed shape lost by it (its 74 ToF cold starts 137.39 → 154.08 mm,
    /// 54 worse), so a shape still moving is what the early along-ray registrations mislead.
    pub ray_last_iterations: usize,
    /// On the iterations that [`Self::ray_last_iterations`] leaves to the closest points (noisy
    /// depth only), register every this many-th point (each weighing as many; 0 or 1: every
    /// point; `hmodel_spheremesh::TrackingCtx::set_point_stride`), each iteration the next share
    /// of them (`set_point_phase`: the points whose index is the iteration modulo the stride), so
    /// that over those iterations every point pulls on the pose. Those iterations only bring the
    /// pose near the data; the last one registers every point along its ray.
    ///
    /// Default 3 (session 38; 1 before): ≈ 0.75 of the ToF frame (≈ 5 ms: 200 frames/s at the
    /// margin) at the accuracy of every point. Measured under ToF, 1 → 3: the frame 6.4 / 6.7
    /// → 5.0 / 5.1 ms (`hands track`, the library's ToF teaser, one thread, two runs each; 4 →
    /// 4.7 / 4.8 ms, 6 → 4.5 / 4.7 ms), the library's 16 motions 21.39 → 21.43 mm (2 better,
    /// 1 worse by more than 0.05 mm), the same motions by random subjects 42.06 → 37.16 mm (4
    /// better, none worse), the 74 ToF cold starts 145.27 → 145.66 mm (7 better, 7 worse), the
    /// issue's random subjects 7–12 1.60 / 1.19 / 1.05 / 1.69 / 1.23 / 1.48 → 1.59 / 1.18 /
    /// 1.03 / 1.67 / 1.24 / 1.45. Noise-free data are untouched (no iteration registers along
    /// the rays there).
    /// - The same share on every early iteration (session 37: every point whose index is a
    ///   multiple of 3) lost accuracy — the library 22.46 mm (12 worse than every point), the
    ///   random subjects' motions 40.48, the cold starts 149.73 (48 worse) — so it was off by
    ///   default.
    /// - Stride 4: the library 21.31 mm, the random subjects' motions 39.22 (one motion worse
    ///   by more than 0.05 mm, 4 better than stride 3); stride 3 divides the default 6 early
    ///   iterations evenly.
    pub early_point_stride: usize,
}

/// The share of the silhouette's area under which [`OnlineConfig::outside_gate`] refuses no
/// frame. On exact depth a well-tracked hand leaves 0.002–0.006 of it outside (the silhouette's
/// pixel steps), so three times the median alone would refuse frames a few pixels apart; under
/// ToF noise the edges leave ≈ 0.035.
pub const OUTSIDE_FLOOR: f64 = 0.01;

/// Frames over which [`OnlineConfig::innovation_gate`] takes its median.
pub const INNOVATION_WINDOW: usize = 60;

impl Default for OnlineConfig {
    fn default() -> Self {
        Self {
            estimator: Estimator::Iekf,
            subset: ShapeSubset::All,
            tracker: honline_schedule(),
            shape_prior: 2.5,
            radius_prior: 10.0,
            limits: 1e5,
            valid: 1e3,
            beta_damping: 300.0,
            measurement_weight: 0.5,
            measurement_ramp: 50,
            initial_information: 1e-3,
            min_points: 50,
            noise_scaled_prior: true,
            noise_prior_exponent: 1.5,
            innovation_gate: 6.0,
            outside_gate: 3.0,
            collision_tolerance: 2.0,
            ray_last_iterations: 1,
            early_point_stride: 3,
        }
    }
}

impl OnlineConfig {
    /// Every weight finite and non-negative, the initial information positive (it makes the
    /// belief invertible before the first measurement).
    pub fn validate(&self) -> Result<(), OnlineError> {
        let weights = [
            ("shape_prior", self.shape_prior),
            ("radius_prior", self.radius_prior),
            ("limits", self.limits),
            ("valid", self.valid),
            ("beta_damping", self.beta_damping),
            ("measurement_weight", self.measurement_weight),
            ("innovation_gate", self.innovation_gate),
            ("outside_gate", self.outside_gate),
            ("noise_prior_exponent", self.noise_prior_exponent),
            ("collision_tolerance", self.collision_tolerance),
        ];
        if let Some((name, w)) = weights.iter().find(|(_, w)| !(w.is_finite() && *w >= 0.0)) {
            return Err(OnlineError::Config(format!(
                "{name} = {w}: must be finite and non-negative"
            )));
        }
        let h0 = self.initial_information;
        if !(h0.is_finite() && h0 > 0.0) {
            return Err(OnlineError::Config(format!(
                "initial_information = {h0}: must be finite and positive"
            )));
        }
        Ok(())
    }
}

/// The Ch. 3 tracker's settings with honline's LM schedule: 7 iterations of which the first is
/// rigid (ANCHOR-FACTS §5.1: `apps/honline_atb/main.cpp`; the benchmark: "7 iterations"),
/// where hmodel ran 8. Measured on `eval/tests/ch4_acceptance.rs` (seed 7, 300 frames): tracking
/// 1.00 → 1.01 mm noise-free and 3.33 → 3.35 mm under ToF, E_β at the end 0.674 → 0.689 and
/// 0.723 → 0.730 mm, the Fig. 4.7 CI draws within ±0.01 mm, Fig. 4.7 at σ = 0.3 (15 draws,
/// 20 s) mean E_β 0.931 → 0.928 mm and max 1.774 → 1.788 mm; the frame costs ⅞.
///
/// With the joint estimator, β's part of each non-rigid step is solved without the PCA pose
/// prior's pull on exact data
/// ([`LmOptions::decouple_aux`](hand_model::solver::LmOptions::decouple_aux)), with it on
/// noisy data: the share of the pull kept follows the measured depth noise
/// ([`OnlineConfig::noise_scaled_prior`]; see the crate docs' "Known biases" for the
/// measurements).
pub fn honline_schedule() -> TrackerConfig {
    let mut config = TrackerConfig::default();
    config.lm.iterations = 7;
    config.lm.decouple_aux = true;
    config
}

/// Why a calibrator could not be built.
#[derive(Debug, thiserror::Error)]
pub enum OnlineError {
    /// Invalid solver options.
    #[error("solver: {0}")]
    Solver(#[from] LmError),
    /// A template without the honline β basis, or a prior that does not fit it.
    #[error("model: {0}")]
    Model(#[from] ModelError),
    /// A weight of [`OnlineConfig`] that is negative or not finite.
    #[error("online calibration settings: {0}")]
    Config(String),
}

/// The output of one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct OnlineFrame {
    /// The DESIGN.md record: pose, keypoints, `shape` (the estimate β̂_n) and
    /// `shape_certainty` (the cumulative certainty), energies, timing, flags.
    pub record: HandRecord,
    /// The estimate β̂_n (all entries; the inactive ones keep the template values).
    pub beta: Vec<f64>,
    /// The per-frame mode β*_n of the joint solve.
    pub frame_beta: Vec<f64>,
    /// The cumulative certainty: the diagonal of Σ̂_n⁻¹ (per mm², 0 for inactive entries).
    pub certainty: Vec<f64>,
    /// The per-frame certainty: the diagonal of Σ*_n⁻¹ (scaled by
    /// [`OnlineConfig::measurement_weight`]; 0 when the frame was not solved).
    pub frame_certainty: Vec<f64>,
    /// The cumulative marginal certainty `1 / diag(Σ̂_n)` (Fig. 4.6; per mm², 0 for inactive
    /// entries): unlike [`OnlineFrame::certainty`] it stays low for two phalanges of a straight
    /// finger whose sum alone is known.
    pub marginal_certainty: Vec<f64>,
    /// The per-frame marginal certainty `1 / diag(Σ*_n)` (Fig. 4.6; Σ*_n⁻¹ scaled as
    /// [`OnlineFrame::frame_certainty`], with [`OnlineConfig::initial_information`] as a ridge
    /// for what the frame does not see; 0 when the frame was not solved).
    pub frame_marginal_certainty: Vec<f64>,
    /// Whether the frame was solved.
    pub solved: bool,
}

/// Reshapes the context's template when β changed and accepts only valid β steps; times the
/// reshaping and the correspondence search apart (the record's `reshape` and
/// `correspondences` stages).
struct ShapeCallback<'a> {
    problem: &'a FrameProblem,
    /// The solver's iteration count ([`hand_model::solver::LmOptions::iterations`]).
    iterations: usize,
    next: Vec<f64>,
    rejected: usize,
    reshape_us: f64,
    correspondences_us: f64,
    /// The frame's along-ray gate, and on how many last iterations it runs (0: on all;
    /// [`OnlineConfig::ray_last_iterations`]).
    ray_gate: Option<f64>,
    ray_last: usize,
    /// [`OnlineConfig::early_point_stride`].
    early_stride: usize,
    /// Whether the last refresh was an early one (closest points, maybe strided): a solve
    /// stopped early ([`hand_model::solver::LmOptions::step_tolerance`]) leaves it so.
    early_last: bool,
}

impl LmCallback<OnlineCtx> for ShapeCallback<'_> {
    fn prepare(
        &mut self,
        pose: &Pose,
        ctx: &mut OnlineCtx,
        info: IterInfo,
    ) -> Result<(), TermError> {
        // The last linearization of the solve is the Laplace one (Eq. 4.5): the evaluation after
        // the last update, or without one (the tracker's default) the last iteration's — the
        // update after it moves β but not the context. The data term keeps its system there;
        // a solve that stops early leaves no copy and the Laplace step assembles its own.
        let last = info.iteration + 1 == self.iterations;
        self.problem
            .data
            .capture_next(info.final_evaluation || last);
        let t = Instant::now();
        self.problem.reshape(ctx)?;
        let t1 = Instant::now();
        self.reshape_us += (t1 - t).as_secs_f64() * 1e6;
        let along = self.ray_last == 0
            || info.final_evaluation
            || info.iteration + self.ray_last >= self.iterations;
        ctx.tracking.set_ray_gate(self.ray_gate.filter(|_| along));
        let early = !along && self.ray_gate.is_some();
        self.early_last = early;
        ctx.tracking
            .set_point_stride(if early { self.early_stride } else { 1 });
        // Each early iteration takes the next share of the points, so that over the early
        // iterations every point pulls on the pose (a fixed share lost accuracy, docs of
        // `OnlineConfig::early_point_stride`).
        ctx.tracking.set_point_phase(info.iteration);
        let r = ctx.tracking.update(pose, info.rigid_only);
        self.correspondences_us += t1.elapsed().as_secs_f64() * 1e6;
        r
    }

    /// β ← β + δβ clamped to the β bounds, β̃ ← β̃ + δβ̃; a step whose shape the basis refuses
    /// (a negative radius, a non-finite value) is dropped, so every iterate is a valid model.
    fn apply_aux(&mut self, ctx: &mut OnlineCtx, delta_aux: &[f64]) {
        let layout = &self.problem.layout;
        let off = layout.beta - layout.num_dofs;
        let lat = layout.latent - layout.num_dofs;
        let (Some(db), Some(dl)) = (
            delta_aux.get(off..off + layout.active.len()),
            delta_aux.get(lat..lat + 3),
        ) else {
            return;
        };
        if db.iter().chain(dl).all(|&d| d == 0.0) {
            return;
        }
        match self
            .problem
            .step_shape(&ctx.beta, ctx.latent, db, dl, &mut self.next)
        {
            Some(latent) => {
                std::mem::swap(&mut ctx.beta, &mut self.next);
                ctx.latent = latent;
                ctx.dirty = true;
            }
            None => self.rejected += 1,
        }
    }
}

/// Joint tracking and online calibration of the sphere-mesh model (thesis Ch. 4, module docs of
/// the crate). One per sequence; it places the hand itself with a Ch. 3 tracker of the
/// starting template that then watches it for a while ([`crate::watch`]).
pub struct OnlineCalibrator<'m> {
    problem: FrameProblem,
    config: OnlineConfig,
    solver: LmSolver,
    ws: LmWorkspace,
    ctx: OnlineCtx,
    iekf: IekfPrior,
    temporal: Temporal,
    belief: ShapeBelief,
    pose: Pose,
    initialized: bool,
    data_ne: NormalEquations,
    next: Vec<f64>,
    /// Median |d2m residual| (mm) of the last solved frame: the Huber threshold of
    /// [`expected_information`](Self::expected_information)'s prediction.
    residual_scale: f64,
    /// Measurements absorbed since the belief was last reset (the ramp's clock).
    measurements: usize,
    /// Scratch for it.
    residuals: Vec<f64>,
    /// The smoothed depth noise σ̂ of the frames so far.
    noise: NoiseMonitor,
    /// Per-frame buffers of the Laplace information and the filter (k × k, k active β), so
    /// that a frame allocates only its output: the frame's information, the mode, the
    /// marginal certainties and the factorizations' scratch.
    frame_info: DMatrix<f64>,
    mode: DVector<f64>,
    cumulative: Vec<f64>,
    per_frame: Vec<f64>,
    scratch: InfoScratch,
    /// E_iekf of the last accepted frames ([`OnlineConfig::innovation_gate`]).
    innovations: Gate,
    /// The model's area outside the silhouette in the last accepted frames
    /// ([`OnlineConfig::outside_gate`]).
    outsides: Gate,
    /// Frames failed in a row by the loss criterion ([`OnlineCalibrator::note_loss`]).
    failed_run: usize,
    /// The pose of the last solved frame not flagged `lost` (`None` before one), what a frame
    /// without a hand reports.
    fitted: Option<Pose>,
    /// The pose prior, for the seed.
    prior: Option<PcaPrior>,
    /// The starting template, the seed's.
    start: &'m SphereMeshTemplate,
    /// The Ch. 3 tracker of the starting template whose re-initialization places the
    /// calibrator whenever it is not placed (the first frame, after a frame without a hand or
    /// a lost run) and which then tracks beside it for a while ([`crate::watch`]); `None` when
    /// no watch is on, or should it fail to build (the calibrator then places the PCA mean
    /// pose on the points).
    seed: Option<hmodel_spheremesh::Tracker<'m>>,
    /// `Some` while the seed, having placed the hand, tracks beside the calibrator.
    shadow: Option<Shadow>,
    /// The recent frames' scores, which trigger the digit search
    /// ([`OnlineCalibrator::mend_digits`]).
    scores: ScoreTrigger,
    /// The digit search's candidate pose and the frames it has fitted better.
    candidate: Option<(Pose, usize)>,
}

impl<'m> OnlineCalibrator<'m> {
    /// Calibrate from `base` (the default template, or any with the honline β basis) with
    /// `config` and an optional PCA pose prior.
    pub fn new(
        base: &'m SphereMeshTemplate,
        config: OnlineConfig,
        prior: Option<&PcaPrior>,
    ) -> Result<Self, OnlineError> {
        config.validate()?;
        let problem = FrameProblem::new(base, &config, prior)?;
        let layout = &problem.layout;
        let nd = layout.num_dofs;
        let mut lm = config.tracker.lm.clone();
        // Without E_iekf a frame's β and pose trade off freely along what one frame cannot
        // tell apart, and the pose prior's pull is what holds that direction (Fig. 4.7 draw 0,
        // σ = 0.2, noise-free, decoupled: split E_β 0.37 → 0.62 mm, per-frame 1.33 → 2.52).
        lm.decouple_aux &= config.estimator == Estimator::Iekf;
        let solver = LmSolver::new(&base.skeleton, layout.dim() - nd, lm)?;
        let ws = solver.workspace();
        let ctx = problem.context(&config.tracker)?;
        let mean: Vec<f64> = layout.active.iter().map(|&i| ctx.beta[i]).collect();
        Ok(Self {
            iekf: IekfPrior::new(layout),
            temporal: Temporal::new(sphere_mesh_points(base), &config.tracker.temporal),
            belief: ShapeBelief::vague(&mean, config.initial_information),
            data_ne: NormalEquations::new(layout.dim()),
            pose: problem.mean_pose.clone(),
            initialized: false,
            next: ctx.beta.clone(),
            residual_scale: 1.0,
            measurements: 0,
            residuals: Vec::new(),
            noise: NoiseMonitor::default(),
            frame_info: DMatrix::zeros(mean.len(), mean.len()),
            mode: DVector::zeros(mean.len()),
            cumulative: Vec::with_capacity(mean.len()),
            per_frame: Vec::with_capacity(mean.len()),
            scratch: InfoScratch::default(),
            innovations: Gate::default(),
            outsides: Gate::default(),
            failed_run: 0,
            fitted: None,
            prior: prior.cloned(),
            start: base,
            seed: None,
            shadow: None,
            scores: ScoreTrigger::new(),
            candidate: None,
            ctx,
            solver,
            ws,
            config,
            problem,
        })
    }

    /// Whether the solved frame failed by the tracker's loss criterion (`fit`,
    /// [`hmodel_spheremesh::TrackerConfig::loss`]): a mis-tracked frame, whose shape step is
    /// refused like the innovation gate's (flag `lost`). After `loss.window` failed frames in a
    /// row the next frame is placed again ([`OnlineCalibrator::is_placed`]).
    fn note_loss(&mut self, fit: &FrameStats) -> bool {
        if !fit.failed {
            self.failed_run = 0;
            return false;
        }
        self.failed_run += 1;
        if self.failed_run >= self.config.tracker.loss.window.max(1) {
            self.initialized = false;
            self.failed_run = 0;
        }
        true
    }

    /// Whether [`OnlineConfig::innovation_gate`] rejects the solved frame's step; an accepted
    /// frame's E_iekf joins the window.
    fn innovation_rejects(&mut self) -> bool {
        if self.config.estimator != Estimator::Iekf || self.config.innovation_gate <= 0.0 {
            return false;
        }
        let energy = self
            .ws
            .report()
            .terms
            .iter()
            .find(|t| t.name == IekfPrior::NAME)
            .map_or(0.0, |t| t.energy);
        self.innovations
            .rejects(energy, self.config.innovation_gate, 0.0)
    }

    /// Whether [`OnlineConfig::outside_gate`] rejects the solved frame's step (`outside`: the
    /// model's area outside the sensor silhouette, [`FrameStats::outside`]); an accepted
    /// frame's share joins the window.
    fn outside_rejects(&mut self, outside: f64) -> bool {
        let gate = self.config.outside_gate;
        gate > 0.0 && self.outsides.rejects(outside, gate, OUTSIDE_FLOOR)
    }

    /// The smoothed depth noise σ̂ (mm) measured so far ([`NoiseMonitor`]; `None` before the
    /// first measurement).
    pub fn depth_noise(&self) -> Option<f64> {
        self.noise.sigma()
    }

    /// The β basis (names, template values, kinds).
    pub fn basis(&self) -> &ShapeBasis {
        &self.problem.basis
    }

    /// The unknowns' layout (which β entries are estimated).
    pub fn layout(&self) -> &Layout {
        &self.problem.layout
    }

    /// The settings.
    pub fn config(&self) -> &OnlineConfig {
        &self.config
    }

    /// The current pose.
    pub fn pose(&self) -> &Pose {
        &self.pose
    }

    /// Whether the next frame is solved from [`OnlineCalibrator::pose`]; false at the start,
    /// after a frame without a hand and after `tracker.loss.window` failed frames in a row:
    /// the next frame then places the hand with the seed ([`crate::watch`]) unless a caller
    /// places it first ([`OnlineCalibrator::set_pose`]).
    pub fn is_placed(&self) -> bool {
        self.initialized
    }

    /// The template at the current β of the tracking model.
    pub fn template(&self) -> &SphereMeshTemplate {
        self.ctx.tracking.template()
    }

    /// The tracking context of the last solve: correspondences and posed model at the last
    /// linearization (on the template of the per-frame β*).
    pub fn context(&self) -> &TrackingCtx<'static> {
        &self.ctx.tracking
    }

    /// The current belief over the active β.
    pub fn belief(&self) -> &ShapeBelief {
        &self.belief
    }

    /// Start the next frame from `pose` (e.g. the first frame's known pose, thesis §4.4.2);
    /// clears the temporal history, and ends the seed's watch: the caller placed the hand. An
    /// error for a pose of the wrong length.
    pub fn set_pose(&mut self, pose: &Pose) -> Result<(), OnlineError> {
        let pose = Pose::from_values(&self.problem.base.skeleton, pose.values.clone())?;
        self.place(pose);
        (self.seed, self.shadow) = (None, None);
        Ok(())
    }

    /// Solve the next frame from `pose`, a new start: the frames before it are not this hand's
    /// motion.
    fn place(&mut self, pose: Pose) {
        self.pose = pose;
        self.initialized = true;
        self.failed_run = 0;
        self.temporal.clear_history();
    }

    /// Start from the shape `beta` (all entries of the basis, mm) instead of the base template:
    /// a previous session's estimate, or the perturbed initializations of thesis §4.4.3 ("random
    /// initializations … drawn from N(β̄, σ)"). The estimate restarts at `beta` with the vague
    /// initial information; the shape-space prior (Eq. 4.14) and the β bounds stay those of the
    /// base template. An error, leaving the calibrator unchanged, for the wrong length, a
    /// non-finite entry or a shape the basis refuses; entries beyond the β bounds are clamped.
    pub fn set_shape(&mut self, beta: &[f64]) -> Result<(), OnlineError> {
        let basis = &self.problem.basis;
        let invalid = |reason: String| {
            OnlineError::Model(ModelError::InvalidArgument {
                name: "beta",
                reason,
            })
        };
        if beta.len() != basis.len() {
            return Err(invalid(format!(
                "{} shape values for {} parameters",
                beta.len(),
                basis.len()
            )));
        }
        let mut next = beta.to_vec();
        if !self.problem.project(&mut next) {
            return Err(invalid("not a valid model of the basis".into()));
        }
        let template = basis.apply(&self.problem.base, &next)?;
        self.ctx.tracking.set_template(template)?;
        let mean: Vec<f64> = self
            .problem
            .layout
            .active
            .iter()
            .map(|&i| next[i])
            .collect();
        self.belief = ShapeBelief::vague(&mean, self.config.initial_information);
        self.measurements = 0;
        self.innovations.clear();
        self.outsides.clear();
        self.ctx.beta.clone_from(&next);
        self.ctx.dirty = false;
        self.next = next;
        self.temporal.clear_history();
        Ok(())
    }

    /// Before solving a frame: an unplaced calibrator is placed by the seed (built on demand),
    /// whose watch starts there; a seed still watching tracks the frame too, and a placement of
    /// its own restarts the watch's count ([`crate::watch`]). Returns whether the calibrator
    /// was placed here, and the seed's record when the watch is still settling: the calibrator
    /// is then placed at the seed's pose and does not solve the frame.
    fn seed_frame(
        &mut self,
        frame: &PreprocessedFrame,
        index: u64,
        timestamp: f64,
    ) -> (bool, Option<HandRecord>) {
        if !self.is_placed() {
            self.shadow = None;
            if self.seed.is_none() {
                let config = self.config.tracker.clone();
                self.seed =
                    hmodel_spheremesh::Tracker::new(self.start, config, self.prior.as_ref()).ok();
            }
        }
        let Some(seed) = self.seed.as_mut() else {
            return (false, None);
        };
        let rec = seed.track(frame, index, timestamp);
        let flagged = |name: &str| rec.flags.iter().any(|f| f == name);
        let hand = !flagged("no_hand") && !flagged("solver_failed");
        let placed = self.shadow.is_none() && hand;
        // Only a shape that has learned nothing yet settles: one learned from earlier frames
        // (a hand that comes back, a lost run) may track better than the seed's template.
        let settle = self.measurements == 0;
        if placed {
            self.shadow = Some(Shadow::new(settle));
        } else if let Some(shadow) = self.shadow.as_mut() {
            // The seed placed the hand again (lost, or a better start at its second look): the
            // watch counts from there.
            if flagged("reinitialized") {
                *shadow = Shadow::new(settle);
            }
        }
        // A frame the seed failed to solve keeps its previous pose, which the calibrator follows.
        let settling = !flagged("no_hand") && self.shadow.is_some_and(|s| s.is_settling());
        if placed || settling {
            let pose = seed.pose().clone();
            self.place(pose);
        }
        (placed, settling.then_some(rec))
    }

    /// After a frame: one frame of the seed's watch ([`crate::watch`]). Restarts the
    /// calibrator from the seed's pose with the starting shape when it has fitted clearly
    /// worse for long enough (true then), and lets the seed go once the watch is over.
    fn watch(&mut self) -> bool {
        let (Some(seed), Some(shadow)) = (self.seed.as_ref(), self.shadow.as_mut()) else {
            return false;
        };
        let loss = self.config.tracker.loss.for_noise(self.noise.sigma());
        let score = |ctx: &TrackingCtx<'_>| ctx.frame_stats(&loss).score();
        if shadow.is_settling() {
            shadow.frames += 1;
            return false;
        }
        if shadow.observe(score(&self.ctx.tracking), score(seed.context())) {
            *shadow = Shadow::new(false);
            let pose = seed.pose().clone();
            let start = self.problem.basis.template_values();
            if self.set_shape(&start).is_err() {
                return false;
            }
            self.place(pose);
            return true;
        }
        if shadow.is_over() {
            (self.seed, self.shadow) = (None, None);
        }
        false
    }

    /// The digit search during tracking ([`hand_model::solver::FrameLoop::search_digits`]),
    /// triggered as the Ch. 3 tracker's by a frame that fits much worse than the recent ones
    /// ([`ScoreTrigger`]): two fingers exchanged leave the model outside the silhouette where
    /// the wrong one lies, a minimum the joint solve does not leave. A Ch. 3 tracker of the
    /// current template solves each digit's variants with the shape held fixed. A variant that
    /// fits the frame better becomes a candidate, which replaces `pose` only once it has also
    /// fitted the next [`CONFIRM_FRAMES`] − 1 frames better
    /// ([`hand_model::solver::FrameLoop::challenge`]); its statistics are returned then, and
    /// the caller treats the frame as a new placement whose shape step is refused.
    fn mend_digits(
        &mut self,
        frame: &PreprocessedFrame,
        fit: &FrameStats,
        pose: &mut Pose,
    ) -> Option<FrameStats> {
        let sigma = self.noise.sigma();
        let ((candidate, stats), wins) = match self.candidate.take() {
            Some((c, wins)) => (
                self.searcher(|t| t.challenge(frame, pose, &c, sigma))?,
                wins + 1,
            ),
            None => {
                if !self.scores.triggers(fit.score()) {
                    return None;
                }
                (self.searcher(|t| t.search_digits(frame, pose, sigma))?, 1)
            }
        };
        if wins < CONFIRM_FRAMES {
            self.candidate = Some((candidate, wins));
            return None;
        }
        *pose = candidate;
        Some(stats)
    }

    /// `f` on a Ch. 3 tracker of the current template, built for it.
    fn searcher<R>(
        &self,
        f: impl FnOnce(&mut hmodel_spheremesh::Tracker<'_>) -> Option<R>,
    ) -> Option<R> {
        let template = self.ctx.tracking.template().clone();
        let config = self.config.tracker.clone();
        let mut tracker =
            hmodel_spheremesh::Tracker::new(&template, config, self.prior.as_ref()).ok()?;
        f(&mut tracker)
    }

    /// The mean pose moved so that the model's sphere centroid sits 10 mm behind the points'
    /// centroid.
    fn centered_pose(&self, points: &[Vector3<f64>]) -> Pose {
        let mut pose = self.problem.mean_pose.clone();
        let n = points.len().max(1) as f64;
        let target = points.iter().sum::<Vector3<f64>>() / n + Vector3::new(0.0, 0.0, 10.0);
        let posed = PosedSphereMesh::new(self.template(), &pose);
        let m = posed.spheres.len().max(1) as f64;
        let center = posed.spheres.iter().map(|s| s.center).sum::<Vector3<f64>>() / m;
        let sk = &self.problem.base.skeleton;
        for (name, d) in ["global_tx", "global_ty", "global_tz"]
            .iter()
            .zip((target - center).iter())
        {
            if let Some(i) = sk.dof_index(name) {
                pose.values[i] += d;
            }
        }
        pose
    }

    /// The information (over the active β, per mm², scaled like a measurement) that `frame`
    /// would bring if the hand were at `pose`: Eq. 4.5 linearized there with the current shape,
    /// without solving — what calibration guidance ranks candidate poses by (thesis §5.2).
    /// `None` when the frame has too few points or the linearization fails. The next
    /// [`track`](Self::track) sets its own frame, so this leaves tracking unaffected.
    pub fn expected_information(
        &mut self,
        frame: &PreprocessedFrame,
        pose: &Pose,
    ) -> Option<DMatrix<f64>> {
        if frame.points.len() < self.config.min_points.max(1)
            || pose.values.len() != self.problem.layout.num_dofs
        {
            return None;
        }
        // A model rendered from itself fits with zero residuals, where the IRLS weight g/|r| is
        // at its cap g/ε: the information would be ~1000× what a real frame brings. The Huber
        // threshold is raised to the typical residual of the tracked frames for the prediction.
        let irls = self.ctx.tracking.irls().clone();
        let mut typical = irls.clone();
        typical.epsilon = typical.epsilon.max(self.residual_scale);
        self.ctx.tracking.set_irls(typical);
        self.ctx.tracking.set_frame(frame);
        let h = match self.ctx.tracking.update(pose, false) {
            Ok(()) => self
                .problem
                .data_information(&self.ctx, &mut self.data_ne)
                .map(|h| h * self.config.measurement_weight),
            Err(_) => None,
        };
        self.ctx.tracking.set_irls(irls);
        // Restore the tracked pose's linearization for anyone reading the context.
        let _ = self.ctx.tracking.update(&self.pose.clone(), false);
        h.filter(|h| h.iter().all(|v| v.is_finite()))
    }

    /// Track one frame and update the shape estimate (crate docs). Never returns a non-finite
    /// value or an invalid shape: a frame that cannot be solved keeps the previous pose and
    /// estimate and is flagged (`solver_failed`); a frame without a hand (`no_hand`) reports
    /// the pose of the last frame solved without being flagged `lost`. A frame where the seed
    /// placed the hand is flagged `reinitialized`; the first frames after the first placement
    /// are the seed's (`settling`, [`crate::watch`]), not solved (`solved` false).
    ///
    /// The record's `timing_us` splits the frame (µs) so that it compares stage by stage with
    /// the plain tracker's ([`hmodel_spheremesh::Tracker::track`]): `correspondences` (the
    /// context refreshes of the LM), `solve` (the rest of the LM: terms, factorization),
    /// and what calibrating adds — `reshape` (the template and the collision term rebuilt on
    /// a moved β), `laplace` (Eq. 4.5) and `filter` (the estimator and the certainties) —
    /// `seed` (the seed's frame, while it watches) and `track` (the whole call). A settling
    /// frame carries the seed's stages.
    pub fn track(&mut self, frame: &PreprocessedFrame, index: u64, timestamp: f64) -> OnlineFrame {
        let start = Instant::now();
        let (placed, settling) = self.seed_frame(frame, index, timestamp);
        if placed {
            self.scores.clear();
            self.candidate = None;
        }
        let seed_us = start.elapsed().as_secs_f64() * 1e6;
        let watched = self.seed.is_some();
        let mut out = self.solve(frame, index, timestamp, settling);
        if placed && !out.record.flags.iter().any(|f| f == "reinitialized") {
            out.record.flags.insert(0, "reinitialized".into());
        }
        if watched {
            let timing = &mut out.record.timing_us;
            timing.insert("seed".into(), seed_us);
            timing.insert("track".into(), start.elapsed().as_secs_f64() * 1e6);
        }
        if self.watch() {
            self.scores.clear();
            self.candidate = None;
            out.record.flags.push("shape_reset".into());
        }
        // As the trackers' frame loop: a hand that comes back is placed again, not solved from
        // the pose it left at.
        if out.record.flags.iter().any(|f| f == "no_hand") {
            self.initialized = false;
        }
        out
    }

    /// [`Self::track`] but the seed: the frame solved from the pose where the calibrator is, or,
    /// while the seed's watch is settling, the seed's record of it (`settling`) with the
    /// estimate kept.
    fn solve(
        &mut self,
        frame: &PreprocessedFrame,
        index: u64,
        timestamp: f64,
        settling: Option<HandRecord>,
    ) -> OnlineFrame {
        let start = Instant::now();
        let mut rec = HandRecord::for_frame(index, timestamp);
        self.ctx.tracking.take_timing();
        let k = self.problem.layout.active.len();
        self.frame_info.fill(0.0);
        let mut solved = false;
        let finite_points = frame
            .points
            .iter()
            .filter(|p| p.iter().all(|v| v.is_finite()));
        let mut reshape_us = 0.0;
        let mut stats = None;
        if let Some(seed) = settling {
            // The seed's frame: its flags, energies and stages, the calibrator's shape.
            rec.flags = seed.flags;
            rec.flags.push("settling".into());
            rec.energies = seed.energies;
            rec.iterations = seed.iterations;
            rec.timing_us = seed.timing_us;
        } else if finite_points.count() >= self.config.min_points.max(1) {
            self.ctx.tracking.set_frame(frame);
            self.update_noise(frame);
            if !self.is_placed() {
                // No seed to place it.
                let pose = self.centered_pose(&frame.points);
                self.place(pose);
                rec.flags.push("reinitialized".into());
            }
            self.set_prior();
            let t = Instant::now();
            self.problem.refresh_collision(&self.ctx, &self.config);
            reshape_us += t.elapsed().as_secs_f64() * 1e6;
            let saved = (self.ctx.beta.clone(), self.ctx.latent);
            let temporal = self.config.tracker.enabled.temporal;
            let terms = self.problem.terms(
                temporal.then_some(&self.temporal as &dyn EnergyTerm<OnlineCtx>),
                Some(&self.iekf),
            );
            let mut callback = ShapeCallback {
                problem: &self.problem,
                iterations: self.solver.options().iterations,
                next: std::mem::take(&mut self.next),
                rejected: 0,
                reshape_us: 0.0,
                correspondences_us: 0.0,
                ray_gate: self.ctx.tracking.ray_gate(),
                ray_last: self.config.ray_last_iterations,
                early_stride: self.config.early_point_stride,
                early_last: false,
            };
            let mut pose = self.pose.clone();
            self.problem.data.capture_next(false);
            let t0 = Instant::now();
            let result = self.solver.solve(
                &mut self.ws,
                &self.problem.base.skeleton,
                &mut pose,
                &mut self.ctx,
                terms.as_slice(),
                &mut callback,
            );
            let lm_us = t0.elapsed().as_secs_f64() * 1e6;
            self.ctx.tracking.set_ray_gate(callback.ray_gate);
            self.ctx.tracking.set_point_stride(1);
            self.ctx.tracking.set_point_phase(0);
            self.next = callback.next;
            let mut ok = matches!(result, Ok(r) if r.termination.was_successful())
                && pose.values.iter().all(|v| v.is_finite());
            if ok && callback.early_last {
                // The frame's fit and its Laplace measurement are judged on every point
                // registered by the frame's rule, not on an early iteration's.
                ok = self.problem.prepare(&mut self.ctx, &pose, false).is_ok();
            }
            reshape_us += callback.reshape_us;
            rec.timing_us
                .insert("correspondences".into(), callback.correspondences_us);
            for (stage, us) in self.ctx.tracking.take_timing().stages() {
                rec.timing_us.insert(stage.into(), us);
            }
            rec.timing_us.insert(
                "solve".into(),
                lm_us - callback.correspondences_us - callback.reshape_us,
            );
            if ok {
                let t1 = Instant::now();
                // Eq. 4.5 at the last linearization: the data terms' Gauss–Newton Hessian,
                // marginalized over the pose — as the solve's last evaluation assembled it, or
                // assembled here when the solve left no copy.
                let (scratch, info) = (&mut self.scratch, &mut self.frame_info);
                let measured = self.problem.captured_information(scratch, info)
                    || self.problem.data_information_into(
                        &self.ctx,
                        &mut self.data_ne,
                        scratch,
                        info,
                    );
                self.problem.data.capture_next(false);
                // The loss criterion at the measured depth noise.
                let loss = self.config.tracker.loss.for_noise(self.noise.sigma());
                let mut fit = self.ctx.tracking.frame_stats(&loss);
                let lost = measured && self.note_loss(&fit);
                let mended = match (measured && !lost)
                    .then(|| self.mend_digits(frame, &fit, &mut pose))
                    .flatten()
                {
                    Some(at_mended) => {
                        fit = at_mended;
                        true
                    }
                    None => false,
                };
                let rejected = measured
                    && (lost
                        || mended
                        || self.outside_rejects(fit.outside)
                        || self.innovation_rejects());
                if mended {
                    // A new placement: the frames before fitted other fingers, and this
                    // frame's shape step was taken with them.
                    rec.flags.push("reinitialized".into());
                    self.temporal.clear_history();
                }
                if !lost {
                    // After a mend the window keeps the fits from before the loss, whose
                    // scores it held out while lost (`ScoreTrigger`): a second loss soon
                    // after is caught against them, as the Ch. 3 tracker's frame loop does.
                    self.scores.push(fit.score());
                }
                if rejected {
                    (self.ctx.beta, self.ctx.latent) = saved.clone();
                    self.ctx.dirty = true;
                    if !mended {
                        rec.flags
                            .push(if lost { "lost" } else { "shape_rejected" }.into());
                    }
                }
                stats = Some(fit);
                if !measured {
                    self.frame_info.fill(0.0);
                } else {
                    if rejected {
                        self.frame_info.fill(0.0);
                    } else {
                        self.measurements += 1;
                        let ramp =
                            self.measurements as f64 / self.config.measurement_ramp.max(1) as f64;
                        self.frame_info *= self.config.measurement_weight * ramp.min(1.0);
                    }
                    solved = true;
                    self.pose = pose;
                    if !lost {
                        match &mut self.fitted {
                            Some(f) => f.values.clone_from(&self.pose.values),
                            none => *none = Some(self.pose.clone()),
                        }
                    }
                    self.residual_scale =
                        median_abs_residual(&self.ctx.tracking, &mut self.residuals);
                }
                rec.timing_us
                    .insert("laplace".into(), t1.elapsed().as_secs_f64() * 1e6);
            }
            if solved {
                rec.iterations = Some(self.ws.report().iterations as u32);
                rec.add_energies(self.ws.report().terms.iter().map(|t| (t.name, t.energy)));
                if let Some(fit) = &stats {
                    rec.energies
                        .insert("mean_distance_mm".into(), fit.mean_distance);
                    rec.energies.insert("outside_fraction".into(), fit.outside);
                    if let Some(sigma) = self.noise.sigma() {
                        rec.energies.insert("depth_noise_mm".into(), sigma);
                    }
                }
                let posed = PosedSphereMesh::new(self.ctx.tracking.template(), &self.pose);
                if self.config.tracker.enabled.temporal {
                    let _ = self.temporal.push_frame(&posed.skeleton);
                }
            } else {
                (self.ctx.beta, self.ctx.latent) = saved;
                self.ctx.dirty = true;
                rec.flags.push("solver_failed".into());
            }
        } else {
            // As the Ch. 3 tracker's frame loop: the last pose that fitted, not that of a
            // placement on a patch of background taken for the hand before the hand left.
            rec.flags.push("no_hand".into());
            if let Some(f) = &self.fitted {
                self.pose.values.clone_from(&f.values);
            }
        }
        // The estimators (§4.3.1–4.3.3).
        let t2 = Instant::now();
        for (m, &i) in self.mode.iter_mut().zip(&self.problem.layout.active) {
            *m = self.ctx.beta[i];
        }
        let (mode, frame_info) = (&self.mode, &self.frame_info);
        if solved {
            match self.config.estimator {
                Estimator::PerFrame => {
                    self.belief.mean.copy_from(mode);
                    self.belief.information.copy_from(frame_info);
                }
                Estimator::Kf => {
                    self.belief.fuse(mode, frame_info);
                }
                Estimator::Iekf => {
                    self.belief.absorb(mode, frame_info);
                }
            }
        }
        let t3 = Instant::now();
        if self.ctx.dirty {
            if let Ok(t) = self.problem.basis.apply(&self.problem.base, &self.ctx.beta) {
                if self.ctx.tracking.set_template(t).is_ok() {
                    self.ctx.dirty = false;
                }
            }
        }
        let tail_reshape_us = t3.elapsed().as_secs_f64() * 1e6;
        reshape_us += tail_reshape_us;
        let frame_beta = self.ctx.beta.clone();
        let beta = self.estimate(&frame_beta);
        let n = self.problem.basis.len();
        let mut certainty = vec![0.0; n];
        let mut frame_certainty = vec![0.0; n];
        let mut marginal = vec![0.0; n];
        let mut frame_marginal = vec![0.0; n];
        marginal_certainty_into(
            &self.belief.information,
            0.0,
            &mut self.scratch,
            &mut self.cumulative,
        );
        if solved {
            marginal_certainty_into(
                &self.frame_info,
                self.config.initial_information,
                &mut self.scratch,
                &mut self.per_frame,
            );
        } else {
            self.per_frame.clear();
            self.per_frame.resize(k, 0.0);
        }
        for (j, &i) in self.problem.layout.active.iter().enumerate() {
            certainty[i] = self.belief.information[(j, j)];
            frame_certainty[i] = self.frame_info[(j, j)];
            marginal[i] = self.cumulative.get(j).copied().unwrap_or(0.0);
            frame_marginal[i] = self.per_frame.get(j).copied().unwrap_or(0.0);
        }
        rec.timing_us.insert(
            "filter".into(),
            t2.elapsed().as_secs_f64() * 1e6 - tail_reshape_us,
        );
        rec.timing_us.insert("reshape".into(), reshape_us);
        let t = self.ctx.tracking.template();
        let posed = PosedSphereMesh::new(t, &self.pose);
        let names = t.skeleton.dofs().iter().map(|d| d.name.as_str());
        rec.set_pose(names, &self.pose.values, &posed.keypoints(t));
        for ((name, &b), &c) in self.problem.basis.names().zip(&beta).zip(&certainty) {
            rec.shape.insert(name.to_string(), b);
            rec.shape_certainty.insert(name.to_string(), c);
        }
        rec.timing_us
            .insert("track".into(), start.elapsed().as_secs_f64() * 1e6);
        OnlineFrame {
            record: rec,
            beta,
            frame_beta,
            certainty,
            frame_certainty,
            marginal_certainty: marginal,
            frame_marginal_certainty: frame_marginal,
            solved,
        }
    }

    /// When the frame's depth noise was measured ([`NoiseMonitor`]): turn the along-ray
    /// correspondences on or off ([`TrackerConfig::ray_gate_for`]), widen their slide to the
    /// noise ([`TrackerConfig::ray_slide_for`]; the loss criterion follows it too,
    /// [`hand_model::solver::LossParams::for_noise`]), and with
    /// [`OnlineConfig::noise_scaled_prior`] scale the shape-space prior by
    /// `s = max(σ̂ / 1 mm, 1)^p` ([`OnlineConfig::noise_prior_exponent`]) and, with
    /// [`LmOptions::decouple_aux`](hand_model::solver::LmOptions::decouple_aux), keep the
    /// share `1 − 1/s` of the pose prior's pull in β's step (at least the configured
    /// [`aux_prior_share`](hand_model::solver::LmOptions::aux_prior_share)).
    fn update_noise(&mut self, frame: &PreprocessedFrame) {
        if !self.noise.observe(&frame.depth, &frame.hand.mask) {
            return;
        }
        let sigma = self.noise.sigma();
        let gate = self.config.tracker.ray_gate_for(sigma);
        self.ctx.tracking.set_ray_gate(gate);
        let slide = self.config.tracker.ray_slide_for(sigma);
        self.ctx.tracking.set_ray_slide(slide);
        let Some(sigma) = sigma.filter(|_| self.config.noise_scaled_prior) else {
            return;
        };
        let scale = noise_scale(sigma).powf(self.config.noise_prior_exponent / 2.0);
        self.problem.prior.set_noise_scale(scale);
        // The pose prior's pull on β: bias on exact data, regularization on noisy data.
        let share = self
            .config
            .tracker
            .lm
            .aux_prior_share
            .max(1.0 - 1.0 / scale);
        self.solver.set_aux_prior_share(share);
    }

    /// E_iekf's prior `(x̂_{n−1}, Σ̂⁻¹_{n−1})` in the context for the joint estimator (none for
    /// the others), copied into the previous frame's buffers when it has them.
    fn set_prior(&mut self) {
        if self.config.estimator != Estimator::Iekf {
            self.ctx.prior = None;
            return;
        }
        let belief = &self.belief;
        match &mut self.ctx.prior {
            Some((mean, info)) if info.shape() == belief.information.shape() => {
                mean.clear();
                mean.extend(belief.mean.iter().copied());
                info.copy_from(&belief.information);
            }
            prior => {
                *prior = Some((
                    belief.mean.iter().copied().collect(),
                    belief.information.clone(),
                ))
            }
        }
    }

    /// The full β of the belief's mean (inactive entries from `fallback`), clamped to the β
    /// bounds; `fallback` itself when that shape is not a valid model.
    fn estimate(&self, fallback: &[f64]) -> Vec<f64> {
        let mut beta = fallback.to_vec();
        for (j, &i) in self.problem.layout.active.iter().enumerate() {
            beta[i] = self.belief.mean[j];
        }
        if self.problem.project(&mut beta) {
            beta
        } else {
            fallback.to_vec()
        }
    }
}

/// The median |r| over the d2m rows of `ctx`'s linearization (1 mm without rows); `r` is
/// scratch.
fn median_abs_residual(ctx: &TrackingCtx<'_>, r: &mut Vec<f64>) -> f64 {
    r.clear();
    r.extend(ctx.d2m_rows().map(|(_, _, r, _)| r.abs()));
    if r.is_empty() {
        return 1.0;
    }
    let mid = r.len() / 2;
    *r.select_nth_unstable_by(mid, f64::total_cmp).1
}
