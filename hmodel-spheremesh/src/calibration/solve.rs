//! The joint Levenberg–Marquardt calibration over all unknowns (thesis Eq. 3.8): every frame's
//! pose `θ_n` together with the shape of [`ShapeLayout`], on the energies of §3.4.1 — d2m
//! (Eq. 3.11) and, for depth frames, m2d (Eq. 3.12) through the tracker's own correspondence
//! and silhouette machinery ([`TrackingCtx`]), validity (Eq. 3.14), radius bounds, joint limits
//! and a weak prior toward the initial template that fixes the gauge freedoms (a rest rotation
//! about a joint's own axis is indistinguishable from an offset of that joint's angle in every
//! frame). Rigidity (Eq. 3.13) holds by construction: every frame is the template posed by
//! forward kinematics, so its segments keep their rest lengths exactly.
//!
//! Frames couple only through the shape: each step is solved by a Schur complement of the
//! per-frame pose blocks (`block`, faer; [`LinearSolver::Dense`] is the dense reference); steps are accepted only when the energy decreases (true LM, λ adapted).

use std::time::Instant;

use hand_model::kinematics::Pose;
use hand_model::query::{project_point_pill, Projection, SphereMeshGeometry, View};
use hand_model::shape::Element;
use hand_model::solver::{IrlsParams, NormalEquations};
use hand_model::spheremesh::{PosedSphereMesh, SphereMeshTemplate};
use nalgebra::{DMatrix, DVector, Vector3};
use sensor_io::preprocess::{depth_noise, gate_for_noise, noise_scale, PreprocessedFrame};
use sensor_io::SensorView;
use serde::{Deserialize, Serialize};

use super::rows::{DataWeights, Row, RowLayout, ShapeRows};
use super::shape::{on_joint, ShapeSpace, ShapeState};
use crate::context::TrackingCtx;
use crate::jacobian::{FootpointJacobian, MAX_ELEMENT_DOFS};

/// What a calibration frame holds.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FrameKind {
    /// A single depth camera: front-facing correspondences, m2d against the silhouette.
    Depth,
    /// A complete point cloud (multi-view scan): plain closest points.
    Cloud,
}

/// One data frame `D_n` of the calibration.
#[derive(Clone, Debug)]
pub struct CalibrationFrame {
    /// The points (camera frame, mm).
    pub points: Vec<Vector3<f64>>,
    /// For depth frames: the camera and silhouette distance transform (m2d).
    pub sensor: SensorView,
    /// The kind of data.
    pub kind: FrameKind,
    /// The depth noise σ measured on the frame (mm, [`depth_noise`]); `None` when unknown.
    pub noise: Option<f64>,
    /// The fraction of the hand's pixels that `points` sample (1 for clouds): the m2d term sums
    /// over every rendered model pixel, the d2m term over the subsampled points, so τ_m2d is
    /// scaled by it to keep the thesis' balance of the two sums over whole pixel sets.
    pub sampling: f64,
    /// A kd-tree over `points` for the nearest-point queries of a cloud's m2d (`None` for
    /// depth frames, whose m2d uses the silhouette).
    tree: Option<CloudTree>,
}

/// A kd-tree over a cloud's points (kiddo; a scan holds ~5000 points and the m2d queries a few
/// hundred model samples per frame and iteration).
#[derive(Clone)]
struct CloudTree {
    tree: std::sync::Arc<kiddo::ImmutableKdTree<f64, 3>>,
    /// The number of points it was built over: a frame whose points were replaced since
    /// falls back to the brute-force search.
    len: usize,
}

impl std::fmt::Debug for CloudTree {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("CloudTree")
    }
}

impl CloudTree {
    fn new(points: &[Vector3<f64>]) -> Option<Self> {
        let items: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
        let tree = kiddo::ImmutableKdTree::new_from_slice(&items).ok()?;
        Some(Self {
            tree: std::sync::Arc::new(tree),
            len: points.len(),
        })
    }

    /// The point of `points` nearest to `q` (the points the tree was built over).
    fn nearest(&self, points: &[Vector3<f64>], q: &Vector3<f64>) -> Option<Vector3<f64>> {
        if points.len() != self.len {
            return nearest_point(points, q);
        }
        let hit = self
            .tree
            .query(&[q.x, q.y, q.z])
            .nearest_one::<kiddo::SquaredEuclidean<f64>>()
            .execute();
        points.get(hit.item as usize).copied()
    }
}

impl CalibrationFrame {
    /// A depth frame from the preprocessing pipeline; its depth noise is measured on the hand.
    pub fn depth(frame: &PreprocessedFrame) -> Self {
        let mut sensor = SensorView::default();
        sensor.set_frame(frame);
        Self {
            points: frame.points.clone(),
            sensor,
            kind: FrameKind::Depth,
            noise: depth_noise(&frame.depth, &frame.hand.mask),
            sampling: if frame.hand.count > frame.points.len() {
                frame.points.len() as f64 / frame.hand.count as f64
            } else {
                1.0
            },
            tree: None,
        }
    }

    /// A complete point cloud.
    pub fn cloud(points: Vec<Vector3<f64>>) -> Self {
        let finite = points.iter().all(|p| p.iter().all(|v| v.is_finite()));
        Self {
            tree: if finite {
                CloudTree::new(&points)
            } else {
                None
            },
            points,
            sensor: SensorView::default(),
            kind: FrameKind::Cloud,
            noise: None,
            sampling: 1.0,
        }
    }
}

/// How the unknowns are stepped.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Schedule {
    /// One LM over all unknowns (poses and shape) at once.
    Joint,
    /// Alternate a shape step (poses held) and a pose step (shape held), the block-coordinate
    /// counterpart of the thesis' alternating Eq. 3.9–3.10 (there step 1 frees per-frame centers
    /// under the rigidity term; here every frame stays a kinematic posing of the template).
    Alternating,
}

/// How the damped normal equations are solved.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LinearSolver {
    /// Schur complement of the per-frame pose blocks (faer Cholesky factorizations); cost
    /// linear in the number of frames.
    BlockArrow,
    /// Dense Cholesky of the whole matrix (the reference; cubic in the number of frames).
    Dense,
}

