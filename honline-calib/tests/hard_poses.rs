//! Online calibration while its belief is still vague, in a pose that shows little of the
//! hand's shape: a fist seen edge-on, the palm's width along the camera's rays and the folded
//! fingers hiding each other (the pose of the library's `occlusion` motion at its 145th frame,
//! where online calibration started at its 105th frame went up to 24 mm off before session 30).

mod common;

use common::keypoint_error;
use hand_model::kinematics::Pose;
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::{default_right_hand, ShapeBasis};
use hmodel_spheremesh::synthetic::rendered_frame;
use honline_calib::{OnlineCalibrator, OnlineConfig};
use sensor_io::Camera;

/// The default hand is the subject, so whatever the shape learns is error. Placed at the true
/// pose, 90 frames of the same edge-on fist: measured, the largest β change 5.07 mm and the
/// keypoints at most 1.68 mm off; with the β damping at 10 (before session 30, `OnlineConfig::
/// beta_damping`) the shape swung by up to 30 mm between frames and the keypoints went 19.8 mm
/// off (100: 8.4 and 2.9 mm).
#[test]
fn an_edge_on_fist_from_a_cold_start_keeps_its_shape() {
    let t = default_right_hand();
    let prior = PcaPrior::project_default();
    let fist = Pose::from_named(
        &t.skeleton,
        [
            ("global_rx", 0.13),
            ("global_ry", 1.53),
            ("global_rz", 3.16),
            ("global_tx", 0.27),
            ("global_ty", 42.33),
            ("global_tz", 410.01),
            ("index_mcp_flex", 1.41),
            ("index_pip_flex", 1.61),
            ("index_dip_flex", 1.00),
            ("middle_mcp_flex", 1.41),
            ("middle_pip_flex", 1.60),
            ("middle_dip_flex", 0.97),
            ("ring_mcp_flex", 1.41),
            ("ring_pip_flex", 1.55),
            ("ring_dip_flex", 0.94),
            ("pinky_mcp_abd", 0.08),
            ("pinky_mcp_flex", 1.46),
            ("pinky_pip_flex", 1.56),
            ("pinky_dip_flex", 0.93),
            ("thumb_cmc_abd", 0.15),
            ("thumb_cmc_flex", 0.99),
            ("thumb_mcp_flex", 0.69),
            ("thumb_ip_flex", 0.40),
        ],
    )
    .unwrap();
    let frame = rendered_frame(&t, &fist, &Camera::sr300_qvga(), 2500).unwrap();
    let config = OnlineConfig::default();
    let mut calib = OnlineCalibrator::new(&t, config, Some(&prior)).unwrap();
    calib.set_pose(&fist).unwrap();
    let template = ShapeBasis::honline(&t).unwrap().template_values();
    let (mut worst_shape, mut worst_error) = (0.0f64, 0.0f64);
    for f in 0..90 {
        let out = calib.track(&frame, f, f as f64 / 30.0);
        let shape = out
            .beta
            .iter()
            .zip(&template)
            .map(|(b, t)| (b - t).abs())
            .fold(0.0, f64::max);
        let error = keypoint_error(&out.record, &t, &fist);
        assert!(shape.is_finite() && error.is_finite(), "frame {f}");
        worst_shape = worst_shape.max(shape);
        worst_error = worst_error.max(error);
        if f % 10 == 0 {
            println!("frame {f}: keypoints {error:.2} mm, largest β change {shape:.2} mm");
        }
    }
    println!("worst: keypoints {worst_error:.2} mm, β change {worst_shape:.2} mm");
    assert!(worst_error < 2.5, "keypoints {worst_error} mm off");
    assert!(worst_shape < 7.5, "β moved {worst_shape} mm");
}
