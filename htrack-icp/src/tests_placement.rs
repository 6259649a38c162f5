//! Re-initialization's placements: the edge-on backups and this tracker's poor-placement rule
//! ([`crate::TrackerConfig::placement_outside`]).

use hand_model::cylinder::{default_right_hand_cylinders, View};
use hand_model::kinematics::Pose;
use hand_model::math::euler_xyz_to_matrix;
use hand_model::solver::PcaPrior;
use nalgebra::Vector3;

use crate::tests::target_pose;
use crate::tests_e2d::rendered_silhouette;
use crate::tests_ray::noisy_frame;
use crate::{IrlsParams, Tracker, TrackerConfig, TrackingCtx};

/// A hand first seen edge-on (turned 88° about its fingers) is placed edge-on from a cold
/// start (and has settled two frames later), and palm-on when the backups are turned off (`placement_outside` infinite). The
/// fingers behind the nearest one are hidden, so only the palm's placement is compared: its
/// rotation and the wrist and knuckle keypoints.
#[test]
fn a_hand_first_seen_edge_on_is_placed_edge_on() {
    let model = default_right_hand_cylinders();
    let sk = &model.skeleton;
    let mut truth = target_pose(&model);
    for (name, v) in [("global_rx", 0.0), ("global_ry", 1.54), ("global_rz", 3.16)] {
        truth.set(sk, name, v).unwrap();
    }
    let frame = noisy_frame(&model, &truth, 0.0, 0);
    let prior = PcaPrior::project_default();
    let rotation = |p: &Pose| {
        let g = |k: &str| p.values[sk.dof_index(k).unwrap()];
        euler_xyz_to_matrix(g("global_rx"), g("global_ry"), g("global_rz"))
    };
    let expected = model.keypoints(&model.posed(&truth).unwrap());
    let placed = |placement_outside: f64| {
        let config = TrackerConfig {
            placement_outside,
            ..TrackerConfig::default()
        };
        let mut tracker = Tracker::new(&model, config, Some(&prior)).unwrap();
        let first = tracker.track(&frame, 0, 0.0);
        assert!(
            first.flags.iter().any(|f| f == "reinitialized"),
            "{:?}",
            first.flags
        );
        // Two more frames of the same scene: the placement settles as tracking goes on.
        let rec = (1..3).fold(first, |_, i| tracker.track(&frame, i, 0.0));
        let turn = rotation(tracker.pose()).transpose() * rotation(&truth);
        let angle = ((turn.trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos();
        // The wrist and the four finger knuckles (DESIGN.md keypoint order).
        let palm = [0, 5, 9, 13, 17]
            .iter()
            .map(|&k| (Vector3::from(rec.keypoints[k]) - expected[k]).norm())
            .sum::<f64>()
            / 5.0;
        (angle, palm)
    };
    let (angle, palm) = placed(TrackerConfig::default().placement_outside);
    let (angle_on, palm_on) = placed(f64::INFINITY);
    println!(
        "edge-on start: rotation off by {angle:.3} rad, wrist and knuckles {palm:.2} mm; palm-on \
         only {angle_on:.3} rad, {palm_on:.2} mm"
    );
    assert!(angle < 0.05 && palm < 2.0, "{angle} rad, {palm} mm");
    assert!(angle_on > 0.5, "palm-on only: {angle_on} rad");
}

/// [`TrackingCtx::outside_fraction`] is the full rendering's area outside the sensor
/// silhouette over the silhouette's area, although the context renders only the pixels outside
/// it (and the points' own).
#[test]
fn outside_fraction_is_the_rendered_area_outside_the_silhouette() {
    let model = default_right_hand_cylinders();
    let truth = target_pose(&model);
    let frame = noisy_frame(&model, &truth, 0.0, 0);
    let mut ctx = TrackingCtx::new(&model, View::Orthographic, IrlsParams::default());
    ctx.set_frame(&frame);
    ctx.update(&truth, false).unwrap();
    assert_eq!(ctx.outside_fraction(), Some(0.0));
    let mut moved = truth.clone();
    moved.values[model.skeleton.dof_index("global_tx").unwrap()] += 15.0;
    ctx.update(&moved, false).unwrap();
    let (raster, _, _) = rendered_silhouette(&model, &moved);
    let mask = &frame.hand.mask.data;
    let outside = raster
        .hits()
        .iter()
        .filter(|&&k| mask[k as usize] == 0)
        .count();
    let area = mask.iter().filter(|&&m| m != 0).count();
    let expected = outside as f64 / area as f64;
    println!("15 mm off: {expected:.3} of the silhouette's area outside it");
    assert!(expected > 0.05, "{expected}");
    assert_eq!(ctx.outside_fraction(), Some(expected));
    ctx.set_silhouette(false);
    ctx.update(&moved, false).unwrap();
    assert_eq!(ctx.outside_fraction(), None);
}

/// A placement threshold that is not a share (negative or NaN) is refused, naming the field.
#[test]
fn an_absurd_placement_threshold_is_refused() {
    let model = default_right_hand_cylinders();
    for bad in [-0.1, f64::NAN, f64::NEG_INFINITY] {
        let config = TrackerConfig {
            placement_outside: bad,
            ..TrackerConfig::default()
        };
        let err = Tracker::new(&model, config, None).err().expect("refused");
        assert!(err.to_string().contains("placement_outside"), "{err}");
    }
    for good in [0.0, 0.25, f64::INFINITY] {
        let config = TrackerConfig {
            placement_outside: good,
            ..TrackerConfig::default()
        };
        assert!(Tracker::new(&model, config, None).is_ok());
    }
}
