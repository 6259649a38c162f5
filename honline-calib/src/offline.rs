//! The joint multi-frame (batch, offline) baselines of thesis §4.3.4: the per-frame problem of
//! Eq. 4.2 ([`crate::OnlineCalibrator`]'s terms without E_temporal and E_iekf) stacked over
//! frames sub-sampled at ≈ 1/20 ([`subsample`]), each frame `n` with its own pose `θ_n`
//! (initialized from tracking), solved by one Levenberg–Marquardt over all unknowns.
//!
//! - **Offline-Hard** (Eq. 4.12): `argmin_{β, {θ_n}} Σ_n Σ_τ E_τ(d_n, [θ_n, β])` — one β shared
//!   by every frame, initialized with a single β⁰ (the template).
//! - **Offline-Soft** (Eq. 4.13): `argmin_{β, {β_n}, {θ_n}} Σ_n Σ_τ E_τ(d_n, [θ_n, β_n]) +
//!   ω_β Σ_n ‖β_n − β‖²` — a shape per frame tied to the common β by a soft penalty
//!   (ω_β = 10e4 = 1e5 per mm²), the `β_n⁰` from the per-frame optimization of Eq. 4.2.
//!
//! # The system
//! Frames couple only through the shared unknowns, so the normal equations are block-arrow
//! ([`BlockArrow`]): per frame a block of `[θ_n | PCA latents | β̃_n]` (Hard) or
//! `[θ_n | PCA latents | β_n | β̃_n]` (Soft), bordered by the shared β (the active entries of
//! [`crate::ShapeSubset`]); each step is solved by the Schur complement of the frame blocks with
//! faer, linear in the number of frames. Steps are accepted only when the total energy (the
//! terms re-linearized at the candidate: new correspondences) decreases; the damping
//! `A_ii += λ·A_ii` follows Nielsen's rule.
//!
//! # Choices where the thesis is silent
//! - Every term of Eq. 4.2 enters once per frame, as the sums of Eq. 4.12–4.13 are written:
//!   the shape-space prior (Eq. 4.14), the validity barriers (Eq. 4.15) and the β bounds count
//!   `N` times in Offline-Hard, once per `β_n` in Offline-Soft. So Offline-Soft tends to
//!   Offline-Hard as ω_β → ∞ (the tests measure it from the same start).
//! - The latent β̃ of Eq. 4.14 is an auxiliary unknown of each frame's prior (`β̃_n`). At any β
//!   the optimal `β̃_n` of all frames agree, so sharing it in Offline-Hard would change nothing
//!   but the block structure.
//! - The certainty of the result is the data terms' information about the shape, each frame's
//!   pose marginalized ([`crate::marginal_information`], Eq. 4.5), summed over the frames — for
//!   Offline-Hard exactly the Schur complement of the batch data Hessian. The frames are
//!   already sub-sampled at the online estimator's measurement rate, so it is not scaled
//!   (the online calibrator scales every frame's by 1/20 instead).
//! - Every iterate is a valid model: a candidate whose β (shared or per frame) leaves the
//!   bounds is clamped, one the basis refuses is rejected like a step that raises the energy.
//! - Likewise the poses are projected onto the joint limits after every step. E_limits is
//!   one-sided: a linearization inside the limits does not see it, so a step across a limit
//!   would be rejected at its weight (1e7) and the damping would climb by orders of magnitude
//!   (measured: Offline-Hard then needed twice the iterations).

use std::time::Instant;

use hand_model::kinematics::Pose;
use hand_model::solver::{NormalEquations, PcaPrior, TermError};
use hand_model::spheremesh::SphereMeshTemplate;
use hmodel_spheremesh::calibration::{BlockArrow, Unknown};
use nalgebra::{DMatrix, DVector};
use sensor_io::preprocess::PreprocessedFrame;
use serde::{Deserialize, Serialize};

use crate::filter::{Estimator, ShapeBelief};
use crate::frame::{step_latent, FrameProblem};
use crate::online::{OnlineCalibrator, OnlineConfig, OnlineError};
use crate::terms::OnlineCtx;

/// The thesis' sub-sampling of the sequence for the offline calibrations (§4.3.4, "≈ 1/20",
/// also the online estimator's measurement rate).
pub const SUBSAMPLING: usize = 20;

