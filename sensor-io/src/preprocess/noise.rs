//! The depth noise of a frame, measured from the data alone.

use crate::{DepthImage, Mask};

/// Robust estimate of the depth noise σ (mm) on the masked pixels: the median absolute
/// second difference `|z(u,v) − (z(u−1,v) + z(u+1,v))/2|` along rows, scaled to σ for
/// independent Gaussian noise (`1.4826 / √1.5`). A hand's surface is smooth at the pixel scale
/// (its second difference is a fraction of a millimetre), so what remains is the sensor's
/// noise; triples across a depth edge (neighbours more than `EDGE` mm apart) are left out.
/// `None` when fewer than `MIN_SAMPLES` triples qualify (an empty or tiny segment).
pub fn depth_noise(depth: &DepthImage, mask: &Mask) -> Option<f64> {
    depth_noise_with(depth, mask, &mut Vec::new())
}

/// The factor by which a prior measured per squared millimetre of data is scaled to keep its
/// balance against data of noise `sigma` (mm): `max(σ / 1 mm, 1)²`. Data terms are sums of
/// squared millimetres, so noisier data outvote a fixed prior by σ²; data at or below 1 mm
/// (quantization) keep the prior as given. Non-finite σ gives 1.
pub fn noise_scale(sigma: f64) -> f64 {
    if sigma.is_finite() {
        sigma.max(1.0).powi(2)
    } else {
        1.0
    }
}

/// [`depth_noise`] with a caller's scratch buffer (no allocation once it is large enough).
pub fn depth_noise_with(depth: &DepthImage, mask: &Mask, diffs: &mut Vec<f64>) -> Option<f64> {
    const EDGE: f64 = 40.0;
    const MIN_SAMPLES: usize = 50;
    if mask.width != depth.width || mask.height != depth.height || depth.width < 3 {
        return None;
    }
    let w = depth.width as usize;
    diffs.clear();
    for (row, mrow) in depth.data.chunks_exact(w).zip(mask.data.chunks_exact(w)) {
        for u in 1..w - 1 {
            let (a, b, c) = (row[u - 1], row[u], row[u + 1]);
            if mrow[u - 1] == 0 || mrow[u] == 0 || mrow[u + 1] == 0 || a == 0 || b == 0 || c == 0 {
                continue;
            }
            let (a, b, c) = (f64::from(a), f64::from(b), f64::from(c));
            if (a - c).abs() > EDGE {
                continue;
            }
            diffs.push((b - 0.5 * (a + c)).abs());
        }
    }
    if diffs.len() < MIN_SAMPLES {
        return None;
    }
    let mid = diffs.len() / 2;
    let (_, median, _) = diffs.select_nth_unstable_by(mid, f64::total_cmp);
    Some(*median * 1.4826 / 1.5f64.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn plane(sigma: f64, seed: u64) -> (DepthImage, Mask) {
        let (w, h) = (80u32, 60u32);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        // Box–Muller.
        let mut gauss = move || {
            let (a, b): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random());
            (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        };
        let data = (0..w * h)
            .map(|i| {
                let (u, v) = (f64::from(i % w), f64::from(i / w));
                let z = 400.0 + 0.8 * u + 0.3 * v + sigma * gauss();
                z.round() as u16
            })
            .collect();
        let mask = Mask {
            width: w,
            height: h,
            data: vec![1; (w * h) as usize],
        };
        (
            DepthImage {
                width: w,
                height: h,
                data,
            },
            mask,
        )
    }

    #[test]
    fn recovers_the_noise_of_a_tilted_plane() {
        for sigma in [3.0, 5.0, 8.0] {
            let (d, m) = plane(sigma, 3);
            let s = depth_noise(&d, &m).unwrap();
            assert!((s - sigma).abs() < 0.12 * sigma, "σ {sigma}: estimated {s}");
        }
        let (d, m) = plane(0.0, 3);
        assert!(depth_noise(&d, &m).unwrap() < 1.0, "quantization only");
    }

    #[test]
    fn noise_scale_leaves_quantization_alone() {
        assert_eq!(noise_scale(0.3), 1.0);
        assert_eq!(noise_scale(5.0), 25.0);
        assert_eq!(noise_scale(f64::NAN), 1.0);
    }

    #[test]
    fn an_empty_mask_has_no_estimate() {
        let (d, mut m) = plane(3.0, 1);
        m.data.fill(0);
        assert_eq!(depth_noise(&d, &m), None);
    }
}
