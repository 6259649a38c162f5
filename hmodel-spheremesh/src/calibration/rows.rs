//! The rows of one depth frame's data terms over its pose *and* the shape (thesis Eq. 3.11–3.12
//! of the offline calibration; Eq. 4.2 of the online one): shared by [`super::calibrate`] and the
//! per-frame joint pose+shape solve of `honline-calib`.
//!
//! Each row is the tracker's (the same correspondences, residuals, IRLS weights and pushes of a
//! [`TrackingCtx`]) extended by the shape columns of the footpoint: for `q = Σ wᵢcᵢ + (Σ wᵢrᵢ)·n`,
//! `∂q/∂x = Σ wᵢ(∂cᵢ/∂x + n ∂rᵢ/∂x)` ([`ShapeSpace::for_each_sphere_column`], exact; `w`, `n`
//! held fixed as for the pose columns).

use hand_model::solver::NormalEquations;
use hand_model::spheremesh::PosedSphereMesh;
use nalgebra::Vector3;

use super::shape::ShapeSpace;
use crate::context::{SilhouettePush, TrackingCtx};
use crate::jacobian::MAX_ELEMENT_DOFS;

/// A sparse row assembled in a dense scratch vector.
pub(crate) struct Row {
    values: Vec<f64>,
    /// Whether an index is in `touched` (a value may sum back to 0).
    marked: Vec<bool>,
    touched: Vec<usize>,
    pairs: Vec<(usize, f64)>,
}

impl Row {
    pub(crate) fn new(n: usize) -> Self {
        Self {
            values: vec![0.0; n],
            marked: vec![false; n],
            touched: Vec::new(),
            pairs: Vec::new(),
        }
    }

    pub(crate) fn add(&mut self, i: usize, v: f64) {
        if !self.marked[i] {
            self.marked[i] = true;
            self.touched.push(i);
        }
        self.values[i] += v;
    }

    /// Add `w j²` of the row's entries from `from` on to `info[i − from]` (the data term's
    /// information about each shape unknown), then [`Row::flush`].
    pub(crate) fn flush_data(
        &mut self,
        ne: &mut NormalEquations,
        r: f64,
        w: f64,
        from: usize,
        info: &mut [f64],
    ) -> f64 {
        for &i in &self.touched {
            if let Some(x) = i.checked_sub(from).and_then(|k| info.get_mut(k)) {
                *x += w * self.values[i] * self.values[i];
            }
        }
        self.flush(ne, r, w)
    }

    /// Add the row to `ne` and reset; returns the energy `w r²`.
    pub(crate) fn flush(&mut self, ne: &mut NormalEquations, r: f64, w: f64) -> f64 {
        self.pairs.clear();
        for &i in &self.touched {
            self.pairs.push((i, self.values[i]));
            self.values[i] = 0.0;
            self.marked[i] = false;
        }
        self.touched.clear();
        ne.add_row(&self.pairs, r, w).map_or(0.0, |s| s.energy)
    }
}

/// Where one frame's unknowns live in the system.
#[derive(Copy, Clone, Debug)]
pub struct RowLayout<'a> {
    /// Index of the frame's first pose DOF (the pose in the tangent layout of `Pose::retract`).
    pub pose: usize,
    /// Per shape unknown of the [`ShapeSpace`], its index in the system (`None`: held fixed,
    /// its column is dropped).
    pub shape: &'a [Option<usize>],
}

/// τ_d2m per point and τ_m2d per pushed pixel (thesis §3.6: 1 and 0.5).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct DataWeights {
    /// τ_d2m.
    pub d2m: f64,
    /// τ_m2d.
    pub m2d: f64,
}

/// The energies of one frame's data rows at the linearization point.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct DataEnergy {
    /// E_d2m: `τ Σ ρ(r)` (the Huber/IRLS penalty on reweighted iterations, `τ Σ r²` otherwise).
    pub d2m: f64,
    /// E_m2d: `τ Σ ‖π(x) − Π_D(x)‖²` (pixels²).
    pub m2d: f64,
    /// Number of scalar rows added.
    pub rows: usize,
}

/// Scratch for the data rows of frames over pose and shape (module docs). Reuse one per system
/// size: after the first frame nothing allocates.
pub struct ShapeRows {
    pub(crate) row: Row,
    /// Per sphere of the template, its mapped shape columns `(system index, ∂c, ∂r)`:
    /// `columns[starts[s]..starts[s + 1]]`, rebuilt for every frame's posed model.
    columns: Vec<(usize, Vector3<f64>, f64)>,
    starts: Vec<usize>,
}

impl ShapeRows {
    /// Scratch for systems of `n` unknowns.
    pub fn new(n: usize) -> Self {
        Self {
            row: Row::new(n),
            columns: Vec::new(),
            starts: Vec::new(),
        }
    }

