//! The per-frame loop of the sphere-mesh tracker (thesis §3.3, Eq. 3.3): warm start from the
//! previous frame, one rigid-only then full Levenberg–Marquardt iterations over the enabled
//! terms (§3.6 "Reproducibility": 7 iterations; htrack/hmodel iterate 1 rigid + 7), temporal
//! history, loss detection and re-initialization ([`hand_model::solver::FrameLoop`]), and the
//! DESIGN.md record of every frame.

use std::time::Instant;

use hand_model::kinematics::Pose;
use hand_model::query::View;
use hand_model::solver::terms::{
    JointLimits, JointLimitsParams, PosePrior, PosePriorParams, Temporal, TemporalParams,
};
use hand_model::solver::{
    digit_variants, placed_rotation, placement_hypotheses, sphere_mesh_points, timed_solve,
    EnergyTerm, FrameLoop, FrameStats, Hypothesis, IrlsParams, LmError, LmOptions, LmSolver,
    LmWorkspace, LossParams, NoTerm, PcaPrior, PriorSetup, SolveTiming, TrackingProblem,
};
use hand_model::spheremesh::{PosedSphereMesh, SphereMeshTemplate};
use nalgebra::{Vector2, Vector3};
use sensor_io::preprocess::{gate_for_noise, slide_for_noise, NoiseMonitor, PreprocessedFrame};
use sensor_io::record::HandRecord;
use serde::{Deserialize, Serialize};

use crate::context::{CorrespondenceCallback, M2dMode, TrackingCtx, DEFAULT_RAY_SLIDE};
use crate::terms::{Collision, CollisionParams, D2m, D2mParams, M2d, M2dParams};

/// Which terms of Eq. 3.3 take part (the `--no-<term>` switches of `hands track`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EnabledTerms {
    /// E_d2m (Eq. 3.4). The thesis never disables it ("immediate loss of tracking").
    pub d2m: bool,
    /// E_m2d (Eq. 3.5); needs a sensor camera in the frame.
    pub m2d: bool,
    /// E_collision.
    pub collision: bool,
    /// E_pose (Eq. 2.5–2.6); needs a prior.
    pub pose_prior: bool,
    /// E_limits (Eq. 2.8).
    pub joint_limits: bool,
    /// E_temporal (Eq. 2.9).
    pub temporal: bool,
}

impl Default for EnabledTerms {
    fn default() -> Self {
        Self {
            d2m: true,
            m2d: true,
            collision: true,
            pose_prior: true,
            joint_limits: true,
            temporal: true,
        }
    }
}

/// The camera model of the front-facing test (§3.3.1 "Monocular Correspondences").
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FrontFacingView {
    /// The thesis: an orthographic camera looking along +z.
    Orthographic,
    /// The sensor's pinhole at the camera-frame origin (exact viewing rays; the silhouette is
    /// still computed orthographically, toward the model's center).
    Perspective,
}

impl FrontFacingView {
    /// The query view of this camera model.
    pub fn view(self) -> View {
        match self {
            Self::Orthographic => View::Orthographic(Vector3::z()),
            Self::Perspective => View::Perspective {
                camera_center: Vector3::zeros(),
            },
        }
    }
}

