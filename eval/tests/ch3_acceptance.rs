//! Issue 5 acceptance, measured on `hands synth` sequences with the default seed: the Ch. 3
//! sphere-mesh tracker (`hmodel-spheremesh`, default settings) with the subject's true template,
//! scored against the exact ground-truth keypoints.
//!
//! - teaser, 600 frames at 60 Hz, noise-free: mean keypoint error < 3 mm, ≥ 99 % of frames with
//!   max keypoint error < 10 mm among the frames whose ground truth is physically possible
//!   (finger pills interpenetrating by at most 5 mm at the true pose, found by code and
//!   printed; an earlier generator sank the thumb of its fist 11–14 mm into the fingers, which
//!   the collision term rightly refused), and ≥ 98.5 % of all frames;
//! - the same with ToF and structured-light noise: mean < 6 mm, ≥ 98 % of frames < 20 mm;
//! - better than the Ch. 2 cylinder tracker (cylinders fitted to the same subject) on every
//!   motion of the library, by mean keypoint error;
//! - the hand leaving and re-entering the view: flagged while away, recovered after it returns.

use eval::synthetic::{SyntheticRun, SyntheticSequence, SyntheticSpec};

#[path = "support/penetration.rs"]
mod penetration;
use hand_model::cylinder::CylinderModel;
use hand_model::solver::PcaPrior;
use hmodel_spheremesh::{Tracker, TrackerConfig};
use penetration::max_penetration;

fn spec(motion: &str, noise: &str, frames: usize) -> SyntheticSpec {
    SyntheticSpec {
        motion: motion.into(),
        noise: noise.into(),
        frames,
        ..SyntheticSpec::default()
    }
}

fn sequence(motion: &str, noise: &str, frames: usize) -> SyntheticSequence {
    SyntheticSequence::new(spec(motion, noise, frames)).unwrap()
}

fn track(motion: &str, noise: &str, frames: usize) -> SyntheticRun {
    track_with(motion, noise, frames, TrackerConfig::default())
}

fn track_with(motion: &str, noise: &str, frames: usize, config: TrackerConfig) -> SyntheticRun {
    track_spec(spec(motion, noise, frames), config)
}

