//! Issue 6 acceptance (synthetic): for random subjects (β perturbed up to 15 %), the default
//! template calibrated from 8 noise-free depth frames of the `calibration` motion — the frames
//! chosen automatically from a tracking run with the default template, their poses taken from
//! that run — recovers the subject's rest sphere centers and radii, and tracking the teaser
//! with the calibrated template comes close to tracking with the true one.
//!
//! Measured (robust d2m at 1 mm, model points hidden by the wristband not pushed by m2d, the
//! rendered forearm continuing each subject's own wrist, the LM damping floored, τ_m2d scaled
//! by the points' sampling of the hand's pixels, free sphere offsets with the joints held
//! since session 19): centers 0.24–0.89 mm and radii 0.04–0.10 mm on the five subjects.
//! Tracking the noise-free teaser with the calibrated template: 0.206 / 0.238 / 0.239 / 0.222
//! / 0.233 mm mean keypoint error against 0.164 / 0.250 / 0.349 / 0.184 / 0.247 mm with the
//! true template (ratios 1.25 / 0.96 / 0.69 / 1.23 / 0.94 in session 38, whose placements are
//! solved with and without the rigid first iteration — centers 0.21–0.88 mm, radii 0.04–0.10
//! mm, the largest excess of subject 1 on the ring MCP, the wrist and the ring PIP, ≈ 0.1 mm
//! each, of subject 4 on the wrist, 0.17 mm; 1.26 / 0.95 / 0.69 / 1.21 / 0.94 in session 36,
//! whose placements solved three times moved the first frames and some chosen frames; 1.27 /
//! 0.89 / 0.69 / 1.21 / 0.96 in session 33, after the trackers' second look at a placement
//! tried each digit's flexions, which moved the first frames of some runs; 1.22 / 0.91 / 0.69
//! / 1.21 / 0.95 in session 29; subject 1 was 0.208 against 0.165 mm, 1.27, when this was first
//! written; with β and rest rotations alone 1.26 / 0.89 / 0.69 / 1.20 / 0.92, see
//! `CalibrationConfig::free_spheres` for why the free offsets are the default) and 2.5–8.8
//! mm with the default one — "within 10 %" holds on subjects 2, 3 and 5, not on 1 and 4.
//!
//! Where the excess came from and what changed:
//! - The rendered forearm was a fixed pill, thicker than a thin subject's wrist just above the
//!   band; the wrist spheres fitted it and shifted 1.5–3 mm sideways, moving the tracked wrist
//!   keypoint by 1.0–3.2 mm (ratios up to 2.45). The forearm now continues the subject's own
//!   lower wrist spheres (`datasets::synth`), so the true template explains all the skin above
//!   the band.
//! - Subject 3's descent stalled at 14 iterations: its ring DIP angle in one frame was barely
//!   seen (near-zero diagonal) and Marquardt's diagonal scaling let it step to 25 rad into its
//!   joint limit whatever λ; the damping diagonal is now floored (ratio 2.75 → 0.72).
//! - τ_m2d was applied per rendered pixel against d2m over points that sample ≈ 0.3 of the
//!   hand's pixels, so the pixel-quantized silhouette outweighed the exact depth (ratios 1.39 /
//!   0.98 / 0.72 / 1.38 / 0.93 before the scaling; τ_m2d 0.1 unscaled gave 1.21 / 0.87 / 0.69
//!   / 1.17 / 0.93, 2.0 gave 3.5 / – / – / 2.5).
//! - What remains on subjects 1 and 4 (+0.03–0.04 mm mean keypoint error) is the energy's
//!   own minimum, not the descent: calibrated from the TRUE template and TRUE poses of the same
//!   frames they end 0.12 / 0.16 mm (mean center) from the truth and track at 1.21 / 1.20 ×,
//!   the same as from the default template. Subject 4 from the truth: 1.20 with least squares
//!   instead of the Huber d2m, 1.15 without m2d; the data are millimetre-quantized depth and
//!   pixel-quantized silhouettes from 8 frames.
//! - Before the m2d scaling, subjects 1 and 4 ended in a local minimum: started from the true
//!   template and true poses of the same frames, subject 1 stayed at the truth (energy 21 105
//!   against 21 269 reached from the default template) and subject 4 drifted 0.15 mm (ratio
//!   1.33). More iterations (100), a tighter tolerance, least squares instead of the Huber
//!   d2m, a weaker rest-rotation prior, τ_valid 10³ or two more rounds of re-tracking and
//!   re-calibrating did not lower the ratios below 1.34. The wrist's lower spheres lie under
//!   the band (2.3–7.8 mm off, no data sees them).
//! - Session 31, tried on the same five subjects and not kept (ratios 1.22 / 0.91 / 0.69 / 1.21
//!   / 0.95 before): choosing the 8 frames by what they tell about the shape instead of by pose
//!   distance — each frame's marginal information on every shape unknown (the diagonal of the
//!   Schur complement of its Gauss–Newton Hessian over its own pose), frames added greedily by
//!   Σ ln(1 + h/A) over the prior's information A plus that of the frames chosen — picked
//!   near-copies of one fully bent pose (1.27 / 0.96 / 0.66 / 1.31 / 1.05), and among the 24
//!   frames of the pose-distance rule 1.26 / 0.89 / 0.65 / 1.16 / 0.99; calibrating the same 8
//!   frames from every silhouette pixel (≈ 3.3 × the points) 1.24 / 0.85 / 0.63 / 1.12 / 0.86,
//!   centers 0.19–0.90 mm, but under ToF centers 2.35 / 1.98 → 2.55 / 1.72 mm, radii 0.31 /
//!   0.38 → 0.47 / 0.33 mm and 0.65 → 1.37 s a calibration; with the depth dithered by ±0.5 mm
//!   before rounding (every pixel) 1.46 / 0.93 / 0.64 / 1.24 / 1.05, so the rounding's fixed
//!   pattern is not what subjects 1 and 4 fit.