/// Settings of the tracker, with the thesis defaults (§3.6 "Reproducibility").
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackerConfig {
    /// Levenberg–Marquardt: 1 rigid + 7 full iterations.
    pub lm: LmOptions,
    /// Front-facing correspondences (Fig. 3.9) rather than plain closest points.
    pub front_facing: bool,
    /// The camera of the front-facing test.
    pub view: FrontFacingView,
    /// Along-ray correspondences within this distance (mm) of the ray's entry into the model
    /// ([`TrackingCtx::set_ray_gate`]) on the frames that [`Self::ray_gate_noise`] admits;
    /// `None`: the thesis' closest points everywhere.
    pub ray_gate: Option<f64>,
    /// The measured depth noise σ̂ (mm, [`sensor_io::preprocess::NoiseMonitor`]) from which
    /// the along-ray correspondences run; 0: on every frame. They pay off under noise and
    /// cost about as much as the closest points again, so exact and quantized depth (σ̂ < 1
    /// mm) keep the thesis' rule. Measured in session 31 (`hands track`, noise-free teaser,
    /// 120 frames): 3.6 → 8.8 ms a frame at 0, the keypoint error unchanged (0.15 mm); on 64
    /// noise-free cold starts (the library's motions cut at frames 45–165) the sum of mean
    /// keypoint errors 116.60 → 107.14 mm, but 26 cuts worse against 21 better (a rotating fist
    /// 7.72 → 1.37 mm, `crossing` from frame 150 15.37 → 18.68). Nor do they pay off in the
    /// late iterations alone: from the fourth of eight on, ToF frames of online calibration
    /// cost 13.0 → 10.1 ms, but 74 ToF cold starts went 236.49 → 288.45 mm in sum (online
    /// calibration 233.83 → 286.72; a rotating fist from frame 165 7.71 → 29.43): the first
    /// iterations of a frame need the unbiased registration to converge.
    pub ray_gate_noise: f64,
    /// How far an along-ray footpoint may lie from the closest point (mm,
    /// [`TrackingCtx::set_ray_slide`]), on data of up to `ray_slide / ray_slide_noise` of
    /// measured depth noise.
    pub ray_slide: f64,
    /// Above that noise the slide is this many σ̂ ([`Self::ray_slide_for`]; 0: fixed). Default
    /// 1.5: the 7.5 mm slide was chosen on the ToF model's σ̂ ≈ 5 mm. The limit has a cost on
    /// a palm seen edge-on, where the noise slides many footpoints past it and those points keep
    /// their closest points: online calibration then widens the palm along the rays (the ToF
    /// `occlusion` cut from frame 105: `pinky_base_x` +12.5, `index_base_x` −11.2 mm in 60
    /// frames, mean keypoint error 6.53 mm against 3.30 mm with no limit). Measured in session
    /// 34 on the 74 ToF cold starts (90 frames each, mean keypoint error summed), 1.5 → 2.5:
    /// online calibration 169.88 → 194.53 mm, this tracker 152.60 → 163.76 mm (`random` from
    /// frame 165 4.07 → 15.56); weighting those points 0 instead of keeping their closest
    /// points: 169.88 → 170.38 and 152.60 → 171.97 mm.
    pub ray_slide_noise: f64,
    /// ℓ1 by IRLS (as htrack/hmodel, ANCHOR-FACTS §5.3).
    pub irls: IrlsParams,
    /// How m2d finds the model outside the silhouette.
    pub m2d_mode: M2dMode,
    /// Pixel stride of the m2d rendering ([`TrackingCtx::set_m2d_stride`]).
    pub m2d_stride: u32,
    /// Which terms run.
    pub enabled: EnabledTerms,
    /// τ_d2m.
    pub d2m: D2mParams,
    /// τ_m2d.
    pub m2d: M2dParams,
    /// τ_collision.
    pub collision: CollisionParams,
    /// τ_pose and the form of the PCA prior.
    pub pose_prior: PosePriorParams,
    /// τ_limits.
    pub joint_limits: JointLimitsParams,
    /// Temporal weights.
    pub temporal: TemporalParams,
    /// Loss detection.
    pub loss: LossParams,
}

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
            view: FrontFacingView::Perspective,
            ray_gate: Some(20.0),
            ray_gate_noise: 1.5,
            ray_slide: DEFAULT_RAY_SLIDE,
            ray_slide_noise: 1.5,
            irls: IrlsParams::default(),
            m2d_mode: M2dMode::Render,
            m2d_stride: 1,
            enabled: EnabledTerms::default(),
            d2m: D2mParams::default(),
            m2d: M2dParams::default(),
            collision: CollisionParams::default(),
            pose_prior: PosePriorParams {
                weight_projection: 1e4,
                ..PosePriorParams::default()
            },
            joint_limits: JointLimitsParams::default(),
            temporal: TemporalParams::default(),
            loss: LossParams::default(),
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
    /// An invalid template, term settings or a prior that does not fit the template.
    #[error("model: {0}")]
    Model(#[from] hand_model::ModelError),
}

