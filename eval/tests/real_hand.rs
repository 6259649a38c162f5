//! Another person's hand (issues 6 and 8, beyond the random subjects): the original authors'
//! final model of the real scanned hand (`../shared/reference/hand-scans-tkach/fitted`, a real
//! person's calibrated sphere-mesh) carried onto this project's skeleton
//! ([`authors::authors_on_skeleton`]: its own proportions, rest rotations and palm and wrist
//! sphere placement, outside the default template's β space; its joints on its phalanx
//! spheres, as in both models), rendered moving as issue 8's calibration motion and tracked
//! from the default template — with online calibration, and with the offline calibration of
//! Ch. 3 — against the Ch. 3 tracker on the hand's own model (the reference) and on the
//! default template (no calibration). The random subjects of the acceptance tests perturb the
//! default template's β; a real hand also differs where β cannot reach. Skips (and says so)
//! when the reference folder is absent.
//!
//! Measured (300 frames at 30 Hz, last-third mean keypoint error): noise-free, default
//! template 6.57 mm, online 3.12 mm, the hand's own model 0.24 mm (12.8×; E_β 1.98 → 1.62
//! mm); ToF 6.59 / 3.53 / 0.81 mm (4.4×, E_β 1.98 → 1.34 mm) since session 32 smoothed the
//! noisy depth, 6.64 / 3.84 / 1.55 mm (2.5×) on the raw depth (4.29 mm, 2.8×, with the
//! shape-space prior scaled by σ̂² before session 20). Online, the fingertips come within 1–2 mm but the
//! ring, middle and pinky knuckles (MCP keypoints) stay 6–9 mm off, mostly in depth, and the
//! wrist 5 mm: the estimate keeps the knuckles' `base_z` at the template's and shrinks their
//! radii instead (see `honline_calib`'s docs, "Another person's hand"). The offline
//! calibration of Ch. 3 from 8 noise-free frames (the true poses as its start) reaches 1.01
//! mm with its free sphere offsets (the default since this test; 2.19 mm with β and rest
//! rotations alone, which cannot place this palm's spheres). The guards below hold what is
//! reached.

use std::path::Path;

#[path = "support/authors.rs"]
mod authors;

use datasets::scans::FittedReference;
use eval::online::{
    last_third_error, run_online_on, run_template_on, CalibrationMotion, OnlineRun,
};
use eval::synthetic::{SyntheticRun, SyntheticSequence, SyntheticSpec};
use hand_model::kinematics::Pose;
use hand_model::spheremesh::{default_right_hand, ShapeBasis, SphereMeshTemplate};
use hmodel_spheremesh::calibration::{
    calibrate, select_frames, CalibrationConfig, CalibrationFrame,
};
use hmodel_spheremesh::TrackerConfig;
use honline_calib::OnlineConfig;

const FITTED: &str = "../../shared/reference/hand-scans-tkach/fitted";
const FRAMES: usize = 300;
const SEED: u64 = 7;

/// The authors' hand on the default skeleton, or `None` (said) when the folder is absent.
fn authors_hand() -> Option<SphereMeshTemplate> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join(FITTED);
    if !dir.exists() {
        println!("skipped: {} absent", dir.display());
        return None;
    }
    let reference = FittedReference::load(&dir).unwrap();
    let (hand, centers, radii, n) = authors::authors_on_skeleton(&reference, &default_right_hand());
    println!(
        "the authors' hand on our skeleton: rest centers within {centers:.2} mm, radii {radii:.2} mm of theirs ({n} spheres)"
    );
    Some(hand)
}

/// The hand moving as the calibration motion under `noise`.
fn scene(hand: &SphereMeshTemplate, noise: &str) -> (CalibrationMotion, SyntheticSequence) {
    let motion = CalibrationMotion::new(&default_right_hand().skeleton, 0.0, SEED);
    let spec = SyntheticSpec {
        frames: FRAMES,
        fps: 30.0,
        noise: noise.into(),
        seed: SEED,
        ..SyntheticSpec::default()
    };
    let m = motion.clone();
    let seq = SyntheticSequence::custom_hand(spec, hand, move |t, p| m.pose_into(t, p)).unwrap();
    (motion, seq)
}

/// The Ch. 3 tracker on `template` (`None`: the hand's own model).
fn fixed(
    hand: &SphereMeshTemplate,
    noise: &str,
    template: Option<SphereMeshTemplate>,
) -> SyntheticRun {
    let (motion, seq) = scene(hand, noise);
    run_template_on(seq, &motion, TrackerConfig::default(), template).unwrap()
}

