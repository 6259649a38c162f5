//! The Laplace approximation of the per-frame posterior (Eq. 4.5–4.6, §4.6.1) and the
//! cumulative estimates in information form (Eq. 4.8–4.10, Table 1; Table 2).

use hand_model::solver::cholesky_checked;
use nalgebra::{Cholesky, DMatrix, DVector, Dyn};
use serde::{Deserialize, Serialize};

/// How per-frame shape information is accumulated (thesis §4.3.1–4.3.3).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Estimator {
    /// §4.3.1: every frame's joint pose+shape solve starts from the previous frame's β and
    /// keeps no memory; the estimate is the per-frame mode `x*_n` with information `Σ*_n⁻¹`.
    PerFrame,
    /// §4.3.2, split cumulative: a Kalman filter (Table 1, Eq. 4.8–4.10) whose measurements are
    /// the per-frame modes `N(x*_n, Σ*_n)`; the per-frame solves stay independent of it.
    Kf,
    /// §4.3.3, joint cumulative (the default): E_iekf (Eq. 4.11) inside the per-frame LM, an
    /// iterated extended Kalman filter (Table 2, §4.6.3).
    #[default]
    Iekf,
}

impl std::str::FromStr for Estimator {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "per-frame" => Ok(Self::PerFrame),
            "kf" => Ok(Self::Kf),
            "iekf" => Ok(Self::Iekf),
            other => Err(format!(
                "unknown estimator `{other}` (expected iekf, kf or per-frame)"
            )),
        }
    }
}

impl std::fmt::Display for Estimator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::PerFrame => "per-frame",
            Self::Kf => "kf",
            Self::Iekf => "iekf",
        })
    }
}

/// The marginal information of the shape unknowns (Eq. 4.5 restricted to β): for the
/// Gauss–Newton Hessian `H = [[H_θθ, H_θβ], [H_βθ, H_ββ]]` of the data terms, the Schur
/// complement `H_ββ − H_βθ H_θθ⁻¹ H_θβ` — the inverse of the β block of `Σ* = H⁻¹`, i.e. what
/// the frame says about the shape once the pose is free. `theta` and `beta` index `h`. Pose
/// directions no data row touches (hidden fingers) get a tiny ridge (they do not couple to β).
/// The result is symmetric with a non-negative diagonal; `None` when `h` is not finite.
pub fn marginal_information(
    h: &DMatrix<f64>,
    theta: &[usize],
    beta: &[usize],
) -> Option<DMatrix<f64>> {
    let mut out = DMatrix::zeros(0, 0);
    marginal_information_into(h, theta, beta, &mut InfoScratch::default(), &mut out).then_some(out)
}

/// Buffers of [`marginal_information_into`] and [`marginal_certainty_into`], so that the
/// per-frame information algebra of the online calibrator allocates nothing once they have
/// held the frame's sizes.
#[derive(Clone, Debug)]
pub(crate) struct InfoScratch {
    htt: DMatrix<f64>,
    htb: DMatrix<f64>,
    htb_t: DMatrix<f64>,
    product: DMatrix<f64>,
}

impl Default for InfoScratch {
    fn default() -> Self {
        let empty = || DMatrix::zeros(0, 0);
        Self {
            htt: empty(),
            htb: empty(),
            htb_t: empty(),
            product: empty(),
        }
    }
}

/// `m` as a `rows × cols` matrix (reallocated only when its shape differs; contents
/// unspecified).
fn shaped(m: &mut DMatrix<f64>, rows: usize, cols: usize) -> &mut DMatrix<f64> {
    if m.shape() != (rows, cols) {
        *m = DMatrix::zeros(rows, cols);
    }
    m
}

/// Factor `m` in place (its storage becomes the factor's, given back by `Cholesky::unpack`
/// style calls; the factor is bit for bit nalgebra's, `hand_model::solver::factor_lower`);
/// `None`, `m` unspecified, when it is not positive definite.
fn cholesky_in(m: &mut DMatrix<f64>) -> Option<Cholesky<f64, Dyn>> {
    cholesky_checked(m).then(|| Cholesky::pack_dirty(std::mem::replace(m, DMatrix::zeros(0, 0))))
}