/// Most terms of one solve.
const MAX_TERMS: usize = 8;

/// The energy terms of Eq. 3.3, built once per sequence.
struct Terms {
    enabled: EnabledTerms,
    d2m: D2m,
    m2d: M2d,
    collision: Collision,
    limits: JointLimits,
    temporal: Temporal,
    prior: Option<PosePrior>,
}

impl Terms {
    /// The enabled terms in hmodel's order (data first, the pose prior last) in a fixed array.
    fn list<'s, 'm>(&'s self) -> ([&'s dyn EnergyTerm<TrackingCtx<'m>>; MAX_TERMS], usize) {
        let mut out: [&dyn EnergyTerm<TrackingCtx<'m>>; MAX_TERMS] = [&NoTerm; MAX_TERMS];
        let mut n = 0;
        let e = &self.enabled;
        let all: [(bool, &'s dyn EnergyTerm<TrackingCtx<'m>>); 5] = [
            (e.d2m, &self.d2m),
            (e.m2d, &self.m2d),
            (e.collision, &self.collision),
            (e.temporal, &self.temporal),
            (e.joint_limits, &self.limits),
        ];
        for (on, t) in all {
            if on {
                out[n] = t;
                n += 1;
            }
        }
        if let (true, Some(p)) = (e.pose_prior, &self.prior) {
            out[n] = p;
            n += 1;
        }
        (out, n)
    }
}

/// The solve of one frame, as [`FrameLoop`] drives it.
struct Problem<'m> {
    /// The template the context borrows (its skeleton drives the pose retraction).
    template: &'m SphereMeshTemplate,
    ctx: TrackingCtx<'m>,
    solver: LmSolver,
    ws: LmWorkspace,
    /// The workspace of [`TrackingProblem::solve_aside`], which leaves `ws`'s report alone.
    ws_aside: LmWorkspace,
    terms: Terms,
    mean_pose: Pose,
    timing: SolveTiming,
}

impl TrackingProblem for Problem<'_> {
    fn solve(&mut self, pose: &mut Pose) -> bool {
        let (list, n) = self.terms.list();
        let sk = &self.template.skeleton;
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

    fn frame_stats(&self, params: &LossParams) -> FrameStats {
        self.ctx.frame_stats(params)
    }

    fn hypotheses(&self) -> Vec<Hypothesis> {
        let arm = self.ctx.sensor().wristband.map(|b| b.axis);
        placement_hypotheses(self.ctx.points(), arm.as_ref(), |e, roll, target| {
            self.placed_mean_pose(e, roll, target)
        })
    }

    fn clear_history(&mut self) {
        self.terms.temporal.clear_history();
    }

    fn digit_variants(&self, pose: &Pose, digit: usize) -> Vec<Pose> {
        digit_variants(&self.template.skeleton, pose, digit)
    }
}

impl Problem<'_> {
    /// The mean pose turned about the optical axis so that the fingers (+y) point along the
    /// image direction `e` and rolled by `roll` about them ([`placed_rotation`]), with the
    /// centroid of the sphere centers on `target`.
    fn placed_mean_pose(&self, e: Vector2<f64>, roll: f64, target: &Vector3<f64>) -> Option<Pose> {
        let t = self.ctx.template();
        let sk = &t.skeleton;
        let mut pose = placed_rotation(&self.mean_pose, sk, e, roll)?;
        let posed = PosedSphereMesh::new(t, &pose);
        let n = posed.spheres.len();
        if n == 0 {
            return None;
        }
        let center = posed.spheres.iter().map(|s| s.center).sum::<Vector3<f64>>() / n as f64;
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

/// The Ch. 3 sphere-mesh tracker: one per sequence (it holds the temporal history and the
/// loss state).
pub struct Tracker<'m> {
    template: &'m SphereMeshTemplate,
    config: TrackerConfig,
    problem: Problem<'m>,
    frames: FrameLoop,
    posed: PosedSphereMesh,
    noise: NoiseMonitor,
}

