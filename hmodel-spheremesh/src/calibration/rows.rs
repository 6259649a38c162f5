//! The rows of one depth frame's data terms over its pose *and* the shape (thesis Eq. 3.11–3.12
//! of the offline calibration; Eq. 4.2 of the online one): shared by [`super::calibrate`] and the
//! per-frame joint pose+shape solve of `honline-calib`.
//!
//! Each row is the tracker's (the same correspondences, residuals, IRLS weights and pushes of a
//! [`TrackingCtx`]) extended by the shape columns of the footpoint: for `q = Σ wᵢcᵢ + (Σ wᵢrᵢ)·n`,
//! `∂q/∂x = Σ wᵢ(∂cᵢ/∂x + n ∂rᵢ/∂x)` ([`ShapeSpace::for_each_sphere_column`], exact; `w`, `n`
//! held fixed as for the pose columns).
//!
//! # Accumulation per element
//! Rows are not added one by one (a row carries 20–40 pose and shape columns, and `JᵀJ` costs
//! their square per row). Every column of a footpoint row on element `e` is linear in the
//! barycentric weights: `∂c_i/∂θ` and the shape columns `(∂cᵢ, ∂rᵢ)` depend on the sphere only,
//! so the row is `j = z′ᵀE_e`, with `E_e` the `4m × K` matrix stacking per sphere `i` of the
//! element (`m` of them) `[∂cᵢ/∂θ ∂cᵢ/∂β; 0 ∂rᵢ/∂β]` over the element's `K` columns, and
//! `z′ = (wᵢ·[g; g·n])ᵢ` (`g` the row's direction: `u` for d2m, a row of `J_π` for m2d). The
//! rows of an element then sum to `Eᵀ(Σ ω z′z′ᵀ)E`: each row adds `wₗwₗ′·ω zzᵀ` to the 4 × 4
//! blocks of the sphere pairs it weights (a `4m × 4m` moment, `z = [g; g·n]`), and the product
//! is formed once per element and evaluation ([`ShapeRows::add_frame`]; equal to the
//! row-by-row sum up to rounding, tested). A row then costs at most 6 × 16 multiply-adds instead
//! of `K(K+1)/2` scattered ones, and its pose columns are never formed.

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
    elements: ElementMaps,
    /// Whether rows are summed per element (false: every row on its own, the reference the
    /// tests compare with).
    blocked: bool,
}

/// Most spheres of an element (a wedge).
const MAX_SPHERES: usize = 3;
/// Most entries of `z′` (module docs): `[g; g·n]` per sphere.
const Z: usize = 4 * MAX_SPHERES;

/// The rows of one element summed in `z′` space (module docs): `Σ ω z′z′ᵀ`, of which only the
/// 4 × 4 blocks of sphere pairs `l ≤ l′` are kept, and `Σ ω r z′`.
#[derive(Copy, Clone)]
struct Moment {
    m: [[f64; Z]; Z],
    v: [f64; Z],
    used: bool,
}

impl Moment {
    const ZERO: Self = Self {
        m: [[0.0; Z]; Z],
        v: [0.0; Z],
        used: false,
    };

    /// Add the row `z′ = (wₗ z)ₗ` (`wl[..m]`, `z = [g; g·n]`) with residual `r` and weight `ω`:
    /// multiples of one `ω zzᵀ` on fixed-size blocks, 16 multiply-adds per sphere pair (at
    /// most 6), with no `z′` formed.
    #[inline]
    fn add(&mut self, wl: &[f64; MAX_SPHERES], m: usize, z: &[f64; 4], r: f64, w: f64) {
        match m {
            0 => {}
            1 => self.add_spheres::<1>(wl, z, r, w),
            2 => self.add_spheres::<2>(wl, z, r, w),
            _ => self.add_spheres::<MAX_SPHERES>(wl, z, r, w),
        }
        self.used = true;
    }

