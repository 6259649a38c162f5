//! The per-frame tracking loop of thesis §2.4 (Fig. 2.3): warm start from the previous frame,
//! one rigid-only then full Levenberg–Marquardt iterations over the enabled terms (Eq. 2.1,
//! Eq. 2.11), temporal history, loss detection and re-initialization, and the DESIGN.md output
//! record of every frame.
//!
//! # Loss detection and re-initialization (what is built, what is not)
//! htrack's `TrackingMonitor` fed a logistic of push/pull errors into a 10-frame window and then
//! re-initialized with QianDetection (ANCHOR-FACTS §5.7). Here a frame *fails* when, after the
//! solve, the mean distance of the sensor points to the model exceeds
//! [`LossParams::max_mean_distance`] or more than [`LossParams::max_unexplained`] of them lie
//! farther than [`LossParams::unexplained_distance`]; tracking is *lost* after
//! [`LossParams::window`] consecutive failed frames. The re-initializer is not Qian et al.'s
//! fingertip detector: it runs short rigid-then-full solves from a few hypotheses — the current
//! pose, and the mean pose (PCA mean, §2.3.2) placed on the point cloud's centroid with its
//! fingers along the cloud's principal image axis (both signs) or upright — and keeps the one
//! that explains the points best. The current pose is always a candidate, so re-initialization
//! never makes the fit worse by this measure.

use std::time::Instant;

use hand_model::cylinder::{CylinderModel, View};
use hand_model::kinematics::{Pose, PosedSkeleton};
use hand_model::solver::terms::{
    JointLimits, JointLimitsParams, PosePrior, PosePriorParams, Temporal, TemporalParams,
};
use hand_model::solver::{
    cylinder_points, placement_directions, EnergyTerm, FrameStats, IterInfo, LmCallback, LmError,
    LmOptions, LmSolver, LmWorkspace, LossParams, PcaPrior, TermError,
};
use nalgebra::{Vector2, Vector3};
use sensor_io::preprocess::PreprocessedFrame;
use sensor_io::record::HandRecord;
use serde::{Deserialize, Serialize};

use crate::context::{CorrespondenceCallback, TrackingCtx};
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
        }
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

/// [`CorrespondenceCallback`], timed: the correspondence stage (re-pose, front-facing
/// correspondences, IRLS weights, silhouette raster) inside the solver's per-iteration callback.
struct TimedCallback {
    correspondences_us: f64,
}

impl LmCallback<TrackingCtx<'_>> for TimedCallback {
    fn prepare(
        &mut self,
        pose: &Pose,
        ctx: &mut TrackingCtx<'_>,
        info: IterInfo,
    ) -> Result<(), TermError> {
        let t = Instant::now();
        let r = CorrespondenceCallback.prepare(pose, ctx, info);
        self.correspondences_us += t.elapsed().as_secs_f64() * 1e6;
        r
    }
}

/// A term that adds nothing: fills the unused slots of the per-frame term list.
struct NoTerm;

impl EnergyTerm<TrackingCtx<'_>> for NoTerm {
    fn name(&self) -> &'static str {
        "none"
    }
    fn accumulate(
        &self,
        _: &TrackingCtx<'_>,
        _: &mut hand_model::solver::NormalEquations,
    ) -> Result<hand_model::solver::TermStats, TermError> {
        Ok(hand_model::solver::TermStats::ZERO)
    }
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

/// The Ch. 2 tracker: one per sequence (it holds the temporal history and the loss state).
pub struct Tracker<'m> {
    model: &'m CylinderModel,
    config: TrackerConfig,
    ctx: TrackingCtx<'m>,
    solver: LmSolver,
    ws: LmWorkspace,
    terms: Terms,
    /// The PCA mean pose (zeros without a prior) at the identity global transform.
    mean_pose: Pose,
    pose: Pose,
    best: Pose,
    posed: PosedSkeleton,
    initialized: bool,
    failed_run: usize,
}

