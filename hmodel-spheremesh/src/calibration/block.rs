//! The block-arrow normal equations of a multi-frame calibration and their solve. Frames couple
//! only through the shared unknowns (the shape): the matrix is per-frame blocks `P_n` (no
//! frame-to-frame entries), bordered by the frame–shared blocks `C_n` and the shared block `S`.
//! Eliminating the frames' unknowns (Schur complement) leaves a system of the shared size,
//!
//! `(S − Σ C_nᵀ P_n⁻¹ C_n) δ_s = b_s − Σ C_nᵀ P_n⁻¹ b_n`,   `δ_n = P_n⁻¹ (b_n − C_n δ_s)`,
//!
//! so the cost and the storage grow linearly with the number of frames instead of cubically
//! and quadratically (every Cholesky factorization by faer). Used by the Ch. 3 calibration
//! ([`super::calibrate`], which assembles a dense system and converts it with
//! [`BlockArrow::from_dense`]; the dense Cholesky is the reference the tests compare against)
//! and by the Offline-Hard/Soft calibrations of `honline-calib` (thesis §4.3.4), which assemble
//! the blocks directly.

use faer::linalg::solvers::Solve;
use faer::{Mat, Side};
use nalgebra::{DMatrix, DVector};

/// Where an unknown of one frame's equations lives in a [`BlockArrow`] system.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Unknown {
    /// The `i`-th unknown of the frame's own block.
    Frame(usize),
    /// The `i`-th shared unknown.
    Shared(usize),
}

/// One frame's rows of the system: `P_n`, `C_n`, `b_n`.
#[derive(Clone, Debug)]
struct FrameBlock {
    p: Mat<f64>,
    c: Mat<f64>,
    b: Mat<f64>,
}

/// Symmetric normal equations `A δ = b` with the block-arrow structure of the module docs:
/// `frames` blocks of `frame_dim` unknowns each, then `shared_dim` shared unknowns. The flat
/// layout of a step `δ` is `[δ_0 | δ_1 | … | δ_{N−1} | δ_s]`.
#[derive(Clone, Debug)]
pub struct BlockArrow {
    frames: Vec<FrameBlock>,
    frame_dim: usize,
    shared: Mat<f64>,
    shared_b: Mat<f64>,
}

impl BlockArrow {
    /// Zero equations.
    pub fn new(frames: usize, frame_dim: usize, shared_dim: usize) -> Self {
        let block = FrameBlock {
            p: Mat::zeros(frame_dim, frame_dim),
            c: Mat::zeros(frame_dim, shared_dim),
            b: Mat::zeros(frame_dim, 1),
        };
        Self {
            frames: vec![block; frames],
            frame_dim,
            shared: Mat::zeros(shared_dim, shared_dim),
            shared_b: Mat::zeros(shared_dim, 1),
        }
    }

    /// The blocks of a dense symmetric `a` (and `b`) laid out as `frames` blocks of `nd`
    /// unknowns followed by the shared ones; entries between different frames are ignored (they
    /// are zero in a block-arrow matrix). `None` when `a` is smaller than the frames' blocks or
    /// not square, or `b` does not match.
    pub fn from_dense(
        a: &DMatrix<f64>,
        b: &DVector<f64>,
        frames: usize,
        nd: usize,
    ) -> Option<Self> {
        let so = frames.checked_mul(nd)?;
        let ns = a.nrows().checked_sub(so)?;
        if a.ncols() != a.nrows() || b.len() != a.nrows() {
            return None;
        }
        let mut out = Self::new(frames, nd, ns);
        for (f, block) in out.frames.iter_mut().enumerate() {
            let o = f * nd;
            block.p = Mat::from_fn(nd, nd, |i, j| a[(o + i, o + j)]);
            block.c = Mat::from_fn(nd, ns, |i, j| a[(o + i, so + j)]);
            block.b = Mat::from_fn(nd, 1, |i, _| b[o + i]);
        }
        out.shared = Mat::from_fn(ns, ns, |i, j| a[(so + i, so + j)]);
        out.shared_b = Mat::from_fn(ns, 1, |i, _| b[so + i]);
        Some(out)
    }

