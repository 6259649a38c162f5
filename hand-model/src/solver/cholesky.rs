//! The dense Cholesky factorization of the solvers' normal equations (`A = L Lᵀ`), in place.
//!
//! Why not nalgebra's `Cholesky::new_unchecked` directly: its column update is a generic
//! strided `axpy` that the compiler does not vectorize, and it was ≈ 3 % of an online
//! calibration frame (106 unknowns). Why not faer's (faster still, session 38): its rounding
//! differs, and a tracker amplifies rounding on fragile frames, so a speed change became an
//! accuracy change. [`factor_lower`] performs nalgebra's arithmetic exactly — the same
//! left-looking order, every element updated as `y ← y + (−l_jk)·x` for `k` ascending, then
//! `√` and division — on contiguous column slices with four columns fused per pass over the
//! target (each element still takes the four updates in order), compiled for the CPU's
//! widest vector unit through `pulp`'s run-time dispatch (no `unsafe` here; separate
//! multiplies and adds, never fused). Its factor is bit for bit nalgebra's (`tests`), so
//! `Cholesky::pack_dirty` and nalgebra's triangular solves use it as their own. Measured
//! (20 000 factorizations each, session 40): 106 unknowns (online calibration) 38.8 → 18.6 µs
//! with AVX2 (≈ 26 µs without it), 28 unknowns (a pose) 1.32 → 0.94 µs.

use nalgebra::DMatrix;

/// Overwrite the lower triangle (diagonal included) of the square `m` with its Cholesky factor
/// `L`, bit for bit what `nalgebra::Cholesky::new_unchecked(m).unpack_dirty()` gives; the strict
/// upper triangle is left as it was. Nothing is checked: a non-positive pivot yields NaN or
/// infinity on the diagonal and beyond, which the callers test (the LM solver's pivot rule,
/// [`cholesky_checked`]).
///
/// # Panics
/// If `m` is not square.
pub fn factor_lower(m: &mut DMatrix<f64>) {
    assert!(
        m.is_square(),
        "the Cholesky factorization needs a square matrix"
    );
    let n = m.nrows();
    let data = m.as_mut_slice();
    // Compiled for the widest vector unit that pulp finds at run time (AVX2 on x86-64 v3
    // CPUs); without fused multiply-adds, so the rounding stays nalgebra's.
    pulp::Arch::new().dispatch(Columns { data, n });
}

/// The column-major storage of an `n × n` matrix to factor, as a pulp operation.
struct Columns<'a> {
    data: &'a mut [f64],
    n: usize,
}

impl pulp::WithSimd for Columns<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        factor_columns(self.data, self.n);
    }
}

/// [`factor_lower`] on the column-major storage of an `n × n` matrix.
#[inline(always)]
fn factor_columns(data: &mut [f64], n: usize) {
    for j in 0..n {
        let (left, right) = data.split_at_mut(j * n);
        let target = &mut right[j..n];
        let column = |k: usize| &left[k * n + j..k * n + n];
        // Four columns of `L` per pass over the target.
        let mut k = 0;
        while k + 4 <= j {
            let a = [0, 1, 2, 3].map(|d| -left[(k + d) * n + j]);
            let len = target.len();
            let x = [0, 1, 2, 3].map(|d| &column(k + d)[..len]);
            for i in 0..len {
                // Sequential additions: the rounding of k, k + 1, k + 2, k + 3 one by one.
                let mut y = target[i];
                y += a[0] * x[0][i];
                y += a[1] * x[1][i];
                y += a[2] * x[2][i];
                y += a[3] * x[3][i];
                target[i] = y;
            }
            k += 4;
        }
        for k in k..j {
            let a = -left[k * n + j];
            for (y, x) in target.iter_mut().zip(column(k)) {
                *y += a * x;
            }
        }
        let denom = target[0].sqrt();
        target[0] = denom;
        for y in &mut target[1..] {
            *y /= denom;
        }
    }
}

/// [`factor_lower`] with nalgebra's `Cholesky::new` acceptance rule: false unless every pivot
/// is positive (NaN pivots fail). `m` holds the factor either way.
pub fn cholesky_checked(m: &mut DMatrix<f64>) -> bool {
    factor_lower(m);
    (0..m.nrows()).all(|j| m[(j, j)] > 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Cholesky;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A random SPD matrix `B Bᵀ + n·I` with entries of mixed scale.
    fn spd(n: usize, seed: u64) -> DMatrix<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let b = DMatrix::from_fn(n, n, |_, _| {
            rng.random_range(-1.0..1.0) * 10f64.powi(rng.random_range(-3..4))
        });
        &b * b.transpose() + DMatrix::identity(n, n) * n as f64
    }

    #[test]
    fn the_factor_is_nalgebras_bit_for_bit() {
        for (n, seed) in [
            (0, 1),
            (1, 2),
            (3, 3),
            (4, 4),
            (7, 5),
            (28, 6),
            (34, 7),
            (106, 8),
        ] {
            let a = spd(n, seed);
            let expected = Cholesky::new_unchecked(a.clone()).unpack_dirty();
            let mut got = a.clone();
            factor_lower(&mut got);
            for j in 0..n {
                for i in j..n {
                    assert_eq!(
                        got[(i, j)].to_bits(),
                        expected[(i, j)].to_bits(),
                        "n = {n}, ({i}, {j})"
                    );
                }
            }
            // And it solves: L Lᵀ = A to rounding.
            let l = got.lower_triangle();
            let err = (&l * l.transpose() - &a).abs().max();
            assert!(err <= 1e-9 * a.abs().max(), "n = {n}: {err}");
        }
    }

    #[test]
    fn indefinite_or_nan_matrices_are_refused_like_nalgebra() {
        let mut indefinite = spd(6, 9);
        indefinite[(3, 3)] = -1e6;
        let mut with_nan = spd(6, 10);
        with_nan[(2, 2)] = f64::NAN;
        for m in [indefinite, with_nan, DMatrix::zeros(3, 3)] {
            let mut f = m.clone();
            assert!(!cholesky_checked(&mut f));
            assert!(Cholesky::new(m).is_none());
        }
        let mut ok = spd(5, 11);
        assert!(cholesky_checked(&mut ok));
    }
}
