//! The 2D distance transform of the sensor silhouette used by the silhouette term E2D (thesis
//! Eq. 2.3, §2.3.1 "2D correspondences"): for every pixel, the nearest pixel of the sensor
//! silhouette `𝒮_s`, by the linear-time algorithm of Felzenszwalb and Huttenlocher (exact squared
//! Euclidean distance; one lower envelope of parabolas per row, then per column; ANCHOR-FACTS
//! §5.4). The projection `Π_{𝒮_s}(p)` of Eq. 2.3 is [`DistanceTransform::nearest`].
//!
//! Pixels are indexed row-major, `v·width + u` (OpenCV image rows, y down; htrack flips the
//! mask to y-up, which only renames the rows).

/// Index of "no silhouette pixel" in [`DistanceTransform::nearest_index`].
pub const NO_PIXEL: u32 = u32::MAX;

/// Reusable distance-transform buffers (allocation-free once sized for an image).
#[derive(Clone, Debug, Default)]
pub struct DistanceTransform {
    width: usize,
    height: usize,
    dist2: Vec<f64>,
    nearest: Vec<u32>,
    row_dist2: Vec<f64>,
    row_arg: Vec<u32>,
    f: Vec<f64>,
    d: Vec<f64>,
    arg: Vec<usize>,
    v: Vec<usize>,
    z: Vec<f64>,
}

/// Why a transform could not be computed.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum DistanceTransformError {
    /// The mask does not hold `width·height` pixels, or that product overflows or does not fit
    /// the `u32` pixel indices.
    BadSize,
}

impl std::fmt::Display for DistanceTransformError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("mask size does not match width·height (or exceeds u32 indices)")
    }
}

impl std::error::Error for DistanceTransformError {}

/// 1D lower envelope of the parabolas `(x − q)² + f(q)` over the sites with finite `f(q)`:
/// `d[x] = min_q`, `arg[x]` the minimizing site (`usize::MAX` and `∞` when there is none).
fn envelope(f: &[f64], d: &mut [f64], arg: &mut [usize], v: &mut Vec<usize>, z: &mut Vec<f64>) {
    v.clear();
    z.clear();
    for (q, &fq) in f.iter().enumerate() {
        if !fq.is_finite() {
            continue;
        }
        let qf = q as f64;
        // z[k] is the left end of the interval where parabola v[k] is lowest.
        while let (Some(&p), Some(&zl)) = (v.last(), z.last()) {
            let pf = p as f64;
            let s = ((fq + qf * qf) - (f[p] + pf * pf)) / (2.0 * (qf - pf));
            if s <= zl {
                v.pop();
                z.pop();
            } else {
                v.push(q);
                z.push(s);
                break;
            }
        }
        if v.is_empty() {
            v.push(q);
            z.push(f64::NEG_INFINITY);
        }
    }
    if v.is_empty() {
        d.fill(f64::INFINITY);
        arg.fill(usize::MAX);
        return;
    }
    let mut k = 0;
    for (x, (dx, ax)) in d.iter_mut().zip(arg.iter_mut()).enumerate() {
        let xf = x as f64;
        while k + 1 < v.len() && z[k + 1] < xf {
            k += 1;
        }
        let q = v[k];
        let t = xf - q as f64;
        *dx = t * t + f[q];
        *ax = q;
    }
}

impl DistanceTransform {
    /// Empty buffers.
    pub fn new() -> Self {
        Self::default()
    }

