//! The energy terms of the per-frame joint pose+shape solve (thesis Eq. 4.2) that involve β:
//! the data terms with shape columns, the shape-space prior (Eq. 4.14) with the β bounds, the
//! shape-validity barriers (Eq. 4.15) and the IEKF prior (Eq. 4.11). The pose-only terms are the
//! tracker's ([`hmodel_spheremesh::terms`], [`hand_model::solver::terms`]), run on the same
//! context through [`PoseContext`] or [`Lifted`].

use std::cell::{RefCell, RefMut};

use hand_model::kinematics::{Pose, PosedSkeleton, Skeleton};
use hand_model::solver::{EnergyTerm, NormalEquations, PoseContext, TermError, TermStats};
use hand_model::spheremesh::{ShapeBasis, ShapeKind};
use hmodel_spheremesh::calibration::{DataWeights, RowLayout, ShapeRows, ShapeSpace};
use hmodel_spheremesh::TrackingCtx;
use nalgebra::DMatrix;

/// Where the unknowns of the per-frame system live: `[θ (num_dofs) | PCA latents | β_active |
/// β̃ (3)]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    /// Pose DOFs.
    pub num_dofs: usize,
    /// Index of the first active β unknown.
    pub beta: usize,
    /// Indices into the β basis of the active entries ([`crate::ShapeSubset`]).
    pub active: Vec<usize>,
    /// Index of the 3 latent scale factors β̃ (height, width, thickness) of Eq. 4.14.
    pub latent: usize,
}

impl Layout {
    /// Total number of unknowns.
    pub fn dim(&self) -> usize {
        self.latent + 3
    }

    /// System index of the `k`-th active β entry.
    pub fn beta_index(&self, k: usize) -> usize {
        self.beta + k
    }
}

/// The per-iteration context of the online solve: the tracker's context (its template is the
/// base template reshaped to the current β) and the shape state.
pub struct OnlineCtx {
    /// Correspondences, pushes, posed model.
    pub tracking: TrackingCtx<'static>,
    /// The full honline β (absolute values, mm).
    pub beta: Vec<f64>,
    /// The latent scale factors β̃ of Eq. 4.14 (1 = template).
    pub latent: [f64; 3],
    /// The IEKF prior `(x̂_{n−1}, Σ̂⁻¹_{n−1})` over the active β (Eq. 4.11), when used.
    pub prior: Option<(Vec<f64>, DMatrix<f64>)>,
    /// Whether `beta` changed since the template was last reshaped.
    pub dirty: bool,
}

impl PoseContext for OnlineCtx {
    fn skeleton(&self) -> &Skeleton {
        self.tracking.skeleton()
    }
    fn pose(&self) -> &Pose {
        self.tracking.pose()
    }
    fn posed(&self) -> &PosedSkeleton {
        self.tracking.posed()
    }
}

/// A tracker term over [`TrackingCtx`] run on the [`OnlineCtx`] (e.g. the collision term).
pub struct Lifted<T>(pub T);

impl<T: EnergyTerm<TrackingCtx<'static>>> EnergyTerm<OnlineCtx> for Lifted<T> {
    fn name(&self) -> &'static str {
        self.0.name()
    }
    fn accumulate(
        &self,
        ctx: &OnlineCtx,
        ne: &mut NormalEquations,
    ) -> Result<TermStats, TermError> {
        self.0.accumulate(&ctx.tracking, ne)
    }
    fn pose_only_prior(&self) -> bool {
        self.0.pose_only_prior()
    }
}

/// E_d2m + E_m2d (Eq. 4.2's data terms, Eq. 3.4–3.5) over pose *and* the active β: the rows of
/// [`ShapeRows`] (shared with the offline calibration), columns exact.
///
/// It can keep a copy of the system it adds on one chosen evaluation
/// ([`ShapeData::capture_next`]): the online calibrator's Laplace information (Eq. 4.5) is this
/// term's Hessian at the last linearization of the solve, which the LM's final evaluation has
/// just assembled — kept, it need not be assembled a second time (one full pass over the rows).
pub struct ShapeData {
    space: ShapeSpace,
    /// Per unknown of `space`, its index in the system.
    map: Vec<Option<usize>>,
    weights: DataWeights,
    rows: RefCell<ShapeRows>,
    capture: RefCell<Capture>,
}

