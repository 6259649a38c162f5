//! Per-block accumulation of many rows that share one sparsity pattern (the data rows of one
//! bone or one element: thousands per frame), added to the [`NormalEquations`] once per block.

use super::normal_equations::NormalEquations;
use super::term::TermError;

/// Most unknowns of one block.
pub const BLOCK_DOFS: usize = 16;
/// Most blocks of one [`PackedBlocks`].
pub const MAX_BLOCKS: usize = 48;
const PACKED: usize = BLOCK_DOFS * (BLOCK_DOFS + 1) / 2;

/// Dense packed upper triangles and right-hand sides of up to [`MAX_BLOCKS`] blocks of up to
/// [`BLOCK_DOFS`] unknowns, on the stack (≈ 55 KiB): a data term sums its rows per block with no
/// index arithmetic per entry and no allocation, then [`PackedBlocks::flush`]es them through
/// [`NormalEquations::add_packed_block`]. The result equals adding every row with
/// [`NormalEquations::add_row`] up to the order of the additions (tested).
pub struct PackedBlocks {
    upper: [[f64; PACKED]; MAX_BLOCKS],
    rhs: [[f64; BLOCK_DOFS]; MAX_BLOCKS],
    len: [u8; MAX_BLOCKS],
}

impl Default for PackedBlocks {
    fn default() -> Self {
        Self::new()
    }
}

impl PackedBlocks {
    /// Empty blocks.
    pub fn new() -> Self {
        Self {
            upper: [[0.0; PACKED]; MAX_BLOCKS],
            rhs: [[0.0; BLOCK_DOFS]; MAX_BLOCKS],
            len: [0; MAX_BLOCKS],
        }
    }

    /// Whether a block index and width can be held (otherwise add the row directly).
    #[inline]
    pub fn fits(block: usize, k: usize) -> bool {
        block < MAX_BLOCKS && k <= BLOCK_DOFS
    }

    /// Add the row `jac` (over the block's `jac.len()` unknowns, the same for every row of the
    /// block) with residual `r` and weight `w`: `A += w jjᵀ`, `b −= w j r`. Rows that do not
    /// [`fit`](Self::fits), or whose width differs from the block's first row, are an error.
    #[inline]
    pub fn add_row(&mut self, block: usize, jac: &[f64], r: f64, w: f64) -> Result<(), TermError> {
        let k = jac.len();
        if !Self::fits(block, k) || (self.len[block] != 0 && usize::from(self.len[block]) != k) {
            return Err(TermError::Failed("row does not fit its packed block"));
        }
        self.len[block] = k as u8;
        let (up, b) = (&mut self.upper[block], &mut self.rhs[block]);
        let mut off = 0;
        for a in 0..k {
            let wa = w * jac[a];
            b[a] -= wa * r;
            for (x, &jb) in up[off..off + k - a].iter_mut().zip(&jac[a..k]) {
                *x += wa * jb;
            }
            off += k - a;
        }
        Ok(())
    }

    /// Add every used block to `ne`, block `i` over the unknowns `cols(i)` (whose length must be
    /// the width of its rows).
    pub fn flush<'c>(
        &self,
        ne: &mut NormalEquations,
        cols: impl Fn(usize) -> &'c [usize],
    ) -> Result<(), TermError> {
        for (i, &k) in self.len.iter().enumerate() {
            if k == 0 {
                continue;
            }
            let c = cols(i);
            if c.len() != usize::from(k) {
                return Err(TermError::Failed(
                    "packed block width differs from its columns",
                ));
            }
            ne.add_packed_block(c, &self.upper[i], &self.rhs[i])?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_equal_row_by_row_assembly() {
        let cols_a = [0usize, 2, 3];
        let cols_b = [1usize, 3];
        let rows: [(usize, [f64; 3], f64, f64); 4] = [
            (0, [1.0, -2.0, 0.5], 0.3, 2.0),
            (0, [0.2, 0.1, -1.0], -1.5, 0.5),
            (1, [3.0, 1.0, 0.0], 0.7, 1.0),
            (1, [-1.0, 2.0, 0.0], 0.1, 4.0),
        ];
        let mut direct = NormalEquations::new(4);
        let mut blocked = NormalEquations::new(4);
        let mut blocks = PackedBlocks::new();
        for (blk, j, r, w) in rows {
            let cols: &[usize] = if blk == 0 { &cols_a } else { &cols_b };
            let pairs: Vec<(usize, f64)> = cols.iter().copied().zip(j).collect();
            direct.add_row(&pairs, r, w).unwrap();
            blocks.add_row(blk, &j[..cols.len()], r, w).unwrap();
        }
        blocks
            .flush(&mut blocked, |i| if i == 0 { &cols_a } else { &cols_b })
            .unwrap();
        direct.symmetrize();
        blocked.symmetrize();
        assert!((direct.lhs() - blocked.lhs()).norm() < 1e-12);
        assert!((direct.rhs() - blocked.rhs()).norm() < 1e-12);
        assert!(blocks.add_row(0, &[1.0], 0.0, 1.0).is_err());
        assert!(blocks.add_row(MAX_BLOCKS, &[1.0], 0.0, 1.0).is_err());
    }
}
