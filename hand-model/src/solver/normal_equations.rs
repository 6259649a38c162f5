//! The Gauss–Newton normal equations `(Σ ωᵢ JᵢᵀJᵢ) δ = −Σ ωᵢ Jᵢᵀ rᵢ` (thesis Eq. 2.11).

use std::ops::{Add, AddAssign};

use nalgebra::{DMatrix, DVector, Vector3};

use super::term::TermError;
use crate::kinematics::{PosedSkeleton, Skeleton};

/// What one term (or one call of a [`NormalEquations`] helper) contributed: its energy at the
/// linearization point (`Σ ω r²`, thesis Eq. 2.10 at δ = 0) and its number of residual rows.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct TermStats {
    /// Energy `E = Σ ω·r²` at the current unknowns.
    pub energy: f64,
    /// Number of scalar residual rows (for quadratic-form terms: the number of unknowns touched).
    pub rows: usize,
}

impl TermStats {
    /// No energy, no rows.
    pub const ZERO: TermStats = TermStats {
        energy: 0.0,
        rows: 0,
    };
}

impl Add for TermStats {
    type Output = TermStats;
    fn add(self, o: TermStats) -> TermStats {
        TermStats {
            energy: self.energy + o.energy,
            rows: self.rows + o.rows,
        }
    }
}

impl AddAssign for TermStats {
    fn add_assign(&mut self, o: TermStats) {
        *self = *self + o;
    }
}

/// Dense normal equations `A δ = b` for `n` unknowns (pose DOFs first, then auxiliary unknowns
/// such as PCA latents), accumulated term by term.
///
/// # Convention (shared by every term)
/// A term with residuals `r(θ)` and weight ω has energy `E = ω‖r‖²`; linearized,
/// `E(θ ⊞ δ) ≈ ω‖r + Jδ‖²` (thesis Eq. 2.10). Its contribution is
/// - `A += ω JᵀJ` (the Gauss–Newton Hessian, `½∂²E/∂θ²` up to second-order residual terms),
/// - `b −= ω Jᵀr`, so that **`b = −½ ∂E/∂θ`** — the thesis' `Σ Jᵢᵀeᵢ` with `e = −r`
///   ("target − current", ANCHOR-FACTS §5.2), and `δ = A⁻¹b` (Eq. 2.11).
///
/// Weights multiply `JᵀJ` and `Jᵀr` once (ω is *not* squared): the htrack/hmodel/honline
/// convention for the prior terms (ANCHOR-FACTS §5.2).
///
/// # Storage
/// Helpers fill only the upper triangle of `A` (`i ≤ j`); [`NormalEquations::symmetrize`]
/// mirrors it once after all terms (STYLE practice 8). Terms can only *add* (there is no
/// mutable access to `A` or `b`), so the order in which terms run does not matter beyond
/// floating-point rounding. Nothing allocates after construction.
#[derive(Clone, Debug)]
pub struct NormalEquations {
    n: usize,
    lhs: DMatrix<f64>,
    rhs: DVector<f64>,
    symmetric: bool,
    scratch: Vec<(usize, Vector3<f64>)>,
    zbuf: Vec<f64>,
}

impl NormalEquations {
    /// Zeroed equations for `n` unknowns.
    pub fn new(n: usize) -> Self {
        Self {
            n,
            lhs: DMatrix::zeros(n, n),
            rhs: DVector::zeros(n),
            symmetric: true,
            scratch: Vec::with_capacity(n.max(8)),
            zbuf: Vec::with_capacity(n),
        }
    }

    /// Number of unknowns.
    #[inline]
    pub fn dim(&self) -> usize {
        self.n
    }

    /// Zero `A` and `b` (keeps the storage).
    pub fn clear(&mut self) {
        // On the contiguous storage (one `memset`; `fill` on the matrix went element by
        // element).
        self.lhs.as_mut_slice().fill(0.0);
        self.rhs.as_mut_slice().fill(0.0);
        self.symmetric = true;
    }

    #[inline]
    fn check(&self, index: usize) -> Result<(), TermError> {
        if index < self.n {
            Ok(())
        } else {
            Err(TermError::IndexOutOfRange { index, dim: self.n })
        }
    }

    /// `A[i][j] += v` for `i ≤ j` (upper triangle, column-major storage).
    #[inline]
    fn add_upper(&mut self, i: usize, j: usize, v: f64) {
        let (i, j) = if i <= j { (i, j) } else { (j, i) };
        self.lhs[(i, j)] += v;
    }

