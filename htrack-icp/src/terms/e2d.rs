//! The silhouette alignment term E2D (thesis Eq. 2.3, §2.3.1 "2D correspondences", Jacobian
//! §2.7.2 "Perspective projection Jacobian").

use hand_model::solver::{EnergyTerm, NormalEquations, PoseContext, TermError, TermStats};
use nalgebra::{Vector2, Vector3};
use serde::{Deserialize, Serialize};

use crate::context::TrackingCtx;

/// Settings of [`E2d`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct E2dParams {
    /// ω₂ of Eq. 2.3 (thesis and htrack: 1, ANCHOR-FACTS §5.4).
    pub weight: f64,
}

impl Default for E2dParams {
    fn default() -> Self {
        Self { weight: 1.0 }
    }
}

/// Most DOFs on one bone's chain (the cylinder skeleton has at most 6 + 4).
const MAX_CHAIN: usize = 64;

/// One push constraint of E2D: a rendered pixel outside the sensor silhouette.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SilhouettePush {
    /// The rendered pixel `(u, v)`.
    pub pixel: (u32, u32),
    /// The model point `x` seen at that pixel (camera frame, mm), rigidly attached to `bone`.
    pub point: Vector3<f64>,
    /// The bone carrying `x`.
    pub bone: usize,
    /// `Π_{S_s}(p)`: the center of the nearest sensor-silhouette pixel (from the distance
    /// transform of `S_s`).
    pub target: Vector2<f64>,
}

/// E2D, thesis Eq. 2.3: `E2D = ω₂ Σ_{p ∈ S_r} ‖p − Π_{S_s}(p, θ)‖²`, the rendered silhouette
/// `S_r` of the model pushed into the sensor silhouette `S_s`. Each push weighs
/// `ω₂ · (320 / width)⁴`: ω₂ holds for the 320 × 240 frames the originals tracked, and wider
/// images count in proportion ([`sensor_io::Camera::qvga_share`]). Measured in session 24
/// (`hands track --model cylinders`, teaser, 240 frames, NYU camera 640 × 480, mean keypoint
/// error): default hand noise-free 1.17 → 1.19 mm, ToF 2.41 → 1.72 mm; a random subject under
/// ToF 13.79 → 5.31 mm (through the 320 × 240 SR300 preset 5.78 mm; ω₂ / 4 instead gave
/// 7.07 mm).
///
/// As in htrack (ANCHOR-FACTS §5.4) only rendered pixels **outside** `S_s` contribute (inside,
/// `Π_{S_s}(p) = p`); each gives two rows (pixels), with the correspondence `Π_{S_s}(p)` the
/// nearest sensor-silhouette pixel, read from the distance transform of `S_s`
/// ([`crate::SensorView`]) and held fixed during the iteration. The rendered pixel `p` carries
/// the model point `x` of [`TrackingCtx::raster`] (the first hit of the pixel's ray, "caching
/// the bone identifier and the 3D location associated with each pixel in a texture"), rigidly
/// attached to its bone, so with the projection `π` of the sensor camera
///
/// - residual (current − target) `r = π(x) − Π_{S_s}(p)` (2 rows, pixels),
/// - Jacobian `∂r/∂θ = J_persp(x) · J_skel(x)` (§2.7.2: `J_persp` the 2×3 perspective
///   projection Jacobian, `J_skel(x)` the columns [`hand_model::kinematics::PosedSkeleton::column`]
///   of the bone's chain),
/// - energy `ω₂ Σ‖r‖²` (the weight multiplies `JᵀJ` once, see [`NormalEquations`]).
///
/// Beyond htrack: a rendered pixel whose model point the segmentation hides
/// ([`crate::SensorView::hides`]: under or beyond the wristband, past the depth-only forearm
/// cut) is not pushed — the silhouette is cut there whatever the hand looks like (the
/// sphere-mesh m2d term does the same). Measured (`hands track --model cylinders`, 8 synthetic
/// sequences of 240 frames, random subjects, mean keypoint error summed over them): wristband
/// 57.97 → 57.92 mm, depth-only segmentation 62.74 → 58.63 mm (fist ToF 8.52 → 6.77).
///
/// # Pixel center vs projected point
/// Eq. 2.3 writes the residual with the pixel `p`; we use `π(x)` as the current value. At the
/// linearization point the two agree (`x` lies on the ray through the pixel center, so `π(x)`
/// is the pixel center up to rounding), but only `π(x)` moves with θ: the rendered pixel is a
/// discrete label. Using `π(x)` makes the rows the exact Gauss–Newton linearization of the
/// bone-attached points with fixed correspondences, which is what the finite-difference tests
/// check (the energy as a function of θ, re-rendered, is piecewise constant in the pixel set and
/// not differentiable).
///
/// Pixels without a nearest silhouette pixel (empty `S_s`) add nothing, and so does everything
/// without a sensor camera, with the silhouette disabled, or at a non-finite pose (the raster is
/// empty then).
#[derive(Clone, Debug, PartialEq)]
pub struct E2d {
    params: E2dParams,
}

