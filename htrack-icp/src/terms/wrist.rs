//! The wrist alignment term E_wrist (thesis Eq. 2.4; htrack's `Wristband` energy).

use hand_model::solver::{EnergyTerm, NormalEquations, PoseContext, TermError, TermStats};
use nalgebra::{Vector2, Vector3};
use serde::{Deserialize, Serialize};

use crate::context::TrackingCtx;

/// Settings of [`Wrist`].
///
/// The weight: htrack's code uses ω = 1e5 on a residual in pixels (ANCHOR-FACTS §5.2, §5.5),
/// the thesis lists ω₃ = 1e8 for its Ch. 2 results (§2.4). We keep htrack's 1e5 (ω not
/// squared, like every prior term); 1e8 pins the wrist to the line as a hard constraint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WristParams {
    /// ω₃ of Eq. 2.4 (per px²).
    pub weight: f64,
}

impl Default for WristParams {
    fn default() -> Self {
        Self { weight: 1e5 }
    }
}

/// Distance (mm) from the wristband center to the second axis point that is projected to get
/// the image line (htrack projects `center + 100·dir`; any point of the axis gives the same line).
const AXIS_POINT_MM: f64 = 100.0;

/// Smallest depth (mm) at which a point is projected.
const MIN_DEPTH: f64 = 1e-6;

/// E_wrist, thesis Eq. 2.4: `E = ω₃ ‖Π_2D(k₀(θ)) − Π_ℓ(k₀(θ))‖²`, keeping the projected wrist
/// keypoint `k₀` on the image line `ℓ` of the wristband axis.
///
/// `k₀` is the model's keypoint 0 (the wrist: htrack's palm root for the htrack-proportioned
/// model, the wrist joint for [`hand_model::cylinder::CylinderModel::from_sphere_mesh`]); `ℓ` is
/// the line through the projections of the band center `c` and of `c + 100 mm·axis`
/// ([`crate::SensorView::wristband`], camera frame). With `n⊥` the unit normal of `ℓ` in the
/// image, the residual is the signed pixel distance `r = n⊥ᵀ(Π(k₀) − Π(c))` and the row
/// `n⊥ᵀ J_proj(k₀) J_skel(k₀)` (ANCHOR-FACTS §5.5; htrack's rhs is `−r`, our convention is
/// current − target, see [`NormalEquations`]). The line does not depend on θ, so the row is the
/// exact gradient. Energy `ω₃ r²` (px²), one row.
///
/// No row when the frame has no camera or no wristband, when `k₀`, `c` or the second axis point
/// is not in front of the camera, or when the axis projects to a point (it points along the
/// viewing ray).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Wrist {
    params: WristParams,
}

impl Wrist {
    /// The term with `params`.
    pub fn new(params: WristParams) -> Self {
        Self { params }
    }

    /// The settings.
    pub fn params(&self) -> &WristParams {
        &self.params
    }
}

/// The image line of the wristband axis: a point on it and its unit normal (px).
fn band_line(
    camera: &sensor_io::Camera,
    center: &Vector3<f64>,
    axis: &Vector3<f64>,
) -> Option<(Vector2<f64>, Vector2<f64>)> {
    let far = center + axis * AXIS_POINT_MM;
    if !(center.z > MIN_DEPTH && far.z > MIN_DEPTH) {
        return None;
    }
    let c = camera.project(center);
    let dir = (camera.project(&far) - c).try_normalize(1e-9)?;
    Some((c, Vector2::new(-dir.y, dir.x)))
}

