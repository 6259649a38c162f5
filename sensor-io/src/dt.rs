//! Exact Euclidean distance transform with closest-pixel indices (Felzenszwalb & Huttenlocher,
//! "Distance transforms of sampled functions", 2012), as used by the 2D silhouette terms
//! (thesis §2.3.1 "2D correspondences", Eq. 2.3; ANCHOR-FACTS §5.4).
//!
//! Written by hand because no maintained crate returns the closest-pixel index together with
//! the distance in linear time with reusable buffers (`imageproc` gives distances only).

use crate::image::Mask;

/// Index stored for pixels when the mask is empty (no closest pixel exists).
pub const NO_PIXEL: u32 = u32::MAX;

/// Reusable distance-transform buffers: for every pixel, the squared distance (px²) to the
/// nearest set pixel of a mask and that pixel's linear index (`v·width + u`).
#[derive(Clone, Debug, Default)]
pub struct DistanceTransform {
    width: u32,
    height: u32,
    /// Squared distance to the nearest set pixel (px²); `f32::INFINITY` when the mask is empty.
    pub dist2: Vec<f32>,
    /// Linear index of the nearest set pixel; [`NO_PIXEL`] when the mask is empty.
    pub nearest: Vec<u32>,
    col_d: Vec<u32>,
    col_arg: Vec<u32>,
    env_v: Vec<usize>,
    env_z: Vec<f64>,
    env_f: Vec<f64>,
}

const BIG: u32 = u32::MAX / 4;

impl DistanceTransform {
    /// Width of the last transformed mask.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height of the last transformed mask.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Transform a mask; allocates only when the image size grows. Linear time.
    pub fn compute(&mut self, mask: &Mask) {
        let (w, h) = (mask.width as usize, mask.height as usize);
        self.width = mask.width;
        self.height = mask.height;
        let n = w * h;
        self.dist2.resize(n, 0.0);
        self.nearest.resize(n, NO_PIXEL);
        self.col_d.resize(n, BIG);
        self.col_arg.resize(n, 0);
        self.env_v.resize(w.max(1), 0);
        self.env_z.resize(w + 1, 0.0);
        self.env_f.resize(w.max(1), 0.0);
        // Pass 1: per column, distance (in rows) to the nearest set pixel, by a downward and an
        // upward sweep over whole rows (contiguous memory).
        {
            let (d, arg) = (&mut self.col_d[..n], &mut self.col_arg[..n]);
            for v in 0..h {
                let row = v * w;
                let (prev_d, cur_d) = d.split_at_mut(row);
                let (prev_a, cur_a) = arg.split_at_mut(row);
                let cur_d = &mut cur_d[..w];
                let cur_a = &mut cur_a[..w];
                let m = &mask.data[row..row + w];
                if v == 0 {
                    for u in 0..w {
                        (cur_d[u], cur_a[u]) = if m[u] != 0 { (0, 0) } else { (BIG, 0) };
                    }
                } else {
                    let pd = &prev_d[row - w..row];
                    let pa = &prev_a[row - w..row];
                    for u in 0..w {
                        (cur_d[u], cur_a[u]) = if m[u] != 0 {
                            (0, v as u32)
                        } else if pd[u] < BIG {
                            (pd[u] + 1, pa[u])
                        } else {
                            (BIG, 0)
                        };
                    }
                }
            }
            for v in (0..h.saturating_sub(1)).rev() {
                let row = v * w;
                let (cur_d, next_d) = d.split_at_mut(row + w);
                let (cur_a, next_a) = arg.split_at_mut(row + w);
                let (cur_d, cur_a) = (&mut cur_d[row..], &mut cur_a[row..]);
                let (nd, na) = (&next_d[..w], &next_a[..w]);
                for u in 0..w {
                    if nd[u] < BIG && nd[u] + 1 < cur_d[u] {
                        cur_d[u] = nd[u] + 1;
                        cur_a[u] = na[u];
                    }
                }
            }
        }
        // Pass 2: per row, lower envelope of the parabolas (u − q)² + g(q)², over the columns
        // that have a set pixel at all (others are +∞ and never on the envelope).
        for v in 0..h {
            let row = v * w;
            let mut k = 0usize;
            let mut found = false;
            for q in 0..w {
                let g = self.col_d[row + q];
                if g >= BIG {
                    continue;
                }
                let fq = (g as f64) * (g as f64) + (q * q) as f64;
                if !found {
                    found = true;
                    k = 0;
                    self.env_v[0] = q;
                    self.env_f[0] = fq;
                    self.env_z[0] = f64::NEG_INFINITY;
                    self.env_z[1] = f64::INFINITY;
                    continue;
                }
                loop {
                    let p = self.env_v[k];
                    let s = (fq - self.env_f[k]) / (2.0 * (q - p) as f64);
                    if s <= self.env_z[k] && k > 0 {
                        k -= 1;
                        continue;
                    }
                    if s <= self.env_z[k] {
                        // The new parabola dominates the only one left.
                        self.env_v[0] = q;
                        self.env_f[0] = fq;
                        self.env_z[1] = f64::INFINITY;
                        break;
                    }
                    k += 1;
                    self.env_v[k] = q;
                    self.env_f[k] = fq;
                    self.env_z[k] = s;
                    self.env_z[k + 1] = f64::INFINITY;
                    break;
                }
            }
            if !found {
                self.dist2[row..row + w].fill(f32::INFINITY);
                self.nearest[row..row + w].fill(NO_PIXEL);
                continue;
            }
            let mut j = 0usize;
            for u in 0..w {
                while self.env_z[j + 1] < u as f64 {
                    j += 1;
                }
                let q = self.env_v[j];
                let du = u as f64 - q as f64;
                let g = self.col_d[row + q] as f64;
                self.dist2[row + u] = (du * du + g * g) as f32;
                self.nearest[row + u] = self.col_arg[row + q] * w as u32 + q as u32;
            }
        }
    }