impl E2d {
    /// The term with `params`.
    pub fn new(params: E2dParams) -> Self {
        Self { params }
    }

    /// The settings.
    pub fn params(&self) -> &E2dParams {
        &self.params
    }

    /// Visit the push constraints at the context's last update: every rendered pixel outside
    /// the sensor silhouette that has a nearest silhouette pixel. An error when the raster does
    /// not match the sensor camera (the camera changed without [`TrackingCtx::update`]).
    pub fn for_each_push(
        ctx: &TrackingCtx<'_>,
        mut f: impl FnMut(&SilhouettePush) -> Result<(), TermError>,
    ) -> Result<(), TermError> {
        let sensor = ctx.sensor();
        let raster = ctx.raster();
        let Some(camera) = sensor.camera.as_ref() else {
            return Ok(());
        };
        if raster.hits().is_empty() {
            return Ok(());
        }
        if raster.width() != camera.width || raster.height() != camera.height {
            return Err(TermError::Failed(
                "rendered silhouette does not match the sensor camera",
            ));
        }
        let w = camera.width;
        for &i in raster.hits() {
            let (u, v) = (i % w, i / w);
            if sensor.in_silhouette(u, v) {
                continue;
            }
            let Some((nu, nv)) = sensor.nearest_pixel(u, v) else {
                continue;
            };
            let Some(hit) = raster.hit(i as usize) else {
                continue;
            };
            // Where the segmentation cannot see the hand (under or beyond the wristband, past
            // the depth-only forearm cut) a model pixel outside the silhouette is no evidence.
            if sensor.hides(&hit.point) {
                continue;
            }
            f(&SilhouettePush {
                pixel: (u, v),
                point: hit.point,
                bone: hit.bone,
                target: Vector2::new(f64::from(nu), f64::from(nv)),
            })?;
        }
        Ok(())
    }
}

impl Default for E2d {
    fn default() -> Self {
        Self::new(E2dParams::default())
    }
}

impl EnergyTerm<TrackingCtx<'_>> for E2d {
    fn name(&self) -> &'static str {
        "e2d"
    }

    fn accumulate(
        &self,
        ctx: &TrackingCtx<'_>,
        ne: &mut NormalEquations,
    ) -> Result<TermStats, TermError> {
        let Some(camera) = ctx.sensor().camera.as_ref() else {
            return Ok(TermStats::ZERO);
        };
        let skeleton = ctx.skeleton();
        let posed = ctx.posed();
        let omega = self.params.weight * camera.qvga_share();
        let bones = skeleton.bones().len();
        let mut cu = [(0usize, 0.0f64); MAX_CHAIN];
        let mut cv = [(0usize, 0.0f64); MAX_CHAIN];
        let mut stats = TermStats::ZERO;
        Self::for_each_push(ctx, |push| {
            if push.bone >= bones {
                return Err(TermError::BoneOutOfRange {
                    bone: push.bone,
                    bones,
                });
            }
            let chain = skeleton.chain(push.bone);
            if chain.len() > MAX_CHAIN {
                return Err(TermError::Failed("kinematic chain longer than 64 DOFs"));
            }
            let x = &push.point;
            let r = camera.project(x) - push.target;
            let jp = camera.projection_jacobian(x);
            for ((su, sv), &d) in cu.iter_mut().zip(cv.iter_mut()).zip(chain) {
                let c = posed.column(d, x);
                *su = (d, jp.row(0).dot(&c.transpose()));
                *sv = (d, jp.row(1).dot(&c.transpose()));
            }
            stats += ne.add_row(&cu[..chain.len()], r.x, omega)?;
            stats += ne.add_row(&cv[..chain.len()], r.y, omega)?;
            Ok(())
        })?;
        Ok(stats)
    }
}