/// Fewer frames cannot separate shape from pose (one frame is the per-frame problem).
pub const MIN_FRAMES: usize = 2;

/// Which offline calibration (thesis §4.3.4).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Offline {
    /// Offline-Hard (Eq. 4.12): one β shared by every frame.
    Hard,
    /// Offline-Soft (Eq. 4.13, the default): a β_n per frame tied to the common β by
    /// `ω_β ‖β_n − β‖²`.
    #[default]
    Soft,
}

impl std::str::FromStr for Offline {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "offline-hard" | "hard" => Ok(Self::Hard),
            "offline-soft" | "soft" => Ok(Self::Soft),
            other => Err(format!(
                "unknown offline calibration `{other}` (expected offline-hard or offline-soft)"
            )),
        }
    }
}

impl std::fmt::Display for Offline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Hard => "offline-hard",
            Self::Soft => "offline-soft",
        })
    }
}

/// Where Offline-Soft's per-frame shapes `β_n⁰` start.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SoftStart {
    /// The thesis: the per-frame optimization of Eq. 4.2 ([`Estimator::PerFrame`] over the
    /// selected frames in order, each from its tracked pose and the previous frame's β); the
    /// common β⁰ is their mean, its poses the per-frame solves'.
    #[default]
    PerFrame,
    /// Every `β_n⁰` and β⁰ at the template, the poses as given (Offline-Hard's start).
    Template,
}

/// Settings of the offline calibrations.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OfflineConfig {
    /// Offline-Hard or Offline-Soft.
    pub method: Offline,
    /// The per-frame terms and weights (Eq. 4.2, 4.14, 4.15, the β bounds and damping, the
    /// tracker's terms and correspondence settings, `min_points`); the estimator fields only
    /// matter to [`SoftStart::PerFrame`], which runs the per-frame estimator.
    pub frame: OnlineConfig,
    /// ω_β of Eq. 4.13, per mm² (thesis: 10e4).
    pub omega_beta: f64,
    /// Offline-Soft's start.
    pub soft_start: SoftStart,
    /// Most LM iterations (accepted or not; honline's batch solver ran 100 offline).
    pub iterations: usize,
    /// Initial LM damping, relative to the diagonal.
    pub lambda: f64,
    /// Stop when an accepted step lowers the energy by less than this fraction.
    pub tolerance: f64,
}

impl Default for OfflineConfig {
    fn default() -> Self {
        Self {
            method: Offline::Soft,
            frame: OnlineConfig::default(),
            omega_beta: 1e5,
            soft_start: SoftStart::PerFrame,
            iterations: 50,
            lambda: 1e-3,
            tolerance: 1e-5,
        }
    }
}

impl OfflineConfig {
    /// Check the fields the offline solve adds.
    pub fn validate(&self) -> Result<(), OfflineError> {
        let bad = |name: &str, v: f64, positive: bool| {
            let ok = v.is_finite() && if positive { v > 0.0 } else { v >= 0.0 };
            (!ok).then(|| {
                let need = if positive { "positive" } else { "non-negative" };
                OfflineError::Config(format!("`{name}` must be finite and {need}, got {v}"))
            })
        };
        bad("omega_beta", self.omega_beta, false)
            .or_else(|| bad("lambda", self.lambda, true))
            .or_else(|| bad("tolerance", self.tolerance, false))
            .map_or(Ok(()), Err)
    }
}

