//! The per-frame tracking loop of thesis §2.4 (Fig. 2.3): warm start from the previous frame,
//! one rigid-only then full Levenberg–Marquardt iterations over the enabled terms (Eq. 2.1,
//! Eq. 2.11), temporal history, loss detection and re-initialization, and the DESIGN.md output
//! record of every frame.
//!
//! # Loss detection and re-initialization (what is built, what is not)
//! The shared [`FrameLoop`] (module docs of `hand_model::solver` loss): a frame fails on its
//! mean point-to-model distance or share of unexplained points ([`LossParams`]), tracking is
//! lost after a window of failed frames, and the re-initializer solves from the current pose
//! and the mean pose (PCA mean, §2.3.2) placed on the point cloud's centroid with its fingers
//! along the cloud's principal image axis (both signs) or upright — none pointing back along
//! the forearm where the segmentation found one, the forearm's own direction added — keeping
//! the one that explains the points best. It is not Qian et al.'s fingertip detector (htrack's
//! `QianDetection`, ANCHOR-FACTS §5.7).

use std::time::Instant;

use hand_model::cylinder::{CylinderModel, View};
use hand_model::kinematics::{Pose, PosedSkeleton};
use hand_model::solver::terms::{
    JointLimits, JointLimitsParams, PosePrior, PosePriorParams, Temporal, TemporalParams,
};
use hand_model::solver::{
    cylinder_points, digit_variants, placed_rotation, placement_hypotheses, timed_solve,
    EnergyTerm, FrameLoop, FrameStats, Hypothesis, LmError, LmOptions, LmSolver, LmWorkspace,
    LossParams, NoTerm, PcaPrior, PriorSetup, SolveTiming, TrackingProblem,
};
use nalgebra::{Vector2, Vector3};
use sensor_io::preprocess::{gate_for_noise, slide_for_noise, NoiseMonitor, PreprocessedFrame};
use sensor_io::record::HandRecord;
use serde::{Deserialize, Serialize};

use crate::context::{CorrespondenceCallback, TrackingCtx, DEFAULT_RAY_SLIDE};
use crate::terms::{
    Collision, CollisionParams, E2d, E2dParams, E3d, E3dParams, Wrist, WristParams,
};
use hand_model::solver::IrlsParams;

/// Which terms of Eq. 2.1 take part (the `--no-<term>` switches of `hands track`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EnabledTerms {
    /// E3D (Eq. 2.2).
    pub e3d: bool,
    /// E2D (Eq. 2.3); needs a sensor camera in the frame.
    pub e2d: bool,
    /// E_wrist (Eq. 2.4); needs a wristband in the frame.
    pub wrist: bool,
    /// E_collision (Eq. 2.7).
    pub collision: bool,
    /// E_pose (Eq. 2.5–2.6); needs a prior.
    pub pose_prior: bool,
    /// E_bounds (Eq. 2.8).
    pub joint_limits: bool,
    /// E_temporal (Eq. 2.9).
    pub temporal: bool,
}

impl Default for EnabledTerms {
    fn default() -> Self {
        Self {
            e3d: true,
            e2d: true,
            wrist: true,
            collision: true,
            pose_prior: true,
            joint_limits: true,
            temporal: true,
        }
    }
}