/// Weights and stopping rule of the calibration (thesis §3.6 "Reproducibility": τ_d2m = 1,
/// τ_m2d = 0.5, τ_valid = 1e2).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CalibrationConfig {
    /// Most LM iterations (accepted or not) of the full stage.
    pub iterations: usize,
    /// Most LM iterations of the anisotropic-scaling stage that initializes the shape (0:
    /// none; thesis §3.4 "Initialization").
    pub scaling_iterations: usize,
    /// Joint or alternating steps.
    pub schedule: Schedule,
    /// Block-arrow or dense solve of each step.
    pub solver: LinearSolver,
    /// Optimize the shape (false: poses only, e.g. to initialize a frame's pose).
    pub fit_shape: bool,
    /// τ_d2m per point (squared distance, mm²).
    pub d2m: f64,
    /// τ_m2d per pushed pixel (squared pixels), times each depth frame's
    /// [`CalibrationFrame::sampling`] (the points sample ≈ 0.3 of the hand's pixels). Measured
    /// on the five synthetic subjects of `eval/tests/ch3_calibration.rs` (noise-free): with the
    /// unscaled 0.5 per pixel the pixel-quantized silhouette outweighed the exact depth and
    /// the teaser tracked with the calibrated template at 1.39 / 0.98 / 0.72 / 1.38 / 0.93 × the
    /// true template's error; scaled, 1.26 / 0.89 / 0.69 / 1.20 / 0.92 ×.
    pub m2d: f64,
    /// Huber threshold (mm) of the robust d2m (Eq. 3.11's ℓ1 beyond it); 0: least squares.
    /// Default 1 mm: data the hand model cannot explain (a forearm thicker than the model's
    /// wrist near the band, depth quantization) then pulls with bounded force. Measured on the
    /// five synthetic subjects of `eval/tests/ch3_calibration.rs` (noise-free): mean center
    /// error 0.63 / 1.03 / 1.45 / 1.12 / 0.68 mm with least squares, 0.48 / 0.41 / 1.16 / 0.65 /
    /// 0.58 mm with 1 mm.
    pub robust: f64,
    /// Huber threshold (mm) of the m2d of cloud frames (ℓ1 beyond it); 0: least squares. A
    /// scan's holes (between curled fingers, under the palm) leave model surface without data
    /// near it, whose pull to the nearest point elsewhere the squared m2d overweights.
    pub m2d_robust: f64,
    /// τ_valid (Eq. 3.14), per mm².
    pub valid: f64,
    /// Optimize the rest orientations of the kinematic frames `T̄` (Fig. 3.8; joint positions
    /// are part of β).
    pub kinematic: bool,
    /// Also free per-sphere center offsets and radii beyond the β space ([`ShapeSpace`]; the
    /// thesis frees every center and radius, Eq. 3.9). On by default: β cannot place a real
    /// hand's palm spheres (their centers move in x and y only) and the fit then moves the
    /// knuckles to fill the palm. Measured on the original authors' model of their real hand
    /// carried onto this skeleton (`eval/tests/real_hand.rs`, 8 noise-free frames, last-third
    /// keypoint error of the tracked calibration motion): 2.19 mm with β and rest rotations
    /// alone, 1.14 mm free, 1.01 mm free with the joints held ([`Self::prior_free_joint`]),
    /// against 0.24 mm with the hand's own model; on the five random subjects of
    /// `eval/tests/ch3_calibration.rs`, which live inside β, the tracking ratios move by ≤ 0.03
    /// (1.26 / 0.89 / 0.69 / 1.20 / 0.92 → 1.27 / 0.91 / 0.69 / 1.21 / 0.95), at ≈ 1.3× the time
    /// (0.40–0.64 s a calibration there, against 0.22–0.56 s; one run each, shared machine).
    pub free_spheres: bool,
    /// Prior toward the initial template on rest rotations (per rad²).
    pub prior_rotation: f64,
    /// Prior toward the initial template on β (per mm²).
    pub prior_beta: f64,
    /// Prior toward zero on the free sphere offsets and radii (per mm²).
    pub prior_free: f64,
    /// Prior toward zero on the free center offsets of the spheres on a joint (a phalanx's first
    /// sphere, which β moves with its joint), per mm²: the joint, which is the keypoint, follows
    /// the sphere through β instead of staying behind. Default 10³ (100 × `prior_free`); the
    /// complete clouds of [`Self::clouds`] keep `prior_free` (held there, the six real scans fit
    /// at 1.16 instead of 1.10 mm mean d2m).
    pub prior_free_joint: f64,
    /// Express the four priors above per unit of the data's noise: multiply them by
    /// `max(σ̂ / 1 mm, 1)²`, σ̂ the median of the frames' measured depth noise
    /// ([`CalibrationFrame::noise`]). The data terms are sums of squared millimetres, so noisy
    /// frames would otherwise outvote the priors by σ̂² and the shape absorbs the noise; data
    /// at or below 1 mm noise (quantization) keep the weights as given. Measured on two random
    /// subjects with ToF noise (σ̂ ≈ 5 mm, 8 frames): rest centers 3.63 / 2.88 mm from the
    /// truth without (the default template: 5.55 / 2.63), 3.48 / 2.02 mm with (3.28 / 2.41 with
    /// the scaled τ_m2d); noise-free
    /// results are unchanged (σ̂ < 1 mm).
    pub noise_scaled_priors: bool,
    /// Along-ray correspondences of depth frames within this distance (mm) of the ray's entry
    /// (as the tracker's, [`crate::TrackerConfig::ray_gate`]) on the frames whose measured
    /// noise is at least [`Self::ray_gate_noise`]; `None`: closest points everywhere.
    pub ray_gate: Option<f64>,
    /// The measured depth noise (mm) from which a depth frame's points register along their
    /// rays; 0: every depth frame.
    pub ray_gate_noise: f64,
    /// Radius bounds (mm) of every sphere.
    pub radius_limits: [f64; 2],
    /// Weight of the radius bounds and of the joint limits of every `θ_n`.
    pub limits: f64,
    /// Initial LM damping (relative to the diagonal).
    pub lambda: f64,
    /// Stop when an accepted step lowers the energy by less than this fraction.
    pub tolerance: f64,
}