use eval::synthetic::{SyntheticRun, SyntheticSequence, SyntheticSpec};
use hand_model::kinematics::Pose;
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::{default_right_hand, SphereMeshTemplate};
use hmodel_spheremesh::calibration::{
    calibrate, rest_sphere_errors, select_frames, CalibrationConfig, CalibrationFrame,
};
use hmodel_spheremesh::{Tracker, TrackerConfig};

fn spec(motion: &str, seed: u64, frames: usize) -> SyntheticSpec {
    noisy_spec(motion, seed, frames, "none")
}

fn noisy_spec(motion: &str, seed: u64, frames: usize, noise: &str) -> SyntheticSpec {
    SyntheticSpec {
        motion: motion.into(),
        subject: "random".into(),
        seed,
        frames,
        noise: noise.into(),
        ..SyntheticSpec::default()
    }
}

/// Calibrate the default template to a subject's `calibration` sequence (8 frames chosen from
/// a tracking run); returns the result and the subject's true template.
fn calibrate_subject(
    seed: u64,
    noise: &str,
    config: &CalibrationConfig,
) -> (
    hmodel_spheremesh::calibration::Calibration,
    SphereMeshTemplate,
    Vec<usize>,
) {
    let base = default_right_hand();
    let sk = &base.skeleton;
    let mut seq = SyntheticSequence::new(noisy_spec("calibration", seed, 300, noise)).unwrap();
    let truth = seq.template().clone();
    let (run, frames) = track_keep(&mut seq, &base);
    let poses: Vec<Pose> = run
        .records
        .iter()
        .map(|r| Pose {
            values: sk
                .dofs()
                .iter()
                .map(|d| r.pose.get(&d.name).copied().unwrap_or(0.0))
                .collect(),
        })
        .collect();
    let usable = |i: usize| run.records[i].flags.is_empty();
    let chosen = select_frames(sk, &poses, usable, 8);
    let cal_frames: Vec<CalibrationFrame> = chosen.iter().map(|&i| frames[i].clone()).collect();
    let init: Vec<Pose> = chosen.iter().map(|&i| poses[i].clone()).collect();
    let cal = calibrate(&base, &cal_frames, &init, config).unwrap();
    (cal, truth, chosen)
}

/// Track `seq` with `template`; keep every frame's calibration data.
fn track_keep(
    seq: &mut SyntheticSequence,
    template: &SphereMeshTemplate,
) -> (SyntheticRun, Vec<CalibrationFrame>) {
    let prior = PcaPrior::project_default();
    let mut tracker = Tracker::new(template, TrackerConfig::default(), Some(&prior)).unwrap();
    let mut frames = Vec::new();
    let run = seq
        .run(
            |f, t| {
                frames.push(CalibrationFrame::depth(f));
                tracker.track(f, t.frame, t.timestamp)
            },
            |_| {},
        )
        .unwrap();
    (run, frames)
}