/// Settings of the tracker, with the thesis defaults (§2.4 "Parameters"; ANCHOR-FACTS §5).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackerConfig {
    /// Levenberg–Marquardt: 1 rigid + 7 full iterations, λ = 100 (§2.4, §2.7.5).
    pub lm: LmOptions,
    /// Front-facing correspondences (§2.3.1) rather than plain closest points (Fig. 2.6).
    pub front_facing: bool,
    /// Along-ray correspondences within this distance (mm) of the ray's entry into the model
    /// ([`TrackingCtx::set_ray_gate`]) on the frames that [`Self::ray_gate_noise`] admits;
    /// `None`: the thesis' correspondences everywhere.
    pub ray_gate: Option<f64>,
    /// The measured depth noise σ̂ (mm, [`NoiseMonitor`]) from which the along-ray
    /// correspondences run; 0: on every frame. Exact and quantized depth (σ̂ < 1 mm) keep the
    /// thesis' rule and its speed, as in the sphere-mesh tracker.
    pub ray_gate_noise: f64,
    /// How far an along-ray footpoint may lie from the closest point (mm,
    /// [`TrackingCtx::set_ray_slide`]), on data of up to `ray_slide / ray_slide_noise` of
    /// measured depth noise.
    pub ray_slide: f64,
    /// Above that noise the slide is this many σ̂ ([`Self::ray_slide_for`]; 0: fixed). Default
    /// 1.5: the 7.5 mm slide was chosen on the ToF model's σ̂ ≈ 5 mm.
    pub ray_slide_noise: f64,
    /// ℓ1 by IRLS (§2.7.4).
    pub irls: IrlsParams,
    /// Which terms run.
    pub enabled: EnabledTerms,
    /// ω₁.
    pub e3d: E3dParams,
    /// ω₂.
    pub e2d: E2dParams,
    /// ω₃.
    pub wrist: WristParams,
    /// ω₆.
    pub collision: CollisionParams,
    /// ω₄, ω₅ and the form of the PCA prior.
    pub pose_prior: PosePriorParams,
    /// ω₇.
    pub joint_limits: JointLimitsParams,
    /// ω₈, ω₉.
    pub temporal: TemporalParams,
    /// Loss detection.
    pub loss: LossParams,
    /// A re-initialization placement whose rendered model covers more than this share of the
    /// sensor silhouette's area outside it is poor, and the edge-on backups are then tried
    /// ([`PLACEMENT_ROLLS`](hand_model::solver::PLACEMENT_ROLLS); see
    /// [`DEFAULT_PLACEMENT_OUTSIDE`]). Needs E2D's rendering (with `enabled.e2d` off, or
    /// without a camera, every placement is palm-on); infinity: palm-on only.
    pub placement_outside: f64,
}

/// The default [`TrackerConfig::placement_outside`]. Unlike the sphere-mesh trackers'
/// [`hand_model::solver::POOR_PLACEMENT_OUTSIDE`] (0.2, or a failed frame), a failed frame alone
/// does not make a placement poor here: the real scans' two-finger pose fails its palm-on
/// placements, and an edge-on backup won there wrongly (`eval/tests/scan_tracking.rs`: noise-free
/// fingertips 11.16 → 29.17 mm). On 74 ToF cold starts (library and random-subject sequences cut
/// at frames 45–250) the backups took the occlusion motion from 71.08 / 64.14 / 63.71 mm to
/// 2.76 / 3.46 / 5.09 mm (cut at frames 105 / 150 / 165) and a rotating fist from 14.64 to
/// 3.91 mm, and cost one random subject's fist 5.91 → 7.76 mm. At 0.2 a rotating fist cut at
/// frame 150 went 5.65 → 44.42 mm (an edge-on backup taken for a fist); at 0.3 and 0.25 it
/// went to 3.50; 0.25 also won two more fist cuts. The library's sequences and the real scans
/// are unchanged.
pub const DEFAULT_PLACEMENT_OUTSIDE: f64 = 0.25;

impl Default for TrackerConfig {
    fn default() -> Self {
        Self {
            lm: LmOptions {
                iterations: 8,
                rigid_iterations: 1,
                final_evaluation: false,
                ..LmOptions::default()
            },
            front_facing: true,
            ray_gate: Some(20.0),
            ray_gate_noise: 1.5,
            ray_slide: DEFAULT_RAY_SLIDE,
            ray_slide_noise: 1.5,
            irls: IrlsParams::default(),
            enabled: EnabledTerms::default(),
            e3d: E3dParams::default(),
            e2d: E2dParams::default(),
            wrist: WristParams::default(),
            collision: CollisionParams::default(),
            pose_prior: PosePriorParams::default(),
            joint_limits: JointLimitsParams::default(),
            temporal: TemporalParams::default(),
            loss: LossParams::default(),
            placement_outside: DEFAULT_PLACEMENT_OUTSIDE,
        }
    }
}

impl TrackerConfig {
    /// The along-ray gate for data of measured depth noise `sigma` (mm; `None`: not measured
    /// yet): [`Self::ray_gate`] when [`Self::ray_gate_noise`] admits it.
    pub fn ray_gate_for(&self, sigma: Option<f64>) -> Option<f64> {
        gate_for_noise(self.ray_gate, self.ray_gate_noise, sigma)
    }