impl Default for CalibrationConfig {
    fn default() -> Self {
        Self {
            iterations: 30,
            scaling_iterations: 20,
            schedule: Schedule::Joint,
            solver: LinearSolver::BlockArrow,
            fit_shape: true,
            d2m: 1.0,
            m2d: 0.5,
            robust: 1.0,
            m2d_robust: 0.0,
            valid: 1e2,
            kinematic: true,
            free_spheres: true,
            prior_rotation: 1e3,
            prior_beta: 1e-2,
            prior_free: 10.0,
            prior_free_joint: 1e3,
            noise_scaled_priors: true,
            ray_gate: Some(20.0),
            ray_gate_noise: 1.5,
            radius_limits: [1.5, 30.0],
            limits: 1e5,
            lambda: 1e-3,
            tolerance: 1e-6,
        }
    }
}

impl CalibrationConfig {
    /// These settings with the priors scaled by the frames' noise
    /// ([`CalibrationConfig::noise_scaled_priors`]).
    pub fn noise_scaled(&self, frames: &[CalibrationFrame]) -> Self {
        let mut noise: Vec<f64> = frames.iter().filter_map(|f| f.noise).collect();
        if !self.noise_scaled_priors || noise.is_empty() {
            return self.clone();
        }
        let mid = noise.len() / 2;
        let (_, sigma, _) = noise.select_nth_unstable_by(mid, f64::total_cmp);
        let scale = noise_scale(*sigma);
        Self {
            prior_beta: self.prior_beta * scale,
            prior_rotation: self.prior_rotation * scale,
            prior_free: self.prior_free * scale,
            prior_free_joint: self.prior_free_joint * scale,
            ..self.clone()
        }
    }

    /// The settings for complete point clouds ([`FrameKind::Cloud`], e.g.
    /// [`calibrate_clouds`](super::calibrate_clouds)): the defaults with the free per-sphere
    /// offsets and radii (the thesis frees every center; `prior_free` 1 per mm²), a Huber m2d
    /// at 1 mm and a stiffer prior on the rest rotations (10⁴ per rad²), which the free offsets
    /// otherwise trade against; a least-squares d2m (a Huber d2m at 1–5 mm, the depth-frame
    /// default, measured 1.37–1.48 mm here: a scan has no forearm-under-band outliers, and its
    /// fingers need the full pull). Measured on the six real scans of `hand-scans-tkach`
    /// (`eval/tests/ch3_scans.rs`, mean d2m of the hand parts): 1.08 mm against 1.47 mm with
    /// the defaults; each setting alone: free spheres 1.30 mm, with `prior_free` 1 1.24 mm, the
    /// Huber m2d on top 1.13 mm.
    pub fn clouds() -> Self {
        Self {
            free_spheres: true,
            prior_free: 1.0,
            prior_free_joint: 1.0,
            robust: 0.0,
            m2d_robust: 1.0,
            prior_rotation: 1e4,
            ..Self::default()
        }
    }

    /// Every weight, threshold and the damping finite and non-negative, the radius bounds
    /// ordered and the along-ray gate positive: a configuration file's typo is named here
    /// instead of turning into a silently wrong shape.
    pub fn validate(&self) -> Result<(), CalibrationError> {
        let values = [
            ("d2m", self.d2m),
            ("m2d", self.m2d),
            ("robust", self.robust),
            ("m2d_robust", self.m2d_robust),
            ("valid", self.valid),
            ("prior_rotation", self.prior_rotation),
            ("prior_beta", self.prior_beta),
            ("prior_free", self.prior_free),
            ("prior_free_joint", self.prior_free_joint),
            ("ray_gate_noise", self.ray_gate_noise),
            ("limits", self.limits),
            ("lambda", self.lambda),
            ("tolerance", self.tolerance),
        ];
        let bad = |reason: String| Err(CalibrationError::Input(reason));
        if let Some((name, v)) = values.iter().find(|(_, v)| !(v.is_finite() && *v >= 0.0)) {
            return bad(format!("{name} = {v}: must be finite and non-negative"));
        }
        let [lo, hi] = self.radius_limits;
        if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo < hi) {
            return bad(format!(
                "radius_limits = [{lo}, {hi}]: need 0 ≤ lower < upper, finite"
            ));
        }
        match self.ray_gate {
            Some(g) if !(g.is_finite() && g > 0.0) => {
                bad(format!("ray_gate = {g}: must be finite and positive"))
            }
            _ => Ok(()),
        }
    }
}

/// The stages of a calibration.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Stage {
    /// The initialization: the template scaled anisotropically (height, width, thickness: the
    /// latent β̃ of thesis Eq. 4.14), jointly with the poses.
    Scaling,
    /// Every shape unknown.
    Full,
}

impl Stage {
    /// The stage ends when an accepted step lowers the energy by less than this fraction. The
    /// scaling stage only has to bring the template near the data: it hands over at 1 %.
    fn tolerance(self, config: &CalibrationConfig) -> f64 {
        match self {
            Stage::Scaling => config.tolerance.max(1e-2),
            Stage::Full => config.tolerance,
        }
    }
}

/// One LM iteration of the calibration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IterationRecord {
    /// Total energy at the candidate.
    pub energy: f64,
    /// Its d2m part.
    pub d2m: f64,
    /// Its m2d part.
    pub m2d: f64,
    /// Its validity part.
    pub valid: f64,
    /// The damping used.
    pub lambda: f64,
    /// Whether the step was accepted.
    pub accepted: bool,
    /// The stage it belongs to.
    pub stage: Stage,
    /// Wall time (ms).
    pub ms: f64,
}

