//! Issue 5 acceptance, measured on `hands synth` sequences with the default seed: the Ch. 3
//! sphere-mesh tracker (`hmodel-spheremesh`, default settings) with the subject's true template,
//! scored against the exact ground-truth keypoints.

use eval::synthetic::{SyntheticRun, SyntheticSequence, SyntheticSpec};
use hmodel_spheremesh::{Tracker, TrackerConfig};

const FRAMES: usize = 600;

fn track(motion: &str, noise: &str, frames: usize) -> SyntheticRun {
    let mut seq = SyntheticSequence::new(SyntheticSpec {
        motion: motion.into(),
        noise: noise.into(),
        frames,
        ..SyntheticSpec::default()
    })
    .unwrap();
    let template = seq.template().clone();
    let prior = hand_model::solver::PcaPrior::project_default();
    let mut tracker = Tracker::new(&template, TrackerConfig::default(), Some(&prior)).unwrap();
    let run = seq
        .run(|f, t| tracker.track(f, t.frame, t.timestamp), |_| {})
        .unwrap();
    let s = run.summary();
    println!(
        "{motion} {noise}: {} frames, mean {:.2} mm, median {:.2} mm, mean max {:.2} mm, {:.1}% max < 10 mm, {:.1}% max < 20 mm, lost {:.1}%, reinitialized {:.1}%, track median {:.0} µs (correspondences {:.0}, solve {:.0})",
        s.frames,
        s.mean,
        s.median,
        s.mean_max,
        100.0 * run.fraction_max_under(10.0),
        100.0 * run.fraction_max_under(20.0),
        100.0 * run.flag_fraction("lost"),
        100.0 * run.flag_fraction("reinitialized"),
        run.median_stage_us("track"),
        run.median_stage_us("correspondences"),
        run.median_stage_us("solve"),
    );
    assert!(run.records.iter().all(|r| r.is_finite()));
    run
}

#[test]
fn teaser_noise_free() {
    let run = track("teaser", "none", FRAMES);
    let s = run.summary();
    assert_eq!(s.frames, FRAMES);
    assert!(s.mean < 3.0, "mean keypoint error {} mm", s.mean);
    assert!(run.fraction_max_under(10.0) >= 0.99);
}
