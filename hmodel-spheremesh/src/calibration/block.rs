//! The block-arrow solve of the calibration's normal equations. Frames couple only through the
//! shape: the matrix is per-frame pose blocks `P_n` (no frame-to-frame entries), bordered by the
//! pose–shape blocks `C_n` and the shape block `S`. Eliminating the poses (Schur complement)
//! leaves a system of the shape's size,
//!
//! `(S − Σ C_nᵀ P_n⁻¹ C_n) δ_s = b_s − Σ C_nᵀ P_n⁻¹ b_n`,   `δ_n = P_n⁻¹ (b_n − C_n δ_s)`,
//!
//! so the cost grows linearly with the number of frames instead of cubically (every Cholesky
//! factorization by faer). The dense Cholesky of the whole matrix is kept as the reference the
//! tests compare against.

use faer::linalg::solvers::Solve;
use faer::{Mat, Side};
use nalgebra::{DMatrix, DVector};

/// Solve `a δ = b` where `a` (symmetric positive definite) has the block-arrow structure of
/// `frames` pose blocks of `nd` unknowns followed by the shape unknowns; `None` when a
/// factorization fails or the solution is not finite.
pub(crate) fn block_arrow_solve(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    frames: usize,
    nd: usize,
) -> Option<DVector<f64>> {
    let so = frames * nd;
    let ns = a.nrows().checked_sub(so)?;
    let mut reduced = Mat::from_fn(ns, ns, |i, j| a[(so + i, so + j)]);
    let mut reduced_rhs = Mat::from_fn(ns, 1, |i, _| b[so + i]);
    // Per frame, P_n⁻¹ [C_n | b_n]: its last column recovers δ_n once δ_s is known.
    let mut eliminated = Vec::with_capacity(frames);
    for f in 0..frames {
        let o = f * nd;
        let p = Mat::from_fn(nd, nd, |i, j| a[(o + i, o + j)]);
        let c = Mat::from_fn(nd, ns, |i, j| a[(o + i, so + j)]);
        let mut x = Mat::from_fn(nd, ns + 1, |i, j| if j < ns { c[(i, j)] } else { b[o + i] });
        p.llt(Side::Lower).ok()?.solve_in_place(x.as_mut());
        reduced -= c.transpose() * x.subcols(0, ns);
        reduced_rhs -= c.transpose() * x.subcols(ns, 1);
        eliminated.push((c, x));
    }
    reduced
        .llt(Side::Lower)
        .ok()?
        .solve_in_place(reduced_rhs.as_mut());
    let mut delta = DVector::zeros(a.nrows());
    for i in 0..ns {
        delta[so + i] = reduced_rhs[(i, 0)];
    }
    for (f, (_, x)) in eliminated.iter().enumerate() {
        let back = x.subcols(0, ns) * &reduced_rhs;
        for i in 0..nd {
            delta[f * nd + i] = x[(i, ns)] - back[(i, 0)];
        }
    }
    delta.iter().all(|v| v.is_finite()).then_some(delta)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// A random block-arrow SPD system solved both ways: the Schur complement equals the dense
    /// Cholesky solution.
    #[test]
    fn matches_the_dense_cholesky() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let (frames, nd, ns) = (5, 7, 4);
        let n = frames * nd + ns;
        let mut a = DMatrix::<f64>::zeros(n, n);
        // Rows that touch one frame's poses and the shape, as the data terms' rows do.
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
        let dense = a.clone().cholesky().unwrap().solve(&b);
        let block = block_arrow_solve(&a, &b, frames, nd).unwrap();
        assert!((dense - block).amax() < 1e-9);
    }
}