/// The calibrated template, the frames' poses and how the optimization went.
#[derive(Clone, Debug)]
pub struct Calibration {
    /// The calibrated template.
    pub template: SphereMeshTemplate,
    /// Per frame its pose.
    pub poses: Vec<Pose>,
    /// Energy of the initial guess.
    pub initial_energy: f64,
    /// Every iteration.
    pub iterations: Vec<IterationRecord>,
    /// Total wall time (s).
    pub seconds: f64,
    /// Per shape unknown (named): how much the data (d2m + m2d) constrains it at the result —
    /// the diagonal of the data terms' Gauss–Newton Hessian `Σ w j²` (per mm² for β and free
    /// offsets, per rad² for rest rotations).
    pub information: Vec<(String, f64)>,
}

impl Calibration {
    /// The lowest energy reached: the initial one or that of an accepted step.
    pub fn best_energy(&self) -> f64 {
        self.iterations
            .iter()
            .filter(|r| r.accepted)
            .map(|r| r.energy)
            .fold(self.initial_energy, f64::min)
    }

    /// The shape unknowns the data barely constrains: information below `fraction` of the
    /// median over unknowns of the same kind (β, rotations, free offsets), e.g. the phalanx
    /// lengths of fingers that stayed straight in every frame. Their values stay near the
    /// starting template (held by the priors), so they are not calibrated.
    pub fn unconstrained(&self, fraction: f64) -> Vec<&str> {
        let kind = |n: &str| n.split(':').next().unwrap_or("").to_string();
        let mut out = Vec::new();
        for (name, info) in &self.information {
            let mut same: Vec<f64> = self
                .information
                .iter()
                .filter(|(m, _)| kind(m) == kind(name))
                .map(|(_, v)| *v)
                .collect();
            same.sort_by(f64::total_cmp);
            let median = same[same.len() / 2];
            if *info < fraction * median {
                out.push(name.as_str());
            }
        }
        out
    }
}

/// Why a calibration could not run.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationError {
    /// Frames and poses differ in number, or there is no frame.
    #[error("{0}")]
    Input(String),
    /// The template cannot be tracked (its geometry or Jacobians).
    #[error("template: {0}")]
    Template(#[from] hand_model::ModelError),
}

/// Energies of one linearization, by part, and the data terms' information per shape unknown.
#[derive(Clone, Debug, Default)]
struct Parts {
    d2m: f64,
    m2d: f64,
    valid: f64,
    rest: f64,
    info: Vec<f64>,
}

impl Parts {
    fn total(&self) -> f64 {
        self.d2m + self.m2d + self.valid + self.rest
    }
}

/// The state being optimized.
#[derive(Clone)]
struct State {
    shape: ShapeState,
    template: SphereMeshTemplate,
    poses: Vec<Pose>,
}

struct Problem<'a> {
    base: &'a SphereMeshTemplate,
    frames: &'a [CalibrationFrame],
    space: ShapeSpace,
    initial: ShapeState,
    /// `(element, sphere slot)` pairs degenerate already in the initial template.
    exempt: Vec<(usize, usize)>,
    jacobian: FootpointJacobian,
    config: &'a CalibrationConfig,
    nd: usize,
    /// Per pose DOF whether it is a global (root) one.
    global: Vec<bool>,
}

