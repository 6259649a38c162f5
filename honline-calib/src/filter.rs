//! The Laplace approximation of the per-frame posterior (Eq. 4.5–4.6, §4.6.1) and the
//! cumulative estimates in information form (Eq. 4.8–4.10, Table 1; Table 2).

use nalgebra::{DMatrix, DVector};
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
    if !h.iter().all(|v| v.is_finite()) {
        return None;
    }
    let (nt, nb) = (theta.len(), beta.len());
    let htt = DMatrix::from_fn(nt, nt, |i, j| h[(theta[i], theta[j])]);
    let htb = DMatrix::from_fn(nt, nb, |i, j| h[(theta[i], beta[j])]);
    let hbb = DMatrix::from_fn(nb, nb, |i, j| h[(beta[i], beta[j])]);
    let scale = (0..nt)
        .map(|i| htt[(i, i)].abs())
        .fold(0.0, f64::max)
        .max(1.0);
    let mut reg = htt;
    for i in 0..nt {
        reg[(i, i)] += 1e-9 * scale;
    }
    let chol = reg.cholesky()?;
    let x = chol.solve(&htb);
    let mut s = hbb - htb.transpose() * x;
    let s2 = (&s + s.transpose()) * 0.5;
    s = s2;
    for i in 0..nb {
        s[(i, i)] = s[(i, i)].max(0.0);
    }
    Some(s)
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
    let n = information.nrows();
    let mut h = information.clone();
    for i in 0..n.min(h.ncols()) {
        h[(i, i)] += ridge;
    }
    match h.cholesky() {
        Some(c) => c
            .inverse()
            .diagonal()
            .iter()
            .map(|v| {
                if v.is_finite() && *v > 0.0 {
                    1.0 / v
                } else {
                    0.0
                }
            })
            .collect(),
        None => vec![0.0; n],
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