    /// One scalar residual row `r` with sparse Jacobian row `cols = [(unknown, ∂r/∂unknown)]`
    /// and weight ω: `A += ω jjᵀ`, `b −= ω j r`; returns `ω r²` and one row.
    ///
    /// Repeated indices in `cols` are summed (as if the row were densified first).
    pub fn add_row(
        &mut self,
        cols: &[(usize, f64)],
        residual: f64,
        weight: f64,
    ) -> Result<TermStats, TermError> {
        for &(i, _) in cols {
            self.check(i)?;
        }
        self.symmetric = false;
        for (a, &(ia, ja)) in cols.iter().enumerate() {
            let wa = weight * ja;
            self.rhs[ia] -= wa * residual;
            self.lhs[(ia, ia)] += wa * ja;
            for &(ib, jb) in &cols[a + 1..] {
                // A repeated index contributes twice its cross product to the diagonal.
                let v = if ia == ib { 2.0 * wa * jb } else { wa * jb };
                self.add_upper(ia, ib, v);
            }
        }
        Ok(TermStats {
            energy: weight * residual * residual,
            rows: 1,
        })
    }

    /// A block accumulated elsewhere over the unknowns `cols` (k of them): `A[cols[a]][cols[b]]
    /// += upper[·]` for `a ≤ b`, the packed upper triangle row by row (`upper` holds
    /// `k(k+1)/2` values: row `a` is `A[a][a..k]`), and `b[cols[a]] += rhs[a]`. A term that sums
    /// many rows with the same sparsity (the points of one bone) adds them here once; the
    /// result equals [`NormalEquations::add_row`] per row up to the order of the additions.
    /// Repeated indices in `cols` are summed (an off-diagonal entry of a repeated index adds to
    /// the diagonal twice, as in `add_row`).
    pub fn add_packed_block(
        &mut self,
        cols: &[usize],
        upper: &[f64],
        rhs: &[f64],
    ) -> Result<(), TermError> {
        let k = cols.len();
        if upper.len() < k * (k + 1) / 2 || rhs.len() < k {
            return Err(TermError::Failed("packed block shorter than its columns"));
        }
        for &i in cols {
            self.check(i)?;
        }
        self.symmetric = false;
        let mut off = 0;
        for (a, &ia) in cols.iter().enumerate() {
            self.rhs[ia] += rhs[a];
            self.lhs[(ia, ia)] += upper[off];
            for (&ib, &v) in cols[a + 1..].iter().zip(&upper[off + 1..off + k - a]) {
                let v = if ia == ib { 2.0 * v } else { v };
                self.add_upper(ia, ib, v);
            }
            off += k - a;
        }
        Ok(())
    }

    /// One scalar residual row whose Jacobian is dense over the contiguous unknowns
    /// `offset .. offset + row.len()`: the rank-one update `A += ω jjᵀ`, `b −= ω j r`.
    pub fn add_rank1(
        &mut self,
        offset: usize,
        row: &[f64],
        residual: f64,
        weight: f64,
    ) -> Result<TermStats, TermError> {
        match offset.checked_add(row.len()) {
            Some(end) if end <= self.n => {}
            _ => {
                return Err(TermError::IndexOutOfRange {
                    index: offset.saturating_add(row.len()).saturating_sub(1),
                    dim: self.n,
                })
            }
        }
        self.symmetric = false;
        for (b, &jb) in row.iter().enumerate() {
            let j = offset + b;
            let wb = weight * jb;
            self.rhs[j] -= wb * residual;
            let mut col = self.lhs.column_mut(j);
            for (a, &ja) in row[..=b].iter().enumerate() {
                col[offset + a] += wb * ja;
            }
        }
        Ok(TermStats {
            energy: weight * residual * residual,
            rows: 1,
        })
    }

    /// Three residual rows of a 3D point: `cols = [(unknown, ∂p/∂unknown)]` (a 3×k Jacobian
    /// given column by column), residual vector `r` (e.g. `p − target`) and weight ω:
    /// `A += ω JᵀJ`, `b −= ω Jᵀr`; returns `ω‖r‖²` and three rows.
    ///
    /// The column indices must be distinct (as produced by
    /// [`PosedSkeleton::for_each_column`]).
    pub fn add_point_rows(
        &mut self,
        cols: &[(usize, Vector3<f64>)],
        residual: &Vector3<f64>,
        weight: f64,
    ) -> Result<TermStats, TermError> {
        for &(i, _) in cols {
            self.check(i)?;
        }
        self.symmetric = false;
        let n = self.n;
        let lhs = self.lhs.as_mut_slice();
        let rhs = self.rhs.as_mut_slice();
        for (a, (ia, ca)) in cols.iter().enumerate() {
            let wa = ca * weight;
            rhs[*ia] -= wa.dot(residual);
            lhs[*ia * n + *ia] += wa.dot(ca);
            for (ib, cb) in &cols[a + 1..] {
                // Column-major upper triangle: (i, j) with i ≤ j at j·n + i.
                let (i, j) = if ia <= ib { (*ia, *ib) } else { (*ib, *ia) };
                lhs[j * n + i] += wa.dot(cb);
            }
        }
        Ok(TermStats {
            energy: weight * residual.norm_squared(),
            rows: 3,
        })
    }