impl Problem<'_> {
    fn dim(&self) -> usize {
        self.frames.len() * self.nd + self.space.len()
    }

    fn shape_offset(&self) -> usize {
        self.frames.len() * self.nd
    }

    /// Linearize every energy at `state`.
    fn linearize(&self, state: &State) -> Result<(NormalEquations, Parts), CalibrationError> {
        let n = self.dim();
        let so = self.shape_offset();
        let mut ne = NormalEquations::new(n);
        let mut rows = ShapeRows::new(n);
        let shape_index: Vec<Option<usize>> = (0..self.space.len()).map(|i| Some(so + i)).collect();
        let mut parts = Parts {
            info: vec![0.0; self.space.len()],
            ..Parts::default()
        };
        let t = &state.template;
        // Eq. 3.11's robust ℓ1 as a Huber norm: quadratic below `robust` mm, ℓ1 beyond (IRLS
        // weight min(1, robust/|r|)); 0 keeps plain least squares.
        let irls = IrlsParams {
            reweight: self.config.robust > 0.0,
            reweight_rigid: true,
            epsilon: self.config.robust.max(1e-9),
            gain: self.config.robust.max(1e-9),
        };
        let mut cols = [Vector3::zeros(); MAX_ELEMENT_DOFS];
        for (f, (frame, pose)) in self.frames.iter().zip(&state.poses).enumerate() {
            let view = View::Perspective {
                camera_center: Vector3::zeros(),
            };
            let mut ctx = TrackingCtx::new(t, view, irls.clone())?;
            ctx.set_points(&frame.points);
            *ctx.sensor_mut() = frame.sensor.clone();
            ctx.set_front_facing(frame.kind == FrameKind::Depth);
            if frame.kind == FrameKind::Depth {
                let gate = self.config.ray_gate;
                ctx.set_ray_gate(gate_for_noise(
                    gate,
                    self.config.ray_gate_noise,
                    frame.noise,
                ));
            }
            ctx.set_m2d((frame.kind == FrameKind::Depth).then_some(crate::M2dMode::Render));
            if ctx.update(pose, false).is_err() {
                return Err(CalibrationError::Input(format!(
                    "frame {f}: the posed template is not finite"
                )));
            }
            let posed = ctx.posed_mesh().clone();
            let theta = f * self.nd;
            let layout = RowLayout {
                pose: theta,
                shape: &shape_index,
            };
            let weights = DataWeights {
                d2m: self.config.d2m,
                m2d: self.config.m2d * frame.sampling,
            };
            let data = rows.add_frame(
                &ctx,
                &self.space,
                &layout,
                &weights,
                &mut ne,
                &mut parts.info,
                so,
            );
            parts.d2m += data.d2m;
            parts.m2d += data.m2d;
            // m2d on a complete cloud (Eq. 3.12 with Π_D the closest data point): samples of
            // the posed model's visible surface pulled to their nearest cloud point, weighted so
            // that the two distances keep the thesis' balance τ_m2d/τ_d2m per unit of
            // |D|⁻¹ and |M|⁻¹ normalization.
            if frame.kind == FrameKind::Cloud && !frame.points.is_empty() {
                let samples = surface_samples(ctx.geometry());
                let w = self.config.m2d * frame.points.len() as f64 / samples.len().max(1) as f64;
                for q in &samples {
                    let nearest = match &frame.tree {
                        Some(tree) => tree.nearest(&frame.points, &q.point),
                        None => nearest_point(&frame.points, &q.point),
                    };
                    let Some(p) = nearest else {
                        continue;
                    };
                    let d = q.point - p;
                    let len = d.norm();
                    if len <= 1e-9 {
                        continue;
                    }
                    let u = d / len;
                    let dofs = self.jacobian.columns(
                        &posed,
                        q.element as usize,
                        &q.spheres,
                        &q.weights,
                        &mut cols,
                    );
                    for (&dof, col) in dofs.iter().zip(&cols) {
                        rows.row.add(theta + dof, u.dot(col));
                    }
                    let un = u.dot(&q.normal);
                    for (&sph, &wt) in q.spheres.iter().zip(&q.weights) {
                        if wt == 0.0 {
                            continue;
                        }
                        self.space.for_each_sphere_column(
                            t,
                            &posed,
                            sph as usize,
                            wt,
                            &mut |i, dc, dr| {
                                rows.row.add(so + i, u.dot(&dc) + un * dr);
                            },
                        );
                    }
                    let delta = self.config.m2d_robust;
                    if delta > 0.0 && len > delta {
                        rows.row
                            .flush_data(&mut ne, len, w * delta / len, so, &mut parts.info);
                        parts.m2d += w * (2.0 * delta * len - delta * delta);
                    } else {
                        parts.m2d += rows.row.flush_data(&mut ne, len, w, so, &mut parts.info);
                    }
                }
            }
            // Joint limits of θ_n.
            for (d, dof) in t.skeleton.dofs().iter().enumerate() {
                let Some([lo, hi]) = dof.limits else { continue };
                let v = pose.values[d];
                let r = if v > hi {
                    v - hi
                } else if v < lo {
                    v - lo
                } else {
                    continue;
                };
                rows.row.add(theta + d, 1.0);
                parts.rest += rows.row.flush(&mut ne, r, self.config.limits);
            }
        }
        let rest = PosedSphereMesh::new(t, &Pose::zeros(&t.skeleton));
        parts.valid += self.validity(t, &rest, &mut ne, &mut rows.row);
        parts.rest += self.shape_priors(state, &rest, &mut ne, &mut rows.row);
        ne.symmetrize();
        Ok((ne, parts))
    }

    /// Validity (Eq. 3.14) on the rest template: a sphere center inside the rest of its element
    /// (the element without that sphere) is pulled to that part's surface, the footpoint held
    /// fixed; 3 rows per degenerate sphere. Spheres already inside at the initial template
    /// (the template's own design, e.g. a membrane sphere sunk into a finger base) are exempt:
    /// the term guards against calibration collapsing elements, not against the template.
    fn validity(
        &self,
        t: &SphereMeshTemplate,
        rest: &PosedSphereMesh,
        ne: &mut NormalEquations,
        row: &mut Row,
    ) -> f64 {
        let so = self.shape_offset();
        let mut energy = 0.0;
        for (e, el) in t.elements.iter().enumerate() {
            for (k, &i) in el.element.spheres().iter().enumerate() {
                if self.exempt.contains(&(e, k)) {
                    continue;
                }
                let Some(target) = degenerate_target(&el.element, k, &rest.spheres) else {
                    continue;
                };
                let res = rest.spheres[i as usize].center - target;
                for axis in 0..3 {
                    self.space.for_each_sphere_column(
                        t,
                        rest,
                        i as usize,
                        1.0,
                        &mut |idx, dc, _| {
                            row.add(so + idx, dc[axis]);
                        },
                    );
                    energy += row.flush(ne, res[axis], self.config.valid);
                }
            }
        }
        energy
    }

    /// Radius bounds and the priors toward the initial template (gauge).
    fn shape_priors(
        &self,
        state: &State,
        rest: &PosedSphereMesh,
        ne: &mut NormalEquations,
        row: &mut Row,
    ) -> f64 {
        let so = self.shape_offset();
        let t = &state.template;
        let mut energy = 0.0;
        let [lo, hi] = self.config.radius_limits;
        for (s, sphere) in rest.spheres.iter().enumerate() {
            let r = sphere.radius;
            let res = if r > hi {
                r - hi
            } else if r < lo {
                r - lo
            } else {
                continue;
            };
            self.space
                .for_each_sphere_column(t, rest, s, 1.0, &mut |i, _, dr| row.add(so + i, dr));
            energy += row.flush(ne, res, self.config.limits);
        }
        let c = self.config;
        for (j, (b, b0)) in state.shape.beta.iter().zip(&self.initial.beta).enumerate() {
            row.add(so + j, 1.0);
            energy += row.flush(ne, b - b0, c.prior_beta);
        }
        let mut rotations = 0;
        for (k, o) in self.space.rotation_slots() {
            rotations += 1;
            let w = nalgebra::Rotation3::from_matrix(&state.shape.rotation[k]).scaled_axis();
            for j in 0..3 {
                row.add(so + o + j, 1.0);
                energy += row.flush(ne, w[j], c.prior_rotation);
            }
        }
        let first = self.space.num_beta() + rotations * 3;
        for (s, o) in self.space.sphere_offsets() {
            let held = on_joint(&self.base.spheres[s]);
            for j in 0..4 {
                let w = if j < 3 && held {
                    c.prior_free_joint
                } else {
                    c.prior_free
                };
                row.add(so + o + j, 1.0);
                energy += row.flush(ne, state.shape.free[o - first + j], w);
            }
        }
        energy
    }

    /// Apply the step `delta` to `state`; `None` when the shape leaves the valid templates.
    fn step(&self, state: &State, delta: &DVector<f64>) -> Option<State> {
        let so = self.shape_offset();
        let mut shape_delta: Vec<f64> = delta.as_slice()[so..].to_vec();
        if !self.config.kinematic {
            for o in self.space.rotation_offsets() {
                shape_delta[o..o + 3].fill(0.0);
            }
        }
        let shape = self.space.step(&state.shape, &shape_delta);
        let template = self.space.template(self.base, &shape).ok()?;
        let poses = state
            .poses
            .iter()
            .enumerate()
            .map(|(f, p)| {
                p.retract(
                    &self.base.skeleton,
                    &delta.as_slice()[f * self.nd..(f + 1) * self.nd],
                )
            })
            .collect();
        Some(State {
            shape,
            template,
            poses,
        })
    }
}