/// [`marginal_information`] into `out` with the buffers of `scratch` (the same arithmetic, in
/// the same order, so the same bits); false (`out` unspecified) where it returns `None`.
pub(crate) fn marginal_information_into(
    h: &DMatrix<f64>,
    theta: &[usize],
    beta: &[usize],
    scratch: &mut InfoScratch,
    out: &mut DMatrix<f64>,
) -> bool {
    if !h.iter().all(|v| v.is_finite()) {
        return false;
    }
    let (nt, nb) = (theta.len(), beta.len());
    let reg = shaped(&mut scratch.htt, nt, nt);
    for (j, &tj) in theta.iter().enumerate() {
        for (i, &ti) in theta.iter().enumerate() {
            reg[(i, j)] = h[(ti, tj)];
        }
    }
    let htb = shaped(&mut scratch.htb, nt, nb);
    for (j, &bj) in beta.iter().enumerate() {
        for (i, &ti) in theta.iter().enumerate() {
            htb[(i, j)] = h[(ti, bj)];
        }
    }
    let scale = (0..nt)
        .map(|i| reg[(i, i)].abs())
        .fold(0.0, f64::max)
        .max(1.0);
    for i in 0..nt {
        reg[(i, i)] += 1e-9 * scale;
    }
    let Some(chol) = cholesky_in(&mut scratch.htt) else {
        return false;
    };
    // x = H_θθ⁻¹ H_θβ, held in `product` until the product below.
    let x = shaped(&mut scratch.product, nt, nb);
    x.copy_from(&scratch.htb);
    chol.solve_mut(x);
    scratch.htt = chol.unpack_dirty();
    let htb_t = shaped(&mut scratch.htb_t, nb, nt);
    scratch.htb.transpose_to(htb_t);
    // S = H_ββ − H_βθ x, then (S + Sᵀ)/2 with a non-negative diagonal.
    let s = shaped(out, nb, nb);
    htb_t.mul_to(&scratch.product, s);
    for (j, &bj) in beta.iter().enumerate() {
        for (i, &bi) in beta.iter().enumerate() {
            s[(i, j)] = h[(bi, bj)] - s[(i, j)];
        }
    }
    for j in 0..nb {
        for i in 0..j {
            let (a, b) = (s[(i, j)], s[(j, i)]);
            s[(i, j)] = (a + b) * 0.5;
            s[(j, i)] = (b + a) * 0.5;
        }
        s[(j, j)] = ((s[(j, j)] + s[(j, j)]) * 0.5).max(0.0);
    }
    true
}

/// A Gaussian over the active β in information form: mean `x̂` and information `Ĥ = Σ̂⁻¹`.
#[derive(Clone, Debug, PartialEq)]
pub struct ShapeBelief {
    /// The mean `x̂` (mm).
    pub mean: DVector<f64>,
    /// The information `Ĥ` (per mm²).
    pub information: DMatrix<f64>,
}

impl ShapeBelief {
    /// `N(mean, (h0·I)⁻¹)`: the template with a vague prior (honline: `h0 = 0.001`).
    pub fn vague(mean: &[f64], h0: f64) -> Self {
        let n = mean.len();
        Self {
            mean: DVector::from_column_slice(mean),
            information: DMatrix::identity(n, n) * h0,
        }
    }

    /// Eq. 4.9–4.10 (Table 1, the product of Gaussians in information form):
    /// `Ĥ_n = Ĥ_{n−1} + H*_n`, `x̂_n = Ĥ_n⁻¹ (Ĥ_{n−1} x̂_{n−1} + H*_n x*_n)`. Unchanged (and
    /// false returned) when the update is not finite.
    pub fn fuse(&mut self, measured: &DVector<f64>, information: &DMatrix<f64>) -> bool {
        let h = &self.information + information;
        let b = &self.information * &self.mean + information * measured;
        let Some(chol) = h.clone().cholesky() else {
            return false;
        };
        let x = chol.solve(&b);
        if !x.iter().all(|v| v.is_finite()) {
            return false;
        }
        self.mean = x;
        self.information = h;
        true
    }

    /// Table 2's update after the joint solve: the mode already includes the prior, so
    /// `x̂_n = x*_n` and `Ĥ_n = Ĥ_{n−1} + H_n` (the data information at the mode).
    pub fn absorb(&mut self, mode: &DVector<f64>, information: &DMatrix<f64>) -> bool {
        if !mode.iter().all(|v| v.is_finite()) || !information.iter().all(|v| v.is_finite()) {
            return false;
        }
        self.mean.copy_from(mode);
        self.information += information;
        true
    }

