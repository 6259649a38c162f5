//! Marker (keypoint) metrics (DESIGN.md "Metrics"; thesis §3.5 "Quantitative comparison",
//! Fig. 3.14/4.13): per frame the average and the maximum Euclidean error over the markers, and
//! the fraction of frames whose error is under a threshold ε.

/// The errors of one frame over its markers (mm).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct FrameError {
    /// Mean over the markers.
    pub mean: f64,
    /// Maximum over the markers.
    pub max: f64,
}

/// The errors of one frame between estimated and true markers (same order, camera frame, mm);
/// `None` when the counts differ, there are no markers, or any coordinate is not finite.
pub fn frame_error(estimate: &[[f64; 3]], truth: &[[f64; 3]]) -> Option<FrameError> {
    if estimate.len() != truth.len() || truth.is_empty() {
        return None;
    }
    let (mut sum, mut max) = (0.0, 0.0f64);
    for (a, b) in estimate.iter().zip(truth) {
        let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
        if !d.is_finite() {
            return None;
        }
        sum += d;
        max = max.max(d);
    }
    Some(FrameError {
        mean: sum / truth.len() as f64,
        max,
    })
}

/// The fraction of `values` that are `< epsilon` (0 for an empty list).
pub fn fraction_under(values: &[f64], epsilon: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.iter().filter(|&&v| v < epsilon).count() as f64 / values.len() as f64
}

/// The curve `ε ↦ fraction of values < ε` sampled at `epsilons` (the papers' "% frames with
/// error < ε" plots).
pub fn under_curve(values: &[f64], epsilons: &[f64]) -> Vec<f64> {
    epsilons
        .iter()
        .map(|&e| fraction_under(values, e))
        .collect()
}

/// The median of `values` (NaN for an empty list; the upper median for even lengths).
pub fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// The mean of `values` (NaN for an empty list).
pub fn mean(values: &[f64]) -> f64 {
    if values.is_empty() {
        f64::NAN
    } else {
        values.iter().sum::<f64>() / values.len() as f64
    }
}

/// Summary of a sequence's marker errors.
#[derive(Clone, Debug, PartialEq)]
pub struct MarkerSummary {
    /// Frames with an error.
    pub frames: usize,
    /// Mean over frames of the per-frame mean error (mm).
    pub mean: f64,
    /// Median over frames of the per-frame mean error (mm).
    pub median: f64,
    /// Mean over frames of the per-frame maximum error (mm).
    pub mean_max: f64,
    /// Fraction of frames whose maximum error is < 25 mm.
    pub frac_max_under_25: f64,
}

impl MarkerSummary {
    /// Summarize per-frame errors.
    pub fn new(errors: &[FrameError]) -> Self {
        let means: Vec<f64> = errors.iter().map(|e| e.mean).collect();
        let maxes: Vec<f64> = errors.iter().map(|e| e.max).collect();
        Self {
            frames: errors.len(),
            mean: mean(&means),
            median: median(&means),
            mean_max: mean(&maxes),
            frac_max_under_25: fraction_under(&maxes, 25.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_error_by_hand() {
        let a = [[0.0, 0.0, 0.0], [1.0, 2.0, 2.0]];
        let b = [[3.0, 4.0, 0.0], [1.0, 2.0, 2.0]];
        let e = frame_error(&a, &b).unwrap();
        assert_eq!(e.mean, 2.5);
        assert_eq!(e.max, 5.0);
        assert!(frame_error(&a, &b[..1]).is_none());
        assert!(frame_error(&[], &[]).is_none());
        assert!(frame_error(&[[f64::NAN, 0.0, 0.0]], &[[0.0; 3]]).is_none());
    }

    #[test]
    fn fractions_and_medians() {
        let v = [1.0, 5.0, 30.0, 24.9];
        assert_eq!(fraction_under(&v, 25.0), 0.75);
        assert_eq!(under_curve(&v, &[0.0, 2.0, 100.0]), vec![0.0, 0.25, 1.0]);
        assert_eq!(median(&v), 24.9);
        assert!(median(&[]).is_nan());
        let s = MarkerSummary::new(&[
            FrameError {
                mean: 2.0,
                max: 10.0,
            },
            FrameError {
                mean: 4.0,
                max: 30.0,
            },
        ]);
        assert_eq!((s.mean, s.mean_max, s.frac_max_under_25), (3.0, 20.0, 0.5));
    }
}
