//! One frame's joint pose+shape problem (thesis Eq. 4.2): the unknowns' layout, the β basis
//! and the terms over `x_n = [θ_n; β_n]`, built once from the settings. The online calibrator
//! solves it frame by frame (adding E_temporal and E_iekf); the offline calibrations (Eq.
//! 4.12–4.13) stack it over the selected frames.

use hand_model::kinematics::Pose;
use hand_model::solver::terms::{JointLimits, PosePrior};
use hand_model::solver::{EnergyTerm, NoTerm, NormalEquations, PcaPrior, PriorSetup, TermError};
use hand_model::spheremesh::{ShapeBasis, SphereMeshTemplate};
use hmodel_spheremesh::calibration::{DataWeights, ShapeSpace};
use hmodel_spheremesh::terms::{Collision, CollisionParams};
use hmodel_spheremesh::{EnabledTerms, TrackerConfig, TrackingCtx};
use nalgebra::DMatrix;

use crate::filter::{marginal_information_into, InfoScratch};
use crate::online::{OnlineConfig, OnlineError};
use crate::terms::{
    finger_order_constraints, Layout, Lifted, OnlineCtx, ShapeData, ShapePrior, ShapePriorParams,
    ShapeValidity,
};

/// The most terms one solve runs.
const MAX_TERMS: usize = 8;

/// The terms of one solve, without allocating.
pub(crate) struct TermList<'a> {
    terms: [&'a dyn EnergyTerm<OnlineCtx>; MAX_TERMS],
    len: usize,
}

impl<'a> TermList<'a> {
    fn push(&mut self, term: &'a dyn EnergyTerm<OnlineCtx>) {
        if let Some(slot) = self.terms.get_mut(self.len) {
            *slot = term;
            self.len += 1;
        }
    }

    /// The terms.
    pub(crate) fn as_slice(&self) -> &[&'a dyn EnergyTerm<OnlineCtx>] {
        &self.terms[..self.len]
    }
}

/// The per-frame problem (module docs).
pub(crate) struct FrameProblem {
    /// The template β is applied to.
    pub(crate) base: SphereMeshTemplate,
    /// Its honline β basis.
    pub(crate) basis: ShapeBasis,
    /// Where the unknowns live.
    pub(crate) layout: Layout,
    /// E_d2m + E_m2d over pose and β.
    pub(crate) data: ShapeData,
    /// E_shape-space (Eq. 4.14), the β bounds and the β damping.
    pub(crate) prior: ShapePrior,
    /// E_shape-valid (Eq. 4.15).
    pub(crate) validity: ShapeValidity,
    collision: Lifted<Collision>,
    /// The β whose rest pose gave the collision term its rest overlaps.
    collision_beta: Vec<f64>,
    limits: JointLimits,
    pose_prior: Option<PosePrior>,
    /// The PCA mean pose (the rest pose without a prior).
    pub(crate) mean_pose: Pose,
    enabled: EnabledTerms,
    /// The system indices of the pose DOFs and of the active β (the blocks of Eq. 4.5).
    theta_index: Vec<usize>,
    beta_index: Vec<usize>,
}

impl FrameProblem {
    /// The problem of `base` with the weights of `config` and an optional PCA pose prior.
    pub(crate) fn new(
        base: &SphereMeshTemplate,
        config: &OnlineConfig,
        prior: Option<&PcaPrior>,
    ) -> Result<Self, OnlineError> {
        let sk = &base.skeleton;
        let tc = &config.tracker;
        let PriorSetup {
            prior: pose_prior,
            mean_pose,
            ..
        } = PriorSetup::new::<OnlineError>(sk, prior, &tc.pose_prior, &tc.lm)?;
        let num_pca = pose_prior.as_ref().map_or(0, PosePrior::num_aux);
        let space = ShapeSpace::new(base, false)?;
        let basis = space.basis().clone();
        let active = config.subset.indices(&basis);
        let nd = sk.num_dofs();
        let layout = Layout {
            num_dofs: nd,
            beta: nd + num_pca,
            latent: nd + num_pca + active.len(),
            active,
        };
        let weights = DataWeights {
            d2m: if tc.enabled.d2m { tc.d2m.weight } else { 0.0 },
            m2d: tc.m2d.weight,
        };
        Ok(Self {
            data: ShapeData::new(space, &layout, weights),
            prior: ShapePrior::new(
                &basis,
                &layout,
                ShapePriorParams {
                    weight: config.shape_prior,
                    radius_weight: config.radius_prior,
                    limits: config.limits,
                    damping: config.beta_damping,
                },
            ),
            validity: ShapeValidity::new(finger_order_constraints(&basis), &layout, config.valid),
            collision: Lifted(Collision::new(base, collision_params(config))),
            collision_beta: basis.template_values(),
            limits: JointLimits::new(sk, &tc.joint_limits),
            pose_prior,
            mean_pose,
            enabled: tc.enabled.clone(),
            theta_index: (0..layout.num_dofs).collect(),
            beta_index: (0..layout.active.len())
                .map(|j| layout.beta_index(j))
                .collect(),
            base: base.clone(),
            basis,
            layout,
        })
    }