    /// The certainty of each entry: the diagonal of the information matrix (per mm²; the
    /// certainty of an entry with all others known).
    pub fn certainty(&self) -> Vec<f64> {
        self.information.diagonal().iter().copied().collect()
    }

    /// The marginal certainty of each entry, `1 / diag(Σ̂)` (per mm²; Fig. 4.6's "inverse of
    /// the diagonal entry of the covariance"): low for two phalanges of a straight finger even
    /// when their sum is certain. Zeros when the information is singular.
    pub fn marginal_certainty(&self) -> Vec<f64> {
        marginal_certainty(&self.information, 0.0)
    }
}

/// The marginal certainty `1 / diag((H + ridge·I)⁻¹)` of each entry of a Gaussian with
/// information `H` (per mm²; Fig. 4.6 plots it for Σ*_n and Σ̂_n). `ridge` stands for a vague
/// prior (e.g. [`crate::OnlineConfig::initial_information`]) where `H` alone is singular — a
/// frame says nothing of a hidden finger. Zeros when the matrix is not positive definite or not
/// finite.
pub fn marginal_certainty(information: &DMatrix<f64>, ridge: f64) -> Vec<f64> {
    let mut out = Vec::new();
    marginal_certainty_into(information, ridge, &mut InfoScratch::default(), &mut out);
    out
}

/// [`marginal_certainty`] into `out` with the buffers of `scratch` (the same arithmetic, so
/// the same bits).
pub(crate) fn marginal_certainty_into(
    information: &DMatrix<f64>,
    ridge: f64,
    scratch: &mut InfoScratch,
    out: &mut Vec<f64>,
) {
    let n = information.nrows();
    out.clear();
    // A non-square matrix is refused by the factorization below as by nalgebra's.
    assert!(information.is_square(), "information must be square");
    let h = shaped(&mut scratch.htt, n, n);
    h.copy_from(information);
    for i in 0..n {
        h[(i, i)] += ridge;
    }
    let Some(c) = cholesky_in(&mut scratch.htt) else {
        out.resize(n, 0.0);
        return;
    };
    scratch.htt = c.unpack_dirty();
    let inv = shaped(&mut scratch.product, n, n);
    inverse_factor(&scratch.htt, inv);
    out.extend((0..n).map(|i| {
        let v = inv.column(i).rows(i, n - i).norm_squared();
        if v.is_finite() && v > 0.0 {
            1.0 / v
        } else {
            0.0
        }
    }));
}