    /// Number of frames.
    pub fn num_frames(&self) -> usize {
        self.frames.len()
    }

    /// Unknowns per frame.
    pub fn frame_dim(&self) -> usize {
        self.frame_dim
    }

    /// Number of shared unknowns.
    pub fn shared_dim(&self) -> usize {
        self.shared.nrows()
    }

    /// Total number of unknowns (the length of a step).
    pub fn dim(&self) -> usize {
        self.frames.len() * self.frame_dim + self.shared_dim()
    }

    /// Index of `u` of frame `frame` in the flat layout of a step.
    pub fn flat_index(&self, frame: usize, u: Unknown) -> usize {
        match u {
            Unknown::Frame(i) => frame * self.frame_dim + i,
            Unknown::Shared(i) => self.frames.len() * self.frame_dim + i,
        }
    }

    /// `A[u, v] += value` (one entry of the matrix; add the mirrored entry separately, or use
    /// [`BlockArrow::add_symmetric`]). Entries outside the blocks are ignored.
    fn add_entry(&mut self, frame: usize, u: Unknown, v: Unknown, value: f64) {
        match (u, v) {
            (Unknown::Frame(i), Unknown::Frame(j)) => {
                if let Some(f) = self.frames.get_mut(frame) {
                    if i < f.p.nrows() && j < f.p.ncols() {
                        f.p[(i, j)] += value;
                    }
                }
            }
            (Unknown::Frame(i), Unknown::Shared(j)) => {
                if let Some(f) = self.frames.get_mut(frame) {
                    if i < f.c.nrows() && j < f.c.ncols() {
                        f.c[(i, j)] += value;
                    }
                }
            }
            // The transposed border C_nᵀ is not stored: `A` is symmetric.
            (Unknown::Shared(_), Unknown::Frame(_)) => {}
            (Unknown::Shared(i), Unknown::Shared(j)) => {
                if i < self.shared.nrows() && j < self.shared.ncols() {
                    self.shared[(i, j)] += value;
                }
            }
        }
    }

    /// `A[u, v] += value` and `A[v, u] += value` (once when `u == v`) for frame `frame`.
    pub fn add_symmetric(&mut self, frame: usize, u: Unknown, v: Unknown, value: f64) {
        match (u, v) {
            (Unknown::Shared(_), Unknown::Frame(_)) => self.add_entry(frame, v, u, value),
            (Unknown::Frame(_), Unknown::Shared(_)) => self.add_entry(frame, u, v, value),
            _ => {
                self.add_entry(frame, u, v, value);
                if u != v {
                    self.add_entry(frame, v, u, value);
                }
            }
        }
    }

    /// `b[u] += value` for frame `frame`.
    pub fn add_rhs(&mut self, frame: usize, u: Unknown, value: f64) {
        match u {
            Unknown::Frame(i) => {
                if let Some(f) = self.frames.get_mut(frame) {
                    if i < f.b.nrows() {
                        f.b[(i, 0)] += value;
                    }
                }
            }
            Unknown::Shared(i) => {
                if i < self.shared_b.nrows() {
                    self.shared_b[(i, 0)] += value;
                }
            }
        }
    }

    /// Add one frame's dense symmetric equations `lhs δ = rhs` whose `k`-th unknown lives at
    /// `map[k]` (`map.len()` must equal the size of `lhs` and `rhs`; extra entries are ignored).
    pub fn add_system(
        &mut self,
        frame: usize,
        map: &[Unknown],
        lhs: &DMatrix<f64>,
        rhs: &DVector<f64>,
    ) {
        let n = map.len().min(lhs.nrows()).min(lhs.ncols()).min(rhs.len());
        for j in 0..n {
            self.add_rhs(frame, map[j], rhs[j]);
            for i in 0..n {
                self.add_entry(frame, map[i], map[j], lhs[(i, j)]);
            }
        }
    }

