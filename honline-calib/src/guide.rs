//! Calibration guidance (thesis §5.2, "Feedback for Hand Calibration"; no published system has
//! it): which shape parameters are still uncertain, and which pose the user should show next so
//! that the data constrain them most.
//!
//! For every candidate pose (e.g. the pose prior's corpus), the current template is rendered at
//! it (the frame the sensor would see, [`hmodel_spheremesh::synthetic::rendered_frame`]) and the
//! information that frame would bring is linearized there
//! ([`OnlineCalibrator::expected_information`], Eq. 4.5). The `targets` least-certain parameters
//! `T` are those of lowest *marginal* certainty `1 / Σ̂_ii` (two phalanges of a straight finger
//! are weak apart even when their sum is known); a candidate's expected gain is the mutual
//! information it brings about them, `½ ln det Σ̂_TT − ½ ln det Σ'_TT` with
//! `Σ' = (Σ̂⁻¹ + ΔH)⁻¹` — correlations included, so a pose that only tells the sum of two
//! lengths again gains little.

use hand_model::kinematics::Pose;
use hmodel_spheremesh::synthetic::rendered_frame;
use nalgebra::DMatrix;
use sensor_io::Camera;

use crate::OnlineCalibrator;

/// The outcome of [`guide`].
#[derive(Clone, Debug, PartialEq)]
pub struct Guidance {
    /// The least-certain active shape parameters, weakest first: `(β index, name, marginal
    /// certainty 1/Σ̂_ii per mm²)`.
    pub weakest: Vec<(usize, String, f64)>,
    /// Index of the candidate with the largest expected gain.
    pub best: usize,
    /// Per candidate its expected gain (0 where the candidate could not be rendered or
    /// linearized).
    pub gains: Vec<f64>,
}

/// Points of a candidate's rendered frame.
const POINTS: usize = 1500;

/// Rank `candidates` (poses of the calibrator's skeleton, placed in front of `camera`) by the
/// expected information gain (nats) on the `targets` least-certain shape parameters (module
/// docs).
/// `None` without candidates or when no candidate can be rendered and linearized.
pub fn guide(
    calib: &mut OnlineCalibrator,
    candidates: &[Pose],
    camera: &Camera,
    targets: usize,
) -> Option<Guidance> {
    let active = calib.layout().active.clone();
    let information = calib.belief().information.clone();
    let marginal = calib.belief().marginal_certainty();
    let mut order: Vec<usize> = (0..active.len()).collect();
    order.sort_by(|&a, &b| marginal[a].total_cmp(&marginal[b]));
    order.truncate(targets.max(1));
    let names: Vec<String> = calib.basis().names().map(str::to_string).collect();
    let weakest = order
        .iter()
        .map(|&j| (active[j], names[active[j]].clone(), marginal[j]))
        .collect();
    let before = target_log_det(&information, &order)?;
    let mut gains = vec![0.0; candidates.len()];
    let mut any = false;
    for (gain, pose) in gains.iter_mut().zip(candidates) {
        let template = calib.template().clone();
        let Ok(frame) = rendered_frame(&template, pose, camera, POINTS) else {
            continue;
        };
        let Some(h) = calib.expected_information(&frame, pose) else {
            continue;
        };
        let Some(after) = target_log_det(&(&information + h), &order) else {
            continue;
        };
        any = true;
        *gain = 0.5 * (before - after);
    }
    let best = (0..gains.len()).max_by(|&a, &b| gains[a].total_cmp(&gains[b]))?;
    any.then_some(Guidance {
        weakest,
        best,
        gains,
    })
}

/// `ln det Σ_TT` of the covariance `Σ = H⁻¹` restricted to the `targets`; `None` when `H` is not
/// positive definite.
fn target_log_det(information: &DMatrix<f64>, targets: &[usize]) -> Option<f64> {
    let sigma = information.clone().cholesky()?.inverse();
    let n = targets.len();
    let block = DMatrix::from_fn(n, n, |a, b| sigma[(targets[a], targets[b])]);
    let chol = block.cholesky()?;
    let l = chol.l_dirty();
    let log_det = 2.0 * (0..n).map(|i| l[(i, i)].ln()).sum::<f64>();
    log_det.is_finite().then_some(log_det)
}