/// Online calibration from the default template (E_β against the hand's own β values).
fn online(hand: &SphereMeshTemplate, noise: &str) -> OnlineRun {
    let (motion, seq) = scene(hand, noise);
    let truth = ShapeBasis::honline(hand).unwrap().template_values();
    run_online_on(seq, &truth, None, &motion, OnlineConfig::default()).unwrap()
}

/// The Ch. 3 offline calibration of the default template from 8 noise-free frames of the
/// hand, chosen by farthest-point sampling of the true poses, which also start it.
fn offline(hand: &SphereMeshTemplate) -> SphereMeshTemplate {
    let base = default_right_hand();
    let sk = &base.skeleton;
    let (_, mut seq) = scene(hand, "none");
    let mut frames = Vec::new();
    let run = seq
        .run(
            |f, t| {
                frames.push(CalibrationFrame::depth(f));
                t.clone()
            },
            |_| {},
        )
        .unwrap();
    let poses: Vec<Pose> = run
        .truth
        .iter()
        .map(|r| Pose {
            values: sk.dofs().iter().map(|d| r.pose[&d.name]).collect(),
        })
        .collect();
    let chosen = select_frames(sk, &poses, |_| true, 8);
    let picked: Vec<CalibrationFrame> = chosen.iter().map(|&i| frames[i].clone()).collect();
    let start: Vec<Pose> = chosen.iter().map(|&i| poses[i].clone()).collect();
    calibrate(&base, &picked, &start, &CalibrationConfig::default())
        .unwrap()
        .template
}

/// The `n` keypoints of `run` with the largest mean error over its last third, `index error`.
fn worst_keypoints(run: &SyntheticRun, n: usize) -> String {
    let frames = run.records.len();
    let tail = frames - frames / 3..frames;
    let mut mean: Vec<(usize, f64)> = (0..run.truth[0].keypoints.len())
        .map(|j| {
            let sum: f64 = tail
                .clone()
                .map(|k| {
                    let (a, b) = (&run.records[k].keypoints[j], &run.truth[k].keypoints[j]);
                    (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>().sqrt()
                })
                .sum();
            (j, sum / tail.len() as f64)
        })
        .collect();
    mean.sort_by(|a, b| b.1.total_cmp(&a.1));
    let top: Vec<String> = mean[..n]
        .iter()
        .map(|(j, e)| format!("{j} {e:.1}"))
        .collect();
    top.join(", ")
}

#[test]
fn calibrating_a_real_persons_hand() {
    let Some(hand) = authors_hand() else {
        return;
    };
    let mut uncalibrated = f64::NAN;
    for noise in ["none", "tof"] {
        let (default, own, online) = std::thread::scope(|s| {
            let default = s.spawn(|| fixed(&hand, noise, Some(default_right_hand())));
            let own = s.spawn(|| fixed(&hand, noise, None));
            let online = online(&hand, noise);
            (default.join().unwrap(), own.join().unwrap(), online)
        });
        let (d, t, o) = (
            last_third_error(&default),
            last_third_error(&own),
            last_third_error(&online.run),
        );
        println!(
            "{noise}: last-third keypoint error: default template {d:.2} mm, online {o:.2} mm, the hand's own model {t:.2} mm (online / own {:.1}, default / own {:.1}); E_β {:.2} → {:.2} mm; worst keypoints online (mm): {}",
            o / t,
            d / t,
            online.start_error(),
            online.end_error(),
            worst_keypoints(&online.run, 5)
        );
        assert!(d.is_finite() && t.is_finite() && o.is_finite());
        assert!(t < 0.5 * d, "{noise}: own model {t} mm vs default {d} mm");
        assert!(o < 0.8 * d, "{noise}: online {o} mm vs default {d} mm");
        assert!(online.end_error() < online.start_error());
        if noise == "none" {
            uncalibrated = d;
        }
    }
    let calibrated = offline(&hand);
    let run = fixed(&hand, "none", Some(calibrated));
    let c = last_third_error(&run);
    println!(
        "none: offline calibration (8 frames): {c:.2} mm; worst keypoints (mm): {}",
        worst_keypoints(&run, 5)
    );
    // β and rest rotations alone reach 2.19 mm (a third of the default template's error).
    assert!(
        c < 0.25 * uncalibrated,
        "offline {c} mm vs default {uncalibrated} mm"
    );
}