/// Why an offline calibration could not run.
#[derive(Debug, thiserror::Error)]
pub enum OfflineError {
    /// Not one initial pose per frame.
    #[error("{frames} frame(s) and {poses} initial pose(s): offline calibration needs one pose per frame (from tracking)")]
    PoseCount {
        /// Frames given.
        frames: usize,
        /// Poses given.
        poses: usize,
    },
    /// Too few frames.
    #[error("{found} frame(s): offline calibration needs at least {needed} in different poses (thesis §4.3.4; sub-sample a sequence at ≈ 1/20)")]
    TooFewFrames {
        /// Frames given.
        found: usize,
        /// [`MIN_FRAMES`].
        needed: usize,
    },
    /// A frame without enough finite points.
    #[error(
        "frame {frame} has {points} finite points, fewer than {needed}: no hand to calibrate on"
    )]
    NoHand {
        /// Its position in the given frames.
        frame: usize,
        /// Its finite points.
        points: usize,
        /// `min_points` of the settings.
        needed: usize,
    },
    /// An initial pose of the wrong length or with a non-finite value.
    #[error("initial pose {frame}: {reason}")]
    Pose {
        /// Its position.
        frame: usize,
        /// What is wrong.
        reason: String,
    },
    /// A frame's terms cannot be evaluated at the initial state.
    #[error("frame {frame}: {source}")]
    Term {
        /// Its position.
        frame: usize,
        /// The term's or the context's error.
        #[source]
        source: TermError,
    },
    /// Invalid settings.
    #[error("invalid offline settings: {0}")]
    Config(String),
    /// The per-frame problem cannot be built (template, prior, solver options).
    #[error(transparent)]
    Online(#[from] OnlineError),
}

/// One LM iteration of an offline calibration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OfflineIteration {
    /// Total energy at the candidate (∞ when its shape was refused or the damped system could
    /// not be solved).
    pub energy: f64,
    /// Its part per term over the frames (`data` = E_d2m + E_m2d, `collision`,
    /// `joint_limits`, `pose_prior`, `shape_prior` with the β bounds, `shape_valid`), and
    /// `coupling`, `ω_β Σ ‖β_n − β‖²` (Offline-Soft); empty when the candidate was refused.
    pub terms: Vec<(String, f64)>,
    /// The damping λ of the step.
    pub lambda: f64,
    /// Whether the step was accepted.
    pub accepted: bool,
    /// Wall time (ms).
    pub ms: f64,
}

/// The result of an offline calibration.
#[derive(Clone, Debug)]
pub struct OfflineCalibration {
    /// Which one ran.
    pub method: Offline,
    /// The calibrated β (the shared one; full basis order, inactive entries at the template).
    pub beta: Vec<f64>,
    /// The template at [`OfflineCalibration::beta`] (the input of `hands track --template`).
    pub template: SphereMeshTemplate,
    /// The active entries: mean β and the information matrix (module docs: the frames' data
    /// information about the shape, poses marginalized; per mm²).
    pub belief: ShapeBelief,
    /// The certainty per β entry: the diagonal of the information (full basis order, 0 for
    /// inactive entries).
    pub certainty: Vec<f64>,
    /// Per frame its shape `β_n` (Offline-Hard: β).
    pub frame_betas: Vec<Vec<f64>>,
    /// Per frame its pose `θ_n`.
    pub poses: Vec<Pose>,
    /// The energy at the start of the LM (for Offline-Soft after the per-frame start).
    pub initial_energy: f64,
    /// Every LM iteration.
    pub iterations: Vec<OfflineIteration>,
    /// Total wall time (s), the per-frame start included.
    pub seconds: f64,
}

impl OfflineCalibration {
    /// The energy of the result: the lowest accepted one, or the initial one.
    pub fn final_energy(&self) -> f64 {
        self.iterations
            .iter()
            .filter(|r| r.accepted)
            .map(|r| r.energy)
            .fold(self.initial_energy, f64::min)
    }

    /// The number of accepted LM steps.
    pub fn accepted_steps(&self) -> usize {
        self.iterations.iter().filter(|r| r.accepted).count()
    }
}

/// Frames sub-sampled at ≈ 1/`interval` (thesis §4.3.4): in every window of `interval`
/// consecutive frames, the first one that is `usable` (tracked, with a hand). `interval` 0 is
/// taken as 1.
pub fn subsample(usable: &[bool], interval: usize) -> Vec<usize> {
    let interval = interval.max(1);
    usable
        .chunks(interval)
        .enumerate()
        .filter_map(|(w, chunk)| chunk.iter().position(|&u| u).map(|i| w * interval + i))
        .collect()
}

/// The unknowns of the batch at one iterate.
#[derive(Clone)]
struct State {
    poses: Vec<Pose>,
    /// Per frame its β (Offline-Hard: all equal to `shared`).
    betas: Vec<Vec<f64>>,
    /// Per frame its β̃.
    latents: Vec<[f64; 3]>,
    /// The common β (full basis order).
    shared: Vec<f64>,
}