    /// Levenberg–Marquardt damping: `A_ii += lambda·A_ii + epsilon` on every diagonal entry.
    pub fn damp(&mut self, lambda: f64, epsilon: f64) {
        let damp = |m: &mut Mat<f64>| {
            for i in 0..m.nrows() {
                m[(i, i)] += lambda * m[(i, i)] + epsilon;
            }
        };
        for f in &mut self.frames {
            damp(&mut f.p);
        }
        damp(&mut self.shared);
    }

    /// Whether every entry is finite.
    pub fn is_finite(&self) -> bool {
        let finite =
            |m: &Mat<f64>| (0..m.ncols()).all(|j| (0..m.nrows()).all(|i| m[(i, j)].is_finite()));
        self.frames
            .iter()
            .all(|f| finite(&f.p) && finite(&f.c) && finite(&f.b))
            && finite(&self.shared)
            && finite(&self.shared_b)
    }

    /// The diagonal of `A` in the flat layout.
    pub fn diagonal(&self) -> DVector<f64> {
        let nd = self.frame_dim;
        let so = self.frames.len() * nd;
        DVector::from_fn(self.dim(), |k, _| {
            if k < so {
                self.frames[k / nd].p[(k % nd, k % nd)]
            } else {
                self.shared[(k - so, k - so)]
            }
        })
    }

    /// `b` in the flat layout.
    pub fn rhs(&self) -> DVector<f64> {
        let nd = self.frame_dim;
        let so = self.frames.len() * nd;
        DVector::from_fn(self.dim(), |k, _| {
            if k < so {
                self.frames[k / nd].b[(k % nd, 0)]
            } else {
                self.shared_b[(k - so, 0)]
            }
        })
    }

    /// The decrease `2δᵀb − δᵀAδ` that the quadratic model predicts for the step `delta`
    /// (flat layout; 0 when its length does not match).
    pub fn predicted_decrease(&self, delta: &DVector<f64>) -> f64 {
        if delta.len() != self.dim() {
            return 0.0;
        }
        let nd = self.frame_dim;
        let so = self.frames.len() * nd;
        let ns = self.shared_dim();
        let ds = Mat::from_fn(ns, 1, |i, _| delta[so + i]);
        let mut quad = (ds.transpose() * &self.shared * &ds)[(0, 0)];
        let mut lin = (ds.transpose() * &self.shared_b)[(0, 0)];
        for (f, block) in self.frames.iter().enumerate() {
            let dn = Mat::from_fn(nd, 1, |i, _| delta[f * nd + i]);
            quad += (dn.transpose() * &block.p * &dn)[(0, 0)];
            quad += 2.0 * (dn.transpose() * &block.c * &ds)[(0, 0)];
            lin += (dn.transpose() * &block.b)[(0, 0)];
        }
        2.0 * lin - quad
    }