/// When sphere `k` of `element` has its center inside the rest of the element (Eq. 3.14's
/// `χ`), the closest point of that rest's surface; `None` otherwise.
fn degenerate_target(
    element: &Element,
    k: usize,
    spheres: &[hand_model::shape::Sphere],
) -> Option<Vector3<f64>> {
    let ids = element.spheres();
    let c = spheres[ids[k] as usize].center;
    let others: Vec<u32> = ids
        .iter()
        .enumerate()
        .filter(|&(j, _)| j != k)
        .map(|(_, &s)| s)
        .collect();
    match others.as_slice() {
        [j] => {
            let o = &spheres[*j as usize];
            let d = c - o.center;
            let len = d.norm();
            (len < o.radius && len > 1e-9).then(|| o.center + d * (o.radius / len))
        }
        [j, l] => project_point_pill(&c, &spheres[*j as usize], &spheres[*l as usize])
            .filter(|p| p.distance < 0.0)
            .map(|p| p.point),
        _ => None,
    }
}

/// Samples of a posed model's surface: on every element, points projected from a few
/// directions around its skeleton (pills: 5 stations × 8 directions; wedges: 4 barycentric
/// stations × both faces and 3 edge directions), keeping those on the union's surface (not
/// buried in another element).
fn surface_samples(g: &SphereMeshGeometry) -> Vec<Projection> {
    let mut out = Vec::new();
    let sp = g.spheres();
    for (e, el) in g.elements().iter().enumerate() {
        let ids = el.spheres();
        let c: Vec<Vector3<f64>> = ids.iter().map(|&i| sp[i as usize].center).collect();
        let rmax = ids
            .iter()
            .map(|&i| sp[i as usize].radius)
            .fold(0.0, f64::max);
        let mut probe = |s: Vector3<f64>, dir: Vector3<f64>| {
            let Some(n) = dir.try_normalize(1e-12) else {
                return;
            };
            let Some(q) = g.project_on_element(e, &(s + n * (rmax + 5.0))) else {
                return;
            };
            if !g.is_buried(&q.point, 0.5) {
                out.push(q);
            }
        };
        match c.as_slice() {
            [a, b] => {
                let axis = b - a;
                let u = any_perpendicular(&axis);
                let v = axis.cross(&u).try_normalize(1e-12).unwrap_or(u);
                for k in 0..5 {
                    let s = a + axis * (f64::from(k) / 4.0);
                    for j in 0..8 {
                        let ang = f64::from(j) * std::f64::consts::FRAC_PI_4;
                        probe(s, u * ang.cos() + v * ang.sin());
                    }
                }
                probe(*a, -axis);
                probe(*b, axis);
            }
            [a, b, d] => {
                let n = (b - a).cross(&(d - a));
                for w in [
                    [1.0, 1.0, 1.0],
                    [4.0, 1.0, 1.0],
                    [1.0, 4.0, 1.0],
                    [1.0, 1.0, 4.0],
                ] {
                    let sum: f64 = w.iter().sum();
                    let s = (a * w[0] + b * w[1] + d * w[2]) / sum;
                    probe(s, n);
                    probe(s, -n);
                }
                let centroid = (a + b + d) / 3.0;
                for (p, q) in [(a, b), (b, d), (d, a)] {
                    let mid = (p + q) / 2.0;
                    probe(mid, mid - centroid);
                }
            }
            _ => {}
        }
    }
    out
}

/// A unit vector perpendicular to `v` (any, when `v` is zero).
fn any_perpendicular(v: &Vector3<f64>) -> Vector3<f64> {
    let helper = if v.x.abs() < 0.9 * v.norm() {
        Vector3::x()
    } else {
        Vector3::y()
    };
    v.cross(&helper)
        .try_normalize(1e-12)
        .unwrap_or_else(Vector3::z)
}

/// The point of `points` nearest to `q` by brute force (the reference of [`CloudTree`]).
fn nearest_point(points: &[Vector3<f64>], q: &Vector3<f64>) -> Option<Vector3<f64>> {
    points
        .iter()
        .min_by(|a, b| (*a - q).norm_squared().total_cmp(&(*b - q).norm_squared()))
        .copied()
}