    /// Euclidean distance (px) of pixel (u, v) to the mask.
    #[inline]
    pub fn distance(&self, u: u32, v: u32) -> f32 {
        self.dist2[(v * self.width + u) as usize].sqrt()
    }

    /// The nearest set pixel (u, v) of pixel (u, v), or `None` for an empty mask.
    #[inline]
    pub fn nearest_pixel(&self, u: u32, v: u32) -> Option<(u32, u32)> {
        let i = self.nearest[(v * self.width + u) as usize];
        (i != NO_PIXEL).then(|| (i % self.width, i / self.width))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn matches_brute_force_on_random_masks() {
        let mut rng = ChaCha8Rng::seed_from_u64(42);
        let mut dt = DistanceTransform::default();
        for trial in 0..60 {
            let w = rng.random_range(1..40u32);
            let h = rng.random_range(1..40u32);
            let density = [0.0, 0.002, 0.05, 0.3, 0.9][trial % 5];
            let mut m = Mask::zeros(w, h);
            for x in &mut m.data {
                *x = rng.random_bool(density) as u8;
            }
            dt.compute(&m);
            let set: Vec<(i64, i64)> = (0..h as i64)
                .flat_map(|v| (0..w as i64).map(move |u| (u, v)))
                .filter(|&(u, v)| m.get(u as u32, v as u32))
                .collect();
            for v in 0..h {
                for u in 0..w {
                    let best = set
                        .iter()
                        .map(|&(a, b)| (a - u as i64).pow(2) + (b - v as i64).pow(2))
                        .min();
                    let i = (v * w + u) as usize;
                    match best {
                        None => {
                            assert!(dt.dist2[i].is_infinite());
                            assert_eq!(dt.nearest[i], NO_PIXEL);
                        }
                        Some(b) => {
                            assert_eq!(dt.dist2[i], b as f32, "pixel ({u},{v}) of {w}×{h}");
                            let (nu, nv) = dt.nearest_pixel(u, v).expect("nearest");
                            assert!(m.get(nu, nv));
                            let d = (nu as i64 - u as i64).pow(2) + (nv as i64 - v as i64).pow(2);
                            assert_eq!(d, b, "nearest index is not a closest pixel");
                        }
                    }
                }
            }
        }
    }
}