/// The copy of the data system taken by [`ShapeData::capture_next`], with its scratch.
struct Capture {
    /// Whether the next evaluation is copied.
    armed: bool,
    /// Whether `ne` holds the copy of the last armed evaluation.
    valid: bool,
    ne: NormalEquations,
    /// `0..dim` (the columns of the copy) and the packed upper triangle of the system.
    all: Vec<usize>,
    upper: Vec<f64>,
}

impl Capture {
    fn new(n: usize) -> Self {
        Self {
            armed: false,
            valid: false,
            ne: NormalEquations::new(n),
            all: (0..n).collect(),
            upper: Vec::with_capacity(n * (n + 1) / 2),
        }
    }

    /// Copy `ne` (upper triangle and `b`) into the capture: `0 + x` for every entry, so the
    /// copy has the bits of the original (a −0 becomes +0).
    fn copy(&mut self, ne: &NormalEquations) {
        let n = self.all.len();
        self.upper.clear();
        for a in 0..n {
            self.upper.extend((a..n).map(|b| ne.lhs_entry(a, b)));
        }
        self.ne.clear();
        self.valid = self
            .ne
            .add_packed_block(&self.all, &self.upper, ne.rhs().as_slice())
            .is_ok();
    }
}

/// Whether every entry of `A`'s upper triangle and of `b` is zero (a cleared system).
fn is_cleared(ne: &NormalEquations) -> bool {
    let n = ne.dim();
    ne.rhs().iter().all(|&v| v == 0.0) && (0..n).all(|j| (0..=j).all(|i| ne.lhs_entry(i, j) == 0.0))
}

impl ShapeData {
    /// The data term of `space` (β of the base template) for `layout`, with τ_d2m, τ_m2d.
    pub fn new(space: ShapeSpace, layout: &Layout, weights: DataWeights) -> Self {
        let mut map = vec![None; space.len()];
        for (k, &i) in layout.active.iter().enumerate() {
            map[i] = Some(layout.beta_index(k));
        }
        Self {
            rows: RefCell::new(ShapeRows::new(layout.dim())),
            capture: RefCell::new(Capture::new(layout.dim())),
            space,
            map,
            weights,
        }
    }

    /// Copy the system of the next [`EnergyTerm::accumulate`] (`on`), or not; forgets the
    /// previous copy either way. Only an evaluation that starts on a cleared system (this
    /// term first, as [`crate::OnlineCalibrator`] orders them) is copied: then the copy is
    /// exactly this term's part.
    pub fn capture_next(&self, on: bool) {
        if let Ok(mut c) = self.capture.try_borrow_mut() {
            c.armed = on;
            c.valid = false;
        }
    }

    /// The system copied by the evaluation [`ShapeData::capture_next`] armed (upper triangle
    /// as accumulated), if it ran; it equals a fresh `accumulate` on a cleared system at the
    /// same context.
    pub(crate) fn captured(&self) -> Option<RefMut<'_, NormalEquations>> {
        let c = self.capture.try_borrow_mut().ok()?;
        c.valid.then(|| RefMut::map(c, |c| &mut c.ne))
    }
}

impl EnergyTerm<OnlineCtx> for ShapeData {
    fn name(&self) -> &'static str {
        "data"
    }
    fn accumulate(
        &self,
        ctx: &OnlineCtx,
        ne: &mut NormalEquations,
    ) -> Result<TermStats, TermError> {
        let layout = RowLayout {
            pose: 0,
            shape: &self.map,
        };
        let Ok(mut rows) = self.rows.try_borrow_mut() else {
            return Err(TermError::Failed("data term re-entered"));
        };
        let mut capture = self.capture.try_borrow_mut().ok().filter(|c| c.armed);
        let fresh = capture
            .as_ref()
            .is_some_and(|c| ne.dim() == c.all.len() && is_cleared(ne));
        let e = rows.add_frame(
            &ctx.tracking,
            &self.space,
            &layout,
            &self.weights,
            ne,
            &mut [],
            0,
        );
        if let Some(c) = capture.as_mut() {
            c.armed = false;
            if fresh {
                c.copy(ne);
            }
        }
        Ok(TermStats {
            energy: e.d2m + e.m2d,
            rows: e.rows,
        })
    }
}

/// Settings of [`ShapePrior`].
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ShapePriorParams {
    /// ω_shape-space per mm² for lengths and positions (Eq. 4.14; "≪ 1" relative to the data).
    pub weight: f64,
    /// ω_shape-space per mm² for radii.
    pub radius_weight: f64,
    /// Weight of the β bounds ([`ShapeKind::default_limits`], honline's joint-limit energy on β).
    pub limits: f64,
    /// LM damping of β per mm² (energy 0; it only shortens the step).
    pub damping: f64,
}

