//! The per-iteration context of the Ch. 2 tracker (STYLE practice 5): the posed cylinder model,
//! the sensor points and their front-facing correspondences (thesis §2.3.1 "3D
//! correspondences") with one IRLS weight each (§2.7.4 "Point cloud alignment"), and the
//! rendered silhouette `S_r` of the model with its per-pixel bone and 3D point (§2.3.1 "2D
//! correspondences", Eq. 2.3).

use hand_model::cylinder::{CylinderModel, CylinderProjection, CylinderRaster, View, NO_SEED};
use hand_model::kinematics::{Pose, PosedSkeleton, Skeleton};
use hand_model::render::Intrinsics;
use hand_model::solver::{IterInfo, LmCallback, PoseContext, TermError};
use nalgebra::Vector3;
use sensor_io::dt::NO_PIXEL;
use sensor_io::preprocess::PreprocessedFrame;
use sensor_io::Camera;
use serde::{Deserialize, Serialize};

/// How the ℓ1 norm of Eq. 2.2 is approximated by iteratively re-weighted least squares
/// (thesis §2.7.4: `ω_re = 1/‖d‖`; htrack reweights with `3.5/√(d + 1e−3)` baked into both `J`
/// and `e`, an effective weight `3.5²/d`, ANCHOR-FACTS §5.3).
///
/// With the point-to-plane residual `r = nᵀ(y − x)` the term minimizes the Huber-smoothed ℓ1
/// energy `2g·ρ_ε(r)`, `ρ_ε(r) = |r|` for `|r| ≥ ε`, `r²/(2ε) + ε/2` below, whose IRLS weight is
/// `w = (2g·ρ_ε)'(r)/(2r) = g / max(|r|, ε)`. With that weight the quadratic surrogate
/// `w·(r + Jδ)² + const` has exactly the value and the gradient of `2g·ρ_ε` at the linearization
/// point, so the linearization is finite-difference checkable and the reported energy is
/// `2g Σ‖x − y‖` (Eq. 2.2 scaled) whenever `n ∥ x − y` (every closest-point correspondence).
///
/// The gain `g` sets how strongly the reweighted data term pulls against the damping λ = 100
/// and the priors. The default `g = 3.5² = 12.25` is htrack's effective weight (the thesis'
/// `ω_re = 1/‖d‖` is `g = 1`: with it the data term is ~12× weaker than in the code whose
/// numbers the thesis reports, and a perturbed pose converges several times slower against
/// λ = 100 — measured in `tests/tracker.rs`). On non-reweighted iterations the weight is 1,
/// as in htrack. `ε` avoids the division by zero (htrack skips reweighting below
/// `d = 1e−3` mm).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IrlsParams {
    /// Reweight at all (false: plain point-to-plane least squares `Σ r²` on every iteration).
    pub reweight: bool,
    /// Also reweight on rigid-only iterations (htrack `fit3D_reweight_rigid`, off: "allows fast
    /// rigid motion", ANCHOR-FACTS §5.3).
    pub reweight_rigid: bool,
    /// Huber threshold ε (mm) below which the ℓ1 norm is replaced by a quadratic.
    pub epsilon: f64,
    /// Gain `g` of the reweighted term (htrack 12.25; thesis formula 1).
    pub gain: f64,
}

impl Default for IrlsParams {
    fn default() -> Self {
        Self {
            reweight: true,
            reweight_rigid: false,
            epsilon: 1e-3,
            gain: 12.25,
        }
    }
}

impl IrlsParams {
    /// The penalty `2g·ρ_ε(r)` whose IRLS weight is [`IrlsParams::weight`].
    #[inline]
    pub fn penalty(&self, r: f64) -> f64 {
        let a = r.abs();
        let eps = self.eps();
        let rho = if a >= eps {
            a
        } else {
            r * r / (2.0 * eps) + eps / 2.0
        };
        2.0 * self.gain() * rho
    }

    /// The IRLS weight `w = g / max(|r|, ε)` of [`IrlsParams::penalty`].
    #[inline]
    pub fn weight(&self, r: f64) -> f64 {
        self.gain() / r.abs().max(self.eps())
    }

    /// ε, made positive and finite so that no weight divides by zero.
    #[inline]
    fn eps(&self) -> f64 {
        if self.epsilon.is_finite() && self.epsilon > 1e-12 {
            self.epsilon
        } else {
            1e-12
        }
    }