    /// [`Moment::add`] for an element of `M` spheres, unrolled. The pairs a footpoint does
    /// not weigh (a cap or an edge of a wedge: `wₗ = 0`) are added too, as ±0 that leaves
    /// every sum bit for bit unchanged (a sum that starts at +0 is never −0), rather than
    /// skipped behind a branch that the footpoints' mix of faces, edges and caps mispredicts.
    #[inline(always)]
    fn add_spheres<const M: usize>(
        &mut self,
        wl: &[f64; MAX_SPHERES],
        z: &[f64; 4],
        r: f64,
        w: f64,
    ) {
        let mut zz = [[0.0; 4]; 4];
        for (row, &za) in zz.iter_mut().zip(z) {
            for (x, &zb) in row.iter_mut().zip(z) {
                *x = w * za * zb;
            }
        }
        for l in 0..M {
            let wr = w * r * wl[l];
            for (v, &zc) in self.v[4 * l..4 * l + 4].iter_mut().zip(z) {
                *v += wr * zc;
            }
            for l2 in l..M {
                let c = wl[l] * wl[l2];
                for (row, zzr) in self.m[4 * l..4 * l + 4].iter_mut().zip(&zz) {
                    for (x, &y) in row[4 * l2..4 * l2 + 4].iter_mut().zip(zzr) {
                        *x += c * y;
                    }
                }
            }
        }
    }
}

/// The matrices `E_e` of the module docs, rebuilt for every evaluation (allocation-free once
/// sized), and the scratch of their products.
#[derive(Default)]
struct ElementMaps {
    /// Per element its spheres and their count; `None` where its rows go one by one (more than
    /// three spheres, or a column outside the system).
    spheres: Vec<Option<([u32; MAX_SPHERES], usize)>>,
    /// Per element the sums of its rows.
    moments: Vec<Moment>,
    /// System indices of the columns of every element, element after element: element `e`
    /// has `cols[col_start[e]..col_start[e + 1]]`, its pose DOFs first.
    cols: Vec<usize>,
    col_start: Vec<usize>,
    /// `E_e` row-major (`4m` rows of `K` values) at `e_start[e]`.
    e: Vec<f64>,
    e_start: Vec<usize>,
    /// Per element and row of `E_e`, the columns `[lo, hi)` outside which the row is zero
    /// (a radius row holds the one or two radius columns of its sphere): the products with
    /// those zeros would only add ±0.
    spans: Vec<[[usize; 2]; Z]>,
    /// Per system unknown, its slot in the element being mapped (`u32::MAX`: none yet).
    slot_of: Vec<u32>,
    /// Flush scratch: `M E_e`, the packed `K × K` block and its right-hand side.
    me: Vec<f64>,
    upper: Vec<f64>,
    rhs: Vec<f64>,
}

impl ElementMaps {
    /// The slot of system unknown `i` among the columns of the element whose columns start at
    /// `start`, added when new; `None` when `i` is outside the system.
    fn slot(&mut self, i: usize, start: usize) -> Option<usize> {
        let s = self.slot_of.get_mut(i)?;
        if *s == u32::MAX {
            *s = (self.cols.len() - start) as u32;
            self.cols.push(i);
        }
        Some(*s as usize)
    }

    /// Map every element of `ctx`'s posed template for a system of `dim` unknowns, its pose
    /// at `theta`, with the shape columns of [`ShapeRows`].
    fn build(
        &mut self,
        ctx: &TrackingCtx<'_>,
        columns: &[(usize, Vector3<f64>, f64)],
        starts: &[usize],
        theta: usize,
        dim: usize,
    ) {
        let t = ctx.template();
        let (posed, jacobian) = (ctx.posed_mesh(), ctx.jacobian());
        self.spheres.clear();
        self.moments.clear();
        self.moments.resize(t.elements.len(), Moment::ZERO);
        self.cols.clear();
        self.col_start.clear();
        self.e.clear();
        self.e_start.clear();
        self.spans.clear();
        self.slot_of.clear();
        self.slot_of.resize(dim, u32::MAX);
        let mut g = [Vector3::zeros(); MAX_ELEMENT_DOFS];
        for (el, def) in t.elements.iter().enumerate() {
            let start = self.cols.len();
            self.col_start.push(start);
            self.e_start.push(self.e.len());
            let ids = def.element.spheres();
            let dofs = jacobian.dofs(el);
            // Pose DOFs first: slot j is the j-th DOF (distinct, sorted), as `columns` writes.
            let mut ok = ids.len() <= MAX_SPHERES;
            for (j, &d) in dofs.iter().enumerate() {
                ok &= self.slot(theta + d, start) == Some(j);
            }
            for &s in ids {
                let range = starts.get(s as usize..s as usize + 2);
                ok &= range.is_some();
                for &(i, _, _) in range.map_or(&[][..], |r| &columns[r[0]..r[1]]) {
                    ok &= self.slot(i, start).is_some();
                }
            }
            let k = self.cols.len() - start;
            let mut spans = [[0, 0]; Z];
            if ok {
                let e0 = self.e.len();
                self.e.resize(e0 + 4 * ids.len() * k, 0.0);
                for (l, &s) in ids.iter().enumerate() {
                    let rows = &mut self.e[e0 + 4 * l * k..e0 + 4 * (l + 1) * k];
                    // ∂cₛ/∂θ: the footpoint columns of the sphere center alone.
                    let n = jacobian
                        .columns(posed, el, &[s; 3], &[1.0, 0.0, 0.0], &mut g)
                        .len();
                    for (j, col) in g[..n].iter().enumerate() {
                        for c in 0..3 {
                            rows[c * k + j] = col[c];
                        }
                    }
                    // The center rows span the pose columns and the sphere's center columns,
                    // the radius row its radius columns (empty: `[k, 0)`).
                    let (mut center, mut radius) = ([0, n], [k, 0]);
                    let s = s as usize;
                    for &(i, dc, dr) in &columns[starts[s]..starts[s + 1]] {
                        let slot = self.slot_of[i] as usize;
                        for c in 0..3 {
                            rows[c * k + slot] += dc[c];
                        }
                        rows[3 * k + slot] += dr;
                        if dc != Vector3::zeros() {
                            center[1] = center[1].max(slot + 1);
                        }
                        if dr != 0.0 {
                            radius = [radius[0].min(slot), radius[1].max(slot + 1)];
                        }
                    }
                    spans[4 * l..4 * l + 3].fill(center);
                    spans[4 * l + 3] = [radius[0].min(radius[1]), radius[1]];
                }
                let mut spheres = [0; MAX_SPHERES];
                spheres[..ids.len()].copy_from_slice(ids);
                self.spheres.push(Some((spheres, ids.len())));
            } else {
                self.spheres.push(None);
            }
            self.spans.push(spans);
            for &i in &self.cols[start..] {
                self.slot_of[i] = u32::MAX;
            }
            if !ok {
                self.cols.truncate(start);
            }
        }
        self.col_start.push(self.cols.len());
    }

