//! Edge-aware smoothing of the hand's depth (beyond the thesis, whose pipelines only
//! median-downsample, ANCHOR-FACTS §0).
//!
//! Each silhouette pixel becomes the mean of itself and the pairs of mirrored neighbours of its
//! `(2r+1)²` window that are both silhouette pixels with depth within `range` of its own: a box
//! filter that does not average across the depth steps between a finger and what lies behind
//! it, and that keeps a tilted surface where its window reaches past the outline. A plain mean
//! of the valid neighbours is one-sided there: it pulled a finger's outline toward the camera
//! by up to a few millimetres, the fingers came out thinner, and online calibration learned them
//! so (noise-free teaser, mean keypoint error 0.23 mm raw, 0.37 mm with the plain mean, 0.21 mm
//! with mirrored pairs). Written here rather than taken from an image crate because it must skip
//! the pixels outside the mask and those beyond the range, which the general filters (`image`'s
//! blur, a bilateral filter's Gaussian range weight) do not.
//!
//! Why: a time-of-flight sensor's per-pixel noise (≈ 5 mm at 40 cm in the synthetic ToF model)
//! puts many points inside the thin fingers, where their closest points are back-facing and
//! biased. A 3×3 window divides independent noise by 3; the surface's own curvature moves the
//! mean by a few hundredths of a millimetre at a finger's middle, a few tenths next to its
//! outline. Only the points are smoothed ([`super::PreprocessConfig::smoothing`]): the trackers
//! still measure the sensor's own noise and keep registering points along their camera rays on
//! noisy data. When it applies ([`SmoothParams`]):
//! - Only on noisy depth (`min_noise`, the along-ray switch's 1.5 mm): exact depth gains
//!   nothing that can be told from chance. The sphere-mesh tracker's 64 noise-free cold starts,
//!   smoothed from their 31st frame: 6 cuts better, 8 worse, median change −0.01 mm (105.36 →
//!   104.24 mm summed); from the first frame 158.27 mm (a fist lost).
//! - From a sequence's 31st frame (`after_frames`): smoothed from the first frame, fists placed
//!   from afar stayed stuck where the raw depth let them converge (ToF `rotating_fist` from
//!   frame 60, sphere-mesh tracker: 2.79 → 22.27 mm; from frame 165 7.71 → 33.60 mm), though
//!   most cold starts gained.
//!
//! Measured as it is (smoothing from the 31st frame of noisy sequences), mean keypoint error:
//! - 74 ToF cold starts (the library's motions and random subjects cut at frames 45–250),
//!   summed: sphere-mesh tracker 236.49 → 219.83 mm (63 cuts better, 6 worse, median −0.19
//!   mm), with online calibration 233.83 → 226.07 mm (50 better, 9 worse), the Ch. 2
//!   cylinders 425.15 → 406.03 mm (46 better, 15 worse);
//! - the library's 16 ToF motions from frame 0 (all but `leave_reenter`), summed: sphere-mesh
//!   17.31 → 13.54 mm, online calibration 20.65 → 18.79 mm, cylinders 32.89 → 31.55 mm;
//! - noise-free sequences: unchanged (not smoothed).
//!
//! What it costs: the online estimate of the shape does not gain. On the six random subjects
//! of issue 8 under ToF (`eval/tests/ch4_acceptance.rs`, `subject_ratios`) E_β ends at 0.31–0.42
//! mm (0.30–0.42 raw), and since tracking with each subject's true template gains more, the
//! ratio of online to true-template keypoint error rises from 1.31 / 1.10 / 1.05 / 1.36 / 1.13
//! / 1.36 to 1.57 / 1.25 / 1.09 / 1.78 / 1.20 / 1.59. A 5×5 window smoothed more (ToF teaser
//! 0.65 against 0.70 mm) but its curvature bias cost exact depth (0.19 → 0.35 mm), so the
//! default radius is 1.

use crate::image::{DepthImage, Mask};

/// Settings of [`smooth_depth`].
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SmoothParams {
    /// Window radius (px): the window is `(2·radius + 1)²`, and so is the cost a pixel; 0
    /// leaves the depth as it is.
    pub radius: u32,
    /// Neighbours deeper or shallower than this (mm) are left out of a pixel's mean: more than
    /// the noise (a ToF pixel's ±3σ at 40 cm), less than a finger's depth step in front of the
    /// palm or another finger.
    pub range: f64,
    /// The preprocessor smooths a sequence's frames only while the depth noise it measures
    /// ([`super::NoiseMonitor`], as the trackers do) is at least this (mm; ≤ 0: always): as the
    /// trackers' along-ray registration, a remedy for noisy depth that exact or quantized depth
    /// does without (module docs).
    pub min_noise: f64,
    /// The first this many frames of a sequence are not smoothed: a tracker's cold start
    /// converges from its placement on the raw depth where it stayed stuck on the smoothed one
    /// (module docs).
    pub after_frames: usize,
}