/// E_shape-space (Eq. 4.14) `Σ ω (β_i − β̄_i β̃_{k(i)})²` over the active entries, jointly in β
/// and the latent β̃ (height, width, thickness; [`ShapeKind::latent_axis`]), plus the β bounds
/// as one-sided quadratic barriers and the LM damping of β.
pub struct ShapePrior {
    params: ShapePriorParams,
    /// Factor on the two ω ([`ShapePrior::set_noise_scale`]).
    scale: f64,
    layout: Layout,
    /// Per active entry: template value, latent axis, bounds, radius.
    entries: Vec<(f64, usize, Option<[f64; 2]>, bool)>,
}

impl ShapePrior {
    /// The prior over `layout.active` of `basis`.
    pub fn new(basis: &ShapeBasis, layout: &Layout, params: ShapePriorParams) -> Self {
        let entries = layout
            .active
            .iter()
            .map(|&i| {
                let p = &basis.params[i];
                (
                    p.template_value,
                    p.kind.latent_axis(),
                    p.limits,
                    p.kind == ShapeKind::Radius,
                )
            })
            .collect();
        Self {
            params,
            scale: 1.0,
            layout: layout.clone(),
            entries,
        }
    }

    /// Express ω per unit of the data's noise: both ω times `scale`
    /// (`sensor_io::preprocess::noise_scale` of σ̂; a non-finite or sub-1 value counts as 1;
    /// see [`crate::OnlineConfig::noise_scaled_prior`]).
    pub fn set_noise_scale(&mut self, scale: f64) {
        self.scale = if scale.is_finite() {
            scale.max(1.0)
        } else {
            1.0
        };
    }
}

impl EnergyTerm<OnlineCtx> for ShapePrior {
    fn name(&self) -> &'static str {
        "shape_prior"
    }
    fn accumulate(
        &self,
        ctx: &OnlineCtx,
        ne: &mut NormalEquations,
    ) -> Result<TermStats, TermError> {
        let mut stats = TermStats::ZERO;
        for (k, (&i, &(bar, axis, limits, radius))) in
            self.layout.active.iter().zip(&self.entries).enumerate()
        {
            let b = ctx.beta.get(i).copied().ok_or(TermError::ShapeMismatch {
                expected: i + 1,
                found: ctx.beta.len(),
            })?;
            let bi = self.layout.beta_index(k);
            let w = self.scale
                * if radius {
                    self.params.radius_weight
                } else {
                    self.params.weight
                };
            let r = b - bar * ctx.latent[axis];
            stats += ne.add_row(&[(bi, 1.0), (self.layout.latent + axis, -bar)], r, w)?;
            if let Some([lo, hi]) = limits {
                let excess = if b > hi {
                    b - hi
                } else if b < lo {
                    b - lo
                } else {
                    0.0
                };
                if excess != 0.0 {
                    stats += ne.add_row(&[(bi, 1.0)], excess, self.params.limits)?;
                }
            }
            ne.add_diagonal(bi, self.params.damping)?;
        }
        Ok(stats)
    }
}

/// One shape-validity constraint of Eq. 4.15: `⟨β, κ⟩ ≥ 0`, enforced by the quadratic barrier
/// `χ(β)·⟨β, κ⟩²` with `χ = 1` only when violated.
#[derive(Clone, Debug, PartialEq)]
pub struct Constraint {
    /// What it keeps valid.
    pub name: String,
    /// `κ` as `(β index, coefficient)`.
    pub kappa: Vec<(usize, f64)>,
}

impl Constraint {
    /// `⟨β, κ⟩`.
    pub fn value(&self, beta: &[f64]) -> f64 {
        self.kappa
            .iter()
            .map(|&(i, c)| c * beta.get(i).copied().unwrap_or(0.0))
            .sum()
    }
}