    /// Add a row with direction `z = [g; g·n]`, residual `r` and weight `w` at the footpoint
    /// `spheres`, `weights` on element `el` to the element's moment; false when the element has
    /// no map or a weighted sphere is not the element's (that row goes on its own).
    #[inline]
    fn add(
        &mut self,
        el: usize,
        (spheres, weights): (&[u32; 3], &[f64; 3]),
        z: &[f64; 4],
        r: f64,
        w: f64,
    ) -> bool {
        let (Some(&Some((ids, m))), Some(moment)) =
            (self.spheres.get(el), self.moments.get_mut(el))
        else {
            return false;
        };
        let mut wl = [0.0; MAX_SPHERES];
        for (&s, &x) in spheres.iter().zip(weights) {
            if x != 0.0 {
                let Some(l) = ids[..m].iter().position(|&i| i == s) else {
                    return false;
                };
                wl[l] += x;
            }
        }
        moment.add(&wl, m, z, r, w);
        true
    }

    /// Add `Eᵀ M E` and `Eᵀ v` of every element's moments to `ne` (and the diagonal to
    /// `info[k − from]` for unknowns `k ≥ from`).
    fn flush(&mut self, ne: &mut NormalEquations, from: usize, info: &mut [f64]) {
        for el in 0..self.spheres.len() {
            let (Some((_, m)), mom) = (self.spheres[el], &self.moments[el]) else {
                continue;
            };
            if !mom.used {
                continue;
            }
            let d = 4 * m;
            let cols = &self.cols[self.col_start[el]..self.col_start[el + 1]];
            let k = cols.len();
            let e = &self.e[self.e_start[el]..self.e_start[el] + d * k];
            let spans = &self.spans[el][..d];
            // M E, row `a` from the kept blocks: `M[b][a]` left of `a`'s diagonal block, `M[a][b]`
            // from it on; each product only over the span of `E_e`'s row `b`. Zeros inside a
            // span (and zero entries of `M`) are multiplied out rather than tested: they add ±0,
            // which leaves the sums bit for bit unchanged, and the tests mispredicted.
            self.me.clear();
            self.me.resize(d * k, 0.0);
            for (a, me) in self.me.chunks_exact_mut(k).enumerate() {
                let diagonal = a / 4 * 4;
                let mut add = |b: usize, x: f64| {
                    let [lo, hi] = spans[b];
                    add_scaled(&mut me[lo..hi], x, &e[b * k + lo..b * k + hi]);
                };
                for b in 0..diagonal {
                    add(b, mom.m[b][a]);
                }
                for b in diagonal..d {
                    add(b, mom.m[a][b]);
                }
            }
            // Eᵀ (M E), upper triangle packed row by row, and b = −Eᵀ v, over the spans.
            self.upper.clear();
            self.upper.resize(k * (k + 1) / 2, 0.0);
            self.rhs.clear();
            self.rhs.resize(k, 0.0);
            for (i, (&vi, &[lo, hi])) in mom.v[..d].iter().zip(spans).enumerate() {
                let (er, mr) = (&e[i * k..(i + 1) * k], &self.me[i * k..(i + 1) * k]);
                // Row `lo` of the packed triangle.
                let mut off = lo * k - lo * lo.saturating_sub(1) / 2;
                for p in lo..hi {
                    let x = er[p];
                    add_scaled(&mut self.upper[off..off + k - p], x, &mr[p..]);
                    self.rhs[p] -= x * vi;
                    off += k - p;
                }
            }
            // The columns were checked against the system's size when mapped.
            let _ = ne.add_packed_block(cols, &self.upper, &self.rhs);
            let mut off = 0;
            for (p, &c) in cols.iter().enumerate() {
                if let Some(x) = c.checked_sub(from).and_then(|i| info.get_mut(i)) {
                    *x += self.upper[off];
                }
                off += k - p;
            }
        }
    }
}