    /// Rebuild the collision term on `ctx`'s template when β moved since it was built. The
    /// collision term (Ch. 3) tolerates the overlap the pills have at the rest pose; that
    /// overlap belongs to the shape, so kept at the starting template's it counts a
    /// thicker-fingered estimate's own rest geometry as penetration, pushes the fingers apart
    /// and, through the data term, the radii down (issue 8 acceptance: E_β 1.4 mm off a
    /// subject's truth within 1 s when started *at* the truth, ≈ 0.4 mm with the rebuild).
    pub(crate) fn refresh_collision(&mut self, ctx: &OnlineCtx, config: &OnlineConfig) {
        if self.collision_beta != ctx.beta {
            self.collision = Lifted(Collision::new(
                ctx.tracking.template(),
                collision_params(config),
            ));
            self.collision_beta.clone_from(&ctx.beta);
        }
    }

    /// A context on the base template (β at the template values, β̃ = 1) with the tracker's
    /// correspondence settings `tc` and no frame.
    pub(crate) fn context(&self, tc: &TrackerConfig) -> Result<OnlineCtx, OnlineError> {
        let mut tracking = TrackingCtx::owned(self.base.clone(), tc.view.view(), tc.irls.clone())?;
        tracking.set_front_facing(tc.front_facing);
        tracking.set_ray_gate(tc.ray_gate_for(None));
        tracking.set_ray_slide(tc.ray_slide);
        tracking.set_m2d(tc.enabled.m2d.then_some(tc.m2d_mode));
        tracking.set_m2d_stride(tc.m2d_stride);
        Ok(OnlineCtx {
            tracking,
            beta: self.basis.template_values(),
            latent: [1.0; 3],
            prior: None,
            dirty: false,
        })
    }