impl<'m> Tracker<'m> {
    /// A tracker of `template` with `config` and an optional PCA pose prior (E_pose is skipped
    /// without one; its mean gives the initial finger pose).
    pub fn new(
        template: &'m SphereMeshTemplate,
        config: TrackerConfig,
        prior: Option<&PcaPrior>,
    ) -> Result<Self, TrackerError> {
        let sk = &template.skeleton;
        let mut ctx = TrackingCtx::new(template, config.view.view(), config.irls.clone())?;
        ctx.set_front_facing(config.front_facing);
        ctx.set_ray_gate(config.ray_gate_for(None));
        ctx.set_ray_slide(config.ray_slide);
        ctx.set_m2d(config.enabled.m2d.then_some(config.m2d_mode));
        ctx.set_m2d_stride(config.m2d_stride);
        let PriorSetup {
            prior: pose_prior,
            solver,
            mean_pose,
        } = PriorSetup::new::<TrackerError>(sk, prior, &config.pose_prior, &config.lm)?;
        let (ws, ws_aside) = (solver.workspace(), solver.workspace());
        let terms = Terms {
            enabled: config.enabled.clone(),
            d2m: D2m::new(config.d2m.clone()),
            m2d: M2d::new(config.m2d.clone()),
            collision: Collision::new(template, config.collision.clone()),
            limits: JointLimits::new(sk, &config.joint_limits),
            temporal: Temporal::new(sphere_mesh_points(template), &config.temporal),
            prior: pose_prior,
        };
        Ok(Self {
            template,
            frames: FrameLoop::new(mean_pose.clone(), config.loss.clone()),
            posed: PosedSphereMesh::new(template, &mean_pose),
            noise: NoiseMonitor::default(),
            problem: Problem {
                template,
                ctx,
                solver,
                ws_aside,
                ws,
                terms,
                mean_pose,
                timing: SolveTiming::default(),
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

    /// The template.
    pub fn template(&self) -> &'m SphereMeshTemplate {
        self.template
    }

    /// The per-iteration context (correspondences and pushes at the last linearization).
    pub fn context(&self) -> &TrackingCtx<'m> {
        &self.problem.ctx
    }

    /// Start the next frame from `pose` instead of re-initializing; clears the temporal history.
    pub fn set_pose(&mut self, pose: &Pose) -> Result<(), TrackerError> {
        let checked = Pose::from_values(&self.template.skeleton, pose.values.clone())?;
        self.frames.set_pose(checked);
        self.problem.clear_history();
        Ok(())
    }

    /// The along-ray registration and the loss criterion for depth noise `sigma` (mm; `None`:
    /// not measured).
    fn set_noise(&mut self, sigma: Option<f64>) {
        let ctx = &mut self.problem.ctx;
        ctx.set_ray_gate(self.config.ray_gate_for(sigma));
        ctx.set_ray_slide(self.config.ray_slide_for(sigma));
        self.frames.set_noise(sigma);
    }

    /// Load `frame` with depth noise `sigma` for a search from `poses`; false when the frame
    /// has too few points or a pose is not this skeleton's.
    fn load_aside(
        &mut self,
        frame: &PreprocessedFrame,
        poses: &[&Pose],
        sigma: Option<f64>,
    ) -> bool {
        let nd = self.template.skeleton.num_dofs();
        if frame.points.len() < self.frames.loss().min_points.max(1)
            || poses.iter().any(|p| p.values.len() != nd)
        {
            return false;
        }
        self.problem.ctx.set_frame(frame);
        self.set_noise(sigma);
        true
    }

    /// The digit search of the frame loop ([`FrameLoop::search_digits`]) from `pose` on
    /// `frame`, for a caller that drives its own loop: the online calibrator, whose solve moves
    /// the shape too, has its fingers looked at by a tracker of its current template, which the
    /// search then holds fixed. `sigma` is the depth noise the caller measured (mm; `None`: not
    /// measured); it sets the along-ray registration and the loss criterion as in
    /// [`Self::track`]. Returns the better pose and its statistics, or `None` when no variant
    /// fits the frame better (or the frame has too few points, or `pose` is not this
    /// skeleton's). The tracker continues from the pose returned.
    pub fn search_digits(
        &mut self,
        frame: &PreprocessedFrame,
        pose: &Pose,
        sigma: Option<f64>,
    ) -> Option<(Pose, FrameStats)> {
        if !self.load_aside(frame, &[pose], sigma) {
            return None;
        }
        self.frames.search_digits(&mut self.problem, pose.clone())
    }

    /// [`FrameLoop::challenge`] on `frame`: whether `candidate`, a pose the digit search found
    /// on an earlier frame, solved on this one still fits better than `tracked` (the caller's
    /// pose for this frame); the solved candidate and its statistics when it does. `sigma` as in
    /// [`Self::search_digits`]. `None` too when the frame has too few points or a pose is not
    /// this skeleton's.
    pub fn challenge(
        &mut self,
        frame: &PreprocessedFrame,
        tracked: &Pose,
        candidate: &Pose,
        sigma: Option<f64>,
    ) -> Option<(Pose, FrameStats)> {
        if !self.load_aside(frame, &[tracked, candidate], sigma) {
            return None;
        }
        self.frames
            .challenge(&mut self.problem, tracked, candidate.clone())
    }

    /// Track one preprocessed frame and return its DESIGN.md record (pose by DOF name, 21
    /// keypoints, per-term energies of the last linearization, iterations, per-stage µs,
    /// flags `no_hand`, `lost`, `reinitialized`, `solver_failed`). Never returns a non-finite
    /// pose (see [`FrameLoop::step`]).
    pub fn track(&mut self, frame: &PreprocessedFrame, index: u64, timestamp: f64) -> HandRecord {
        let start = Instant::now();
        let mut rec = HandRecord::for_frame(index, timestamp);
        self.problem.timing = SolveTiming::default();
        self.problem.ctx.take_timing();
        let n = frame.points.len();
        if n >= self.frames.loss().min_points.max(1) {
            self.problem.ctx.set_frame(frame);
            if self.noise.observe(&frame.depth, &frame.hand.mask) {
                self.set_noise(self.noise.sigma());
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
            rec.energies
                .insert("outside_fraction".into(), stats.outside);
        }
        let pose = &self.frames.pose;
        self.posed.update(self.template, pose);
        if outcome.stats.is_some() && self.config.enabled.temporal {
            // Cannot fail: the term's points are on this template's bones.
            let _ = self.problem.terms.temporal.push_frame(&self.posed.skeleton);
        }
        let names = self
            .template
            .skeleton
            .dofs()
            .iter()
            .map(|d| d.name.as_str());
        rec.set_pose(names, &pose.values, &self.posed.keypoints(self.template));

        rec.timing_us
            .insert("correspondences".into(), self.problem.timing.callback_us);
        for (stage, us) in self.problem.ctx.take_timing().stages() {
            rec.timing_us.insert(stage.into(), us);
        }
        rec.timing_us
            .insert("solve".into(), self.problem.timing.solve_us);
        rec.timing_us
            .insert("track".into(), start.elapsed().as_secs_f64() * 1e6);
        rec
    }
}