/// `y += a x`.
#[inline]
fn add_scaled(y: &mut [f64], a: f64, x: &[f64]) {
    for (y, &x) in y.iter_mut().zip(x) {
        *y += a * x;
    }
}

impl ShapeRows {
    /// Scratch for systems of `n` unknowns.
    pub fn new(n: usize) -> Self {
        Self {
            row: Row::new(n),
            columns: Vec::new(),
            starts: Vec::new(),
            elements: ElementMaps::default(),
            blocked: true,
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

    /// One footpoint row `r`, weight `w`, direction `[g; gn]` at the footpoint `(element,
    /// spheres, weights)`: into its element's moment, or on its own (`Σ w j²` of the unknowns
    /// `k ≥ from` into `info[k − from]`) where the element has none. Returns `w r²`.
    #[allow(clippy::too_many_arguments)]
    fn add_footpoint(
        &mut self,
        ctx: &TrackingCtx<'_>,
        at: (u32, &[u32; 3], &[f64; 3]),
        g: &Vector3<f64>,
        gn: f64,
        r: f64,
        w: f64,
        (theta, ne, from, info): (usize, &mut NormalEquations, usize, &mut [f64]),
    ) -> f64 {
        let (el, spheres, weights) = (at.0 as usize, at.1, at.2);
        let z = [g.x, g.y, g.z, gn];
        if self.blocked && self.elements.add(el, (spheres, weights), &z, r, w) {
            return w * r * r;
        }
        let mut cols = [Vector3::zeros(); MAX_ELEMENT_DOFS];
        let dofs = ctx
            .jacobian()
            .columns(ctx.posed_mesh(), el, spheres, weights, &mut cols);
        for (&d, col) in dofs.iter().zip(&cols) {
            self.row.add(theta + d, g.dot(col));
        }
        self.add_shape(spheres, weights, g, gn);
        self.row.flush_data(ne, r, w, from, info)
    }

    /// Add the d2m rows (Eq. 3.11 / Eq. 3.4: `r = −‖p − q‖`, row `uᵀ∂q/∂x`, IRLS weight) and the
    /// m2d rows (Eq. 3.12 / Eq. 3.5: two pixel rows `J_π ∂x/∂x` per push, each weighing as in
    /// [`crate::terms::M2d`], `(320 / width)⁴` included) of the frame held by
    /// `ctx` (already updated at the frame's pose) to `ne`, over the pose DOFs at
    /// `layout.pose` and the shape unknowns mapped by `layout.shape`. The data information
    /// `Σ w j²` of each system unknown `k ≥ info_from` is added to `info[k − info_from]` (an empty
    /// slice skips it). The rows are summed per element (module docs).
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
        let theta = layout.pose;
        self.elements
            .build(ctx, &self.columns, &self.starts, theta, ne.dim());
        let irls = ctx.irls();
        let mut out = DataEnergy::default();
        for (c, u, r, wr) in ctx.d2m_rows() {
            let at = (c.element, &c.spheres, &c.weights);
            let sink = (theta, &mut *ne, info_from, &mut *info);
            self.add_footpoint(ctx, at, u, u.dot(&c.normal), r, weights.d2m * wr, sink);
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
            let w = weights.m2d * ctx.m2d_pixel_weight() * camera.qvga_share();
            let posed = ctx.posed_mesh();
            for push in ctx.pushes() {
                let x = &push.point;
                let res = camera.project(x) - push.target;
                let jp = camera.projection_jacobian(x);
                let normal = posed_normal(posed, push);
                for axis in 0..2 {
                    let g = jp.row(axis).transpose();
                    let at = (push.element, &push.spheres, &push.weights);
                    let sink = (theta, &mut *ne, info_from, &mut *info);
                    out.m2d += self.add_footpoint(ctx, at, &g, g.dot(&normal), res[axis], w, sink);
                    out.rows += 1;
                }
            }
        }
        self.elements.flush(ne, info_from, info);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::rendered_frame;
    use crate::M2dMode;
    use hand_model::kinematics::Pose;
    use hand_model::query::View;
    use hand_model::solver::IrlsParams;
    use hand_model::spheremesh::default_right_hand;
    use sensor_io::Camera;

    /// The rows summed per element through their moments equal the rows added one by one (the
    /// assembly before the moments) to 1e-10 of the largest entry: pose and shape blocks, right
    /// side, information and energies, for both m2d modes, a frame index offset and held shape
    /// unknowns, with front-facing substitutes and IRLS weights.
    #[test]
    fn element_moments_equal_row_by_row_assembly() {
        let base = default_right_hand();
        let sk = &base.skeleton;
        let space = ShapeSpace::new(&base, true).unwrap();
        let truth = Pose::from_named(
            sk,
            [
                ("global_tz", 400.0),
                ("global_ry", 0.4),
                ("index_mcp_flex", 0.5),
                ("middle_pip_flex", 0.7),
                ("thumb_mcp_flex", 0.3),
            ],
        )
        .unwrap();
        let frame = rendered_frame(&base, &truth, &Camera::sr300_qvga(), 2500).unwrap();
        let mut pose = truth.clone();
        pose.values[sk.dof_index("global_tx").unwrap()] += 15.0;
        pose.values[sk.dof_index("ring_mcp_abd").unwrap()] += 0.2;
        let theta = 7;
        let so = theta + sk.num_dofs() + 3;
        let n = so + space.len();
        for (mode, held) in [(M2dMode::Render, 0), (M2dMode::Centers, 3)] {
            let view = View::Perspective {
                camera_center: Vector3::zeros(),
            };
            let mut ctx = TrackingCtx::new(&base, view, IrlsParams::default()).unwrap();
            ctx.set_frame(&frame);
            ctx.set_m2d(Some(mode));
            ctx.update(&pose, false).unwrap();
            let pushes = ctx.pushes().len();
            assert!(pushes > 2 && ctx.reweighted(), "{mode:?}: {pushes} pushes");
            // Every `held`-th shape unknown dropped (`None`), as the online layout drops some.
            let shape: Vec<Option<usize>> = (0..space.len())
                .map(|i| (held == 0 || i % held != 0).then_some(so + i))
                .collect();
            let layout = RowLayout {
                pose: theta,
                shape: &shape,
            };
            let weights = DataWeights { d2m: 1.0, m2d: 0.5 };
            let run = |blocked: bool| {
                let mut rows = ShapeRows::new(n);
                rows.blocked = blocked;
                let mut ne = NormalEquations::new(n);
                let mut info = vec![0.0; space.len()];
                let e = rows.add_frame(&ctx, &space, &layout, &weights, &mut ne, &mut info, so);
                ne.symmetrize();
                // Every element of the hand is mapped (none left to the row-by-row path).
                let mapped = rows.elements.spheres.iter().flatten().count();
                assert_eq!(mapped, base.elements.len());
                (ne, info, e)
            };
            let (blocked, info, e) = run(true);
            let (reference, info_ref, e_ref) = run(false);
            let scale = reference.lhs().amax();
            let a = (blocked.lhs() - reference.lhs()).amax() / scale;
            let b = (blocked.rhs() - reference.rhs()).amax() / reference.rhs().amax();
            let i = info
                .iter()
                .zip(&info_ref)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max)
                / info_ref.iter().copied().fold(0.0, f64::max);
            assert!(a < 1e-10 && b < 1e-10 && i < 1e-10, "{mode:?}: {a} {b} {i}");
            assert!(info_ref.iter().filter(|&&x| x > 0.0).count() > 20);
            assert_eq!(e.rows, e_ref.rows);
            assert!((e.d2m - e_ref.d2m).abs() <= 1e-12 * e_ref.d2m);
            assert!((e.m2d - e_ref.m2d).abs() <= 1e-10 * e_ref.m2d && e.m2d > 0.0);
        }
    }
}
