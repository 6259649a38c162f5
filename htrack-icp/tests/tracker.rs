//! The tracking loop on hand-made frames: convergence from a perturbed pose and from scratch,
//! and bad input (empty frames, NaN and absurd points) never giving a non-finite record.

use hand_model::cylinder::{default_right_hand_cylinders, CylinderModel};
use hand_model::kinematics::Pose;
use htrack_icp::synthetic::{qvga_camera, upright_pose, visible_surface_points};
use htrack_icp::{Tracker, TrackerConfig};
use nalgebra::Vector3;
use sensor_io::preprocess::PreprocessedFrame;
use sensor_io::record::HandRecord;

/// A preprocessed frame holding only the visible points of the posed model.
fn frame_of(model: &CylinderModel, pose: &Pose) -> PreprocessedFrame {
    let posed = model.posed(pose).unwrap();
    PreprocessedFrame {
        points: visible_surface_points(model, &posed, &qvga_camera(), 2, 0.5),
        ..PreprocessedFrame::default()
    }
}

fn mean_keypoint_error(rec: &HandRecord, model: &CylinderModel, truth: &Pose) -> f64 {
    let k = model.keypoints(&model.posed(truth).unwrap());
    rec.keypoints
        .iter()
        .zip(k.iter())
        .map(|(a, b)| (Vector3::from(*a) - b).norm())
        .sum::<f64>()
        / k.len() as f64
}

#[test]
fn converges_from_a_perturbed_warm_start() {
    let model = default_right_hand_cylinders();
    let truth = upright_pose(&model).expect("valid pose");
    let frame = frame_of(&model, &truth);
    assert!(frame.points.len() > 500, "{} points", frame.points.len());
    let mut tracker = Tracker::new(&model, TrackerConfig::default(), None).unwrap();
    let mut start = truth.clone();
    for (name, d) in [
        ("global_tx", 8.0),
        ("global_tz", -10.0),
        ("index_mcp_flex", 0.25),
        ("ring_mcp_flex", -0.3),
    ] {
        start.values[model.skeleton.dof_index(name).unwrap()] += d;
    }
    tracker.set_pose(&start).unwrap();
    let before = {
        let k0 = model.keypoints(&model.posed(&start).unwrap());
        let k1 = model.keypoints(&model.posed(&truth).unwrap());
        k0.iter().zip(&k1).map(|(a, b)| (a - b).norm()).sum::<f64>() / 21.0
    };
    let mut rec = HandRecord::default();
    for i in 0..3 {
        rec = tracker.track(&frame, i, i as f64 / 60.0);
    }
    let after = mean_keypoint_error(&rec, &model, &truth);
    println!(
        "mean keypoint error {before:.2} → {after:.2} mm; flags {:?}",
        rec.flags
    );
    assert!(after < 3.0 && after < before / 4.0, "{before} → {after}");
    assert!(rec.flags.is_empty(), "{:?}", rec.flags);
    for stage in ["correspondences", "solve", "track"] {
        assert!(rec.timing_us[stage] > 0.0, "{stage} timing missing");
    }
    assert!(rec.energies["e3d"] > 0.0);
}

#[test]
fn initializes_from_scratch() {
    let model = default_right_hand_cylinders();
    let truth = upright_pose(&model).expect("valid pose");
    let frame = frame_of(&model, &truth);
    let mut tracker = Tracker::new(&model, TrackerConfig::default(), None).unwrap();
    let first = tracker.track(&frame, 0, 0.0);
    assert!(first.flags.iter().any(|f| f == "reinitialized"));
    let mut rec = first.clone();
    for i in 1..4 {
        rec = tracker.track(&frame, i, 0.0);
    }
    let err = mean_keypoint_error(&rec, &model, &truth);
    println!(
        "from scratch: mean keypoint error {err:.2} mm, flags {:?}",
        rec.flags
    );
    assert!(err < 8.0, "{err}");
}

#[test]
fn bad_frames_keep_a_valid_pose_and_are_flagged() {
    let model = default_right_hand_cylinders();
    let truth = upright_pose(&model).expect("valid pose");
    let good = frame_of(&model, &truth);
    let mut tracker = Tracker::new(&model, TrackerConfig::default(), None).unwrap();
    tracker.set_pose(&truth).unwrap();
    tracker.track(&good, 0, 0.0);

    // Empty frame: no hand, the pose is kept.
    let empty = PreprocessedFrame::default();
    let rec = tracker.track(&empty, 1, 0.0);
    assert!(rec.is_finite());
    assert_eq!(rec.flags, vec!["no_hand".to_string()]);
    assert_eq!(rec.keypoints.len(), 21);
    assert_eq!(rec.pose.len(), model.skeleton.num_dofs());

    // NaN and absurd points mixed into the cloud.
    let mut bad = good.clone();
    for (i, p) in bad.points.iter_mut().enumerate() {
        match i % 7 {
            0 => *p = Vector3::new(f64::NAN, 0.0, 400.0),
            1 => *p = Vector3::new(1e12, -1e12, 1e15),
            _ => {}
        }
    }
    for i in 2..6 {
        let rec = tracker.track(&bad, i, f64::NAN);
        assert!(rec.is_finite(), "frame {i}: {rec:?}");
        assert!(tracker.pose().values.iter().all(|v| v.is_finite()));
    }
    // Only absurd points: finite output, flagged.
    let mut absurd = good.clone();
    for p in &mut absurd.points {
        *p = Vector3::new(1e30, f64::INFINITY, -1e30);
    }
    let rec = tracker.track(&absurd, 6, 0.0);
    assert!(rec.is_finite(), "{rec:?}");
    assert!(!rec.flags.is_empty());
    // And it recovers on good data.
    let mut rec = HandRecord::default();
    for i in 7..12 {
        rec = tracker.track(&good, i, 0.0);
    }
    let err = mean_keypoint_error(&rec, &model, &truth);
    assert!(err < 8.0, "after recovery {err} mm, flags {:?}", rec.flags);
}