/// The system and energies of one linearization.
struct Linearization {
    system: BlockArrow,
    energy: f64,
    /// Per term its energy over the frames (see [`OfflineIteration::terms`]).
    terms: Vec<(String, f64)>,
}

/// The stacked problem: the per-frame terms, a context per frame and the index map.
struct Batch<'a> {
    problem: &'a FrameProblem,
    method: Offline,
    omega: f64,
    ctxs: Vec<OnlineCtx>,
    /// Per unknown of the per-frame layout, where it lives in the [`BlockArrow`].
    map: Vec<Unknown>,
    frame_dim: usize,
    ne: NormalEquations,
}

impl<'a> Batch<'a> {
    fn new(
        problem: &'a FrameProblem,
        config: &OfflineConfig,
        frames: &[PreprocessedFrame],
    ) -> Result<Self, OfflineError> {
        let layout = &problem.layout;
        let (map, frame_dim): (Vec<Unknown>, usize) = match config.method {
            Offline::Soft => (
                (0..layout.dim()).map(Unknown::Frame).collect(),
                layout.dim(),
            ),
            Offline::Hard => (
                (0..layout.dim())
                    .map(|i| {
                        if i < layout.beta {
                            Unknown::Frame(i)
                        } else if i < layout.latent {
                            Unknown::Shared(i - layout.beta)
                        } else {
                            Unknown::Frame(layout.beta + i - layout.latent)
                        }
                    })
                    .collect(),
                layout.beta + 3,
            ),
        };
        let ctxs = frames
            .iter()
            .map(|f| {
                let mut ctx = problem.context(&config.frame.tracker)?;
                ctx.tracking.set_frame(f);
                Ok(ctx)
            })
            .collect::<Result<_, OfflineError>>()?;
        Ok(Self {
            problem,
            method: config.method,
            omega: config.omega_beta,
            ctxs,
            map,
            frame_dim,
            ne: NormalEquations::new(layout.dim()),
        })
    }

    /// Put frame `f`'s context at `state` (reshape, re-pose, correspondences).
    fn prepare(&mut self, f: usize, state: &State) -> Result<(), TermError> {
        let ctx = &mut self.ctxs[f];
        if ctx.beta != state.betas[f] {
            ctx.beta.clone_from(&state.betas[f]);
            ctx.dirty = true;
        }
        ctx.latent = state.latents[f];
        self.problem.prepare(ctx, &state.poses[f], false)
    }

    /// Linearize every frame's terms at `state` into the block-arrow system (Eq. 4.12), plus
    /// the coupling of Eq. 4.13 for Offline-Soft. The error names the frame.
    fn linearize(&mut self, state: &State) -> Result<Linearization, (usize, TermError)> {
        let layout = &self.problem.layout;
        let k = layout.active.len();
        let mut system = BlockArrow::new(self.ctxs.len(), self.frame_dim, k);
        let terms = self.problem.terms(None, None);
        let mut parts: Vec<(String, f64)> = terms
            .as_slice()
            .iter()
            .map(|t| (t.name().to_string(), 0.0))
            .collect();
        for f in 0..self.ctxs.len() {
            self.prepare(f, state).map_err(|e| (f, e))?;
            self.ne.clear();
            for (term, part) in terms.as_slice().iter().zip(&mut parts) {
                let stats = term
                    .accumulate(&self.ctxs[f], &mut self.ne)
                    .map_err(|e| (f, e))?;
                part.1 += stats.energy;
            }
            self.ne.symmetrize();
            if !self.ne.is_finite() {
                return Err((f, TermError::Failed("the frame's system is not finite")));
            }
            system.add_system(f, &self.map, self.ne.lhs(), self.ne.rhs());
        }
        let mut coupling = 0.0;
        if self.method == Offline::Soft {
            let w = self.omega;
            for (f, beta) in state.betas.iter().enumerate() {
                for (j, &i) in layout.active.iter().enumerate() {
                    let (own, common) = (Unknown::Frame(layout.beta_index(j)), Unknown::Shared(j));
                    let r = beta[i] - state.shared[i];
                    system.add_symmetric(f, own, own, w);
                    system.add_symmetric(f, common, common, w);
                    system.add_symmetric(f, own, common, -w);
                    system.add_rhs(f, own, -w * r);
                    system.add_rhs(f, common, w * r);
                    coupling += w * r * r;
                }
            }
        }
        if self.method == Offline::Soft {
            parts.push(("coupling".to_string(), coupling));
        }
        let energy: f64 = parts.iter().map(|p| p.1).sum();
        if !energy.is_finite() || !system.is_finite() {
            return Err((0, TermError::Failed("the batch system is not finite")));
        }
        Ok(Linearization {
            system,
            energy,
            terms: parts,
        })
    }