impl Default for SmoothParams {
    fn default() -> Self {
        Self {
            radius: 1,
            range: 15.0,
            min_noise: 1.5,
            after_frames: 30,
        }
    }
}

/// Smooths the depth of the pixels of `mask` (module docs) into `out`, in the depth image's
/// units as `f64` (sub-unit means kept); pixels outside the mask or without depth get 0. `unit_mm`
/// is the depth unit in mm (for `range`). A mask of another size than the depth (or images
/// whose data do not fill their size), or a non-finite or non-positive unit, gives the depth
/// unchanged.
pub fn smooth_depth(
    depth: &DepthImage,
    mask: &Mask,
    params: &SmoothParams,
    unit_mm: f64,
    out: &mut Vec<f64>,
) {
    let (w, h) = (depth.width as usize, depth.height as usize);
    out.clear();
    out.resize(depth.data.len(), 0.0);
    let member = |i: usize| mask.data[i] != 0 && depth.data[i] != 0;
    let sized = mask.width == depth.width
        && mask.height == depth.height
        && mask.data.len() == depth.data.len()
        && depth.data.len() == w * h;
    if !(sized && unit_mm.is_finite() && unit_mm > 0.0) || params.radius == 0 {
        for (i, o) in out.iter_mut().enumerate() {
            if !sized || member(i) {
                *o = f64::from(depth.data[i]);
            }
        }
        return;
    }
    let r = params.radius as i64;
    let range = params.range / unit_mm;
    let (wi, hi) = (w as i64, h as i64);
    let usable = |u: i64, v: i64, c: f64| {
        let j = (v * wi + u) as usize;
        (u >= 0 && v >= 0 && u < wi && v < hi && member(j))
            .then(|| f64::from(depth.data[j]))
            .filter(|d| (d - c).abs() <= range)
    };
    for v in 0..hi {
        for u in 0..wi {
            let i = (v * wi + u) as usize;
            if !member(i) {
                continue;
            }
            let c = f64::from(depth.data[i]);
            let (mut sum, mut n) = (c, 1.0);
            // Half the window's offsets, each with its mirror: a neighbour counts only with its
            // mirror, so that the mean of a tilted surface is its center's depth even where the
            // window reaches past the outline (one-sided, it was pulled toward the inside).
            for dy in 0..=r {
                for dx in -r..=r {
                    if dy == 0 && dx <= 0 {
                        continue;
                    }
                    if let (Some(a), Some(b)) =
                        (usable(u + dx, v + dy, c), usable(u - dx, v - dy, c))
                    {
                        sum += a + b;
                        n += 2.0;
                    }
                }
            }
            out[i] = sum / n;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: u32, h: u32, f: impl Fn(u32, u32) -> u16) -> DepthImage {
        let mut d = DepthImage::zeros(w, h);
        for v in 0..h {
            for u in 0..w {
                d.data[(v * w + u) as usize] = f(u, v);
            }
        }
        d
    }

    fn full_mask(d: &DepthImage) -> Mask {
        let mut m = Mask::zeros(d.width, d.height);
        for (m, &z) in m.data.iter_mut().zip(&d.data) {
            *m = u8::from(z != 0);
        }
        m
    }

    /// A tilted plane is kept exactly everywhere: at the image border, along a masked-out
    /// region's edge and beside a hole, where the window is one-sided (each neighbour counts
    /// only with its mirror).
    #[test]
    fn a_tilted_plane_is_kept_up_to_its_outline() {
        let d = image(9, 7, |u, v| 400 + 2 * u as u16 + v as u16);
        let mut m = full_mask(&d);
        for v in 0..4 {
            for u in 5..9 {
                m.data[v * 9 + u] = 0;
            }
        }
        let mut holed = d.clone();
        holed.data[5 * 9 + 2] = 0;
        let mut out = Vec::new();
        smooth_depth(&holed, &m, &SmoothParams::default(), 1.0, &mut out);
        for (i, (&z, &k)) in out.iter().zip(&m.data).enumerate() {
            let expected = if k == 0 || holed.data[i] == 0 {
                0.0
            } else {
                f64::from(d.data[i])
            };
            assert!((z - expected).abs() < 1e-12, "pixel {i}: {z} vs {expected}");
        }
    }

    /// Independent noise is divided by about the window's side; a step beyond the range is
    /// not blurred; pixels outside the mask and without depth are neither smoothed nor used.
    #[test]
    fn noise_drops_and_steps_stay() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut noise = vec![0i32; 64 * 64];
        for e in &mut noise {
            *e = rng.random_range(-8..=8);
        }
        // Left half a finger at 400 mm, right half the palm 30 mm behind it.
        let d = image(64, 64, |u, v| {
            let base = if u < 32 { 400 } else { 430 };
            (base + noise[(v * 64 + u) as usize]) as u16
        });
        let mut out = Vec::new();
        smooth_depth(&d, &full_mask(&d), &SmoothParams::default(), 1.0, &mut out);
        let spread = |vals: &mut dyn Iterator<Item = f64>, mean: f64| {
            let v: Vec<f64> = vals.collect();
            (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
        };
        let inner = |u: usize, v: usize| (1..63).contains(&u) && (1..63).contains(&v);
        let left = |k: usize| k % 64 < 31;
        let right = |k: usize| k % 64 > 32;
        let raw = spread(
            &mut (0..64 * 64)
                .filter(|&k| inner(k % 64, k / 64) && left(k))
                .map(|k| f64::from(d.data[k])),
            400.0,
        );
        let smooth = spread(
            &mut (0..64 * 64)
                .filter(|&k| inner(k % 64, k / 64) && left(k))
                .map(|k| out[k]),
            400.0,
        );
        assert!(
            smooth < 0.45 * raw,
            "raw {raw:.2} mm, smoothed {smooth:.2} mm"
        );
        // Every pixel stays on its own side of the 30 mm step.
        for (k, &z) in out.iter().enumerate() {
            let base = if left(k) || k % 64 == 31 {
                400.0
            } else {
                430.0
            };
            assert!((z - base).abs() <= 8.0, "pixel {k}: {z}");
            if right(k) {
                assert!(z > 415.0);
            }
        }
        // A masked-out pixel: 0, and its neighbour leaves it out with its mirror.
        let mut m = full_mask(&d);
        m.data[5 * 64 + 5] = 0;
        let mut out2 = Vec::new();
        smooth_depth(&d, &m, &SmoothParams::default(), 1.0, &mut out2);
        assert_eq!(out2[5 * 64 + 5], 0.0);
        let i = 5 * 64 + 6;
        let expected: Vec<f64> = [4usize, 5, 6]
            .iter()
            .flat_map(|&v| [5usize, 6, 7].map(|u| v * 64 + u))
            .filter(|&j| j != 5 * 64 + 5 && j != 5 * 64 + 7)
            .map(|j| f64::from(d.data[j]))
            .collect();
        let mean = expected.iter().sum::<f64>() / expected.len() as f64;
        assert!((out2[i] - mean).abs() < 1e-9, "{} vs {mean}", out2[i]);
    }

    #[test]
    fn radius_zero_or_a_mismatched_mask_keeps_the_depth() {
        let d = image(5, 4, |u, v| 300 + (u * v) as u16);
        let mut out = Vec::new();
        let none = SmoothParams {
            radius: 0,
            ..SmoothParams::default()
        };
        smooth_depth(&d, &full_mask(&d), &none, 1.0, &mut out);
        assert!(out.iter().zip(&d.data).all(|(a, &b)| *a == f64::from(b)));
        smooth_depth(
            &d,
            &Mask::zeros(3, 3),
            &SmoothParams::default(),
            1.0,
            &mut out,
        );
        assert!(out.iter().zip(&d.data).all(|(a, &b)| *a == f64::from(b)));
        smooth_depth(
            &d,
            &full_mask(&d),
            &SmoothParams::default(),
            f64::NAN,
            &mut out,
        );
        assert!(out.iter().zip(&d.data).all(|(a, &b)| *a == f64::from(b)));
        // Data shorter than the size says: no panic, the depth as it is.
        let mut short = d.clone();
        short.data.truncate(7);
        let mask = full_mask(&d);
        smooth_depth(&short, &mask, &SmoothParams::default(), 1.0, &mut out);
        assert_eq!(out.len(), 7);
        assert!(out
            .iter()
            .zip(&short.data)
            .all(|(a, &b)| *a == f64::from(b)));
    }
}