/// `L⁻¹` of the lower-triangular `l` (its upper part ignored) into the lower triangle of `inv`
/// (the upper part left unspecified), column by column by forward substitution. Then
/// `diag((L Lᵀ)⁻¹)_i = ‖(L⁻¹)_{·i}‖²`: a sixth of the flops of solving `L Lᵀ X = I` for the whole
/// inverse, which the certainties of every frame took before (≈ 0.1 ms a frame at 60 β).
fn inverse_factor(l: &DMatrix<f64>, inv: &mut DMatrix<f64>) {
    let n = l.nrows();
    for j in 0..n {
        let mut col = inv.column_mut(j);
        col.rows_mut(j, n - j).fill(0.0);
        col[j] = 1.0;
        for k in j..n {
            let x = col[k] / l[(k, k)];
            col[k] = x;
            if x != 0.0 {
                col.rows_mut(k + 1, n - k - 1)
                    .axpy(-x, &l.column(k).rows(k + 1, n - k - 1), 1.0);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The information-form update equals the covariance-form Kalman update of Table 3 with
    /// `J = I` (§4.6.2).
    #[test]
    fn fuse_matches_covariance_form() {
        let p0 = DMatrix::from_row_slice(2, 2, &[2.0, 0.3, 0.3, 1.0]);
        let r = DMatrix::from_row_slice(2, 2, &[0.5, -0.1, -0.1, 0.8]);
        let x0 = DVector::from_row_slice(&[1.0, 2.0]);
        let z = DVector::from_row_slice(&[1.5, 1.0]);
        let mut b = ShapeBelief {
            mean: x0.clone(),
            information: p0.clone().try_inverse().unwrap(),
        };
        assert!(b.fuse(&z, &r.clone().try_inverse().unwrap()));
        let k = &p0 * (&p0 + &r).try_inverse().unwrap();
        let x = &x0 + &k * (&z - &x0);
        let p = (DMatrix::identity(2, 2) - &k) * &p0;
        assert!((b.mean - x).norm() < 1e-12);
        assert!((b.information.try_inverse().unwrap() - p).norm() < 1e-12);
    }

    /// The buffered forms give the bits of the textbook expressions they replaced (the online
    /// calibrator's results must not move; the certainties, read off the inverse factor, to
    /// rounding), reusing their buffers across sizes.
    #[test]
    fn buffered_forms_match_the_textbook_expressions_bit_for_bit() {
        let mut scratch = InfoScratch::default();
        let (mut out, mut diag) = (DMatrix::zeros(0, 0), Vec::new());
        for n in [5usize, 12, 40, 12] {
            let a = DMatrix::from_fn(n, n, |i, j| (((i * 7 + j * 3) % 11) as f64 - 5.0) * 0.37);
            let h = &a * a.transpose() + DMatrix::identity(n, n) * 0.1;
            let theta: Vec<usize> = (0..n).filter(|i| i % 3 != 1).collect();
            let beta: Vec<usize> = (0..n).filter(|i| i % 3 == 1).collect();
            // Schur complement, as written before the buffers.
            let htt = DMatrix::from_fn(theta.len(), theta.len(), |i, j| h[(theta[i], theta[j])]);
            let htb = DMatrix::from_fn(theta.len(), beta.len(), |i, j| h[(theta[i], beta[j])]);
            let hbb = DMatrix::from_fn(beta.len(), beta.len(), |i, j| h[(beta[i], beta[j])]);
            let scale = (0..theta.len())
                .map(|i| htt[(i, i)].abs())
                .fold(1.0, f64::max);
            let reg = htt + DMatrix::identity(theta.len(), theta.len()) * (1e-9 * scale);
            let s = hbb - htb.transpose() * reg.cholesky().unwrap().solve(&htb);
            let mut expected = (&s + s.transpose()) * 0.5;
            expected.diagonal().iter().for_each(|d| assert!(*d >= 0.0));
            assert!(marginal_information_into(
                &h,
                &theta,
                &beta,
                &mut scratch,
                &mut out
            ));
            assert_eq!(out, expected, "n = {n}");
            expected = h.clone() + DMatrix::identity(n, n) * 0.25;
            let inverse = expected.cholesky().unwrap().inverse();
            let certainty: Vec<f64> = inverse.diagonal().iter().map(|v| 1.0 / v).collect();
            // The certainties come from the inverse factor (fewer flops, other rounding).
            marginal_certainty_into(&h, 0.25, &mut scratch, &mut diag);
            assert_eq!(diag.len(), n);
            for (a, b) in diag.iter().zip(&certainty) {
                assert!((a - b).abs() <= 1e-10 * b.abs(), "n = {n}: {a} vs {b}");
            }
        }
        // Not positive definite: zeros, and the buffers recover.
        let bad = -DMatrix::<f64>::identity(4, 4);
        marginal_certainty_into(&bad, 0.0, &mut scratch, &mut diag);
        assert_eq!(diag, [0.0; 4]);
        assert!(!marginal_information_into(
            &bad,
            &[0, 1],
            &[2, 3],
            &mut scratch,
            &mut out
        ));
        let two = marginal_certainty(&DMatrix::identity(3, 3), 1.0);
        assert!(two.iter().all(|c| (c - 2.0).abs() < 1e-12), "{two:?}");
    }

    /// The Schur complement is the inverse of the β block of the covariance.
    #[test]
    fn marginal_information_inverts_the_covariance_block() {
        let a = DMatrix::from_fn(5, 5, |i, j| ((i * 7 + j * 3) % 5) as f64 - 2.0);
        let h = &a * a.transpose() + DMatrix::identity(5, 5);
        let s = marginal_information(&h, &[0, 2, 4], &[1, 3]).unwrap();
        let cov = h.try_inverse().unwrap();
        let block = DMatrix::from_fn(2, 2, |i, j| cov[([1, 3][i], [1, 3][j])]);
        assert!((s.try_inverse().unwrap() - block).norm() < 1e-6);
    }
}