    /// `state ⊞ δ` (flat layout of the system), the poses projected onto the joint limits and
    /// the shapes onto the β bounds; `None` when a pose is not finite or a shape is refused.
    fn step(&self, state: &State, delta: &DVector<f64>, system: &BlockArrow) -> Option<State> {
        let layout = &self.problem.layout;
        let (nd, k) = (layout.num_dofs, layout.active.len());
        let sk = &self.problem.base.skeleton;
        let slice = |f: usize, u: Unknown, len: usize| {
            let o = system.flat_index(f, u);
            delta.as_slice().get(o..o + len)
        };
        let mut next = state.clone();
        let mut scratch = Vec::new();
        let shared_delta = slice(0, Unknown::Shared(0), k)?;
        if !self
            .problem
            .step_beta(&state.shared, shared_delta, &mut scratch)
        {
            return None;
        }
        next.shared.clone_from(&scratch);
        for f in 0..state.poses.len() {
            next.poses[f] = state.poses[f].retract(sk, slice(f, Unknown::Frame(0), nd)?);
            next.poses[f].clamp_to_limits(sk);
            if !next.poses[f].values.iter().all(|v| v.is_finite()) {
                return None;
            }
            let latent_at = match self.method {
                Offline::Hard => layout.beta,
                Offline::Soft => layout.latent,
            };
            next.latents[f] =
                step_latent(state.latents[f], slice(f, Unknown::Frame(latent_at), 3)?)?;
            match self.method {
                Offline::Hard => next.betas[f].clone_from(&next.shared),
                Offline::Soft => {
                    let own = slice(f, Unknown::Frame(layout.beta), k)?;
                    if !self.problem.step_beta(&state.betas[f], own, &mut scratch) {
                        return None;
                    }
                    next.betas[f].clone_from(&scratch);
                }
            }
        }
        Some(next)
    }

    /// Σ_n of the frames' data information about their shape, poses marginalized (module docs),
    /// at `state`.
    fn information(&mut self, state: &State) -> DMatrix<f64> {
        let k = self.problem.layout.active.len();
        let mut info = DMatrix::zeros(k, k);
        for f in 0..self.ctxs.len() {
            if self.prepare(f, state).is_err() {
                continue;
            }
            if let Some(h) = self.problem.data_information(&self.ctxs[f], &mut self.ne) {
                info += h;
            }
        }
        info
    }
}

/// The frames with their non-finite points dropped; an error for one with fewer than `needed`.
fn finite_frames(
    frames: &[PreprocessedFrame],
    needed: usize,
) -> Result<Vec<PreprocessedFrame>, OfflineError> {
    frames
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let mut out = f.clone();
            out.points.retain(|p| p.iter().all(|v| v.is_finite()));
            if out.points.len() < needed {
                return Err(OfflineError::NoHand {
                    frame: i,
                    points: out.points.len(),
                    needed,
                });
            }
            Ok(out)
        })
        .collect()
}