    /// The along-ray slide for data of measured depth noise `sigma` (mm; `None`: not measured
    /// yet): [`Self::ray_slide`], or [`Self::ray_slide_noise`]·σ̂ where that is larger
    /// ([`slide_for_noise`]).
    pub fn ray_slide_for(&self, sigma: Option<f64>) -> f64 {
        slide_for_noise(self.ray_slide, self.ray_slide_noise, sigma)
    }
}

/// Why a tracker could not be built.
#[derive(Debug, thiserror::Error)]
pub enum TrackerError {
    /// Invalid solver options.
    #[error("solver: {0}")]
    Solver(#[from] LmError),
    /// Invalid term settings or a prior that does not fit the model.
    #[error("model: {0}")]
    Model(#[from] hand_model::ModelError),
}

/// Most terms of one solve.
const MAX_TERMS: usize = 8;

/// The energy terms of the tracker (Eq. 2.1), built once per sequence.
struct Terms {
    enabled: EnabledTerms,
    e3d: E3d,
    e2d: E2d,
    wrist: Wrist,
    collision: Collision,
    limits: JointLimits,
    temporal: Temporal,
    prior: Option<PosePrior>,
}

impl Terms {
    /// The enabled terms in htrack's order (data first, the PCA prior last), in a fixed array
    /// (no allocation per frame); returns the array and how many slots are used.
    fn list<'s, 'm>(&'s self) -> ([&'s dyn EnergyTerm<TrackingCtx<'m>>; MAX_TERMS], usize) {
        let mut out: [&dyn EnergyTerm<TrackingCtx<'m>>; MAX_TERMS] = [&NoTerm; MAX_TERMS];
        let mut n = 0;
        let mut push = |t: &'s dyn EnergyTerm<TrackingCtx<'m>>| {
            out[n] = t;
            n += 1;
        };
        let e = &self.enabled;
        if e.e3d {
            push(&self.e3d);
        }
        if e.e2d {
            push(&self.e2d);
        }
        if e.collision {
            push(&self.collision);
        }
        if e.temporal {
            push(&self.temporal);
        }
        if e.wrist {
            push(&self.wrist);
        }
        if e.joint_limits {
            push(&self.limits);
        }
        if e.pose_prior {
            if let Some(p) = &self.prior {
                push(p);
            }
        }
        (out, n)
    }
}

/// The solve of one frame, as [`FrameLoop`] drives it.
struct Problem<'m> {
    ctx: TrackingCtx<'m>,
    solver: LmSolver,
    ws: LmWorkspace,
    /// The workspace of [`TrackingProblem::solve_aside`], which leaves `ws`'s report alone.
    ws_aside: LmWorkspace,
    terms: Terms,
    mean_pose: Pose,
    timing: SolveTiming,
    /// [`TrackerConfig::placement_outside`].
    placement_outside: f64,
}

impl TrackingProblem for Problem<'_> {
    fn solve(&mut self, pose: &mut Pose) -> bool {
        let (list, n) = self.terms.list();
        let sk = &self.ctx.model().skeleton;
        timed_solve(
            &self.solver,
            &mut self.ws,
            sk,
            pose,
            &mut self.ctx,
            &list[..n],
            &mut CorrespondenceCallback,
            &mut self.timing,
        )
    }

    fn set_rigid_first(&mut self, on: bool) -> bool {
        self.solver.set_rigid_first(on)
    }

    fn set_aside(&mut self, aside: bool) {
        std::mem::swap(&mut self.ws, &mut self.ws_aside);
        self.terms.temporal.set_history_aside(aside);
    }

    fn refresh(&mut self, pose: &Pose) -> bool {
        self.ctx.update(pose, false).is_ok()
    }

    /// Distances of the sensor points to the model at the last linearization point (the pose
    /// before the last LM update: the last step is small, and this saves a correspondence pass).
    fn frame_stats(&self, params: &LossParams) -> FrameStats {
        let distances = self
            .ctx
            .correspondences()
            .iter()
            .zip(self.ctx.points())
            .map(|(c, x)| c.as_ref().map(|c| (c.point - x).norm()));
        FrameStats::from_distances(distances, params)
    }

    /// Initial poses from the point cloud ([`placement_hypotheses`]): the mean pose with its
    /// palm center 10 mm behind the cloud's centroid, fingers along ± the principal image axis
    /// of the cloud, or upright (fingers toward image −y), or along the forearm (the wristband
    /// or forearm cut's axis), never back along it; palm toward the camera, and as
    /// backups edge-on, as in the sphere-mesh tracker but with this tracker's own
    /// poor-placement rule ([`Self::is_poor_placement`]).
    fn hypotheses(&self) -> Vec<Hypothesis> {
        let arm = self.ctx.sensor().wristband.map(|b| b.axis);
        placement_hypotheses(self.ctx.points(), arm.as_ref(), |e, roll, target| {
            self.placed_mean_pose(e, roll, target)
        })
    }

    /// Poor when the rendered model covers more than [`TrackerConfig::placement_outside`] of
    /// the silhouette's area outside it ([`TrackingCtx::outside_fraction`]); a failed frame
    /// alone is not (see [`DEFAULT_PLACEMENT_OUTSIDE`]).
    fn is_poor_placement(&self, _stats: &FrameStats) -> bool {
        self.ctx
            .outside_fraction()
            .is_some_and(|o| o > self.placement_outside)
    }

    fn clear_history(&mut self) {
        self.terms.temporal.clear_history();
    }

    fn digit_variants(&self, pose: &Pose, digit: usize) -> Vec<Pose> {
        digit_variants(&self.ctx.model().skeleton, pose, digit)
    }
}

impl Problem<'_> {
    /// The mean pose turned about the optical axis so that the model's +y (fingers) maps to
    /// the image direction `e` and rolled by `roll` about them ([`placed_rotation`]),
    /// translated so that the palm center lands on `target`.
    fn placed_mean_pose(&self, e: Vector2<f64>, roll: f64, target: &Vector3<f64>) -> Option<Pose> {
        let model = self.ctx.model();
        let sk = &model.skeleton;
        let mut pose = placed_rotation(&self.mean_pose, sk, e, roll)?;
        let posed = PosedSkeleton::new(sk, &pose);
        let palm = model
            .segments
            .iter()
            .max_by(|a, b| (a.r1 * a.r1y).total_cmp(&(b.r1 * b.r1y)))?;
        let center = posed
            .globals
            .get(palm.bone)?
            .transform_point(&(palm.end_local() * 0.5));
        let shift = target - center;
        for (name, d) in ["global_tx", "global_ty", "global_tz"]
            .iter()
            .zip(shift.iter())
        {
            let i = sk.dof_index(name)?;
            pose.values[i] += d;
        }
        Some(pose)
    }
}