    /// g, made positive and finite (1 otherwise).
    #[inline]
    fn gain(&self) -> f64 {
        if self.gain.is_finite() && self.gain > 0.0 {
            self.gain
        } else {
            1.0
        }
    }
}

/// The shared per-iteration state of the Ch. 2 tracker: the cylinder model, the current pose θ
/// and its forward kinematics, the sensor point cloud `𝒳_s` (camera frame, mm), for every point
/// its front-facing correspondence `y = Π_M(x, θ)` (§2.3.1) and its IRLS weight (§2.7.4).
///
/// With a sensor camera ([`SensorView::camera`]) and the silhouette enabled
/// ([`TrackingCtx::set_silhouette`], on by default) it also holds the rendered silhouette `S_r`
/// of the model (§2.3.1 "2D correspondences"): the posed model rasterized from the sensor camera
/// ([`CylinderRaster`]), per pixel the segment, its bone and the camera-frame surface point —
/// only for the pixels outside the sensor silhouette `S_s` (`S_r \ S_s`, all E2D needs; the
/// others are not ray cast).
///
/// Refreshed by [`TrackingCtx::update`] (called by [`CorrespondenceCallback`] before every LM
/// iteration); nothing allocates once the buffers have held the current number of points and
/// image size.
#[derive(Clone, Debug)]
pub struct TrackingCtx<'m> {
    model: &'m CylinderModel,
    pose: Pose,
    posed: PosedSkeleton,
    points: Vec<Vector3<f64>>,
    correspondences: Vec<Option<CylinderProjection>>,
    /// Per point the segment of its last correspondence: the first segment searched at the
    /// next update (temporal coherence; the result does not depend on it).
    seeds: Vec<u16>,
    residuals: Vec<f64>,
    weights: Vec<f64>,
    reweighted: bool,
    rigid_only: bool,
    view: View,
    front_facing: bool,
    irls: IrlsParams,
    sensor: SensorView,
    silhouette: bool,
    raster: CylinderRaster,
}

/// What the image-space terms (E2D Eq. 2.3, E_wrist Eq. 2.4) read of the current frame: the
/// camera of the processed images, for every pixel the linear index of the nearest sensor
/// silhouette pixel (the distance transform of `S_s`, ANCHOR-FACTS §5.4), and the wristband
/// axis when the segmentation found one.
#[derive(Clone, Debug, Default)]
pub struct SensorView {
    /// Camera of the processed images; `None` before the first frame (image terms then add no
    /// rows).
    pub camera: Option<Camera>,
    /// Per pixel (`v·width + u`) the nearest silhouette pixel; [`NO_PIXEL`] everywhere when the
    /// silhouette is empty. Empty before the first frame.
    pub nearest: Vec<u32>,
    /// Wristband center and unit axis toward the hand (camera frame, mm).
    pub wristband: Option<(Vector3<f64>, Vector3<f64>)>,
}

impl SensorView {
    /// Whether pixel `(u, v)` (inside the image) belongs to the sensor silhouette `S_s`.
    #[inline]
    pub fn in_silhouette(&self, u: u32, v: u32) -> bool {
        self.camera.as_ref().is_some_and(|c| {
            let i = (v * c.width + u) as usize;
            self.nearest.get(i).is_some_and(|&n| n as usize == i)
        })
    }

    /// The nearest silhouette pixel `(u, v)` of pixel `(u, v)`, `None` outside the image or
    /// when the silhouette is empty.
    #[inline]
    pub fn nearest_pixel(&self, u: u32, v: u32) -> Option<(u32, u32)> {
        let c = self.camera.as_ref()?;
        if u >= c.width || v >= c.height {
            return None;
        }
        let n = *self.nearest.get((v * c.width + u) as usize)?;
        (n != NO_PIXEL).then(|| (n % c.width, n / c.width))
    }
}