    /// The enabled terms of Eq. 4.2 — data, collision, joint limits, PCA pose prior,
    /// shape-space prior with the β bounds, shape validity — with the online calibrator's
    /// `temporal` (E_temporal, after collision) and `iekf` (E_iekf, last) where given. The order
    /// only matters to floating-point rounding.
    pub(crate) fn terms<'a>(
        &'a self,
        temporal: Option<&'a dyn EnergyTerm<OnlineCtx>>,
        iekf: Option<&'a dyn EnergyTerm<OnlineCtx>>,
    ) -> TermList<'a> {
        let mut list = TermList {
            terms: [&NoTerm; MAX_TERMS],
            len: 0,
        };
        let e = &self.enabled;
        let pose_prior = match (&self.pose_prior, e.pose_prior) {
            (Some(p), true) => Some(p as &dyn EnergyTerm<OnlineCtx>),
            _ => None,
        };
        let all: [Option<&'a dyn EnergyTerm<OnlineCtx>>; MAX_TERMS] = [
            Some(&self.data),
            e.collision
                .then_some(&self.collision as &dyn EnergyTerm<OnlineCtx>),
            temporal,
            e.joint_limits
                .then_some(&self.limits as &dyn EnergyTerm<OnlineCtx>),
            pose_prior,
            Some(&self.prior),
            Some(&self.validity),
            iekf,
        ];
        for term in all.into_iter().flatten() {
            list.push(term);
        }
        list
    }

    /// Reshape `ctx`'s template when its β changed, then re-pose it at `pose` and search the
    /// correspondences (the per-iteration precompute of every solve).
    pub(crate) fn prepare(
        &self,
        ctx: &mut OnlineCtx,
        pose: &Pose,
        rigid_only: bool,
    ) -> Result<(), TermError> {
        self.reshape(ctx)?;
        ctx.tracking.update(pose, rigid_only)
    }

    /// The first half of [`FrameProblem::prepare`]: reshape `ctx`'s template when its β
    /// changed (separate so that the online calibrator can time it apart from the
    /// correspondence search, which is what the plain tracker's stages compare with).
    pub(crate) fn reshape(&self, ctx: &mut OnlineCtx) -> Result<(), TermError> {
        if ctx.dirty {
            let t = self
                .basis
                .apply(&self.base, &ctx.beta)
                .map_err(|_| TermError::Failed("invalid shape"))?;
            ctx.tracking
                .set_template(t)
                .map_err(|_| TermError::Failed("template topology changed"))?;
            ctx.dirty = false;
        }
        Ok(())
    }

    /// Clamp the active entries of `beta` to their bounds; whether the result is a valid model
    /// (finite, accepted by the basis).
    pub(crate) fn project(&self, beta: &mut [f64]) -> bool {
        for &i in &self.layout.active {
            if let (Some(v), Some([lo, hi])) = (beta.get_mut(i), self.basis.params[i].limits) {
                *v = v.clamp(lo, hi);
            }
        }
        beta.iter().all(|v| v.is_finite()) && self.basis.apply(&self.base, beta).is_ok()
    }

    /// One shape step: `next ← β + δβ` on the active entries, clamped to the β bounds; false
    /// (and `next` unspecified) when the result is not a valid model or not finite, so that no
    /// invalid shape is ever accepted.
    pub(crate) fn step_beta(&self, beta: &[f64], delta_beta: &[f64], next: &mut Vec<f64>) -> bool {
        if delta_beta.len() != self.layout.active.len() || beta.len() != self.basis.len() {
            return false;
        }
        next.clear();
        next.extend_from_slice(beta);
        for (&i, &d) in self.layout.active.iter().zip(delta_beta) {
            next[i] += d;
        }
        self.project(next)
    }

    /// [`FrameProblem::step_beta`] together with the latent step `β̃ + δβ̃` clamped to
    /// [0.5, 2]; `None` when either is refused.
    pub(crate) fn step_shape(
        &self,
        beta: &[f64],
        latent: [f64; 3],
        delta_beta: &[f64],
        delta_latent: &[f64],
        next: &mut Vec<f64>,
    ) -> Option<[f64; 3]> {
        let latent = step_latent(latent, delta_latent)?;
        self.step_beta(beta, delta_beta, next).then_some(latent)
    }

    /// The Laplace information of Eq. 4.5 restricted to β: the data terms' Gauss–Newton
    /// Hessian at `ctx`'s linearization, marginalized over the pose
    /// ([`crate::marginal_information`]); `ne` is scratch of the layout's size. `None` when the data
    /// term fails or the Hessian is not finite.
    pub(crate) fn data_information(
        &self,
        ctx: &OnlineCtx,
        ne: &mut NormalEquations,
    ) -> Option<DMatrix<f64>> {
        let mut out = DMatrix::zeros(0, 0);
        self.data_information_into(ctx, ne, &mut InfoScratch::default(), &mut out)
            .then_some(out)
    }

    /// [`FrameProblem::data_information`] into `out` with the buffers of `scratch`; false
    /// (`out` unspecified) where that returns `None`.
    pub(crate) fn data_information_into(
        &self,
        ctx: &OnlineCtx,
        ne: &mut NormalEquations,
        scratch: &mut InfoScratch,
        out: &mut DMatrix<f64>,
    ) -> bool {
        ne.clear();
        self.data.accumulate(ctx, ne).is_ok() && self.marginal(ne, scratch, out)
    }

    /// [`FrameProblem::data_information_into`] from the data system that the LM evaluation
    /// armed by [`ShapeData::capture_next`] copied (the same numbers without assembling the
    /// rows again); false when there is no copy or the Hessian is not finite.
    pub(crate) fn captured_information(
        &self,
        scratch: &mut InfoScratch,
        out: &mut DMatrix<f64>,
    ) -> bool {
        self.data
            .captured()
            .is_some_and(|mut ne| self.marginal(&mut ne, scratch, out))
    }

    /// The pose-marginalized β block of the data system `ne` (upper triangle accumulated).
    fn marginal(
        &self,
        ne: &mut NormalEquations,
        scratch: &mut InfoScratch,
        out: &mut DMatrix<f64>,
    ) -> bool {
        ne.symmetrize();
        marginal_information_into(ne.lhs(), &self.theta_index, &self.beta_index, scratch, out)
    }
}

