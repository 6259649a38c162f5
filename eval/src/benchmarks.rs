//! Published benchmark numbers recomputed from published per-frame outputs (issue 7, item 3),
//! with the marker metrics of [`crate::markers`] (thesis §3.5, §4.4.4; Taylor 2016 §4.1
//! "Marker Error"):
//!
//! - **NYU** (Tompson et al. 2014): the mean 3D joint error of 14-joint predictions against the
//!   test ground truth, both uvd files converted to mm with the NYU intrinsics
//!   ([`datasets::nyu`]); per frame the mean and maximum over the 14 joints;
//! - **Dexter-1** (Sridhar et al. 2013): htrack's fingertip error per sequence, output row `i`
//!   against ground-truth frame `i`, unannotated frames (values > 1000) dropped, ground-truth x
//!   negated ([`datasets::dexter`]); the published numbers are the mean and the median over the
//!   individual fingertip errors.

use std::path::Path;

use datasets::dexter::{
    fingertips_for_htrack, htrack_fingertips, is_annotated, read_ground_truth, read_htrack_output,
    DexterFrame, HtrackJoints, DEXTER_FINGERTIPS,
};
use datasets::nyu::{read_xyz_labels, NyuJoints};

use crate::error::{EvalError, Result};
use crate::markers::{frame_error, mean, median, FrameError};

/// Per frame the joint errors of `predictions` against `truth` (same frame count, camera frame,
/// mm). Refused: different frame counts (both named).
pub fn nyu_frame_errors(predictions: &[NyuJoints], truth: &[NyuJoints]) -> Result<Vec<FrameError>> {
    if predictions.len() != truth.len() {
        return Err(EvalError::arg(
            "predictions",
            format!(
                "{} frames of predictions for {} frames of ground truth",
                predictions.len(),
                truth.len()
            ),
        ));
    }
    predictions
        .iter()
        .zip(truth)
        .enumerate()
        .map(|(k, (p, t))| {
            frame_error(p, t)
                .ok_or_else(|| EvalError::arg("predictions", format!("frame {k} is not finite")))
        })
        .collect()
}

/// [`nyu_frame_errors`] of a predictions file against a ground-truth file (both 14-joint uvd).
pub fn nyu_file_errors(predictions: &Path, truth: &Path) -> Result<Vec<FrameError>> {
    nyu_frame_errors(&read_xyz_labels(predictions)?, &read_xyz_labels(truth)?)
}