/// Calibrate `base` to `frames` from the initial per-frame poses (thesis Eq. 3.8, joint LM; see
/// the module docs). Errors: no frame, a pose count or length that does not match, a template
/// the tracker cannot use.
pub fn calibrate(
    base: &SphereMeshTemplate,
    frames: &[CalibrationFrame],
    poses: &[Pose],
    config: &CalibrationConfig,
) -> Result<Calibration, CalibrationError> {
    let start = Instant::now();
    config.validate()?;
    let too_few = config.fit_shape && frames.len() < 2;
    if frames.is_empty() || too_few || frames.len() != poses.len() {
        return Err(CalibrationError::Input(format!(
            "{} frames and {} initial poses: calibration needs as many poses as frames and at least 2 frames in different poses (thesis §3.4: one view cannot separate shape from pose)",
            frames.len(),
            poses.len()
        )));
    }
    if let Some(f) = frames.iter().position(|f| {
        f.points.len() < 50 || f.points.iter().any(|p| !p.iter().all(|v| v.is_finite()))
    }) {
        return Err(CalibrationError::Input(format!(
            "frame {f} has fewer than 50 points or a non-finite point"
        )));
    }
    let nd = base.skeleton.num_dofs();
    if let Some(p) = poses.iter().position(|p| p.values.len() != nd) {
        return Err(CalibrationError::Input(format!(
            "pose {p} does not have {nd} values"
        )));
    }
    let scaled = config.noise_scaled(frames);
    let config = &scaled;
    let space = ShapeSpace::new(base, config.free_spheres)?;
    let initial = space.identity(base);
    let rest = PosedSphereMesh::new(base, &Pose::zeros(&base.skeleton));
    let exempt = base
        .elements
        .iter()
        .enumerate()
        .flat_map(|(e, el)| (0..el.element.spheres().len()).map(move |k| (e, k, el)))
        .filter(|(_, k, el)| degenerate_target(&el.element, *k, &rest.spheres).is_some())
        .map(|(e, k, _)| (e, k))
        .collect();
    let problem = Problem {
        base,
        frames,
        jacobian: FootpointJacobian::new(base)?,
        space,
        initial: initial.clone(),
        exempt,
        config,
        nd,
        global: base
            .skeleton
            .dofs()
            .iter()
            .map(|d| base.skeleton.bones()[d.bone].parent.is_none())
            .collect(),
    };
    let state = State {
        template: problem.space.template(base, &initial)?,
        shape: initial,
        poses: poses.to_vec(),
    };
    let (ne, parts) = problem.linearize(&state)?;
    let mut descent = Descent {
        initial_energy: parts.total(),
        state,
        ne,
        parts,
        lambda: config.lambda,
        growth: 2.0,
        records: Vec::new(),
    };
    if config.fit_shape && config.scaling_iterations > 0 {
        let map = problem.space.latent_map(&descent.state.shape);
        descent.run(
            &problem,
            config.scaling_iterations,
            Stage::Scaling,
            Some(&map),
        )?;
        descent.lambda = config.lambda;
        descent.growth = 2.0;
    }
    descent.run(&problem, config.iterations, Stage::Full, None)?;
    let Descent {
        state,
        parts,
        initial_energy,
        records,
        ..
    } = descent;
    let information = problem
        .space
        .names(base)
        .into_iter()
        .zip(parts.info)
        .collect();
    Ok(Calibration {
        template: state.template,
        poses: state.poses,
        initial_energy,
        iterations: records,
        seconds: start.elapsed().as_secs_f64(),
        information,
    })
}

/// The LM iterate and its bookkeeping, shared by the stages of [`calibrate`].
struct Descent {
    state: State,
    ne: NormalEquations,
    parts: Parts,
    initial_energy: f64,
    lambda: f64,
    /// Nielsen's growth factor of λ after a rejected step.
    growth: f64,
    records: Vec<IterationRecord>,
}

impl Descent {
    /// At most `iterations` LM steps; with `map` (`#shape × k`) the shape step is restricted to
    /// `δ_shape = map · δ_k` (the anisotropic-scaling stage).
    fn run(
        &mut self,
        problem: &Problem<'_>,
        iterations: usize,
        stage: Stage,
        map: Option<&DMatrix<f64>>,
    ) -> Result<(), CalibrationError> {
        let config = problem.config;
        let so = problem.shape_offset();
        for it in 0..iterations {
            let t = Instant::now();
            // Alternating: even iterations step the shape, odd ones the poses. The scaling
            // stage moves only the global poses with the scale: finger angles free to follow
            // a wrong size drift into poses the full stage cannot leave.
            let fixed = |i: usize| {
                (!config.fit_shape && i >= so)
                    || (stage == Stage::Scaling && i < so && !problem.global[i % problem.nd])
                    || match config.schedule {
                        Schedule::Joint => false,
                        Schedule::Alternating => (i >= so) == (it % 2 == 1),
                    }
            };
            let solve = Damped {
                lambda: self.lambda,
                fixed: &fixed,
                solver: config.solver,
                frames: problem.frames.len(),
                nd: problem.nd,
                map,
            };
            let Some(delta) = solve.solve(&self.ne) else {
                self.lambda *= 10.0;
                continue;
            };
            // The decrease the linearization predicts: E(0) − E(δ) = 2δᵀb − δᵀAδ.
            let predicted = 2.0 * delta.dot(self.ne.rhs()) - delta.dot(&(self.ne.lhs() * &delta));
            // A step that breaks the geometry (a negative radius, a non-finite pose) is
            // rejected like one that raises the energy.
            let linearized = problem
                .step(&self.state, &delta)
                .map(|c| problem.linearize(&c).map(|l| (c, l)));
            let mut record = IterationRecord {
                energy: f64::INFINITY,
                d2m: f64::INFINITY,
                m2d: f64::INFINITY,
                valid: f64::INFINITY,
                lambda: self.lambda,
                accepted: false,
                stage,
                ms: 0.0,
            };
            let candidate = match linearized {
                Some(Ok((c, (cne, cparts)))) => {
                    record.energy = cparts.total();
                    record.d2m = cparts.d2m;
                    record.m2d = cparts.m2d;
                    record.valid = cparts.valid;
                    Some((c, cne, cparts))
                }
                _ => None,
            };
            let before = self.parts.total();
            record.accepted = record.energy.is_finite() && record.energy < before;
            record.ms = t.elapsed().as_secs_f64() * 1e3;
            self.records.push(record);
            match candidate {
                Some((c, cne, cparts)) if cparts.total() < before => {
                    // Nielsen's damping update from the gain ratio ρ (actual over predicted
                    // decrease): a well-predicted step relaxes λ up to 3×, a poor one keeps it.
                    let rho = (before - cparts.total()) / predicted.max(1e-300);
                    let factor = (1.0 / 3.0f64).max(1.0 - (2.0 * rho - 1.0).powi(3));
                    self.lambda = (self.lambda * factor).max(1e-9);
                    self.growth = 2.0;
                    let improvement = (before - cparts.total()) / before.max(1e-300);
                    self.state = c;
                    self.ne = cne;
                    self.parts = cparts;
                    if improvement < stage.tolerance(config) {
                        break;
                    }
                }
                _ => {
                    self.lambda *= self.growth;
                    self.growth *= 2.0;
                    if self.lambda > 1e8 {
                        break;
                    }
                }
            }
        }
        Ok(())
    }
}