/// The collision settings of the joint solve: the tracker's, with the online tolerance
/// ([`OnlineConfig::collision_tolerance`], validated finite and non-negative).
fn collision_params(config: &OnlineConfig) -> CollisionParams {
    CollisionParams {
        tolerance: config.collision_tolerance,
        ..config.tracker.collision.clone()
    }
}

/// The latent scale factors β̃ of Eq. 4.14 after the step `delta` (length 3), clamped to
/// [0.5, 2]; `None` when a value is not finite or `delta` has the wrong length.
pub(crate) fn step_latent(latent: [f64; 3], delta: &[f64]) -> Option<[f64; 3]> {
    let &[a, b, c] = delta else {
        return None;
    };
    let next = [latent[0] + a, latent[1] + b, latent[2] + c];
    next.iter()
        .all(|v| v.is_finite())
        .then(|| next.map(|v| v.clamp(0.5, 2.0)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use hand_model::spheremesh::default_right_hand;
    use hmodel_spheremesh::synthetic::rendered_frame;
    use sensor_io::Camera;

    /// The Laplace information read from the data term's copy of an evaluation equals a fresh
    /// assembly at the same context bit for bit (the online calibrator's results must not
    /// depend on which one it uses), and only an armed evaluation on a cleared system is kept.
    #[test]
    fn captured_information_equals_a_fresh_assembly() {
        let base = default_right_hand();
        let config = OnlineConfig::default();
        let problem = FrameProblem::new(&base, &config, None).unwrap();
        let mut ctx = problem.context(&config.tracker).unwrap();
        let pose = Pose::from_named(
            &base.skeleton,
            [
                ("global_tz", 400.0),
                ("global_ry", 0.3),
                ("index_mcp_flex", 0.5),
                ("middle_pip_flex", 0.7),
            ],
        )
        .unwrap();
        let frame = rendered_frame(&base, &pose, &Camera::sr300_qvga(), 1000).unwrap();
        ctx.tracking.set_frame(&frame);
        let mut moved = pose.clone();
        moved.values[0] += 2.0;
        problem.prepare(&mut ctx, &moved, false).unwrap();
        let n = problem.layout.dim();
        let (mut scratch, mut fresh, mut kept) = (
            InfoScratch::default(),
            DMatrix::zeros(0, 0),
            DMatrix::zeros(0, 0),
        );
        let mut ne = NormalEquations::new(n);
        assert!(problem.data_information_into(&ctx, &mut ne, &mut scratch, &mut fresh));
        // Not armed, or armed on a system other terms already hold: no copy.
        ne.clear();
        problem.data.accumulate(&ctx, &mut ne).unwrap();
        assert!(!problem.captured_information(&mut scratch, &mut kept));
        problem.data.capture_next(true);
        ne.clear();
        ne.add_diagonal(0, 1.0).unwrap();
        problem.data.accumulate(&ctx, &mut ne).unwrap();
        assert!(!problem.captured_information(&mut scratch, &mut kept));
        // Armed, first on a cleared system (as the LM runs it): the same bits.
        problem.data.capture_next(true);
        ne.clear();
        problem.data.accumulate(&ctx, &mut ne).unwrap();
        assert!(problem.captured_information(&mut scratch, &mut kept));
        assert!(fresh.iter().any(|v| *v != 0.0));
        assert_eq!(kept, fresh);
        problem.data.capture_next(false);
        assert!(!problem.captured_information(&mut scratch, &mut kept));
    }
}
