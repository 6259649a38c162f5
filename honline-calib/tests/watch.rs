//! The calibrator places the hand itself with a Ch. 3 tracker of the starting template, the
//! seed, which then watches it for a while (`honline_calib::watch`): on a fist seen from a cold
//! start, and on a hand that enters the view.

mod common;

use common::keypoint_error;
use hand_model::kinematics::Pose;
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::default_right_hand;
use hmodel_spheremesh::synthetic::rendered_frame;
use honline_calib::watch::SETTLE_FRAMES;
use honline_calib::{OnlineCalibrator, OnlineConfig, OnlineFrame};
use sensor_io::preprocess::PreprocessedFrame;
use sensor_io::Camera;

fn has(out: &OnlineFrame, flag: &str) -> bool {
    out.record.flags.iter().any(|f| f == flag)
}

/// A fist seen from a cold start: the seed places it as the open mean pose and converges
/// within a few frames. The calibrator follows it for [`SETTLE_FRAMES`] frames (flag
/// `settling`) and only then solves and learns; placed again later, with a shape learned, it
/// does not settle. Measured after 45 frames: 0.80 mm mean keypoint
/// error (the seed alone 0.00 mm); placed there too and solving from the first frame it bent
/// its uncertain shape to the wrong pose and held it: 0.76 mm after one restart by the watch,
/// 28.55 mm without the watch.
#[test]
fn a_fist_from_a_cold_start_is_not_calibrated_to_the_wrong_pose() {
    let t = default_right_hand();
    let prior = PcaPrior::project_default();
    let fist = Pose::from_named(
        &t.skeleton,
        [
            ("global_ry", -0.35),
            ("global_rz", 2.96),
            ("global_tx", -9.8),
            ("global_ty", 42.0),
            ("global_tz", 402.0),
            ("index_mcp_flex", 1.15),
            ("index_pip_flex", 1.32),
            ("index_dip_flex", 0.82),
            ("middle_mcp_flex", 1.08),
            ("middle_pip_flex", 1.24),
            ("middle_dip_flex", 0.75),
            ("ring_mcp_flex", 1.21),
            ("ring_pip_flex", 1.34),
            ("ring_dip_flex", 0.81),
            ("pinky_mcp_flex", 1.32),
            ("pinky_pip_flex", 1.41),
            ("pinky_dip_flex", 0.83),
            ("thumb_cmc_abd", 0.15),
            ("thumb_cmc_flex", 0.8),
            ("thumb_mcp_flex", 0.59),
            ("thumb_ip_flex", 0.34),
        ],
    )
    .unwrap();
    let frame = rendered_frame(&t, &fist, &Camera::sr300_qvga(), 2500).unwrap();
    let mut calib = OnlineCalibrator::new(&t, OnlineConfig::default(), Some(&prior)).unwrap();
    let mut seed = hmodel_spheremesh::Tracker::new(&t, Default::default(), Some(&prior)).unwrap();
    let (mut resets, mut last, mut seed_last) = (0, 0.0, 0.0);
    for f in 0..45 {
        let out = calib.track(&frame, f, f as f64 / 30.0);
        assert_eq!(has(&out, "reinitialized"), f == 0, "frame {f}");
        assert_eq!(has(&out, "settling"), f < SETTLE_FRAMES as u64, "frame {f}");
        assert_eq!(out.solved, f >= SETTLE_FRAMES as u64, "frame {f}");
        resets += usize::from(has(&out, "shape_reset"));
        last = keypoint_error(&out.record, &t, &fist);
        seed_last = keypoint_error(&seed.track(&frame, f, f as f64 / 30.0), &t, &fist);
    }
    println!(
        "fist from a cold start, 45 frames: online {last:.2} mm ({resets} reset), the Ch. 3 tracker {seed_last:.2} mm"
    );
    assert!(last < seed_last + 2.0, "{last} mm, {resets} resets");
    // A placement after a frame without a hand keeps the shape learned so far: no settling.
    let away = calib.track(&PreprocessedFrame::default(), 45, 1.5);
    assert_eq!(away.record.flags, ["no_hand"]);
    let back = calib.track(&frame, 46, 1.5);
    assert!(has(&back, "reinitialized") && !has(&back, "settling") && back.solved);
}

/// The hand slides up into the view from below the image over 8 frames and then holds still.
/// The first placement is made on the fingers (> 20 mm off); the seed finds the hand and the
/// calibrator ends where it is (0.31 mm; 16.28 mm with the watch off and no settling, when the
/// calibrator bent its shape to the first placement). A caller's pose
/// ([`OnlineCalibrator::set_pose`]) ends the watch.
#[test]
fn a_hand_entering_the_view_is_found() {
    let t = default_right_hand();
    let prior = PcaPrior::project_default();
    let camera = Camera::sr300_qvga();
    let ty = t.skeleton.dof_index("global_ty").unwrap();
    let truth = |k: usize| {
        let mut p =
            Pose::from_named(&t.skeleton, [("global_tz", 400.0), ("global_ty", 30.0)]).unwrap();
        p.values[ty] += 120.0 * 8usize.saturating_sub(k) as f64 / 8.0;
        p
    };
    let mut calib = OnlineCalibrator::new(&t, OnlineConfig::default(), Some(&prior)).unwrap();
    let mut errors = Vec::new();
    for k in 0..40usize {
        let frame = rendered_frame(&t, &truth(k), &camera, 1500).unwrap();
        let out = calib.track(&frame, k as u64, 0.0);
        errors.push(keypoint_error(&out.record, calib.template(), &truth(k)));
    }
    let first = errors[0];
    let end = errors.last().copied().unwrap();
    println!("a hand entering the view: first frame {first:.2} mm, last {end:.2} mm");
    assert!(first > 20.0, "the first placement sees only the fingers");
    assert!(end < 2.0, "found: {end:.2} mm");

    let mut calib = OnlineCalibrator::new(&t, OnlineConfig::default(), Some(&prior)).unwrap();
    let frame = rendered_frame(&t, &truth(8), &camera, 1500).unwrap();
    let seeded = |out: &OnlineFrame| out.record.timing_us.contains_key("seed");
    assert!(seeded(&calib.track(&frame, 0, 0.0)));
    assert!(seeded(&calib.track(&frame, 1, 0.0)), "the seed watches");
    calib.set_pose(&truth(8)).unwrap();
    let out = calib.track(&frame, 2, 0.0);
    assert!(!seeded(&out) && out.record.flags.is_empty());
}
