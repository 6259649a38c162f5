//! The model→data term E_m2d (thesis Eq. 3.5).

use hand_model::solver::{EnergyTerm, NormalEquations, TermError, TermStats};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::context::TrackingCtx;
use crate::jacobian::MAX_ELEMENT_DOFS;

/// Settings of [`M2d`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct M2dParams {
    /// τ_m2d (thesis §3.6 "Reproducibility": 0.5; hmodel's code 0.7).
    pub weight: f64,
}

impl Default for M2dParams {
    fn default() -> Self {
        Self { weight: 0.5 }
    }
}

/// E_m2d, thesis Eq. 3.5: `τ_m2d Σ_{x∈M(θ)} ‖x − Π_D(x)‖²` over the model's rendered pixels —
/// the model must lie in the sensor's visual hull. Only model points that project outside the
/// sensor silhouette contribute (inside, `Π_D(x) = x`); each is pushed toward the nearest
/// silhouette pixel of the distance transform ([`crate::SilhouettePush`], computed by
/// [`TrackingCtx`] in either [`crate::M2dMode`]), two pixel rows:
///
/// - residual (current − target) `r = π(x) − Π_D(x)` in pixels, `π` the sensor projection;
/// - Jacobian `J_persp(x) · ∂x/∂θ`, with `∂x/∂θ` the exact footpoint Jacobian of the point on
///   its element ([`crate::FootpointJacobian`]; the originals used the element's bone alone);
/// - energy `τ Σ ‖r‖²`, each push weighing `τ_m2d · (320 / width)⁴`
///   ([`sensor_io::Camera::qvga_share`]): τ_m2d holds for the 320 × 240 frames hmodel
///   tracked, as htrack's ω₂ does for E2D. Measured in session 26 (NYU camera 640 × 480,
///   240 frames, mean keypoint error / worst frame, mm, before → after): default hand, ToF,
///   Ch. 3 tracker: crossing 1.34 / 11.6 → 1.42 / 3.3, fist 0.96 / 11.5 → 1.01 / 4.0,
///   occlusion 1.64 / 10.9 → 1.51 / 5.6, rotation_fast 1.46 / 8.1 → 1.18 / 2.8. Random
///   subjects on the default template moved 4.72 → 5.11 and 9.26 → 9.61 mm, their worst frames
///   15.3 → 6.8 and 17.5 → 11.3 mm. Online calibration, whose joint pose–shape rows weigh the
///   same (`calibration::rows`), summed over these six sequences 9.28 → 8.53 mm, its worst frames
///   6.0–14.2 → 2.0–6.6 mm (crossed fingers 1.81 → 1.98 mm, a random subject under structured
///   light 1.05 → 0.58). The ToF occlusion motion from a cold start at its 150th frame:
///   10.81 → 4.43 mm, online 28.90 → 7.60.
///
/// As for htrack's E2D, `π(x)` rather than the pixel center is the current value (they agree at
/// the linearization point; only `π(x)` moves with θ), so the rows are the exact Gauss–Newton
/// linearization for fixed pushes; the thesis' ℓ1 on this term is not applied (the silhouette
/// residuals are bounded by the distance transform, and hmodel's outline term is ℓ2 too).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct M2d {
    params: M2dParams,
}

impl M2d {
    /// The term with `params`.
    pub fn new(params: M2dParams) -> Self {
        Self { params }
    }
}

impl EnergyTerm<TrackingCtx<'_>> for M2d {
    fn name(&self) -> &'static str {
        "m2d"
    }

    fn accumulate(
        &self,
        ctx: &TrackingCtx<'_>,
        ne: &mut NormalEquations,
    ) -> Result<TermStats, TermError> {
        let Some(camera) = ctx.sensor().camera.as_ref() else {
            return Ok(TermStats::ZERO);
        };
        let tau = self.params.weight * ctx.m2d_pixel_weight() * camera.qvga_share();
        let jac = ctx.jacobian();
        let posed = ctx.posed_mesh();
        let mut cols = [Vector3::zeros(); MAX_ELEMENT_DOFS];
        let mut cu = [(0usize, 0.0f64); MAX_ELEMENT_DOFS];
        let mut cv = [(0usize, 0.0f64); MAX_ELEMENT_DOFS];
        let mut stats = TermStats::ZERO;
        for push in ctx.pushes() {
            let x = &push.point;
            let dofs = jac.columns(
                posed,
                push.element as usize,
                &push.spheres,
                &push.weights,
                &mut cols,
            );
            let k = dofs.len();
            let r = camera.project(x) - push.target;
            let jp = camera.projection_jacobian(x);
            for (((su, sv), &d), c) in cu.iter_mut().zip(cv.iter_mut()).zip(dofs).zip(&cols) {
                let j = jp * c;
                *su = (d, j.x);
                *sv = (d, j.y);
            }
            stats += ne.add_row(&cu[..k], r.x, tau)?;
            stats += ne.add_row(&cv[..k], r.y, tau)?;
        }
        Ok(stats)
    }
}
