//! [`Tracker::search_digits`], the digit search a caller with its own frame loop (online
//! calibration) runs through a tracker of its current template, and
//! [`Tracker::challenge`], which confirms its candidate on later frames: on a rendered frame
//! whose index is curled and middle finger open, a start with the two exchanged is mended, and
//! the true pose is left alone.

use hand_model::kinematics::Pose;
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::{default_right_hand, PosedSphereMesh, SphereMeshTemplate};
use hmodel_spheremesh::synthetic::rendered_frame;
use hmodel_spheremesh::{Tracker, TrackerConfig};
use sensor_io::Camera;

const FLEXIONS: [&str; 3] = ["mcp", "pip", "dip"];

/// A pose at 400 mm with `curled`'s three flexions at 1.1 rad and the other fingers open.
fn pose_curling(t: &SphereMeshTemplate, curled: &str) -> Pose {
    let mut pose = Pose::from_named(&t.skeleton, [("global_tz", 400.0), ("global_ty", 30.0)])
        .expect("a valid pose");
    for f in FLEXIONS {
        let i = t.skeleton.dof_index(&format!("{curled}_{f}_flex")).unwrap();
        pose.values[i] = 1.1;
    }
    pose
}

fn mean_keypoint_error(t: &SphereMeshTemplate, a: &Pose, b: &Pose) -> f64 {
    let (ka, kb) = (
        PosedSphereMesh::new(t, a).keypoints(t),
        PosedSphereMesh::new(t, b).keypoints(t),
    );
    ka.iter().zip(&kb).map(|(p, q)| (p - q).norm()).sum::<f64>() / ka.len() as f64
}

#[test]
fn the_search_mends_two_exchanged_fingers_and_keeps_a_good_pose() {
    let t = default_right_hand();
    let truth = pose_curling(&t, "index");
    let exchanged = pose_curling(&t, "middle");
    let frame = rendered_frame(&t, &truth, &Camera::sr300_qvga(), 2500).unwrap();
    let prior = PcaPrior::project_default();
    let mut tracker = Tracker::new(&t, TrackerConfig::default(), Some(&prior)).unwrap();

    let before = mean_keypoint_error(&t, &exchanged, &truth);
    let (mended, stats) = tracker
        .search_digits(&frame, &exchanged, None)
        .expect("a variant fits better than the exchanged fingers");
    assert!(stats.mean_distance < 1.0, "{stats:?}");
    let after = mean_keypoint_error(&t, &mended, &truth);
    println!("mean keypoint error: exchanged start {before:.2} mm, after the search {after:.2} mm");
    assert!(
        before > 15.0,
        "the start is not wrong enough: {before:.2} mm"
    );
    assert!(after < 3.0, "not mended: {after:.2} mm");

    assert_eq!(tracker.search_digits(&frame, &truth, None), None);
    // A candidate from an earlier frame: it must fit this one better than the tracked pose.
    let (won, _) = tracker
        .challenge(&frame, &exchanged, &mended, None)
        .expect("the mended pose beats the exchanged fingers");
    assert!(mean_keypoint_error(&t, &won, &truth) < 3.0);
    assert_eq!(tracker.challenge(&frame, &truth, &exchanged, None), None);
    let wrong_length = Pose {
        values: vec![0.0; 3],
    };
    assert_eq!(tracker.search_digits(&frame, &wrong_length, None), None);
    assert_eq!(tracker.challenge(&frame, &truth, &wrong_length, None), None);
}