/// The finger-order constraints of Eq. 4.15 (ANCHOR-FACTS §7.4, the thesis' example): for
/// neighbouring fingers (index, middle), (middle, ring), (ring, pinky), the base positions stay
/// ordered across the palm with room for their base spheres,
/// `s·(x_a − x_b) − ½(r_a + r_b) ≥ 0` with `s` the side of the index finger on `basis`'s template
/// (the thumb side is −x on a right hand); and a finger's base stays above the palm's wrist end,
/// `y_base − ½·bottom_length ≥ 0`. Constraints that the template itself violates are dropped.
pub fn finger_order_constraints(basis: &ShapeBasis) -> Vec<Constraint> {
    let idx = |n: &str| basis.names().position(|m| m == n);
    let beta = basis.template_values();
    let side = match (idx("index_base_x"), idx("pinky_base_x")) {
        (Some(a), Some(b)) if beta[a] != beta[b] => (beta[a] - beta[b]).signum(),
        _ => return Vec::new(),
    };
    let mut out = Vec::new();
    let digits = ["index", "middle", "ring", "pinky"];
    for w in digits.windows(2) {
        let (a, b) = (w[0], w[1]);
        let ids = (
            idx(&format!("{a}_base_x")),
            idx(&format!("{b}_base_x")),
            idx(&format!("{a}_base_radius")),
            idx(&format!("{b}_base_radius")),
        );
        if let (Some(xa), Some(xb), Some(ra), Some(rb)) = ids {
            out.push(Constraint {
                name: format!("{a}_{b}_order"),
                kappa: vec![(xa, side), (xb, -side), (ra, -0.5), (rb, -0.5)],
            });
        }
    }
    for d in digits {
        if let (Some(y), Some(l)) = (
            idx(&format!("{d}_base_y")),
            idx(&format!("{d}_bottom_length")),
        ) {
            out.push(Constraint {
                name: format!("{d}_base_above_wrist"),
                kappa: vec![(y, 1.0), (l, -0.5)],
            });
        }
    }
    out.retain(|c| c.value(&beta) >= 0.0);
    out
}

/// E_shape-valid (Eq. 4.15) over the active β: one row per violated [`Constraint`] (columns of
/// inactive entries dropped: they do not move).
pub struct ShapeValidity {
    weight: f64,
    /// Per constraint, its active-β columns.
    rows: Vec<(Constraint, Vec<(usize, f64)>)>,
}

impl ShapeValidity {
    /// The barriers of `constraints` with weight `weight` (per mm²).
    pub fn new(constraints: Vec<Constraint>, layout: &Layout, weight: f64) -> Self {
        let rows = constraints
            .into_iter()
            .map(|c| {
                let cols = c
                    .kappa
                    .iter()
                    .filter_map(|&(i, v)| {
                        layout
                            .active
                            .iter()
                            .position(|&a| a == i)
                            .map(|k| (layout.beta_index(k), v))
                    })
                    .collect();
                (c, cols)
            })
            .collect();
        Self { weight, rows }
    }

    /// The constraints violated by `beta`.
    pub fn violated<'a>(&'a self, beta: &'a [f64]) -> impl Iterator<Item = &'a Constraint> + 'a {
        self.rows
            .iter()
            .map(|(c, _)| c)
            .filter(move |c| c.value(beta) < 0.0)
    }
}

impl EnergyTerm<OnlineCtx> for ShapeValidity {
    fn name(&self) -> &'static str {
        "shape_valid"
    }
    fn accumulate(
        &self,
        ctx: &OnlineCtx,
        ne: &mut NormalEquations,
    ) -> Result<TermStats, TermError> {
        self.rows
            .iter()
            .filter(|(c, cols)| !cols.is_empty() && c.value(&ctx.beta) < 0.0)
            .try_fold(TermStats::ZERO, |acc, (c, cols)| {
                Ok(acc + ne.add_row(cols, c.value(&ctx.beta), self.weight)?)
            })
    }
}

/// E_iekf (Eq. 4.11): `‖Σ̂_{n−1}^{−1/2}(β − β̂_{n−1})‖²` over the active β — the accumulated
/// information of the previous frames as a quadratic prior inside the LM (Table 2, the joint
/// cumulative estimate; §4.6.3: LM on it is an iterated extended Kalman filter). Only the shape
/// block: the pose is not persistent, its temporal prior is the tracker's E_temporal.
pub struct IekfPrior {
    indices: Vec<usize>,
    active: Vec<usize>,
}

impl IekfPrior {
    /// The prior over the active β of `layout`.
    pub fn new(layout: &Layout) -> Self {
        Self {
            indices: (0..layout.active.len())
                .map(|k| layout.beta_index(k))
                .collect(),
            active: layout.active.clone(),
        }
    }

    /// The term's name in solver reports and track records.
    pub const NAME: &'static str = "iekf";
}

