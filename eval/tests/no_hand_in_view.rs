//! No hand in view (the quality bar's "no hand in view" input): the synthetic `leave_reenter`
//! motion takes the hand out of the camera's view for several seconds, leaving the wall behind
//! it (1.1 m), then brings it back. While it is away, the depth-only segmentation must find no
//! hand and both trackers, and the online calibrator used alone, must say so (`no_hand`, the
//! last pose kept) instead of fitting a hand to a patch of the wall; with the hand wholly in
//! view no frame may be `no_hand`; once it is back the trackers must find it again.
//!
//! Measured (session 27; 360 frames at 30 Hz, seed 8, 172 of them with the hand wholly out of
//! view): before the segmentation rejected surfaces, every frame out of view gave a crumpled
//! hand ≈ 700 mm deep in the wall, flagged `lost`, and the Ch. 3 tracker ended 63 mm off under
//! ToF (last 30 frames, the hand back in view). Now 1 of the 172 frames is given a hand (the
//! forearm is still in view just after the hand left), in both trackers and noise models, and
//! the last 30 frames are tracked at 1.01 / 2.23 mm (Ch. 3 / Ch. 2) under ToF and 0.34 / 7.13 mm
//! noise-free; 0.34 / 2.12 mm since session 28's second look at each placement
//! ([`hand_model::solver::RECHECK_FRAMES`]), which undid the cylinders' placement of the hand
//! entering the view with every finger shifted by one.
//!
//! The online calibrator alone (session 28) says `no_hand` as the trackers do. Placing itself
//! (once per loss window) with the Ch. 3 tracker's re-initialization at its current shape, it
//! found the returning hand under ToF (last 30 frames 1.32 mm) but not noise-free (40.45 mm):
//! it had no second look at its placements. Since session 29 it is placed and watched by a
//! Ch. 3 tracker of its starting template (`honline_calib::watch`, before only in `hands
//! track`), and must find the hand again too: last 30 frames 0.27 mm noise-free, 1.38 mm
//! under ToF.

use eval::synthetic::{SyntheticRun, SyntheticSequence, SyntheticSpec};
use hand_model::cylinder::CylinderModel;
use hand_model::solver::PcaPrior;
use nalgebra::Vector3;
use sensor_io::preprocess::{DepthOnlyParams, Segmentation};

/// The depth-only segmentation: what `--segmentation auto` falls back to where no wristband is
/// seen (a wristband segmentation finds no band, hence no hand, once the wrist is out of view).
fn sequence(noise: &str) -> SyntheticSequence {
    let mut spec = SyntheticSpec {
        motion: "leave_reenter".into(),
        noise: noise.into(),
        frames: 360,
        fps: 30.0,
        seed: 8,
        ..SyntheticSpec::default()
    };
    spec.preprocess.segmentation = Segmentation::DepthOnly(DepthOnlyParams::default());
    SyntheticSequence::new(spec).unwrap()
}

/// How many of the 21 true keypoints project inside the image, per frame.
fn keypoints_in_view(seq: &SyntheticSequence, run: &SyntheticRun) -> Vec<usize> {
    let camera = &seq.spec().camera;
    run.truth
        .iter()
        .map(|t| {
            t.keypoints
                .iter()
                .filter(|k| {
                    let q = camera.project(&Vector3::from(**k));
                    k[2] > 0.0
                        && (0.0..f64::from(camera.width)).contains(&q.x)
                        && (0.0..f64::from(camera.height)).contains(&q.y)
                })
                .count()
        })
        .collect()
}

/// (frames wholly out of view, those not flagged `no_hand`, frames wholly in view flagged
/// `no_hand`, mean keypoint error over the last 30 frames, the hand back in view).
fn score(seq: &SyntheticSequence, run: &SyntheticRun) -> (usize, usize, usize, f64) {
    assert!(run.records.iter().all(|r| r.is_finite()));
    let in_view = keypoints_in_view(seq, run);
    let no_hand = |k: usize| run.records[k].flags.iter().any(|f| f == "no_hand");
    let away: Vec<usize> = (0..in_view.len()).filter(|&k| in_view[k] == 0).collect();
    let tracked_away = away.iter().filter(|&&k| !no_hand(k)).count();
    let missed = (0..in_view.len())
        .filter(|&k| in_view[k] == 21 && no_hand(k))
        .count();
    let errors = run.mean_errors();
    let tail = &errors[errors.len() - 30..];
    assert!(
        in_view[in_view.len() - 30..].iter().all(|&n| n == 21),
        "the motion ends in view"
    );
    (
        away.len(),
        tracked_away,
        missed,
        tail.iter().sum::<f64>() / 30.0,
    )
}

/// Each frame out of view (but a few just after the hand left) `no_hand`, none in view, and the
/// last 30 frames tracked within 5 mm.
fn check(name: &str, (away, tracked_away, missed, tail): (usize, usize, usize, f64)) {
    eprintln!(
        "{name}: {away} frames out of view, {tracked_away} of them given a hand; \
         {missed} in-view frames no_hand; last 30 frames {tail:.2} mm"
    );
    assert!(
        away >= 60,
        "{name}: the hand leaves the view ({away} frames)"
    );
    // A frame or two just after the hand left still shows the forearm.
    assert!(
        tracked_away * 20 <= away,
        "{name}: {tracked_away} of {away} frames out of view were given a hand"
    );
    assert_eq!(
        missed, 0,
        "{name}: frames with the hand in view flagged no_hand"
    );
    // Found again, every finger in its place: the cylinders' placement with the fingers
    // shifted by one (7.13 mm noise-free before the second look at placements) fails here.
    assert!(tail < 5.0, "{name}: the hand is found again ({tail:.2} mm)");
}

#[test]
fn trackers_say_no_hand_while_the_hand_is_out_of_view() {
    let prior = PcaPrior::project_default();
    for noise in ["tof", "none"] {
        let mut seq = sequence(noise);
        let template = seq.template().clone();
        let mut tracker = hmodel_spheremesh::Tracker::new(
            &template,
            hmodel_spheremesh::TrackerConfig::default(),
            Some(&prior),
        )
        .unwrap();
        let run = seq
            .run(|f, t| tracker.track(f, t.frame, t.timestamp), |_| {})
            .unwrap();
        check(&format!("sphere-mesh, {noise}"), score(&seq, &run));

        let mut seq = sequence(noise);
        let model = CylinderModel::from_sphere_mesh_with_wrist(seq.template()).unwrap();
        let mut tracker =
            htrack_icp::Tracker::new(&model, htrack_icp::TrackerConfig::default(), Some(&prior))
                .unwrap();
        let run = seq
            .run(|f, t| tracker.track(f, t.frame, t.timestamp), |_| {})
            .unwrap();
        check(&format!("cylinders, {noise}"), score(&seq, &run));

        let mut seq = sequence(noise);
        let mut calib = honline_calib::OnlineCalibrator::new(
            &template,
            honline_calib::OnlineConfig::default(),
            Some(&prior),
        )
        .unwrap();
        let run = seq
            .run(|f, t| calib.track(f, t.frame, t.timestamp).record, |_| {})
            .unwrap();
        check(&format!("online calibration, {noise}"), score(&seq, &run));
    }
}