/// The Ch. 2 tracker: one per sequence (it holds the temporal history and the loss state).
pub struct Tracker<'m> {
    model: &'m CylinderModel,
    config: TrackerConfig,
    problem: Problem<'m>,
    frames: FrameLoop,
    posed: PosedSkeleton,
    noise: NoiseMonitor,
}

impl<'m> Tracker<'m> {
    /// A tracker of `model` with `config` and an optional PCA pose prior (E_pose is skipped
    /// without one). The prior's mean also gives the initial finger pose (§2.3.2). A negative
    /// or NaN [`TrackerConfig::placement_outside`] is an error.
    pub fn new(
        model: &'m CylinderModel,
        config: TrackerConfig,
        prior: Option<&PcaPrior>,
    ) -> Result<Self, TrackerError> {
        if config.placement_outside.is_nan() || config.placement_outside < 0.0 {
            return Err(hand_model::ModelError::InvalidArgument {
                name: "placement_outside",
                reason: format!(
                    "must be a share ≥ 0 (infinity: palm-on placements only), got {}",
                    config.placement_outside
                ),
            }
            .into());
        }
        let sk = &model.skeleton;
        let mut ctx = TrackingCtx::new(model, View::Orthographic, config.irls.clone());
        ctx.set_front_facing(config.front_facing);
        ctx.set_silhouette(config.enabled.e2d);
        ctx.set_ray_gate(config.ray_gate_for(None));
        ctx.set_ray_slide(config.ray_slide);
        let PriorSetup {
            prior: pose_prior,
            solver,
            mean_pose,
        } = PriorSetup::new::<TrackerError>(sk, prior, &config.pose_prior, &config.lm)?;
        let (ws, ws_aside) = (solver.workspace(), solver.workspace());
        let terms = Terms {
            enabled: config.enabled.clone(),
            e3d: E3d::new(config.e3d.clone()),
            e2d: E2d::new(config.e2d.clone()),
            wrist: Wrist::new(config.wrist.clone()),
            collision: Collision::new(model, config.collision.clone()),
            limits: JointLimits::new(sk, &config.joint_limits),
            temporal: Temporal::new(cylinder_points(model), &config.temporal),
            prior: pose_prior,
        };
        Ok(Self {
            model,
            frames: FrameLoop::new(mean_pose.clone(), config.loss.clone()),
            posed: PosedSkeleton::new(sk, &mean_pose),
            noise: NoiseMonitor::default(),
            problem: Problem {
                ctx,
                solver,
                ws_aside,
                ws,
                terms,
                mean_pose,
                timing: SolveTiming::default(),
                placement_outside: config.placement_outside,
            },
            config,
        })
    }