    /// Solve `A δ = b` (`A` symmetric positive definite) by the Schur complement of the frames'
    /// blocks (module docs); the step in the flat layout, `None` when a factorization fails or
    /// the solution is not finite.
    pub fn solve(&self) -> Option<DVector<f64>> {
        let nd = self.frame_dim;
        let ns = self.shared_dim();
        let so = self.frames.len() * nd;
        let mut reduced = self.shared.clone();
        let mut reduced_rhs = self.shared_b.clone();
        // Per frame, P_n⁻¹ [C_n | b_n]: its last column recovers δ_n once δ_s is known.
        let mut eliminated = Vec::with_capacity(self.frames.len());
        for block in &self.frames {
            let mut x = Mat::from_fn(nd, ns + 1, |i, j| {
                if j < ns {
                    block.c[(i, j)]
                } else {
                    block.b[(i, 0)]
                }
            });
            block.p.llt(Side::Lower).ok()?.solve_in_place(x.as_mut());
            reduced -= block.c.transpose() * x.subcols(0, ns);
            reduced_rhs -= block.c.transpose() * x.subcols(ns, 1);
            eliminated.push(x);
        }
        reduced
            .llt(Side::Lower)
            .ok()?
            .solve_in_place(reduced_rhs.as_mut());
        let mut delta = DVector::zeros(self.dim());
        for i in 0..ns {
            delta[so + i] = reduced_rhs[(i, 0)];
        }
        for (f, x) in eliminated.iter().enumerate() {
            let back = x.subcols(0, ns) * &reduced_rhs;
            for i in 0..nd {
                delta[f * nd + i] = x[(i, ns)] - back[(i, 0)];
            }
        }
        delta.iter().all(|v| v.is_finite()).then_some(delta)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// A random block-arrow SPD system (rows that touch one frame's unknowns and the shared
    /// ones, as the data terms' rows do).
    fn random_system(frames: usize, nd: usize, ns: usize) -> (DMatrix<f64>, DVector<f64>) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let n = frames * nd + ns;
        let mut a = DMatrix::<f64>::zeros(n, n);
        for _ in 0..400 {
            let f = rng.random_range(0..frames);
            let mut j = DVector::<f64>::zeros(n);
            for i in 0..nd {
                j[f * nd + i] = rng.random_range(-1.0..1.0);
            }
            for i in 0..ns {
                j[frames * nd + i] = rng.random_range(-1.0..1.0);
            }
            a += &j * j.transpose();
        }
        let b = DVector::from_fn(n, |_, _| rng.random_range(-1.0..1.0));
        (a, b)
    }

    /// The Schur complement equals the dense Cholesky solution, and the predicted decrease is
    /// `2δᵀb − δᵀAδ`.
    #[test]
    fn matches_the_dense_cholesky() {
        let (frames, nd, ns) = (5, 7, 4);
        let (a, b) = random_system(frames, nd, ns);
        let dense = a.clone().cholesky().unwrap().solve(&b);
        let system = BlockArrow::from_dense(&a, &b, frames, nd).unwrap();
        let block = system.solve().unwrap();
        assert!((&dense - &block).amax() < 1e-9);
        let step = DVector::from_fn(a.nrows(), |i, _| (i as f64 * 0.37).sin());
        let expected = 2.0 * step.dot(&b) - step.dot(&(&a * &step));
        assert!((system.predicted_decrease(&step) - expected).abs() < 1e-9 * expected.abs());
        assert!((system.rhs() - &b).amax() == 0.0);
        assert!((system.diagonal() - a.diagonal()).amax() == 0.0);
    }

    /// Assembling frame by frame through a map (frame unknowns and shared ones interleaved in
    /// the frame's own order) gives the same blocks as the dense matrix.
    #[test]
    fn frame_systems_scatter_into_the_blocks() {
        let (frames, nd, ns) = (3, 4, 2);
        let (a, b) = random_system(frames, nd, ns);
        let so = frames * nd;
        let mut system = BlockArrow::new(frames, nd, ns);
        for f in 0..frames {
            // Frame-local order: shared 1, frame 0..nd, shared 0.
            let map: Vec<Unknown> = std::iter::once(Unknown::Shared(1))
                .chain((0..nd).map(Unknown::Frame))
                .chain(std::iter::once(Unknown::Shared(0)))
                .collect();
            let global: Vec<usize> = map.iter().map(|&u| system.flat_index(f, u)).collect();
            let k = map.len();
            // Each frame carries its own blocks plus a 1/frames share of the shared block.
            let lhs = DMatrix::from_fn(k, k, |i, j| {
                let (gi, gj) = (global[i], global[j]);
                let v = a[(gi, gj)];
                if gi >= so && gj >= so {
                    v / frames as f64
                } else {
                    v
                }
            });
            let rhs = DVector::from_fn(k, |i, _| {
                let gi = global[i];
                if gi >= so {
                    b[gi] / frames as f64
                } else {
                    b[gi]
                }
            });
            system.add_system(f, &map, &lhs, &rhs);
        }
        let reference = BlockArrow::from_dense(&a, &b, frames, nd).unwrap();
        let (x, y) = (system.solve().unwrap(), reference.solve().unwrap());
        assert!((x - y).amax() < 1e-9);
    }
}