    /// [`NormalEquations::add_point_rows`] for Jacobian columns produced by a visitor, e.g.
    /// `|push| posed_mesh.for_each_center_column(template, i, push)`; the columns are gathered
    /// in an internal buffer (no allocation while a point has at most `dim()` columns).
    pub fn add_point_rows_with(
        &mut self,
        columns: impl FnOnce(&mut dyn FnMut(usize, Vector3<f64>)),
        residual: &Vector3<f64>,
        weight: f64,
    ) -> Result<TermStats, TermError> {
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.clear();
        columns(&mut |d, c| scratch.push((d, c)));
        let out = self.add_point_rows(&scratch, residual, weight);
        self.scratch = scratch;
        out
    }

    /// The three rows of a point `p` rigidly attached to `bone` of a posed skeleton (skeleton
    /// Jacobian of thesis §2.7.2 from [`PosedSkeleton::for_each_column`]), residual `r`, weight ω.
    pub fn add_skeleton_point(
        &mut self,
        skeleton: &Skeleton,
        posed: &PosedSkeleton,
        bone: usize,
        p: &Vector3<f64>,
        residual: &Vector3<f64>,
        weight: f64,
    ) -> Result<TermStats, TermError> {
        if bone >= skeleton.bones().len() {
            return Err(TermError::BoneOutOfRange {
                bone,
                bones: skeleton.bones().len(),
            });
        }
        self.add_point_rows_with(
            |push| posed.for_each_column(skeleton, bone, p, push),
            residual,
            weight,
        )
    }

    /// `A[i][i] += value` (constant damping, thesis §2.7.5 `E_damp = λ‖δθ‖²`).
    pub fn add_diagonal(&mut self, index: usize, value: f64) -> Result<(), TermError> {
        self.check(index)?;
        self.lhs[(index, index)] += value;
        Ok(())
    }

    /// A quadratic model over the unknowns `indices`: `A[idx, idx] += H`, `b[idx] −= g`, i.e. a
    /// term whose energy satisfies `E(θ ⊞ δ) ≈ E + 2gᵀδ + δᵀHδ` (`g = ½∂E/∂θ`, `H` its
    /// Gauss–Newton Hessian; exact for quadratic energies such as the PCA prior). Only the upper
    /// triangle of `H` (`a ≤ b`) is read; `indices` must be distinct.
    pub fn add_quadratic(
        &mut self,
        indices: &[usize],
        hessian: &DMatrix<f64>,
        half_gradient: &[f64],
    ) -> Result<(), TermError> {
        let k = indices.len();
        if hessian.nrows() != k || hessian.ncols() != k || half_gradient.len() != k {
            return Err(TermError::ShapeMismatch {
                expected: k,
                found: if hessian.nrows() != k {
                    hessian.nrows()
                } else if hessian.ncols() != k {
                    hessian.ncols()
                } else {
                    half_gradient.len()
                },
            });
        }
        for &i in indices {
            self.check(i)?;
        }
        self.symmetric = false;
        for (b, &ib) in indices.iter().enumerate() {
            self.rhs[ib] -= half_gradient[b];
            let hcol = hessian.column(b);
            for (a, &ia) in indices[..=b].iter().enumerate() {
                self.add_upper(ia, ib, hcol[a]);
            }
        }
        Ok(())
    }

