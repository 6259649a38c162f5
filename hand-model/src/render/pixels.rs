//! The pixels a renderer is asked to ray cast ([`DepthRenderer::render_hits`]): any predicate on
//! the linear pixel index, or a [`PixelRuns`] set. The model→data term of Eq. 3.5 renders only
//! the pixels outside the sensor silhouette, and the model's footprint mostly lies inside it:
//! testing the footprint pixel by pixel cost more than the few rays cast. Stored as runs per
//! row, the set yields the kept pixels of a footprint row without visiting the others.
//!
//! [`DepthRenderer::render_hits`]: super::DepthRenderer::render_hits

/// A set of pixels a renderer may ray cast (see the module docs).
pub trait KeptPixels {
    /// Whether pixel `k` (`v·width + u`) is kept.
    fn keeps(&mut self, k: usize) -> bool;

    /// Whether row `v` of an image `width` pixels wide may keep a column of `[u0, u1]`
    /// (inclusive): false only when it keeps none there, so that a renderer can skip the row
    /// without working out which of those columns a footprint covers. The default answers
    /// true (a predicate is not scanned ahead).
    #[inline]
    fn any_in_row(&mut self, width: u32, v: u32, u0: u32, u1: u32) -> bool {
        let _ = (width, v, u0, u1);
        true
    }

    /// Calls `f(u)` for every kept column `u` of `[u0, u1]` (inclusive) in row `v` of an image
    /// `width` pixels wide, in increasing order.
    #[inline]
    fn for_each_in_row(&mut self, width: u32, v: u32, u0: u32, u1: u32, mut f: impl FnMut(u32)) {
        let row = v as usize * width as usize;
        for u in u0..=u1 {
            if self.keeps(row + u as usize) {
                f(u);
            }
        }
    }
}

impl<F: FnMut(usize) -> bool> KeptPixels for F {
    #[inline]
    fn keeps(&mut self, k: usize) -> bool {
        self(k)
    }
}

/// A set of pixels of an image stored per row as sorted, disjoint runs of consecutive columns;
/// built once (e.g. per sensor frame) with [`PixelRuns::set`], reusing its buffers.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PixelRuns {
    width: u32,
    /// Row `v`'s runs are `runs[row_start[v]..row_start[v + 1]]`.
    row_start: Vec<u32>,
    /// Runs `[first, last]` of kept columns (inclusive).
    runs: Vec<[u32; 2]>,
}

impl PixelRuns {
    /// Makes the set the pixels `k` of a `width × height` image with `keep(k)`.
    pub fn set(&mut self, width: u32, height: u32, mut keep: impl FnMut(usize) -> bool) {
        self.width = width;
        self.row_start.clear();
        self.runs.clear();
        for v in 0..height {
            self.row_start.push(self.runs.len() as u32);
            let row = v as usize * width as usize;
            let mut open: Option<u32> = None;
            for u in 0..width {
                match (keep(row + u as usize), open) {
                    (true, None) => open = Some(u),
                    (false, Some(first)) => {
                        self.runs.push([first, u - 1]);
                        open = None;
                    }
                    _ => {}
                }
            }
            if let Some(first) = open {
                self.runs.push([first, width - 1]);
            }
        }
        self.row_start.push(self.runs.len() as u32);
    }

    /// Makes the set the given pixels `v·width + u` of a `width × height` image, listed in
    /// increasing order (repeats allowed; pixels beyond the image are dropped): the same set as
    /// [`PixelRuns::set`] with their membership test, without visiting the other pixels.
    pub fn set_sorted(&mut self, width: u32, height: u32, pixels: impl IntoIterator<Item = u32>) {
        self.width = width;
        self.row_start.clear();
        self.runs.clear();
        let w = width.max(1);
        let end = u64::from(width) * u64::from(height);
        for k in pixels.into_iter().take_while(|&k| u64::from(k) < end) {
            let (u, v) = (k % w, k / w);
            while self.row_start.len() <= v as usize {
                self.row_start.push(self.runs.len() as u32);
            }
            let in_row = self.runs.len() > self.row_start[v as usize] as usize;
            match self.runs.last_mut() {
                Some(last) if in_row && last[1] + 1 >= u => last[1] = last[1].max(u),
                _ => self.runs.push([u, u]),
            }
        }
        while self.row_start.len() <= height as usize {
            self.row_start.push(self.runs.len() as u32);
        }
    }

    /// The runs of row `v` (none beyond the image).
    fn row(&self, v: usize) -> &[[u32; 2]] {
        match (self.row_start.get(v), self.row_start.get(v + 1)) {
            (Some(&a), Some(&b)) => &self.runs[a as usize..b as usize],
            _ => &[],
        }
    }
}

impl KeptPixels for &PixelRuns {
    fn keeps(&mut self, k: usize) -> bool {
        let w = self.width.max(1) as usize;
        let u = (k % w) as u32;
        self.row(k / w).iter().any(|&[a, b]| a <= u && u <= b)
    }

    /// Exact: whether a run of row `v` meets `[u0, u1]` (`width` must be the set's).
    #[inline]
    fn any_in_row(&mut self, width: u32, v: u32, u0: u32, u1: u32) -> bool {
        debug_assert_eq!(width, self.width);
        u0 <= u1
            && self
                .row(v as usize)
                .iter()
                .take_while(|&&[a, _]| a <= u1)
                .any(|&[_, b]| b >= u0)
    }

    /// Visits only the runs that meet `[u0, u1]` (`width` must be the set's).
    #[inline]
    fn for_each_in_row(&mut self, width: u32, v: u32, u0: u32, u1: u32, mut f: impl FnMut(u32)) {
        debug_assert_eq!(width, self.width);
        for &[a, b] in self.row(v as usize) {
            if a > u1 {
                break;
            }
            for u in a.max(u0)..=b.min(u1) {
                f(u);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The runs hold exactly the predicate's pixels, a row visit yields the same columns as
    /// the pixel-by-pixel visit of the predicate, and a row is said to keep some column of a
    /// range exactly when the visit yields one.
    #[test]
    fn runs_equal_the_predicate() {
        let (w, h) = (37u32, 11u32);
        let keep = |k: usize| (k * 7919) % 13 < 5 || (k / 37) % 4 == 0 || k % 37 == 36;
        let mut runs = PixelRuns::default();
        runs.set(w, h, keep);
        for k in 0..(w * h) as usize + 40 {
            assert_eq!((&runs).keeps(k), k < (w * h) as usize && keep(k), "{k}");
        }
        let listed: Vec<u32> = (0..(w * h) as usize + 40)
            .filter(|&k| k < (w * h) as usize && keep(k))
            .flat_map(|k| [k as u32, k as u32])
            .chain([w * h + 3])
            .collect();
        let mut sorted = PixelRuns::default();
        sorted.set_sorted(w, h, listed);
        assert_eq!(sorted, runs, "the sorted list builds the same runs");
        for v in 0..h + 2 {
            for (u0, u1) in [(0, w - 1), (3, 3), (5, 30), (36, 36), (20, 10)] {
                let (mut a, mut b) = (Vec::new(), Vec::new());
                (&runs).for_each_in_row(w, v, u0, u1, |u| a.push(u));
                let mut plain = |k: usize| v < h && keep(k);
                plain.for_each_in_row(w, v, u0, u1, |u| b.push(u));
                assert_eq!(a, b, "row {v} [{u0}, {u1}]");
                assert_eq!((&runs).any_in_row(w, v, u0, u1), !a.is_empty());
            }
        }
    }
}