fn track_spec(spec: SyntheticSpec, config: TrackerConfig) -> SyntheticRun {
    let (motion, noise) = (spec.motion.clone(), spec.noise.clone());
    let mut seq = SyntheticSequence::new(spec).unwrap();
    let template = seq.template().clone();
    let prior = PcaPrior::project_default();
    let mut tracker = Tracker::new(&template, config, Some(&prior)).unwrap();
    let run = seq
        .run(|f, t| tracker.track(f, t.frame, t.timestamp), |_| {})
        .unwrap();
    let s = run.summary();
    println!(
        "spheremesh {motion} {noise}: {} frames, mean {:.2} mm, median {:.2} mm, mean max {:.2} mm, {:.1}% max < 10 mm, {:.1}% max < 20 mm, lost {:.1}%, reinitialized {:.1}%, track median {:.0} µs (correspondences {:.0}, solve {:.0})",
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

fn track_cylinders(motion: &str, noise: &str, frames: usize) -> SyntheticRun {
    let mut seq = sequence(motion, noise, frames);
    let model = CylinderModel::from_sphere_mesh_with_wrist(seq.template()).unwrap();
    let prior = PcaPrior::project_default();
    let mut tracker =
        htrack_icp::Tracker::new(&model, htrack_icp::TrackerConfig::default(), Some(&prior))
            .unwrap();
    seq.run(|f, t| tracker.track(f, t.frame, t.timestamp), |_| {})
        .unwrap()
}

#[test]
fn teaser_noise_free() {
    let run = track("teaser", "none", 600);
    let s = run.summary();
    assert_eq!(s.frames, 600);
    assert!(s.mean < 3.0, "mean keypoint error {} mm", s.mean);
    let template = sequence("teaser", "none", 1).template().clone();
    let possible: Vec<bool> = run
        .truth
        .iter()
        .map(|t| max_penetration(&template, &t.pose) <= 5.0)
        .collect();
    let under = |frames: &[usize]| {
        let n = frames
            .iter()
            .filter(|&&i| run.errors[i].is_some_and(|e| e.max < 10.0))
            .count();
        n as f64 / frames.len().max(1) as f64
    };
    let all: Vec<usize> = (0..run.errors.len()).collect();
    let (valid, impossible): (Vec<usize>, Vec<usize>) = all.iter().partition(|&&i| possible[i]);
    println!(
        "teaser none: max < 10 mm on {:.1}% of all frames, on {:.1}% of the {} frames with a possible ground truth (impossible: {impossible:?})",
        100.0 * under(&all),
        100.0 * under(&valid),
        valid.len()
    );
    assert!(
        under(&valid) >= 0.99,
        "{:.1}% of possible frames",
        100.0 * under(&valid)
    );
    assert!(
        under(&all) >= 0.985,
        "{:.1}% of all frames",
        100.0 * under(&all)
    );
}

#[test]
fn teaser_sensor_noise() {
    for noise in ["tof", "structured"] {
        let run = track("teaser", noise, 600);
        let s = run.summary();
        assert!(s.mean < 6.0, "{noise}: mean keypoint error {} mm", s.mean);
        let under = run.fraction_max_under(20.0);
        assert!(under >= 0.98, "{noise}: {:.1}% under 20 mm", 100.0 * under);
    }
}

/// Along-ray correspondences (`TrackerConfig::ray_gate`; the thesis registers every point at
/// its closest point) under the two noisy sensor models and on exact depth, on every frame
/// (`ray_gate_noise` 0) against the thesis' rule: the closest point of a noisy point is biased
/// outward on curved parts (≈ σ² sin²φ / 2r) and the front-facing rule pulls points behind a
/// silhouette inward, while the residual along the ray is linear in the depth noise. Measured
/// on the teaser (closest points → along rays, mean keypoint error, slide 7.5 mm; 5 mm
/// before session 18): ToF 1.512 → 0.910 mm (0.60×; 0.995 with 5 mm), structured light 0.325
/// → 0.325 mm (0.321 before session 21 ranked the first frame's placement hypotheses by the
/// model's area outside the silhouette too; 0.315 → 0.322 since session 36 solves each
/// placement three times, the first frames placed closer; the guard allows 3 %), noise-free
/// 0.178 → 0.178 mm
/// (0.183 with 5 mm) at twice the correspondence time — which is why by default they run only
/// from a measured noise of 1.5 mm (under ToF here). Measured on the raw depth
/// (`PreprocessConfig::smoothing: None`): the depth smoothing that runs by default on noisy
/// sequences from their 31st frame takes over most of the gain (ToF, session 32: closest points
/// 0.752 mm, along rays 0.703 mm).
#[test]
fn along_ray_correspondences_track_better_under_depth_noise() {
    let thesis = TrackerConfig {
        ray_gate: None,
        ..TrackerConfig::default()
    };
    let along = TrackerConfig {
        ray_gate_noise: 0.0,
        ..TrackerConfig::default()
    };
    for (noise, gain) in [("tof", 0.75), ("structured", 1.03), ("none", 1.05)] {
        let raw = || {
            let mut spec = spec("teaser", noise, 200);
            spec.preprocess.smoothing = None;
            spec
        };
        let (thesis, ray) = std::thread::scope(|s| {
            let (spec, config) = (raw(), thesis.clone());
            let h = s.spawn(move || track_spec(spec, config).summary().mean);
            let ray = track_spec(raw(), along.clone()).summary().mean;
            (h.join().unwrap(), ray)
        });
        println!(
            "teaser {noise}, 200 frames: closest points {thesis:.3} mm, along rays {ray:.3} mm ({:.2}×)",
            ray / thesis
        );
        assert!(
            ray < gain * thesis,
            "{noise}: along rays {ray} mm vs {thesis} mm"
        );
    }
}

#[test]
fn better_than_cylinders_on_every_motion() {
    let frames = 240;
    let mut worse = Vec::new();
    println!("| motion | spheremesh mean (mm) | cylinders mean (mm) |\n|---|---|---|");
    for &motion in datasets::MotionLibrary::names() {
        let sm = track(motion, "tof", frames).summary();
        let cy = track_cylinders(motion, "tof", frames).summary();
        println!("| {motion} | {:.2} | {:.2} |", sm.mean, cy.mean);
        if sm.mean >= cy.mean {
            worse.push(motion);
        }
    }
    assert!(worse.is_empty(), "not better than cylinders on {worse:?}");
}

/// The first time the hand leaves (frames flagged `no_hand`) and slides back into the view:
/// how many frames after its return until the maximum keypoint error stays below 20 mm for 10
/// frames. The hand re-enters from the image border, so part of it is out of view (and its
/// keypoints unobservable) for the first frames after the return.
#[test]
fn leave_and_return_recovers() {
    let run = track("leave_reenter", "tof", 400);
    let no_hand = |i: usize| run.records[i].flags.iter().any(|f| f == "no_hand");
    let gone = (0..run.records.len())
        .find(|&i| no_hand(i))
        .expect("the hand leaves the view");
    let back = (gone..run.records.len())
        .find(|&i| !no_hand(i))
        .expect("the hand returns");
    let good = |i: usize| run.errors[i].is_some_and(|e| e.max < 20.0);
    let recovered = (back..run.records.len().saturating_sub(10)).find(|&i| (i..i + 10).all(good));
    let frames = recovered.map(|r| r - back);
    println!(
        "leave_reenter: away from frame {gone} to {back} ({} frames), recovered {frames:?} frames after the return",
        back - gone
    );
    assert!(
        frames.is_some_and(|f| f <= 90),
        "recovery after {frames:?} frames"
    );
    assert!((gone..back).all(|i| run.records[i].is_finite()));
}