impl EnergyTerm<TrackingCtx<'_>> for Wrist {
    fn name(&self) -> &'static str {
        "wrist"
    }

    fn accumulate(
        &self,
        ctx: &TrackingCtx<'_>,
        ne: &mut NormalEquations,
    ) -> Result<TermStats, TermError> {
        let sensor = ctx.sensor();
        let (Some(camera), Some(band)) = (sensor.camera.as_ref(), sensor.wristband) else {
            return Ok(TermStats::ZERO);
        };
        let Some((c_px, n)) = band_line(camera, &band.center, &band.axis) else {
            return Ok(TermStats::ZERO);
        };
        let (bone, local) = ctx
            .model()
            .keypoint_on_bone(0)
            .ok_or(TermError::Failed("the model has no wrist keypoint"))?;
        let posed = ctx.posed();
        let Some(frame) = posed.globals.get(bone) else {
            return Err(TermError::BoneOutOfRange {
                bone,
                bones: posed.globals.len(),
            });
        };
        let root = frame.transform_point(&local);
        if root.z.is_nan() || root.z <= MIN_DEPTH {
            return Ok(TermStats::ZERO);
        }
        let r = n.dot(&(camera.project(&root) - c_px));
        // n⊥ᵀ J_proj(k₀) as a 3-vector.
        let g = camera.projection_jacobian(&root).transpose() * n;
        let chain = ctx.skeleton().chain(bone);
        let mut cols = [(0usize, 0.0f64); 64];
        if chain.len() > cols.len() {
            return Err(TermError::Failed("kinematic chain longer than 64 DOFs"));
        }
        for (slot, &d) in cols.iter_mut().zip(chain) {
            *slot = (d, g.dot(&posed.column(d, &root)));
        }
        ne.add_row(&cols[..chain.len()], r, self.params.weight)
    }
}

#[cfg(test)]
mod tests {
    use hand_model::cylinder::{default_right_hand_cylinders, CylinderModel, View};
    use hand_model::kinematics::Pose;
    use hand_model::solver::check::check_gradient;
    use hand_model::solver::terms::DampingParams;
    use hand_model::solver::LmOptions;
    use hand_model::spheremesh::default_right_hand;
    use sensor_io::preprocess::Wristband;
    use sensor_io::Camera;

    use super::*;
    use crate::IrlsParams;

    fn camera() -> Camera {
        Camera::new("test", 320, 240, 300.0, 300.0, 160.0, 120.0).unwrap()
    }

    fn target_pose(model: &CylinderModel) -> Pose {
        Pose::from_named(
            &model.skeleton,
            [
                ("global_ty", -60.0),
                ("global_tz", 420.0),
                ("global_rx", 0.3),
                ("global_ry", -0.2),
                ("global_rz", 0.4),
                ("index_mcp_flex", 0.4),
            ],
        )
        .unwrap()
    }

    /// A wristband on the forearm axis of `pose`: 40 mm proximal of the wrist keypoint, the
    /// axis along the palm's +y (toward the hand).
    fn band_of(model: &CylinderModel, pose: &Pose) -> Wristband {
        let posed = model.posed(pose).unwrap();
        let (bone, local) = model.keypoint_on_bone(0).unwrap();
        let root = posed.point(bone, &local);
        let palm = model.skeleton.bone_index("palm").unwrap();
        let axis = posed.globals[palm].rotation * Vector3::y();
        Wristband {
            center: root - axis * 40.0,
            axis,
            reach: 15.0,
        }
    }