impl<'m> Tracker<'m> {
    /// A tracker of `model` with `config` and an optional PCA pose prior (E_pose is skipped
    /// without one). The prior's mean also gives the initial finger pose (§2.3.2).
    pub fn new(
        model: &'m CylinderModel,
        config: TrackerConfig,
        prior: Option<&PcaPrior>,
    ) -> Result<Self, TrackerError> {
        let sk = &model.skeleton;
        let mut ctx = TrackingCtx::new(model, View::Orthographic, config.irls.clone());
        ctx.set_front_facing(config.front_facing);
        ctx.set_silhouette(config.enabled.e2d);
        let pose_prior = prior
            .map(|p| PosePrior::new(sk, p, &config.pose_prior))
            .transpose()?;
        let num_aux = pose_prior.as_ref().map_or(0, PosePrior::num_aux);
        let solver = LmSolver::new(sk, num_aux, config.lm.clone())?;
        let ws = solver.workspace();
        let mut mean_pose = Pose::zeros(sk);
        for g in prior.iter().flat_map(|p| &p.groups) {
            for (name, &m) in g.dofs.iter().zip(&g.mean) {
                mean_pose.set(sk, name, m)?;
            }
        }
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
            ctx,
            solver,
            ws,
            terms,
            pose: mean_pose.clone(),
            best: mean_pose.clone(),
            posed: PosedSkeleton::new(sk, &mean_pose),
            mean_pose,
            config,
            initialized: false,
            failed_run: 0,
        })
    }

    /// The current pose θ.
    pub fn pose(&self) -> &Pose {
        &self.pose
    }

    /// The settings.
    pub fn config(&self) -> &TrackerConfig {
        &self.config
    }

    /// The model.
    pub fn model(&self) -> &'m CylinderModel {
        self.model
    }

    /// The per-iteration context (sensor points and their correspondences at the last
    /// linearization), for visual checks such as `hands track --overlay`.
    pub fn context(&self) -> &TrackingCtx<'m> {
        &self.ctx
    }

    /// Start the next frame from `pose` (e.g. a known initial pose) instead of
    /// re-initializing; clears the temporal history.
    pub fn set_pose(&mut self, pose: &Pose) -> Result<(), TrackerError> {
        let checked = Pose::from_values(&self.model.skeleton, pose.values.clone())?;
        self.pose = checked;
        self.initialized = true;
        self.failed_run = 0;
        self.terms.temporal.clear_history();
        Ok(())
    }

    /// Track one preprocessed frame and return its DESIGN.md record (pose by DOF name, 21
    /// keypoints, per-term energies of the last linearization, iterations, per-stage µs,
    /// flags `no_hand`, `lost`, `reinitialized`, `solver_failed`).
    ///
    /// Never returns a non-finite pose: a frame without enough sensor points keeps the
    /// previous pose (`no_hand`) and the next frame re-initializes; a failed solve reverts to
    /// the previous pose (`solver_failed`).
    pub fn track(&mut self, frame: &PreprocessedFrame, index: u64, timestamp: f64) -> HandRecord {
        let start = Instant::now();
        let mut rec = HandRecord {
            frame: index,
            timestamp: if timestamp.is_finite() {
                timestamp
            } else {
                0.0
            },
            ..HandRecord::default()
        };
        let mut timing = StageTimes::default();
        let enough = frame.points.len() >= self.config.loss.min_points.max(1);
        if !enough {
            rec.flags.push("no_hand".into());
            self.initialized = false;
            self.failed_run = 0;
            self.terms.temporal.clear_history();
        } else {
            self.ctx.set_frame(frame);
            if !self.initialized {
                self.reinitialize(&mut timing);
                rec.flags.push("reinitialized".into());
            } else {
                let ok = self.solve_from_current(&mut timing);
                if !ok {
                    rec.flags.push("solver_failed".into());
                }
            }
            let mut stats = self.frame_stats();
            if stats.failed {
                self.failed_run += 1;
                if self.failed_run >= self.config.loss.window {
                    self.reinitialize(&mut timing);
                    if !rec.flags.iter().any(|f| f == "reinitialized") {
                        rec.flags.push("reinitialized".into());
                    }
                    self.failed_run = 0;
                    stats = self.frame_stats();
                }
            } else {
                self.failed_run = 0;
            }
            if stats.failed {
                rec.flags.push("lost".into());
            }
            rec.iterations = Some(self.ws.report().iterations as u32);
            for t in &self.ws.report().terms {
                if t.energy.is_finite() {
                    *rec.energies.entry(t.name.to_string()).or_default() += t.energy;
                }
            }
            rec.energies
                .insert("mean_distance_mm".into(), stats.mean_distance);
            self.initialized = true;
        }
        self.posed.update(&self.model.skeleton, &self.pose);
        if enough && self.config.enabled.temporal {
            // Cannot fail: the term's points are on this model's bones.
            let _ = self.terms.temporal.push_frame(&self.posed);
        }
        for (name, v) in self.model.skeleton.dofs().iter().zip(&self.pose.values) {
            rec.pose.insert(name.name.clone(), *v);
        }
        rec.keypoints = self
            .model
            .keypoints(&self.posed)
            .iter()
            .map(|k| [k.x, k.y, k.z])
            .collect();
        timing.total_us = start.elapsed().as_secs_f64() * 1e6;
        timing.write(&mut rec.timing_us);
        rec
    }

    /// LM from the current pose (warm start); false (and the pose unchanged) when the solve
    /// failed or left a non-finite pose.
    fn solve_from_current(&mut self, timing: &mut StageTimes) -> bool {
        let mut trial = self.pose.clone();
        let ok = self.solve(&mut trial, timing);
        if ok {
            self.pose = trial;
        }
        ok
    }

    /// One LM solve from `pose` over the enabled terms.
    fn solve(&mut self, pose: &mut Pose, timing: &mut StageTimes) -> bool {
        let (list, n) = self.terms.list();
        let mut cb = TimedCallback {
            correspondences_us: 0.0,
        };
        let t = Instant::now();
        let result = self.solver.solve(
            &mut self.ws,
            &self.model.skeleton,
            pose,
            &mut self.ctx,
            &list[..n],
            &mut cb,
        );
        let total = t.elapsed().as_secs_f64() * 1e6;
        timing.correspondences_us += cb.correspondences_us;
        timing.solve_us += total - cb.correspondences_us;
        let finite = pose.values.iter().all(|v| v.is_finite());
        matches!(result, Ok(r) if r.termination.was_successful()) && finite
    }

    /// Distances of the sensor points to the model at the last linearization point (the pose
    /// before the last LM update: the last step is small, and this saves a correspondence pass).
    fn frame_stats(&self) -> FrameStats {
        let distances = self
            .ctx
            .correspondences()
            .iter()
            .zip(self.ctx.points())
            .map(|(c, x)| c.as_ref().map(|c| (c.point - x).norm()));
        FrameStats::from_distances(distances, &self.config.loss)
    }

    /// Re-initialize (module docs): solve from every hypothesis, keep the best; clears the
    /// temporal history.
    fn reinitialize(&mut self, timing: &mut StageTimes) {
        self.terms.temporal.clear_history();
        let mut best_score = f64::INFINITY;
        let hypotheses = self.hypotheses();
        let candidates = self
            .initialized
            .then(|| self.pose.clone())
            .into_iter()
            .chain(hypotheses);
        for mut pose in candidates {
            if !self.solve(&mut pose, timing) {
                continue;
            }
            // Refresh the correspondences at the solution before scoring.
            if self.ctx.update(&pose, false).is_err() {
                continue;
            }
            let s = self.frame_stats().score();
            if s < best_score {
                best_score = s;
                self.best.values.clone_from(&pose.values);
            }
        }
        if best_score.is_finite() {
            self.pose.values.clone_from(&self.best.values);
        } else {
            self.pose.values.clone_from(&self.mean_pose.values);
        }
        // Leave the context at the chosen pose for the frame statistics.
        let _ = self.ctx.update(&self.pose, false);
    }

    /// Initial poses from the point cloud: the mean pose with its palm on the cloud's centroid
    /// (10 mm behind the visible surface), fingers along ± the principal image axis of the
    /// cloud, or upright (fingers toward image −y).
    fn hypotheses(&self) -> Vec<Pose> {
        let (centroid, dirs) = placement_directions(self.ctx.points());
        let target = centroid + Vector3::new(0.0, 0.0, 10.0);
        dirs.into_iter()
            .filter_map(|e| self.placed_mean_pose(e, &target))
            .collect()
    }

    /// The mean pose rotated about the optical axis so that the model's +y (fingers) maps to
    /// the image direction `e`, translated so that the palm center lands on `target`.
    fn placed_mean_pose(&self, e: Vector2<f64>, target: &Vector3<f64>) -> Option<Pose> {
        let sk = &self.model.skeleton;
        let mut pose = self.mean_pose.clone();
        // R_z(a)·ŷ = (−sin a, cos a, 0) = e.
        let a = (-e.x).atan2(e.y);
        pose.set(sk, "global_rz", a).ok()?;
        let posed = PosedSkeleton::new(sk, &pose);
        let palm = self
            .model
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

/// Wall time of the tracker's stages within one frame (µs).
#[derive(Clone, Debug, Default)]
struct StageTimes {
    correspondences_us: f64,
    solve_us: f64,
    total_us: f64,
}

impl StageTimes {
    fn write(&self, out: &mut std::collections::BTreeMap<String, f64>) {
        out.insert("correspondences".into(), self.correspondences_us);
        out.insert("solve".into(), self.solve_us);
        out.insert("track".into(), self.total_us);
    }
}