/// Offline-Soft's start by the per-frame optimization of Eq. 4.2 ([`SoftStart::PerFrame`]):
/// per frame its mode β*_n and the refined pose (the tracked pose and the previous β where a
/// frame's solve fails).
fn per_frame_start(
    base: &SphereMeshTemplate,
    from_start: bool,
    config: &OfflineConfig,
    prior: Option<&PcaPrior>,
    frames: &[PreprocessedFrame],
    state: &mut State,
) -> Result<(), OfflineError> {
    let online = OnlineConfig {
        estimator: Estimator::PerFrame,
        ..config.frame.clone()
    };
    let mut calib = OnlineCalibrator::new(base, online, prior)?;
    if from_start {
        calib.set_shape(&state.shared)?;
    }
    let mut beta = state.shared.clone();
    for (f, frame) in frames.iter().enumerate() {
        calib.set_pose(&state.poses[f])?;
        let out = calib.track(frame, f as u64, 0.0);
        if out.solved {
            beta.clone_from(&out.frame_beta);
            state.poses[f] = calib.pose().clone();
        }
        state.betas[f].clone_from(&beta);
    }
    Ok(())
}

/// Offline-Hard or Offline-Soft calibration of `base` ([`OfflineConfig::method`], module docs)
/// on `frames` (already sub-sampled, e.g. by [`subsample`]) from the tracked `poses`, with an
/// optional PCA pose prior (as the tracker's), starting from the base template's shape.
///
/// Errors: fewer than [`MIN_FRAMES`] frames, a pose count or pose that does not match, a frame
/// without a hand (fewer than `min_points` finite points), invalid settings, a template without
/// the honline β basis, a frame whose terms fail at the start. Otherwise every output is finite
/// and a valid model.
pub fn calibrate_offline(
    base: &SphereMeshTemplate,
    frames: &[PreprocessedFrame],
    poses: &[Pose],
    config: &OfflineConfig,
    prior: Option<&PcaPrior>,
) -> Result<OfflineCalibration, OfflineError> {
    calibrate_offline_from(base, None, frames, poses, config, prior)
}

