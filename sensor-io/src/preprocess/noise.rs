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

/// `gate` when the measured depth noise `sigma` (mm; `None`: not measured yet) is at least
/// `min_noise` (≤ 0: always), else `None`: the switch of the trackers' along-ray
/// correspondences, which pay off under noise and cost a rendering of the points' pixels.
pub fn gate_for_noise(gate: Option<f64>, min_noise: f64, sigma: Option<f64>) -> Option<f64> {
    gate.filter(|_| is_noisy(min_noise, sigma))
}

/// Whether data of measured depth noise `sigma` (mm; `None`: not measured yet) count as noisy
/// for a switch set at `min_noise` (≤ 0: always): σ̂ ≥ `min_noise`.
pub fn is_noisy(min_noise: f64, sigma: Option<f64>) -> bool {
    min_noise <= 0.0 || sigma.is_some_and(|s| s >= min_noise)
}

/// How far the trackers' along-ray footpoint may slide from the closest point on data of
/// measured depth noise `sigma` (mm): `slide`, raised to `per_noise·σ̂` where that is larger.
/// The footpoint slides with the noise along the ray (by `ε·sin φ`), so a slide measured at
/// one noise level keeps its share of the points at another only in proportion to σ̂.
/// `slide` itself when it is negative (registration off) or NaN, when `per_noise` is not
/// positive, or when `sigma` is not measured or not finite.
pub fn slide_for_noise(slide: f64, per_noise: f64, sigma: Option<f64>) -> f64 {
    match sigma {
        Some(s) if slide >= 0.0 && per_noise > 0.0 && s.is_finite() => slide.max(per_noise * s),
        _ => slide,
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

/// The depth noise of a sequence as a tracker follows it: [`depth_noise`] measured on the first
/// frame that has enough pixels and on every [`NoiseMonitor::INTERVAL`]-th frame after, smoothed
/// exponentially (weight [`NoiseMonitor::SMOOTHING`] per new measurement) so that one odd frame
/// does not flip what the noise decides. Allocation-free once its scratch has held a frame.
#[derive(Clone, Debug, Default)]
pub struct NoiseMonitor {
    sigma: Option<f64>,
    since: usize,
    diffs: Vec<f64>,
}

impl NoiseMonitor {
    /// Frames between two measurements.
    pub const INTERVAL: usize = 15;
    /// Weight of a new measurement in the smoothed σ̂.
    pub const SMOOTHING: f64 = 0.3;

    /// Count one frame (`depth` with the hand's `mask`) and measure it when due; true when σ̂
    /// changed.
    pub fn observe(&mut self, depth: &DepthImage, mask: &Mask) -> bool {
        let due = self.sigma.is_none() || self.since + 1 >= Self::INTERVAL;
        self.since = if due { 0 } else { self.since + 1 };
        if !due {
            return false;
        }
        let Some(sigma) = depth_noise_with(depth, mask, &mut self.diffs) else {
            return false;
        };
        self.sigma = Some(match self.sigma {
            Some(old) => old + Self::SMOOTHING * (sigma - old),
            None => sigma,
        });
        true
    }

    /// The smoothed depth noise σ̂ (mm), `None` before the first measurement.
    pub fn sigma(&self) -> Option<f64> {
        self.sigma
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use rand::{Rng, SeedableRng};

    #[test]
    fn the_slide_follows_the_noise_above_its_own() {
        assert_eq!(slide_for_noise(7.5, 1.5, Some(4.0)), 7.5);
        assert_eq!(slide_for_noise(7.5, 1.5, Some(10.0)), 15.0);
        assert_eq!(slide_for_noise(7.5, 1.5, None), 7.5);
        assert_eq!(slide_for_noise(7.5, 1.5, Some(f64::NAN)), 7.5);
        assert_eq!(slide_for_noise(7.5, 0.0, Some(10.0)), 7.5);
        assert_eq!(slide_for_noise(-1.0, 1.5, Some(10.0)), -1.0);
        assert_eq!(
            slide_for_noise(f64::INFINITY, 1.5, Some(10.0)),
            f64::INFINITY
        );
        assert!(slide_for_noise(f64::NAN, 1.5, Some(10.0)).is_nan());
    }

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

    /// The monitor measures the first frame with a hand, then every `INTERVAL`-th, and follows
    /// a change of noise smoothly.
    #[test]
    fn the_monitor_measures_at_intervals_and_smooths() {
        let (empty, mut none) = plane(3.0, 1);
        none.data.fill(0);
        let mut monitor = NoiseMonitor::default();
        assert!(!monitor.observe(&empty, &none), "nothing to measure");
        assert_eq!(monitor.sigma(), None);
        let (d3, m3) = plane(3.0, 2);
        assert!(monitor.observe(&d3, &m3), "the first frame with a hand");
        let first = monitor.sigma().unwrap();
        assert!((first - 3.0).abs() < 0.4, "{first}");
        let (d8, m8) = plane(8.0, 4);
        let changed: Vec<usize> = (1..=2 * NoiseMonitor::INTERVAL)
            .filter(|_| monitor.observe(&d8, &m8))
            .collect();
        assert_eq!(
            changed,
            [NoiseMonitor::INTERVAL, 2 * NoiseMonitor::INTERVAL]
        );
        let s = monitor.sigma().unwrap();
        let expected = first + (1.0 - (1.0 - NoiseMonitor::SMOOTHING).powi(2)) * (8.0 - first);
        assert!((s - expected).abs() < 0.5, "{s} vs {expected}");
    }
}