    /// Transform `mask` (row-major, `true` = sensor silhouette pixel) of `width × height`.
    pub fn compute(
        &mut self,
        mask: &[bool],
        width: usize,
        height: usize,
    ) -> Result<(), DistanceTransformError> {
        let n = width
            .checked_mul(height)
            .filter(|&n| n == mask.len() && n < NO_PIXEL as usize)
            .ok_or(DistanceTransformError::BadSize)?;
        self.width = width;
        self.height = height;
        for buf in [&mut self.dist2, &mut self.row_dist2] {
            buf.clear();
            buf.resize(n, f64::INFINITY);
        }
        for buf in [&mut self.nearest, &mut self.row_arg] {
            buf.clear();
            buf.resize(n, NO_PIXEL);
        }
        let m = width.max(height);
        self.f.resize(m, 0.0);
        self.d.resize(m, 0.0);
        self.arg.resize(m, 0);
        // Rows: distance to the nearest silhouette pixel of the same row.
        for y in 0..height {
            let row = &mask[y * width..(y + 1) * width];
            for (fx, &m) in self.f[..width].iter_mut().zip(row) {
                *fx = if m { 0.0 } else { f64::INFINITY };
            }
            envelope(
                &self.f[..width],
                &mut self.d[..width],
                &mut self.arg[..width],
                &mut self.v,
                &mut self.z,
            );
            for x in 0..width {
                self.row_dist2[y * width + x] = self.d[x];
                self.row_arg[y * width + x] = if self.arg[x] == usize::MAX {
                    NO_PIXEL
                } else {
                    self.arg[x] as u32
                };
            }
        }
        // Columns over the row distances.
        for x in 0..width {
            for y in 0..height {
                self.f[y] = self.row_dist2[y * width + x];
            }
            envelope(
                &self.f[..height],
                &mut self.d[..height],
                &mut self.arg[..height],
                &mut self.v,
                &mut self.z,
            );
            for y in 0..height {
                let q = self.arg[y];
                if q != usize::MAX {
                    let col = self.row_arg[q * width + x];
                    self.dist2[y * width + x] = self.d[y];
                    self.nearest[y * width + x] = (q * width) as u32 + col;
                }
            }
        }
        Ok(())
    }

    /// Image width of the last transform.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Image height of the last transform.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Per pixel the row-major index of the nearest silhouette pixel ([`NO_PIXEL`] for an
    /// empty silhouette).
    pub fn nearest_index(&self) -> &[u32] {
        &self.nearest
    }

    /// Per pixel the squared distance (pixels²) to the nearest silhouette pixel (∞ for an empty
    /// silhouette).
    pub fn distance2(&self) -> &[f64] {
        &self.dist2
    }

    /// `Π_{𝒮_s}(p)` of Eq. 2.3 for the pixel `(u, v)`: the nearest silhouette pixel `(u, v)`;
    /// `None` outside the image or for an empty silhouette.
    pub fn nearest(&self, u: usize, v: usize) -> Option<(usize, usize)> {
        if u >= self.width || v >= self.height {
            return None;
        }
        let i = self.nearest[v * self.width + u];
        (i != NO_PIXEL).then(|| (i as usize % self.width, i as usize / self.width))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn matches_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut dt = DistanceTransform::new();
        for (w, h, density) in [(37, 23, 0.02), (16, 40, 0.3), (50, 50, 0.001), (1, 9, 0.2)] {
            let mask: Vec<bool> = (0..w * h).map(|_| rng.random::<f64>() < density).collect();
            dt.compute(&mask, w, h).unwrap();
            let sites: Vec<(usize, usize)> = (0..w * h)
                .filter(|&i| mask[i])
                .map(|i| (i % w, i / w))
                .collect();
            for v in 0..h {
                for u in 0..w {
                    let d2 = |&(a, b): &(usize, usize)| {
                        let (du, dv) = (a as f64 - u as f64, b as f64 - v as f64);
                        du * du + dv * dv
                    };
                    let best = sites.iter().map(d2).fold(f64::INFINITY, f64::min);
                    assert_eq!(dt.distance2()[v * w + u], best, "({u}, {v}) in {w}×{h}");
                    match dt.nearest(u, v) {
                        Some(q) => {
                            assert!(mask[q.1 * w + q.0]);
                            assert_eq!(d2(&q), best);
                        }
                        None => assert!(sites.is_empty()),
                    }
                }
            }
        }
    }

    #[test]
    fn bad_sizes_and_empty_masks() {
        let mut dt = DistanceTransform::new();
        assert_eq!(
            dt.compute(&[true; 5], 2, 3),
            Err(DistanceTransformError::BadSize)
        );
        assert_eq!(
            dt.compute(&[], usize::MAX, 2),
            Err(DistanceTransformError::BadSize)
        );
        dt.compute(&[false; 6], 3, 2).unwrap();
        assert!(dt.nearest(1, 1).is_none() && dt.distance2()[0].is_infinite());
        assert!(dt.nearest(3, 0).is_none());
        dt.compute(&[], 0, 0).unwrap();
    }
}
