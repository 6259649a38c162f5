//! Calibration guidance (thesis §5.2, "Feedback for Hand Calibration"; no published system has
//! it): which shape parameters are still uncertain, and which pose the user should show next so
//! that the data constrain them most.
//!
//! For every candidate pose (e.g. the pose prior's corpus), the current template is rendered at
//! it (the frame the sensor would see, [`hmodel_spheremesh::synthetic::rendered_frame`]) and the
//! information that frame would bring is linearized there
//! ([`OnlineCalibrator::expected_information`], Eq. 4.5). The expected gain on the `targets`
//! least-certain parameters `T` is `Σ_{i∈T} ln(1 + ΔH_ii / Ĥ_ii)`: the log of the factor by which
//! each one's certainty (information-matrix diagonal) would grow, summed — a diagonal form of the
//! information gain `½ ln det(I + Σ̂_T ΔH_T)`, which favours poses that help the weakest
//! parameters rather than those already known.

use hand_model::kinematics::Pose;
use hmodel_spheremesh::synthetic::rendered_frame;
use sensor_io::Camera;

use crate::OnlineCalibrator;

/// The outcome of [`guide`].
#[derive(Clone, Debug, PartialEq)]
pub struct Guidance {
    /// The least-certain active shape parameters, weakest first: `(β index, name, certainty per
    /// mm²)`.
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
/// expected information gain on the `targets` least-certain shape parameters (module docs).
/// `None` without candidates or when no candidate can be rendered and linearized.
pub fn guide(
    calib: &mut OnlineCalibrator,
    candidates: &[Pose],
    camera: &Camera,
    targets: usize,
) -> Option<Guidance> {
    let active = calib.layout().active.clone();
    let certainty = calib.belief().certainty();
    let mut order: Vec<usize> = (0..active.len()).collect();
    order.sort_by(|&a, &b| certainty[a].total_cmp(&certainty[b]));
    order.truncate(targets.max(1));
    let names: Vec<String> = calib.basis().names().map(str::to_string).collect();
    let weakest = order
        .iter()
        .map(|&j| (active[j], names[active[j]].clone(), certainty[j]))
        .collect();
    let floor = 1e-9;
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
        any = true;
        *gain = order
            .iter()
            .map(|&j| (h[(j, j)] / certainty[j].max(floor)).ln_1p())
            .sum();
    }
    let best = (0..gains.len()).max_by(|&a, &b| gains[a].total_cmp(&gains[b]))?;
    any.then_some(Guidance {
        weakest,
        best,
        gains,
    })
}