impl<'m> TrackingCtx<'m> {
    /// A context at the rest pose with no points; `view` is the camera model of the
    /// front-facing test (the thesis uses [`View::Orthographic`], `v = (0, 0, 1)`).
    pub fn new(model: &'m CylinderModel, view: View, irls: IrlsParams) -> Self {
        let pose = Pose::zeros(&model.skeleton);
        Self {
            model,
            posed: PosedSkeleton::new(&model.skeleton, &pose),
            pose,
            points: Vec::new(),
            correspondences: Vec::new(),
            seeds: Vec::new(),
            residuals: Vec::new(),
            weights: Vec::new(),
            reweighted: false,
            rigid_only: false,
            view,
            front_facing: true,
            irls,
            sensor: SensorView::default(),
            silhouette: true,
            raster: CylinderRaster::new(),
        }
    }

    /// Enable or disable the rendering of the silhouette `S_r` in [`TrackingCtx::update`] (on by
    /// default; rendering also needs a sensor camera). Disabled, [`TrackingCtx::raster`] is
    /// empty after the next update and E2D adds no rows.
    pub fn set_silhouette(&mut self, enabled: bool) {
        self.silhouette = enabled;
        if !enabled {
            self.raster.clear();
        }
    }

    /// Whether [`TrackingCtx::update`] renders the silhouette.
    pub fn silhouette(&self) -> bool {
        self.silhouette
    }

    /// The rendered model at the last update (§2.3.1 "2D correspondences"): per pixel of the
    /// sensor camera the segment, bone and camera-frame point of the first hit; empty without a
    /// camera, with the silhouette disabled or for a non-finite pose.
    pub fn raster(&self) -> &CylinderRaster {
        &self.raster
    }

    /// Take the sensor data of a preprocessed frame: its points `𝒳_s` ([`TrackingCtx::set_points`]),
    /// camera, silhouette distance transform and wristband ([`SensorView`]). Reuses the buffers.
    pub fn set_frame(&mut self, frame: &PreprocessedFrame) {
        self.set_points(&frame.points);
        self.sensor.camera.clone_from(&frame.camera);
        self.sensor.nearest.clear();
        let consistent = frame.camera.as_ref().is_some_and(|c| {
            frame.dt.width() == c.width
                && frame.dt.height() == c.height
                && frame.dt.nearest.len() == c.num_pixels()
        });
        if consistent {
            self.sensor.nearest.extend_from_slice(&frame.dt.nearest);
        } else {
            self.sensor.camera = None;
        }
        self.sensor.wristband = frame.hand.wristband;
    }

    /// The sensor data of the image-space terms.
    pub fn sensor(&self) -> &SensorView {
        &self.sensor
    }

    /// Mutable sensor data (tests and callers that build frames by hand).
    pub fn sensor_mut(&mut self) -> &mut SensorView {
        &mut self.sensor
    }

    /// Replace the sensor points `𝒳_s` (camera frame, mm); keeps the buffers' capacity. The
    /// correspondences are stale until the next [`TrackingCtx::update`].
    pub fn set_points(&mut self, points: &[Vector3<f64>]) {
        self.points.clear();
        self.points.extend_from_slice(points);
        self.correspondences.clear();
        self.correspondences.resize(points.len(), None);
        self.seeds.clear();
        self.seeds.resize(points.len(), NO_SEED);
        self.residuals.clear();
        self.residuals.resize(points.len(), 0.0);
        self.weights.clear();
        self.weights.resize(points.len(), 0.0);
    }