    /// The current pose θ.
    pub fn pose(&self) -> &Pose {
        &self.frames.pose
    }

    /// The settings.
    pub fn config(&self) -> &TrackerConfig {
        &self.config
    }

    /// The model.
    pub fn model(&self) -> &'m CylinderModel {
        self.model
    }

    /// The per-iteration context (correspondences and rendered silhouette at the last
    /// linearization).
    pub fn context(&self) -> &TrackingCtx<'m> {
        &self.problem.ctx
    }

    /// Start the next frame from `pose` (e.g. a known initial pose) instead of
    /// re-initializing; clears the temporal history.
    pub fn set_pose(&mut self, pose: &Pose) -> Result<(), TrackerError> {
        let checked = Pose::from_values(&self.model.skeleton, pose.values.clone())?;
        self.frames.set_pose(checked);
        self.problem.clear_history();
        Ok(())
    }

    /// Track one preprocessed frame and return its DESIGN.md record (pose by DOF name, 21
    /// keypoints, per-term energies of the last linearization, iterations, per-stage µs,
    /// flags `no_hand`, `lost`, `reinitialized`, `solver_failed`).
    ///
    /// Never returns a non-finite pose: a frame without enough sensor points keeps the
    /// previous pose (`no_hand`) and the next frame re-initializes; a failed solve reverts to
    /// the previous pose (`solver_failed`); see [`FrameLoop::step`].
    pub fn track(&mut self, frame: &PreprocessedFrame, index: u64, timestamp: f64) -> HandRecord {
        let start = Instant::now();
        let mut rec = HandRecord::for_frame(index, timestamp);
        self.problem.timing = SolveTiming::default();
        let n = frame.points.len();
        if n >= self.frames.loss().min_points.max(1) {
            self.problem.ctx.set_frame(frame);
            if self.noise.observe(&frame.depth, &frame.hand.mask) {
                let sigma = self.noise.sigma();
                self.problem
                    .ctx
                    .set_ray_gate(self.config.ray_gate_for(sigma));
                let slide = self.config.ray_slide_for(sigma);
                self.problem.ctx.set_ray_slide(slide);
                self.frames.set_noise(sigma);
            }
        }
        let outcome = self.frames.step(&mut self.problem, n);
        rec.flags = outcome.flags.iter().map(|f| f.to_string()).collect();
        if let Some(stats) = &outcome.stats {
            rec.iterations = Some(self.problem.ws.report().iterations as u32);
            rec.add_energies(
                self.problem
                    .ws
                    .report()
                    .terms
                    .iter()
                    .map(|t| (t.name, t.energy)),
            );
            rec.energies
                .insert("mean_distance_mm".into(), stats.mean_distance);
            if let Some(sigma) = self.noise.sigma() {
                rec.energies.insert("depth_noise_mm".into(), sigma);
            }
        }
        let pose = &self.frames.pose;
        self.posed.update(&self.model.skeleton, pose);
        if outcome.stats.is_some() && self.config.enabled.temporal {
            // Cannot fail: the term's points are on this model's bones.
            let _ = self.problem.terms.temporal.push_frame(&self.posed);
        }
        let names = self.model.skeleton.dofs().iter().map(|d| d.name.as_str());
        rec.set_pose(names, &pose.values, &self.model.keypoints(&self.posed));

        let timing = self.problem.timing;
        rec.timing_us
            .insert("correspondences".into(), timing.callback_us);
        rec.timing_us.insert("solve".into(), timing.solve_us);
        rec.timing_us
            .insert("track".into(), start.elapsed().as_secs_f64() * 1e6);
        rec
    }
}
