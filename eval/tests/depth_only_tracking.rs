//! Tracking without a color image: the sphere-mesh tracker on the depth-only segmentation
//! (`--segmentation depth`, what sequences from other renderers and datasets without a
//! wristband get) must track about as well as on the wristband segmentation of the same frames.
//!
//! Measured (session 15; 240 frames at 30 Hz, random subject 21, the subject's own template,
//! mean keypoint error with the wristband / depth only): before the depth-only segmentation
//! regrew around the palm and past a lone thumb tip, added occluded fingers, filled the palm
//! circle's holes and reported its cut as a band — fist ToF 2.22 / 13.85 mm, teaser noise-free
//! 0.22 / 1.13, teaser ToF 1.48 / 2.20, rotation_fast ToF 4.18 / 9.77, rotation_fast
//! noise-free 0.31 / 10.61; after — 2.22 / 2.35, 0.22 / 0.25, 1.48 / 1.62, 4.18 / 4.24, 0.31 /
//! 4.24. The last one drifted during the fast turn (frames 157–215): seen edge-on, the palm
//! was barely wider than the bunched fingers, the largest inscribed circle jumped to the
//! fingers and the forearm cut went through the palm. With the previous frame's palm as a hint
//! (a circle within 40 mm of it at least 0.75 of the largest is preferred): 2.22 / 2.34, 0.22 /
//! 0.24, 1.48 / 1.62, 4.18 / 4.20, 0.31 / 1.26 — still not within the band's; its bound is a
//! regression guard.

use eval::synthetic::{SyntheticSequence, SyntheticSpec};
use hand_model::solver::PcaPrior;
use hmodel_spheremesh::{Tracker, TrackerConfig};
use sensor_io::preprocess::{DepthOnlyParams, Segmentation, WristbandParams};

fn mean_error(motion: &str, noise: &str, segmentation: Segmentation) -> f64 {
    let mut spec = SyntheticSpec {
        motion: motion.into(),
        noise: noise.into(),
        frames: 240,
        fps: 30.0,
        seed: 21,
        subject: "random".into(),
        ..SyntheticSpec::default()
    };
    spec.preprocess.segmentation = segmentation;
    let mut seq = SyntheticSequence::new(spec).unwrap();
    let template = seq.template().clone();
    let prior = PcaPrior::project_default();
    let mut tracker = Tracker::new(&template, TrackerConfig::default(), Some(&prior)).unwrap();
    let run = seq
        .run(|f, t| tracker.track(f, t.frame, t.timestamp), |_| {})
        .unwrap();
    assert!(run.records.iter().all(|r| r.is_finite()));
    run.summary().mean
}

#[test]
fn depth_only_segmentation_tracks_like_the_wristband() {
    // (motion, noise, the depth-only error's bound as a multiple of the wristband's + 0.2 mm)
    let cases = [
        ("fist", "tof", 1.2),
        ("teaser", "none", 1.2),
        ("teaser", "tof", 1.2),
        ("rotation_fast", "tof", 1.2),
        ("rotation_fast", "none", 5.0),
    ];
    let results: Vec<(f64, f64)> = std::thread::scope(|s| {
        let handles: Vec<_> = cases
            .iter()
            .map(|&(motion, noise, _)| {
                s.spawn(move || {
                    let band = mean_error(
                        motion,
                        noise,
                        Segmentation::Wristband(WristbandParams::default()),
                    );
                    let depth = mean_error(
                        motion,
                        noise,
                        Segmentation::DepthOnly(DepthOnlyParams::default()),
                    );
                    (band, depth)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for ((motion, noise, _), (band, depth)) in cases.iter().zip(&results) {
        println!("{motion} {noise}: wristband {band:.2} mm, depth only {depth:.2} mm");
    }
    for ((motion, noise, factor), (band, depth)) in cases.iter().zip(&results) {
        assert!(
            *depth <= factor * band + 0.2,
            "{motion} {noise}: depth only {depth:.2} mm against the wristband's {band:.2} mm"
        );
    }
}