    /// A quadratic energy `E = zᵀHz` in coordinates `z` that move one-to-one with the unknowns
    /// `indices` (`∂z_a/∂unknown_{indices[a]} = 1`, e.g. `z = θ − μ`): adds `A[idx, idx] += H`,
    /// `b[idx] −= Hz`, returns `zᵀHz` and `indices.len()` rows. `fill_z` writes the current `z`
    /// into a buffer of length `indices.len()` (allocation-free). `H` must be symmetric with
    /// both triangles stored; `indices` must be distinct.
    pub fn add_quadratic_form(
        &mut self,
        indices: &[usize],
        hessian: &DMatrix<f64>,
        fill_z: impl FnOnce(&mut [f64]),
    ) -> Result<TermStats, TermError> {
        let k = indices.len();
        if hessian.nrows() != k || hessian.ncols() != k {
            return Err(TermError::ShapeMismatch {
                expected: k,
                found: if hessian.nrows() != k {
                    hessian.nrows()
                } else {
                    hessian.ncols()
                },
            });
        }
        for &i in indices {
            self.check(i)?;
        }
        self.symmetric = false;
        let mut z = std::mem::take(&mut self.zbuf);
        z.clear();
        z.resize(k, 0.0);
        fill_z(&mut z);
        let mut energy = 0.0;
        for (b, &ib) in indices.iter().enumerate() {
            let hcol = hessian.column(b);
            let g: f64 = hcol.iter().zip(&z).map(|(h, zv)| h * zv).sum();
            energy += z[b] * g;
            self.rhs[ib] -= g;
            for (a, &ia) in indices[..=b].iter().enumerate() {
                self.add_upper(ia, ib, hcol[a]);
            }
        }
        self.zbuf = z;
        Ok(TermStats { energy, rows: k })
    }

    /// Mirror the upper triangle into the lower one (once, after all terms).
    pub fn symmetrize(&mut self) {
        if self.symmetric {
            return;
        }
        let n = self.n;
        for j in 0..n {
            for i in 0..j {
                self.lhs[(j, i)] = self.lhs[(i, j)];
            }
        }
        self.symmetric = true;
    }

    /// Whether the lower triangle is up to date (after [`NormalEquations::symmetrize`]).
    pub fn is_symmetric(&self) -> bool {
        self.symmetric
    }

    /// `A`: upper triangle during accumulation, the full symmetric matrix after
    /// [`NormalEquations::symmetrize`].
    pub fn lhs(&self) -> &DMatrix<f64> {
        &self.lhs
    }

    /// `b = −½ ∂E/∂θ` (see the type docs for the sign convention).
    pub fn rhs(&self) -> &DVector<f64> {
        &self.rhs
    }

    /// `A[i][j]` read from the upper triangle (valid at any time).
    pub fn lhs_entry(&self, i: usize, j: usize) -> f64 {
        let (i, j) = if i <= j { (i, j) } else { (j, i) };
        self.lhs[(i, j)]
    }