impl EnergyTerm<OnlineCtx> for IekfPrior {
    fn name(&self) -> &'static str {
        Self::NAME
    }
    fn accumulate(
        &self,
        ctx: &OnlineCtx,
        ne: &mut NormalEquations,
    ) -> Result<TermStats, TermError> {
        let Some((mean, info)) = &ctx.prior else {
            return Ok(TermStats::ZERO);
        };
        if mean.len() != self.active.len() {
            return Err(TermError::ShapeMismatch {
                expected: self.active.len(),
                found: mean.len(),
            });
        }
        ne.add_quadratic_form(&self.indices, info, |z| {
            for ((z, &i), m) in z.iter_mut().zip(&self.active).zip(mean) {
                *z = ctx.beta.get(i).copied().unwrap_or(0.0) - m;
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hand_model::query::View;
    use hand_model::solver::IrlsParams;
    use hand_model::spheremesh::default_right_hand;

    /// The β terms' half gradients `b = −½∂E/∂x` against central differences of their energies,
    /// over every active β and latent unknown, with a violated validity constraint, β bounds
    /// crossed and a dense IEKF information matrix.
    #[test]
    fn shape_terms_match_finite_differences() {
        let base = default_right_hand();
        let basis = ShapeBasis::honline(&base).unwrap();
        let active = crate::ShapeSubset::Observable.indices(&basis);
        let k = active.len();
        let layout = Layout {
            num_dofs: base.skeleton.num_dofs(),
            beta: base.skeleton.num_dofs(),
            latent: base.skeleton.num_dofs() + k,
            active: active.clone(),
        };
        let params = ShapePriorParams {
            weight: 2.0,
            radius_weight: 5.0,
            limits: 100.0,
            damping: 0.0,
        };
        let prior = ShapePrior::new(&basis, &layout, params);
        let mut constraints = finger_order_constraints(&basis);
        assert!(!constraints.is_empty());
        // A constraint the test state violates.
        constraints[0].kappa.push((active[0], -3.0));
        let validity = ShapeValidity::new(constraints, &layout, 7.0);
        let iekf = IekfPrior::new(&layout);
        let mut beta = basis.template_values();
        for (j, &i) in active.iter().enumerate() {
            beta[i] *= 1.0 + 0.03 * ((j * 7 % 11) as f64 - 5.0) / 5.0;
        }
        let lim = basis.params[active[0]].limits.unwrap();
        beta[active[0]] = lim[1] + 0.7;
        let a = DMatrix::from_fn(k, k, |i, j| ((i * 3 + j * 5) % 7) as f64 * 0.1);
        let info = &a * a.transpose() + DMatrix::identity(k, k);
        let mean: Vec<f64> = active
            .iter()
            .map(|&i| basis.params[i].template_value)
            .collect();
        let tracking = TrackingCtx::owned(
            base.clone(),
            View::Orthographic(nalgebra::Vector3::z()),
            IrlsParams::default(),
        )
        .unwrap();
        let mut ctx = OnlineCtx {
            tracking,
            beta,
            latent: [1.02, 0.97, 1.05],
            prior: Some((mean, info)),
            dirty: false,
        };
        let terms: [&dyn EnergyTerm<OnlineCtx>; 3] = [&prior, &validity, &iekf];
        let energy = |ctx: &OnlineCtx| {
            let mut ne = NormalEquations::new(layout.dim());
            terms
                .iter()
                .map(|t| t.accumulate(ctx, &mut ne).unwrap().energy)
                .sum::<f64>()
        };
        let mut ne = NormalEquations::new(layout.dim());
        for t in terms {
            t.accumulate(&ctx, &mut ne).unwrap();
        }
        // Every term is piecewise quadratic: central differences are exact away from the kinks.
        let h = 1e-3;
        let mut worst: f64 = 0.0;
        for x in layout.beta..layout.dim() {
            let shift = |ctx: &mut OnlineCtx, d: f64| {
                if x < layout.latent {
                    ctx.beta[active[x - layout.beta]] += d;
                } else {
                    ctx.latent[x - layout.latent] += d;
                }
            };
            shift(&mut ctx, h);
            let ep = energy(&ctx);
            shift(&mut ctx, -2.0 * h);
            let em = energy(&ctx);
            shift(&mut ctx, h);
            let fd = -0.5 * (ep - em) / (2.0 * h);
            let b = ne.rhs()[x];
            worst = worst.max((fd - b).abs() / b.abs().max(1.0));
        }
        assert!(worst < 1e-5, "worst relative error {worst}");
    }
}