    /// Re-pose the model at `pose`, recompute every front-facing correspondence `y` (§2.3.1),
    /// its point-to-plane residual `r = nᵀ(y − x)` and its IRLS weight (§2.7.4; 1 when the
    /// iteration is not reweighted, see [`IrlsParams`]), and render the silhouette `S_r` from the
    /// sensor camera when enabled. A pose of the wrong length is an error; a non-finite pose
    /// value makes every correspondence `None` and the silhouette empty.
    pub fn update(&mut self, pose: &Pose, rigid_only: bool) -> Result<(), TermError> {
        let nd = self.model.skeleton.num_dofs();
        if pose.values.len() != nd {
            return Err(TermError::ShapeMismatch {
                expected: nd,
                found: pose.values.len(),
            });
        }
        self.pose.values.clone_from(&pose.values);
        self.rigid_only = rigid_only;
        self.reweighted = self.irls.reweight && (!rigid_only || self.irls.reweight_rigid);
        if !pose.values.iter().all(|v| v.is_finite()) {
            self.correspondences.fill(None);
            self.raster.clear();
            return Ok(());
        }
        self.posed.update(&self.model.skeleton, &self.pose);
        match (&self.sensor.camera, self.silhouette) {
            (Some(c), true) => {
                let intrinsics = Intrinsics {
                    fx: c.fx,
                    fy: c.fy,
                    cx: c.cx,
                    cy: c.cy,
                    width: c.width,
                    height: c.height,
                };
                // Only pixels outside S_s can carry an E2D push constraint.
                let nearest = &self.sensor.nearest;
                let outside = |i: usize| nearest.get(i).is_none_or(|&n| n as usize != i);
                if self
                    .raster
                    .render_where(self.model, &self.posed, &intrinsics, outside)
                    .is_err()
                {
                    return Err(TermError::Failed("invalid sensor camera"));
                }
            }
            _ => self.raster.clear(),
        }
        if self
            .model
            .project_points_seeded(
                &self.posed,
                &self.points,
                self.front_facing.then_some(self.view),
                &mut self.seeds,
                &mut self.correspondences,
            )
            .is_err()
        {
            return Err(TermError::Failed("correspondence buffer size mismatch"));
        }
        for ((c, x), (r, w)) in self
            .correspondences
            .iter()
            .zip(&self.points)
            .zip(self.residuals.iter_mut().zip(self.weights.iter_mut()))
        {
            (*r, *w) = match c {
                Some(c) => {
                    let res = c.normal.dot(&(c.point - x));
                    let weight = if self.reweighted {
                        self.irls.weight(res)
                    } else {
                        1.0
                    };
                    (res, weight)
                }
                None => (0.0, 0.0),
            };
        }
        Ok(())
    }

    /// The cylinder model.
    pub fn model(&self) -> &'m CylinderModel {
        self.model
    }

    /// The sensor points `𝒳_s`.
    pub fn points(&self) -> &[Vector3<f64>] {
        &self.points
    }

    /// Per point its front-facing correspondence `y = Π_M(x, θ)` (§2.3.1), `None` when there
    /// is none (non-finite point).
    pub fn correspondences(&self) -> &[Option<CylinderProjection>] {
        &self.correspondences
    }

    /// Per point the point-to-plane residual `r = nᵀ(y − x)` (0 without correspondence).
    pub fn residuals(&self) -> &[f64] {
        &self.residuals
    }

    /// Per point the IRLS weight `w` (§2.7.4; see [`IrlsParams`]); 1 on non-reweighted
    /// iterations, 0 without correspondence.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Whether the current weights are IRLS weights (the energy is then the Huber-ℓ1 of
    /// Eq. 2.2) rather than 1 (the energy is then `Σ r²`).
    pub fn reweighted(&self) -> bool {
        self.reweighted
    }

    /// Whether the current iteration only moves the global DOFs.
    pub fn rigid_only(&self) -> bool {
        self.rigid_only
    }

    /// The IRLS settings.
    pub fn irls(&self) -> &IrlsParams {
        &self.irls
    }

    /// Use front-facing correspondences (§2.3.1, default) or plain closest points (the
    /// comparison of Fig. 2.6/2.8).
    pub fn set_front_facing(&mut self, front_facing: bool) {
        self.front_facing = front_facing;
    }

    /// Whether correspondences are front-facing.
    pub fn front_facing(&self) -> bool {
        self.front_facing
    }

    /// The camera model of the front-facing test.
    pub fn view(&self) -> View {
        self.view
    }
}

impl PoseContext for TrackingCtx<'_> {
    fn skeleton(&self) -> &Skeleton {
        &self.model.skeleton
    }
    fn pose(&self) -> &Pose {
        &self.pose
    }
    fn posed(&self) -> &PosedSkeleton {
        &self.posed
    }
}

/// The [`LmCallback`] of the tracker: before every iteration, [`TrackingCtx::update`] at the
/// current pose (re-pose, front-facing correspondences, IRLS weights; the rigid-only flag from
/// [`IterInfo`]).
#[derive(Copy, Clone, Debug, Default)]
pub struct CorrespondenceCallback;

impl LmCallback<TrackingCtx<'_>> for CorrespondenceCallback {
    fn prepare(
        &mut self,
        pose: &Pose,
        ctx: &mut TrackingCtx<'_>,
        info: IterInfo,
    ) -> Result<(), TermError> {
        ctx.update(pose, info.rigid_only)
    }
}