/// Floor of the damping diagonal relative to the largest diagonal entry of `A`.
const DAMPING_FLOOR: f64 = 1e-6;

/// One damped solve `(A + λ max(diag(A), f) + ε I) δ = b` with `f` the floor
/// [`DAMPING_FLOOR`]` · max diag(A)` (see [`Damped::solve`]).
struct Damped<'a> {
    lambda: f64,
    /// Unknowns held at 0.
    fixed: &'a dyn Fn(usize) -> bool,
    solver: LinearSolver,
    frames: usize,
    nd: usize,
    /// A restriction of the shape step, `δ_shape = map · δ_k`.
    map: Option<&'a DMatrix<f64>>,
}

impl Damped<'_> {
    /// The step of the normal equations `ne` with the unknowns `fixed` selects held at 0 and
    /// the shape restricted by `map`, solved by `solver` over `frames` pose blocks of `nd`
    /// unknowns; `None` when the factorization fails.
    fn solve(&self, ne: &NormalEquations) -> Option<DVector<f64>> {
        let mut a: DMatrix<f64> = ne.lhs().clone();
        let mut b = ne.rhs().clone();
        for i in 0..a.nrows() {
            if (self.fixed)(i) {
                a.row_mut(i).fill(0.0);
                a.column_mut(i).fill(0.0);
                a[(i, i)] = 1.0;
                b[i] = 0.0;
            }
        }
        let so = self.frames * self.nd;
        if let Some(map) = self.map {
            (a, b) = restrict(&a, &b, so, map);
        }
        // Marquardt's scaling by the diagonal, floored: an unknown the data barely sees (a
        // finger hidden in one frame) has a near-zero diagonal, and without the floor no λ
        // bounds its step (measured: a ring DIP angle stepped to 25 rad, into its joint limit,
        // and the descent stalled there).
        let floor = DAMPING_FLOOR * a.diagonal().max();
        for i in 0..a.nrows() {
            a[(i, i)] += self.lambda * a[(i, i)].max(floor) + 1e-9;
        }
        let delta = match self.solver {
            LinearSolver::BlockArrow => {
                super::block::BlockArrow::from_dense(&a, &b, self.frames, self.nd)?.solve()?
            }
            LinearSolver::Dense => a.cholesky()?.solve(&b),
        };
        let delta = match self.map {
            Some(map) => {
                let mut full = DVector::zeros(so + map.nrows());
                full.rows_mut(0, so).copy_from(&delta.rows(0, so));
                full.rows_mut(so, map.nrows())
                    .copy_from(&(map * delta.rows(so, map.ncols())));
                full
            }
            None => delta,
        };
        delta.iter().all(|v| v.is_finite()).then_some(delta)
    }
}

/// The normal equations in the unknowns `[θ; k]` with `δ_shape = map · δ_k`:
/// `Tᵀ A T`, `Tᵀ b` for `T = diag(I, map)`, block by block (the pose blocks are unchanged).
fn restrict(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    so: usize,
    map: &DMatrix<f64>,
) -> (DMatrix<f64>, DVector<f64>) {
    let (ns, k) = map.shape();
    let mut ra = DMatrix::zeros(so + k, so + k);
    ra.view_mut((0, 0), (so, so))
        .copy_from(&a.view((0, 0), (so, so)));
    let ps = a.view((0, so), (so, ns)) * map;
    ra.view_mut((0, so), (so, k)).copy_from(&ps);
    ra.view_mut((so, 0), (k, so)).copy_from(&ps.transpose());
    let ss = map.transpose() * a.view((so, so), (ns, ns)) * map;
    ra.view_mut((so, so), (k, k)).copy_from(&ss);
    let mut rb = DVector::zeros(so + k);
    rb.rows_mut(0, so).copy_from(&b.rows(0, so));
    rb.rows_mut(so, k)
        .copy_from(&(map.transpose() * b.rows(so, ns)));
    (ra, rb)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The kd-tree's nearest point equals the brute-force search's on a random cloud.
    #[test]
    fn cloud_tree_finds_the_brute_force_nearest_point() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let mut v = || {
            Vector3::new(
                rng.random_range(-80.0..80.0),
                rng.random_range(-80.0..80.0),
                rng.random_range(300.0..420.0),
            )
        };
        let points: Vec<Vector3<f64>> = (0..3000).map(|_| v()).collect();
        let frame = CalibrationFrame::cloud(points.clone());
        let tree = frame.tree.as_ref().expect("a tree");
        for _ in 0..500 {
            let q = v();
            assert_eq!(tree.nearest(&frame.points, &q), nearest_point(&points, &q));
        }
        // A frame whose points were replaced after the tree was built falls back.
        let shorter = &points[..100];
        let q = v();
        assert_eq!(tree.nearest(shorter, &q), nearest_point(shorter, &q));
    }

    /// An unknown the data barely sees (a near-zero diagonal) still takes a bounded step once
    /// λ is large: the damping diagonal is floored relative to the largest entry.
    #[test]
    fn damping_bounds_a_barely_seen_unknown() {
        let mut ne = NormalEquations::new(2);
        ne.add_row(&[(0, 100.0)], 1.0, 1.0).unwrap();
        ne.add_row(&[(0, 1.0), (1, 1e-7)], 1.0, 1.0).unwrap();
        ne.symmetrize();
        let fixed = |_: usize| false;
        let step = |lambda: f64| {
            Damped {
                lambda,
                fixed: &fixed,
                solver: LinearSolver::Dense,
                frames: 0,
                nd: 0,
                map: None,
            }
            .solve(&ne)
            .expect("solvable")
        };
        let (small, large) = (step(1e-3), step(1e3));
        assert!(large.norm() < 1e-2 * small.norm(), "{small} vs {large}");
        assert!(
            large[1].abs() < 1e-3,
            "barely seen unknown stepped {}",
            large[1]
        );
    }
}