    /// Cache the mapped shape columns of every sphere of `ctx`'s posed template.
    fn cache_columns(&mut self, ctx: &TrackingCtx<'_>, space: &ShapeSpace, layout: &RowLayout<'_>) {
        let t = ctx.template();
        let posed = ctx.posed_mesh();
        self.columns.clear();
        self.starts.clear();
        for s in 0..t.spheres.len() {
            self.starts.push(self.columns.len());
            let columns = &mut self.columns;
            space.for_each_sphere_column(t, posed, s, 1.0, &mut |i, dc, dr| {
                if let Some(Some(k)) = layout.shape.get(i) {
                    columns.push((*k, dc, dr));
                }
            });
        }
        self.starts.push(self.columns.len());
    }

    /// Add the shape part `Σ wᵢ (g·∂cᵢ + gn·∂rᵢ)` of a footpoint row.
    fn add_shape(&mut self, spheres: &[u32; 3], weights: &[f64; 3], g: &Vector3<f64>, gn: f64) {
        for (&s, &w) in spheres.iter().zip(weights) {
            if w == 0.0 {
                continue;
            }
            let s = s as usize;
            let Some(range) = self.starts.get(s..s + 2) else {
                continue;
            };
            for &(k, dc, dr) in &self.columns[range[0]..range[1]] {
                self.row.add(k, w * (g.dot(&dc) + gn * dr));
            }
        }
    }

    /// Add the d2m rows (Eq. 3.11 / Eq. 3.4: `r = −‖p − q‖`, row `uᵀ∂q/∂x`, IRLS weight) and the
    /// m2d rows (Eq. 3.12 / Eq. 3.5: two pixel rows `J_π ∂x/∂x` per push) of the frame held by
    /// `ctx` (already updated at the frame's pose) to `ne`, over the pose DOFs at
    /// `layout.pose` and the shape unknowns mapped by `layout.shape`. The data information
    /// `Σ w j²` of each system unknown `k ≥ info_from` is added to `info[k − info_from]` (an empty
    /// slice skips it).
    #[allow(clippy::too_many_arguments)]
    pub fn add_frame(
        &mut self,
        ctx: &TrackingCtx<'_>,
        space: &ShapeSpace,
        layout: &RowLayout<'_>,
        weights: &DataWeights,
        ne: &mut NormalEquations,
        info: &mut [f64],
        info_from: usize,
    ) -> DataEnergy {
        self.cache_columns(ctx, space, layout);
        let posed = ctx.posed_mesh();
        let jacobian = ctx.jacobian();
        let irls = ctx.irls();
        let theta = layout.pose;
        let mut cols = [Vector3::zeros(); MAX_ELEMENT_DOFS];
        let mut out = DataEnergy::default();
        for (c, u, r, wr) in ctx.d2m_rows() {
            let dofs =
                jacobian.columns(posed, c.element as usize, &c.spheres, &c.weights, &mut cols);
            for (&d, col) in dofs.iter().zip(&cols) {
                self.row.add(theta + d, u.dot(col));
            }
            self.add_shape(&c.spheres, &c.weights, u, u.dot(&c.normal));
            self.row
                .flush_data(ne, r, weights.d2m * wr, info_from, info);
            // The energy the steps are judged by: the Huber norm itself (its IRLS quadratic has
            // the same value and gradient at the linearization point).
            out.d2m += weights.d2m
                * if ctx.reweighted() {
                    irls.penalty(r)
                } else {
                    r * r
                };
            out.rows += 1;
        }
        if let Some(camera) = ctx.sensor().camera.as_ref() {
            let w = weights.m2d * ctx.m2d_pixel_weight();
            for push in ctx.pushes() {
                let x = &push.point;
                let res = camera.project(x) - push.target;
                let jp = camera.projection_jacobian(x);
                let dofs = jacobian.columns(
                    posed,
                    push.element as usize,
                    &push.spheres,
                    &push.weights,
                    &mut cols,
                );
                let normal = posed_normal(posed, push);
                for axis in 0..2 {
                    let g = jp.row(axis).transpose();
                    for (&d, col) in dofs.iter().zip(&cols) {
                        self.row.add(theta + d, g.dot(col));
                    }
                    self.add_shape(&push.spheres, &push.weights, &g, g.dot(&normal));
                    out.m2d += self.row.flush_data(ne, res[axis], w, info_from, info);
                    out.rows += 1;
                }
            }
        }
        out
    }
}

/// The normal of the element surface at a push point (`q − s` of its interpolated sphere).
fn posed_normal(posed: &PosedSphereMesh, push: &SilhouettePush) -> Vector3<f64> {
    let (mut s, mut r) = (Vector3::zeros(), 0.0);
    for (&i, &w) in push.spheres.iter().zip(&push.weights) {
        s += posed.spheres[i as usize].center * w;
        r += posed.spheres[i as usize].radius * w;
    }
    let d = push.point - s;
    if r > 0.0 && d.norm() > 1e-12 {
        d / d.norm()
    } else {
        Vector3::zeros()
    }
}