/// [`calibrate_offline`] starting from the shape `start` (all entries of the basis, mm; `None`:
/// the base template's), e.g. the perturbed initializations of thesis §4.4.3. The shape-space
/// prior and the β bounds stay the base template's. A `start` of the wrong length or that the
/// basis refuses is an [`OfflineError::Config`].
pub fn calibrate_offline_from(
    base: &SphereMeshTemplate,
    start: Option<&[f64]>,
    frames: &[PreprocessedFrame],
    poses: &[Pose],
    config: &OfflineConfig,
    prior: Option<&PcaPrior>,
) -> Result<OfflineCalibration, OfflineError> {
    let clock = Instant::now();
    config.validate()?;
    if frames.len() != poses.len() {
        return Err(OfflineError::PoseCount {
            frames: frames.len(),
            poses: poses.len(),
        });
    }
    if frames.len() < MIN_FRAMES {
        return Err(OfflineError::TooFewFrames {
            found: frames.len(),
            needed: MIN_FRAMES,
        });
    }
    let nd = base.skeleton.num_dofs();
    for (f, p) in poses.iter().enumerate() {
        let reason = if p.values.len() != nd {
            format!("{} values, the skeleton has {nd} DOFs", p.values.len())
        } else if !p.values.iter().all(|v| v.is_finite()) {
            "a value is not finite".to_string()
        } else {
            continue;
        };
        return Err(OfflineError::Pose { frame: f, reason });
    }
    let frames = finite_frames(frames, config.frame.min_points.max(1))?;
    let problem = FrameProblem::new(base, &config.frame, prior)?;
    let mut template_beta = problem.basis.template_values();
    if let Some(beta) = start {
        let mut beta = beta.to_vec();
        if beta.len() != template_beta.len() || !problem.project(&mut beta) {
            return Err(OfflineError::Config(format!(
                "the start shape ({} values for {} parameters) is not a valid model",
                beta.len(),
                template_beta.len()
            )));
        }
        template_beta = beta;
    }
    let n = frames.len();
    let mut state = State {
        poses: poses.to_vec(),
        betas: vec![template_beta.clone(); n],
        latents: vec![[1.0; 3]; n],
        shared: template_beta.clone(),
    };
    if config.method == Offline::Soft && config.soft_start == SoftStart::PerFrame {
        per_frame_start(base, start.is_some(), config, prior, &frames, &mut state)?;
        // β⁰: the mean of the β_n⁰ (valid: the bounds and barriers are convex), the template
        // should the basis refuse it.
        let mut mean = template_beta.clone();
        for &i in &problem.layout.active {
            mean[i] = state.betas.iter().map(|b| b[i]).sum::<f64>() / n as f64;
        }
        if problem.project(&mut mean) {
            state.shared = mean;
        }
    }
    let mut batch = Batch::new(&problem, config, &frames)?;
    let mut lin = batch
        .linearize(&state)
        .map_err(|(frame, source)| OfflineError::Term { frame, source })?;
    let initial_energy = lin.energy;
    let mut lambda = config.lambda;
    let mut growth = 2.0;
    let mut records = Vec::new();
    for _ in 0..config.iterations {
        let t = Instant::now();
        let mut damped = lin.system.clone();
        damped.damp(lambda, 1e-9);
        let candidate = damped.solve().map(|delta| {
            let predicted = lin.system.predicted_decrease(&delta);
            let next = batch
                .step(&state, &delta, &lin.system)
                .and_then(|s| batch.linearize(&s).ok().map(|l| (s, l)));
            (predicted, next)
        });
        let mut record = OfflineIteration {
            energy: f64::INFINITY,
            terms: Vec::new(),
            lambda,
            accepted: false,
            ms: 0.0,
        };
        let before = lin.energy;
        let accepted = match candidate {
            Some((predicted, Some((s, l)))) => {
                record.energy = l.energy;
                record.terms.clone_from(&l.terms);
                (l.energy < before).then_some((predicted, s, l))
            }
            _ => None,
        };
        record.accepted = accepted.is_some();
        record.ms = t.elapsed().as_secs_f64() * 1e3;
        records.push(record);
        match accepted {
            Some((predicted, s, l)) => {
                // Nielsen's update from the gain ratio (actual over predicted decrease).
                let rho = (before - l.energy) / predicted.max(1e-300);
                let factor = (1.0 / 3.0f64).max(1.0 - (2.0 * rho - 1.0).powi(3));
                lambda = (lambda * factor).max(1e-9);
                growth = 2.0;
                let improvement = (before - l.energy) / before.max(1e-300);
                state = s;
                lin = l;
                if improvement < config.tolerance {
                    break;
                }
            }
            None => {
                lambda *= growth;
                growth *= 2.0;
                if lambda > 1e8 {
                    break;
                }
            }
        }
    }
    let information = batch.information(&state);
    let layout = &problem.layout;
    let mean = DVector::from_iterator(
        layout.active.len(),
        layout.active.iter().map(|&i| state.shared[i]),
    );
    let mut certainty = vec![0.0; problem.basis.len()];
    for (j, &i) in layout.active.iter().enumerate() {
        certainty[i] = information[(j, j)];
    }
    // Every accepted shape passed `project`, so the basis applies; the template is the
    // fallback only for a basis that changed its mind.
    let template = problem
        .basis
        .apply(base, &state.shared)
        .unwrap_or_else(|_| base.clone());
    Ok(OfflineCalibration {
        method: config.method,
        beta: state.shared,
        template,
        belief: ShapeBelief { mean, information },
        certainty,
        frame_betas: state.betas,
        poses: state.poses,
        initial_energy,
        iterations: records,
        seconds: clock.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subsample_takes_the_first_usable_frame_of_each_window() {
        let mut usable = vec![true; 65];
        usable[20] = false;
        usable[21] = false;
        usable[40..60].fill(false);
        assert_eq!(subsample(&usable, 20), vec![0, 22, 60]);
        assert_eq!(subsample(&usable, 0).len(), 65 - 22);
        assert!(subsample(&[], 20).is_empty());
    }

    #[test]
    fn names_round_trip() {
        for m in [Offline::Hard, Offline::Soft] {
            assert_eq!(m.to_string().parse::<Offline>(), Ok(m));
        }
        assert!("offline".parse::<Offline>().is_err());
    }

    #[test]
    fn settings_are_checked() {
        let bad = OfflineConfig {
            omega_beta: f64::NAN,
            ..OfflineConfig::default()
        };
        assert!(matches!(bad.validate(), Err(OfflineError::Config(m)) if m.contains("omega_beta")));
        let bad = OfflineConfig {
            lambda: 0.0,
            ..OfflineConfig::default()
        };
        assert!(bad.validate().is_err());
        assert!(OfflineConfig::default().validate().is_ok());
    }
}