/// Per keypoint the mean error over the frames of `run`.
fn keypoint_errors(run: &SyntheticRun) -> Vec<f64> {
    let n = run.records.len().max(1) as f64;
    let mut sum = vec![0.0; run.truth.first().map_or(0, |t| t.keypoints.len())];
    for (r, t) in run.records.iter().zip(&run.truth) {
        for ((s, a), b) in sum.iter_mut().zip(&r.keypoints).zip(&t.keypoints) {
            *s += (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt() / n;
        }
    }
    sum
}

/// The three keypoints whose mean error grows most from `reference` to `run`, as
/// `index excess` (DESIGN.md keypoint order: 0 wrist, then 4 per digit from the thumb).
fn largest_excess(run: &SyntheticRun, reference: &SyntheticRun) -> String {
    let mut excess: Vec<(usize, f64)> = keypoint_errors(run)
        .iter()
        .zip(keypoint_errors(reference))
        .map(|(a, b)| a - b)
        .enumerate()
        .collect();
    excess.sort_by(|a, b| b.1.total_cmp(&a.1));
    excess
        .iter()
        .take(3)
        .map(|(i, e)| format!("{i} {e:+.2}"))
        .collect::<Vec<_>>()
        .join(", ")
}

#[test]
fn calibrates_random_subjects_from_eight_tracked_frames() {
    let base = default_right_hand();
    let mut worst = (0.0f64, 0.0f64, 0.0f64);
    for seed in 1..=5u64 {
        let (cal, truth, chosen) = calibrate_subject(seed, "none", &CalibrationConfig::default());
        let before = rest_sphere_errors(&base, &truth).unwrap();
        let after = rest_sphere_errors(&cal.template, &truth).unwrap();
        // Tracking the teaser with the calibrated and with the true template.
        let teaser = |t: &SphereMeshTemplate| {
            let mut s = SyntheticSequence::new(spec("teaser", seed, 300)).unwrap();
            track_keep(&mut s, t).0
        };
        let (cal_run, true_run) = (teaser(&cal.template), teaser(&truth));
        let (with_cal, with_truth, with_default) = (
            cal_run.summary().mean,
            true_run.summary().mean,
            teaser(&base).summary().mean,
        );
        println!(
            "subject {seed}: frames {chosen:?}; {:.2} s, {} iterations; centers {:.2} → {:.2} mm, radii {:.2} → {:.2} mm; teaser error: default {with_default:.2}, calibrated {with_cal:.3}, true {with_truth:.3} mm (ratio {:.2}); largest excess (keypoint: calibrated − true, mm): {}",
            cal.seconds,
            cal.iterations.len(),
            before.0,
            after.0,
            before.1,
            after.1,
            with_cal / with_truth,
            largest_excess(&cal_run, &true_run)
        );
        worst = (
            worst.0.max(after.0),
            worst.1.max(after.1),
            worst.2.max(with_cal / with_truth),
        );
    }
    println!(
        "worst: centers {:.2} mm, radii {:.2} mm, tracking ratio {:.3}",
        worst.0, worst.1, worst.2
    );
    assert!(worst.0 < 1.5 && worst.1 < 1.0, "{worst:?}");
    assert!(
        worst.2 < 1.5,
        "calibrated/true teaser error ratio {:.2}",
        worst.2
    );
}

/// The same with the ToF noise model (issue 6 "With ToF noise: report"): two subjects; the
/// calibrated template must still be closer to the truth than the default, its radii within
/// 0.75 mm. Measured (session 32, the depth smoothed from the calibration sequence's 31st frame,
/// `sensor_io::preprocess::smooth_depth`): centers 5.55 → 2.00 and 2.63 → 1.40 mm, radii 0.26
/// → 0.49 and 0.48 → 0.27 mm (on the raw depth, session 31: 2.35 / 1.98 mm, 0.31 / 0.38 mm;
/// 2.40 / 2.05 and 0.42 / 0.40 mm when written, 2.51 / 2.05 and 0.41 / 0.40
/// mm without the free sphere offsets of session 19;
/// with the 5 mm along-ray slide before session 18: 2.40 / 2.34 mm, 0.47 / 0.61 mm),
/// with the priors scaled by the measured noise (`CalibrationConfig::noise_scaled_priors`;
/// without: centers 3.63 and 2.88 mm, subject 2 worse than the default template) and the depth
/// frames' points registered along their camera rays (`CalibrationConfig::ray_gate`; with
/// closest points: centers 3.13 / 2.36 mm, radii 0.86 / 0.99 mm — the noise thinned them).
#[test]
fn calibration_with_tof_noise() {
    let base = default_right_hand();
    for seed in [1u64, 2] {
        let (cal, truth, _) = calibrate_subject(seed, "tof", &CalibrationConfig::default());
        let (before, after) = (
            rest_sphere_errors(&base, &truth).unwrap(),
            rest_sphere_errors(&cal.template, &truth).unwrap(),
        );
        println!(
            "tof subject {seed}: centers {:.2} → {:.2} mm, radii {:.2} → {:.2} mm ({:.2} s)",
            before.0, after.0, before.1, after.1, cal.seconds
        );
        assert!(after.0 < before.0, "{before:?} → {after:?}");
        assert!(after.1 < 0.75, "radii {:.2} mm off", after.1);
    }
}