    /// Whether every entry of the upper triangle of `A` and of `b` is finite.
    pub fn is_finite(&self) -> bool {
        // Branch-free per column (exponent bits all ones: ±∞ or NaN), so that it vectorises.
        const EXPONENT: u64 = 0x7ff0_0000_0000_0000;
        let bad = |v: &f64| v.to_bits() & EXPONENT == EXPONENT;
        let n = self.n;
        let data = self.lhs.as_slice();
        (0..n).all(|j| {
            let column = &data[j * n..j * n + j + 1];
            !column.iter().fold(false, |any, v| any | bad(v)) && !bad(&self.rhs[j])
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Dense reference: A = ω JᵀJ, b = −ω Jᵀ r.
    fn dense(n: usize, rows: &[(Vec<f64>, f64, f64)]) -> (DMatrix<f64>, DVector<f64>) {
        let mut a = DMatrix::zeros(n, n);
        let mut b = DVector::zeros(n);
        for (j, r, w) in rows {
            let j = DVector::from_column_slice(j);
            a += &j * j.transpose() * *w;
            b -= &j * (*r * *w);
        }
        (a, b)
    }

    #[test]
    fn helpers_match_dense_products() {
        let n = 9;
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut ne = NormalEquations::new(n);
        let mut rows = vec![];
        // Sparse rows, with a repeated index.
        for _ in 0..5 {
            let cols = [
                (rng.random_range(0..n), rng.random_range(-1.0..1.0)),
                (rng.random_range(0..n), rng.random_range(-1.0..1.0)),
                (rng.random_range(0..n), rng.random_range(-1.0..1.0)),
            ];
            let (r, w) = (rng.random_range(-2.0..2.0), rng.random_range(0.1..3.0));
            let mut j = vec![0.0; n];
            for (i, v) in cols {
                j[i] += v;
            }
            let s = ne.add_row(&cols, r, w).unwrap();
            assert_eq!(s.rows, 1);
            assert!((s.energy - w * r * r).abs() < 1e-15);
            rows.push((j, r, w));
        }
        // Dense segment.
        let seg = [0.3, -0.7, 1.1];
        ne.add_rank1(4, &seg, 0.5, 2.0).unwrap();
        let mut j = vec![0.0; n];
        j[4..7].copy_from_slice(&seg);
        rows.push((j, 0.5, 2.0));
        // A point: three rows.
        let cols = [
            (1, Vector3::new(1.0, 2.0, 3.0)),
            (5, Vector3::new(-1.0, 0.5, 0.0)),
            (8, Vector3::new(0.0, 0.0, 2.0)),
        ];
        let res = Vector3::new(0.1, -0.2, 0.3);
        let s = ne.add_point_rows(&cols, &res, 1.5).unwrap();
        assert_eq!(s.rows, 3);
        for k in 0..3 {
            let mut j = vec![0.0; n];
            for (i, c) in &cols {
                j[*i] = c[k];
            }
            rows.push((j, res[k], 1.5));
        }
        ne.symmetrize();
        let (a, b) = dense(n, &rows);
        assert!((ne.lhs() - &a).norm() < 1e-12);
        assert!((ne.rhs() - &b).norm() < 1e-12);
        assert!(ne.is_finite());
    }

    #[test]
    fn quadratic_and_diagonal() {
        let mut ne = NormalEquations::new(5);
        let h = DMatrix::from_row_slice(2, 2, &[2.0, 0.5, 0.5, 3.0]);
        ne.add_quadratic(&[3, 1], &h, &[1.0, -1.0]).unwrap();
        ne.add_diagonal(0, 7.0).unwrap();
        ne.symmetrize();
        assert_eq!(ne.lhs()[(3, 3)], 2.0);
        assert_eq!(ne.lhs()[(1, 1)], 3.0);
        assert_eq!(ne.lhs()[(1, 3)], 0.5);
        assert_eq!(ne.lhs()[(3, 1)], 0.5);
        assert_eq!(ne.lhs()[(0, 0)], 7.0);
        assert_eq!(ne.rhs()[3], -1.0);
        assert_eq!(ne.rhs()[1], 1.0);
    }

    #[test]
    fn out_of_range_indices_are_errors_not_panics() {
        let mut ne = NormalEquations::new(3);
        assert_eq!(
            ne.add_row(&[(3, 1.0)], 0.0, 1.0),
            Err(TermError::IndexOutOfRange { index: 3, dim: 3 })
        );
        assert!(ne.add_rank1(2, &[1.0, 1.0], 0.0, 1.0).is_err());
        assert!(ne.add_diagonal(7, 1.0).is_err());
        assert!(ne
            .add_point_rows(&[(5, Vector3::x())], &Vector3::zeros(), 1.0)
            .is_err());
        let h = DMatrix::zeros(2, 2);
        assert!(ne.add_quadratic(&[0], &h, &[0.0]).is_err());
        // Nothing was written by the failed calls.
        assert_eq!(ne.lhs().norm(), 0.0);
    }

    #[test]
    fn nan_is_detected() {
        let mut ne = NormalEquations::new(2);
        ne.add_row(&[(1, f64::NAN)], 1.0, 1.0).unwrap();
        assert!(!ne.is_finite());
        ne.clear();
        assert!(ne.is_finite());
    }

    /// `is_finite` is the entry-by-entry test it replaces: a NaN or ±∞ anywhere in the upper
    /// triangle of `A` or in `b` is found, one in the lower triangle (not yet symmetrized) is
    /// not; extreme finite values pass. `clear` zeroes everything.
    #[test]
    fn is_finite_reads_the_upper_triangle_and_the_rhs() {
        let n = 7;
        let reference = |ne: &NormalEquations| {
            (0..n).all(|j| (0..=j).all(|i| ne.lhs()[(i, j)].is_finite()) && ne.rhs()[j].is_finite())
        };
        for bad in [
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MAX,
            -f64::MIN_POSITIVE,
        ] {
            for i in 0..n {
                for j in 0..n {
                    let mut ne = NormalEquations::new(n);
                    ne.add_diagonal(3, 2.0).unwrap();
                    ne.lhs[(i, j)] = bad;
                    assert_eq!(ne.is_finite(), reference(&ne), "{bad} at ({i}, {j})");
                    assert_eq!(ne.is_finite(), i > j || bad.is_finite());
                    ne.clear();
                    assert!(ne.is_finite() && ne.lhs().iter().all(|&v| v == 0.0));
                }
                let mut ne = NormalEquations::new(n);
                ne.rhs[i] = bad;
                assert_eq!(ne.is_finite(), bad.is_finite());
            }
        }
    }
}