/// The fingertip errors of one Dexter-1 sequence: for every output row `i` whose ground-truth
/// frame `i` is annotated, the 5 distances (mm) between htrack's fingertips and the
/// ground-truth fingertips with x negated. Refused: more output rows than ground-truth frames.
pub fn dexter_fingertip_errors(
    output: &[HtrackJoints],
    truth: &[DexterFrame],
) -> Result<Vec<[f64; DEXTER_FINGERTIPS]>> {
    if output.len() > truth.len() {
        return Err(EvalError::arg(
            "output",
            format!(
                "{} output rows for {} ground-truth frames",
                output.len(),
                truth.len()
            ),
        ));
    }
    Ok(output
        .iter()
        .zip(truth)
        .filter(|(_, t)| is_annotated(t))
        .map(|(o, t)| {
            let (est, gt) = (htrack_fingertips(o), fingertips_for_htrack(t));
            std::array::from_fn(|k| {
                (0..3)
                    .map(|c| (est[k][c] - gt[k][c]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
        })
        .collect())
}

/// The Dexter-1 fingertip score of one method over several sequences.
#[derive(Clone, Debug, PartialEq)]
pub struct DexterScore {
    /// Annotated frames scored.
    pub frames: usize,
    /// Mean fingertip error (mm; over all fingertips = over frames of the per-frame mean).
    pub mean: f64,
    /// Median over the individual fingertip errors (mm), the published "median".
    pub median_tip: f64,
    /// Median over frames of the per-frame mean error (mm).
    pub median_frame: f64,
    /// Per frame the mean and maximum over the 5 fingertips.
    pub frame_errors: Vec<FrameError>,
}

impl DexterScore {
    /// Summarize per-frame fingertip errors; `None` without frames.
    pub fn new(errors: &[[f64; DEXTER_FINGERTIPS]]) -> Option<Self> {
        if errors.is_empty() {
            return None;
        }
        let tips: Vec<f64> = errors.iter().flatten().copied().collect();
        let frame_errors: Vec<FrameError> = errors
            .iter()
            .map(|e| FrameError {
                mean: mean(e),
                max: e.iter().copied().fold(0.0, f64::max),
            })
            .collect();
        let means: Vec<f64> = frame_errors.iter().map(|e| e.mean).collect();
        Some(Self {
            frames: errors.len(),
            mean: mean(&tips),
            median_tip: median(&tips),
            median_frame: median(&means),
            frame_errors,
        })
    }
}

/// Score a method's Dexter-1 outputs: `root/groundtruth/<seq>.txt` against
/// `root/<method>/<seq>.txt` for every sequence of `sequences`. Refused: a missing or corrupt
/// file (named), a sequence with more output rows than ground truth, no annotated frame.
pub fn dexter_score(root: &Path, method: &str, sequences: &[&str]) -> Result<DexterScore> {
    let mut all = Vec::new();
    for seq in sequences {
        let truth = read_ground_truth(&root.join("groundtruth").join(format!("{seq}.txt")))?;
        let output = read_htrack_output(&root.join(method).join(format!("{seq}.txt")))?;
        all.extend(dexter_fingertip_errors(&output, &truth)?);
    }
    DexterScore::new(&all).ok_or_else(|| EvalError::arg("sequences", "no annotated frame"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nyu_errors_by_hand_and_mismatched_counts() {
        let mut truth = [[0.0; 3]; 14];
        truth[3] = [1.0, 1.0, 1.0];
        let mut pred = truth;
        pred[0] = [3.0, 4.0, 0.0];
        let e = nyu_frame_errors(&[pred, truth], &[truth, truth]).unwrap();
        assert_eq!(e[0].max, 5.0);
        assert!((e[0].mean - 5.0 / 14.0).abs() < 1e-12);
        assert_eq!(e[1].mean, 0.0);
        let err = nyu_frame_errors(&[pred], &[truth, truth]).unwrap_err();
        assert!(
            err.to_string().contains("1 frames of predictions for 2"),
            "{err}"
        );
    }

    #[test]
    fn dexter_pairs_rows_negates_x_and_drops_unannotated_frames() {
        let mut out = [[0.0; 3]; 24];
        out[7] = [-10.0, 0.0, 300.0]; // joint 8 = fingertip 0
        out[23] = [0.0, 3.0, 300.0];
        let mut gt: DexterFrame = [[0.0, 0.0, 300.0]; 6];
        gt[0] = [10.0, 0.0, 300.0]; // x negated → matches exactly
        let mut invalid = gt;
        invalid[5] = [2000.0, 0.0, 0.0];
        let e = dexter_fingertip_errors(&[out, out], &[gt, invalid]).unwrap();
        assert_eq!(e.len(), 1);
        // Fingertip 1 is 3 mm off; 2..5 sit at the origin, 300 mm from the ground truth.
        assert_eq!(e[0][..2], [0.0, 3.0]);
        assert_eq!(e[0][2], 300.0);
        assert!(dexter_fingertip_errors(&[out, out], &[gt]).is_err());
        let s = DexterScore::new(&[[1.0, 2.0, 3.0, 4.0, 100.0], [1.0; 5]]).unwrap();
        assert_eq!(
            (s.frames, s.median_tip, s.frame_errors[0].max),
            (2, 1.0, 100.0)
        );
        assert_eq!(s.mean, 11.5);
        assert!(DexterScore::new(&[]).is_none());
    }
}