    fn ctx_with<'m>(
        model: &'m CylinderModel,
        pose: &Pose,
        band: Option<Wristband>,
    ) -> TrackingCtx<'m> {
        let mut ctx = TrackingCtx::new(model, View::Orthographic, IrlsParams::default());
        ctx.sensor_mut().camera = Some(camera());
        ctx.sensor_mut().wristband = band;
        ctx.update(pose, false).unwrap();
        ctx
    }

    /// Signed pixel distance of the projected wrist keypoint from the band line.
    fn line_distance(ctx: &TrackingCtx<'_>) -> f64 {
        let mut ne = NormalEquations::new(ctx.skeleton().num_dofs());
        let stats = Wrist::new(WristParams { weight: 1.0 })
            .accumulate(ctx, &mut ne)
            .unwrap();
        assert_eq!(stats.rows, 1);
        stats.energy.sqrt()
    }

    #[test]
    fn wrist_gradient_matches_finite_differences() {
        for model in [
            default_right_hand_cylinders(),
            CylinderModel::from_sphere_mesh(&default_right_hand()).unwrap(),
        ] {
            let sk = &model.skeleton;
            let target = target_pose(&model);
            let band = band_of(&model, &target);
            let mut pose = target.clone();
            pose.values[0] += 12.0;
            pose.values[2] -= 20.0;
            pose.values[5] += 0.2;
            let mut ctx = ctx_with(&model, &pose, Some(band));
            let dist = line_distance(&ctx);
            assert!(dist > 5.0, "{dist}");
            let term = Wrist::default();
            let mut update = |p: &Pose, c: &mut TrackingCtx<'_>| c.update(p, false).unwrap();
            let cmp = check_gradient(sk, &pose, sk.num_dofs(), &term, &mut ctx, &mut update, 1e-6)
                .unwrap();
            let rel = cmp.relative_error(1e-9);
            eprintln!(
                "{}: wrist {dist:.2} px off the band line; gradient relative error {rel:.2e}",
                model.name
            );
            assert!(rel < 1e-6, "relative error {rel:e}\n{cmp:?}");
            // Finger DOFs do not move the wrist keypoint.
            let f = sk.dof_index("index_mcp_flex").unwrap();
            assert_eq!(cmp.analytic[f], 0.0);
        }
    }

    #[test]
    fn no_wristband_or_no_camera_gives_no_rows() {
        let model = default_right_hand_cylinders();
        let pose = target_pose(&model);
        let term = Wrist::default();
        let mut ne = NormalEquations::new(model.skeleton.num_dofs());
        let ctx = ctx_with(&model, &pose, None);
        assert_eq!(term.accumulate(&ctx, &mut ne).unwrap(), TermStats::ZERO);
        let mut ctx = ctx_with(&model, &pose, Some(band_of(&model, &pose)));
        ctx.sensor_mut().camera = None;
        assert_eq!(term.accumulate(&ctx, &mut ne).unwrap(), TermStats::ZERO);
        // An axis along the viewing ray projects to a point: no line, no row.
        let ctx = ctx_with(
            &model,
            &pose,
            Some(Wristband {
                center: Vector3::new(0.0, 0.0, 400.0),
                axis: Vector3::z(),
                reach: 15.0,
            }),
        );
        assert_eq!(term.accumulate(&ctx, &mut ne).unwrap(), TermStats::ZERO);
        assert!(ne.rhs().iter().all(|&v| v == 0.0));
        // On the line: one row with zero residual.
        let ctx = ctx_with(&model, &pose, Some(band_of(&model, &pose)));
        assert!(line_distance(&ctx) < 1e-9);
    }

    #[test]
    fn lm_pulls_a_displaced_wrist_onto_the_band_line() {
        let model = default_right_hand_cylinders();
        let target = target_pose(&model);
        let band = band_of(&model, &target);
        let mut start = target.clone();
        start.values[0] += 25.0;
        start.values[1] -= 15.0;
        let mut ctx = ctx_with(&model, &start, Some(band));
        let before = line_distance(&ctx);
        let term = Wrist::default();
        let options = LmOptions {
            iterations: 5,
            rigid_iterations: 0,
            damping: DampingParams::uniform(1.0),
            ..LmOptions::default()
        };
        let terms: [&dyn EnergyTerm<TrackingCtx<'_>>; 1] = [&term];
        let (pose, report) = crate::tests::solve_terms(&mut ctx, &terms, options, &start);
        ctx.update(&pose, false).unwrap();
        let after = line_distance(&ctx);
        eprintln!(
            "wrist keypoint {before:.2} px -> {after:.2e} px from the band line; {:?}",
            report.termination
        );
        assert!(report.termination.was_successful());
        assert!(before > 10.0 && after < 1e-3, "{before} -> {after}");
    }
}
