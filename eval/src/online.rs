//! Synthetic experiments of the online calibration (thesis §4.4.2–4.4.3, issue 8): subjects
//! drawn at a relative perturbation σ from the default template, the draws of Fig. 4.7 (a
//! user's shape and an initialization perturbed from it by σ, [`Fig47Draw`]), a teaser-like
//! motion — every digit bending with its own period and phase while the hand turns, optionally
//! held straight first (the "uncooperative user" of §4.4.3) — and runners that track such a
//! sequence (rendered, sensor-modelled and preprocessed by [`SyntheticSequence`]) with the
//! online calibrator or with the subject's true template, keeping what the figures need: per
//! frame the estimate β̂_n, the per-frame mode β*_n, both certainties and the keypoint error.

use std::f64::consts::TAU;

use datasets::subjects::{Subject, MAX_PERTURBATION};
use hand_model::kinematics::{Pose, Skeleton};
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::{default_right_hand, ShapeBasis, ShapeKind, SphereMeshTemplate};
use hmodel_spheremesh::{Tracker, TrackerConfig};
use honline_calib::terms::finger_order_constraints;
use honline_calib::{
    beta_error, calibrate_offline_from, error_subset, subsample, OfflineConfig, OnlineCalibrator,
    OnlineConfig, SUBSAMPLING,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sensor_io::preprocess::PreprocessedFrame;

use crate::synthetic::{SyntheticRun, SyntheticSequence, SyntheticSpec};

/// Largest |ξ| of a perturbation draw: a relative factor `1 + σξ` beyond 2.5σ is redrawn (at
/// σ = 0.4 a parameter may still shrink to 0 otherwise).
const MAX_SIGMAS: f64 = 2.5;

/// A standard normal draw (Box–Muller).
fn standard_normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random_range(f64::EPSILON..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
}

/// The entries of `basis` that the Fig. 4.7 experiments perturb and score: the lengths and
/// radii of the E_β subset ([`error_subset`]) — every phalanx length and every radius. Left
/// out: the palm centers, `wrist_width`/`wrist_length`, the thumb membrane and
/// `thumb_additional` (the null space of the data terms or buried, [`honline_calib::ShapeSubset`]),
/// and the position entries (finger-base x/y/z, thumb base, `wrist_width_left`): a relative
/// perturbation of a position depends on where the palm frame's origin is (±30 % moves the
/// index base 8 mm sideways but the middle base 2 mm), and a finger base moved 20 mm along the
/// palm leaves a finger floating beyond the palm, no hand at all.
pub fn size_subset(basis: &ShapeBasis) -> Vec<usize> {
    error_subset(basis)
        .into_iter()
        .filter(|&i| {
            matches!(
                basis.params[i].kind,
                ShapeKind::PhalangeLength | ShapeKind::TopPhalangeLength | ShapeKind::Radius
            )
        })
        .collect()
}

/// A subject for the tracking experiments (the acceptance's "random subject"): the default
/// template's honline β with every entry of [`size_subset`] multiplied by `1 + σξ`, ξ ~ N(0, 1)
/// truncated at ±2.5, redrawn while it leaves the β bounds; the whole draw is redrawn while the
/// basis refuses it or it breaks a finger-order constraint of Eq. 4.15. The other entries keep
/// the template values. Deterministic in `seed`; an error for a σ outside [0, 1] or when 1000
/// draws fail.
pub fn perturbed_subject(sigma: f64, seed: u64) -> anyhow::Result<Vec<f64>> {
    let basis = ShapeBasis::honline(&default_right_hand())?;
    perturbed_shape(&basis.template_values(), sigma, seed)
}

/// `center` (an honline β) with its [`size_subset`] entries perturbed as [`perturbed_subject`]
/// perturbs the default template's.
pub fn perturbed_shape(center: &[f64], sigma: f64, seed: u64) -> anyhow::Result<Vec<f64>> {
    anyhow::ensure!(
        (0.0..=1.0).contains(&sigma),
        "σ must be in [0, 1], got {sigma}"
    );
    let base = default_right_hand();
    let basis = ShapeBasis::honline(&base)?;
    anyhow::ensure!(
        center.len() == basis.len(),
        "{} shape values for {} parameters",
        center.len(),
        basis.len()
    );
    let subset = size_subset(&basis);
    let constraints = finger_order_constraints(&basis);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x4F37_A9C1_0D2E_6B58);
    for _ in 0..1000 {
        let mut beta = center.to_vec();
        for &i in &subset {
            let [lo, hi] = basis.params[i]
                .limits
                .unwrap_or([f64::NEG_INFINITY, f64::INFINITY]);
            let v = (0..100).find_map(|_| {
                let xi = standard_normal(&mut rng);
                let v = center[i] * (1.0 + sigma * xi);
                (xi.abs() <= MAX_SIGMAS && (lo..=hi).contains(&v)).then_some(v)
            });
            beta[i] = v.unwrap_or(center[i]);
        }
        if basis.apply(&base, &beta).is_ok() && constraints.iter().all(|c| c.value(&beta) >= 0.0) {
            return Ok(beta);
        }
    }
    anyhow::bail!("no valid shape at σ = {sigma} from seed {seed}")
}

/// One draw of Fig. 4.7 (thesis §4.4.3): the depth maps are rendered from a user's known shape
/// β̄ and the calibration starts from "random initializations … drawn from N(β̄, σ)".
#[derive(Clone, Debug, PartialEq)]
pub struct Fig47Draw {
    /// The user's shape β̄: a random subject of `datasets` at its largest perturbation (latent
    /// height/width/thickness, then up to ±25 % per parameter, within the human hand-length
    /// range) — a hand unlike the default template, as the thesis' user (a scanned real hand)
    /// is; the shape-space prior (Eq. 4.14) stays anchored on the default template.
    pub user: Vec<f64>,
    /// The initialization: `user` perturbed by σ ([`perturbed_shape`]).
    pub start: Vec<f64>,
}

impl Fig47Draw {
    /// Draw `seed` at `sigma`; an error for a σ outside [0, 1].
    pub fn new(sigma: f64, seed: u64) -> anyhow::Result<Self> {
        let user = Subject::random(seed, MAX_PERTURBATION)?.beta;
        let start = perturbed_shape(&user, sigma, seed)?;
        Ok(Self { user, start })
    }
}

/// The teaser-like motion of the synthetic calibration experiments (thesis §4.4.2 animates the
/// Handy/Teaser poses; ours is analytic so that the bending can be held off): the palm faces
/// the camera ~400 mm away and turns (yaw ±0.6 rad, pitch ±0.3, roll ±0.15) while every digit
/// flexes and extends with its own period (2.6–4.4 s) and phase, the MCP a quarter period
/// ahead of the PIP and DIP (so the phalanges are seen bent one at a time, Fig. 4.4; the DIP
/// follows the PIP at ≈ 0.65 of its angle, the coupling of real fingers), the
/// digits spread between a quarter and all of the library's `spread` key pose (never pressed
/// together), the wrist sways. For the first `straight_s` seconds the digits stay
/// straight (the "uncooperative user"); the bending then fades in over one second.
#[derive(Clone, Debug)]
pub struct CalibrationMotion {
    /// Seconds with straight digits before they start bending.
    pub straight_s: f64,
    /// Per digit (thumb … pinky): period (s) and phase (rad).
    waves: [(f64, f64); 5],
    /// Skeleton DOF index per name of [`CalibrationMotion::pose_into`]'s channels.
    index: Vec<(String, usize)>,
    num_dofs: usize,
    limits: Vec<Option<[f64; 2]>>,
}

impl CalibrationMotion {
    /// The motion for `skeleton` (the default template's DOF names), periods and phases drawn
    /// from `seed`.
    pub fn new(skeleton: &Skeleton, straight_s: f64, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x1D8E_4E27_C47D_124F);
        let waves = std::array::from_fn(|d| {
            let period = 2.6 + 0.45 * d as f64 + rng.random_range(-0.3..0.3);
            (period, rng.random_range(0.0..TAU))
        });
        let index = skeleton
            .dofs()
            .iter()
            .enumerate()
            .map(|(i, d)| (d.name.clone(), i))
            .collect();
        Self {
            straight_s: straight_s.max(0.0),
            waves,
            index,
            num_dofs: skeleton.num_dofs(),
            limits: skeleton.dofs().iter().map(|d| d.limits).collect(),
        }
    }

    /// The bending envelope at `t`: 0 while straight, a smoothstep to 1 over the next second.
    fn envelope(&self, t: f64) -> f64 {
        let u = (t - self.straight_s).clamp(0.0, 1.0);
        u * u * (3.0 - 2.0 * u)
    }

    /// The pose at time `t` (s), clamped to the joint limits; `pose` is resized to the skeleton.
    pub fn pose_into(&self, t: f64, pose: &mut Pose) {
        let t = if t.is_finite() { t } else { 0.0 };
        let placement = datasets::motion::Placement {
            position: nalgebra::Vector3::new(
                12.0 * (TAU * t / 6.1).sin(),
                8.0 * (TAU * t / 7.7).sin(),
                400.0 + 25.0 * (TAU * t / 9.3).sin(),
            ),
            yaw: 0.6 * (TAU * t / 8.0).sin(),
            pitch: 0.3 * (TAU * t / 6.5).sin(),
            roll: 0.15 * (TAU * t / 11.0).sin(),
        };
        let tr = placement.translation();
        let eu = placement.euler();
        let env = self.envelope(t);
        pose.values.clear();
        pose.values.resize(self.num_dofs, 0.0);
        for (name, i) in &self.index {
            let digit = datasets::motion::DIGITS
                .iter()
                .position(|d| name.starts_with(d));
            let wave = |lag: f64| {
                digit.map_or(0.0, |d| {
                    let (period, phase) = self.waves[d];
                    env * 0.5 * (1.0 - (TAU * t / period + phase - lag).cos())
                })
            };
            // Outward only (the library's `spread` key pose scaled by 0.25–1): fingers held
            // together would press into each other, which a real hand cannot.
            let spread = |d: usize| {
                let amount = 0.625 + 0.375 * (TAU * t / (3.7 + d as f64) + d as f64).sin();
                amount * [0.6, 0.3, 0.05, -0.15, -0.3][d]
            };
            pose.values[*i] = match (name.as_str(), digit) {
                ("global_tx", _) => tr.x,
                ("global_ty", _) => tr.y,
                ("global_tz", _) => tr.z,
                ("global_rx", _) => eu[0],
                ("global_ry", _) => eu[1],
                ("global_rz", _) => eu[2],
                ("wrist_flex", _) => 0.25 * (TAU * t / 5.3).sin(),
                ("wrist_abd", _) => 0.12 * (TAU * t / 7.1).sin(),
                ("thumb_cmc_abd", _) => spread(0),
                ("thumb_cmc_flex", _) => 0.35 * wave(0.0),
                ("thumb_mcp_flex", _) => 0.55 * wave(0.0),
                ("thumb_ip_flex", _) => 0.7 * wave(TAU / 4.0),
                (n, Some(d)) if n.ends_with("_mcp_abd") => spread(d),
                (n, Some(_)) if n.ends_with("_mcp_flex") => 1.1 * wave(0.0),
                (n, Some(_)) if n.ends_with("_pip_flex") => 1.4 * wave(TAU / 4.0),
                (n, Some(_)) if n.ends_with("_dip_flex") => 0.9 * wave(TAU / 4.0),
                _ => 0.0,
            };
        }
        for (v, l) in pose.values.iter_mut().zip(&self.limits) {
            if let Some([lo, hi]) = l {
                *v = v.clamp(*lo, *hi);
            }
        }
    }

    /// [`CalibrationMotion::pose_into`] into a new pose.
    pub fn pose_at(&self, t: f64) -> Pose {
        let mut pose = Pose { values: vec![] };
        self.pose_into(t, &mut pose);
        pose
    }
}

/// An online-calibration run on a synthetic sequence.
pub struct OnlineRun {
    /// The calibrator's output of every frame.
    pub frames: Vec<honline_calib::OnlineFrame>,
    /// Records, ground truth and keypoint errors.
    pub run: SyntheticRun,
    /// The subject's β.
    pub truth: Vec<f64>,
    /// The E_β subset (Eq. 4.16): [`size_subset`].
    pub subset: Vec<usize>,
    /// The template's β (the starting estimate).
    pub template: Vec<f64>,
}

impl OnlineRun {
    /// E_β (Eq. 4.16, mm) of the starting template.
    pub fn start_error(&self) -> f64 {
        beta_error(&self.template, &self.truth, &self.subset)
    }

    /// E_β (mm) of the estimate β̂ after frame `k` (the last frame for `k` out of range).
    pub fn error_at(&self, k: usize) -> f64 {
        let Some(f) = self.frames.get(k).or(self.frames.last()) else {
            return self.start_error();
        };
        beta_error(&f.beta, &self.truth, &self.subset)
    }

    /// E_β (mm) of the final estimate (for the per-frame estimator: its last frame's mode, as in
    /// the thesis' Fig. 4.7).
    pub fn end_error(&self) -> f64 {
        self.error_at(usize::MAX)
    }

    /// E_β (mm) of the final estimate over `subset` (e.g. the thesis' M, [`error_subset`]).
    pub fn end_error_over(&self, subset: &[usize]) -> f64 {
        let last = self.frames.last().map_or(&self.template, |f| &f.beta);
        beta_error(last, &self.truth, subset)
    }
}

/// A sequence of subject `beta` moving as `motion` under `spec` (noise, fps, frames, camera,
/// preprocessing; `spec.subject` and `spec.motion` are not used).
pub fn calibration_sequence(
    spec: &SyntheticSpec,
    beta: &[f64],
    motion: &CalibrationMotion,
) -> anyhow::Result<SyntheticSequence> {
    let m = motion.clone();
    SyntheticSequence::custom(spec.clone(), beta, move |t, p| m.pose_into(t, p))
}

/// Track subject `truth` (honline β) moving as `motion` with the online calibrator (`config`,
/// the default PCA pose prior) starting from the shape `start` (`None`: the default template)
/// and the true first pose (thesis §4.4.2: "initialized in the first frame by θ̄_0").
pub fn run_online(
    spec: &SyntheticSpec,
    truth: &[f64],
    start: Option<&[f64]>,
    motion: &CalibrationMotion,
    config: OnlineConfig,
) -> anyhow::Result<OnlineRun> {
    let seq = calibration_sequence(spec, truth, motion)?;
    run_online_on(seq, truth, start, motion, config)
}

/// [`run_online`] on a given sequence `seq` of a hand moving as `motion` (another person's
/// hand: [`SyntheticSequence::custom_hand`]); `truth` is what E_β measures against.
pub fn run_online_on(
    mut seq: SyntheticSequence,
    truth: &[f64],
    start: Option<&[f64]>,
    motion: &CalibrationMotion,
    config: OnlineConfig,
) -> anyhow::Result<OnlineRun> {
    let base = default_right_hand();
    let prior = PcaPrior::project_default();
    let mut calib = OnlineCalibrator::new(&base, config, Some(&prior))?;
    if let Some(beta) = start {
        calib.set_shape(beta)?;
    }
    calib.set_pose(&motion.pose_at(0.0))?;
    let mut frames = Vec::with_capacity(seq.spec().frames);
    let run = seq.run(
        |f, t| {
            let out = calib.track(f, t.frame, t.timestamp);
            let rec = out.record.clone();
            frames.push(out);
            rec
        },
        |_| {},
    )?;
    Ok(OnlineRun {
        frames,
        run,
        truth: truth.to_vec(),
        subset: size_subset(calib.basis()),
        template: start.map_or_else(|| calib.basis().template_values(), <[f64]>::to_vec),
    })
}

/// An Offline-Hard or Offline-Soft calibration (thesis §4.3.4) of a synthetic sequence.
pub struct OfflineRun {
    /// The calibrated β.
    pub beta: Vec<f64>,
    /// The subject's β.
    pub truth: Vec<f64>,
    /// The E_β subset (Eq. 4.16): [`size_subset`].
    pub subset: Vec<usize>,
    /// The frames calibrated from.
    pub frames: Vec<usize>,
    /// Seconds of the batch solve (tracking pass excluded).
    pub seconds: f64,
}

impl OfflineRun {
    /// E_β (Eq. 4.16, mm) of the calibrated β.
    pub fn end_error(&self) -> f64 {
        beta_error(&self.beta, &self.truth, &self.subset)
    }
}

/// Calibrate subject `truth` moving as `motion` offline as `hands calibrate --method
/// offline-hard|offline-soft` does: the sequence is tracked with the Ch. 3 tracker on the
/// template of shape `start` (`None`: the default template) from the true first pose, the
/// tracked frames are sub-sampled at 1/[`SUBSAMPLING`] (§4.3.4) and β is fitted jointly with
/// their poses from `start` (`config.method` says Hard or Soft).
pub fn run_offline(
    spec: &SyntheticSpec,
    truth: &[f64],
    start: Option<&[f64]>,
    motion: &CalibrationMotion,
    config: &OfflineConfig,
) -> anyhow::Result<OfflineRun> {
    let base = default_right_hand();
    let basis = ShapeBasis::honline(&base)?;
    let initial = match start {
        Some(beta) => basis.apply(&base, beta)?,
        None => base.clone(),
    };
    let prior = PcaPrior::project_default();
    let mut tracker = Tracker::new(&initial, config.frame.tracker.clone(), Some(&prior))?;
    tracker.set_pose(&motion.pose_at(0.0))?;
    let mut seq = calibration_sequence(spec, truth, motion)?;
    let sk = &base.skeleton;
    let (mut frames, mut poses, mut usable) = (Vec::new(), Vec::new(), Vec::new());
    let every = SUBSAMPLING;
    seq.run(
        |f, t| {
            let rec = tracker.track(f, t.frame, t.timestamp);
            usable.push(rec.flags.is_empty());
            // Only the frames that can be chosen are kept (the first usable of every `every`).
            let k = usable.len() - 1;
            let block = k / every * every;
            if rec.flags.is_empty() && !usable[block..k].iter().any(|&u| u) {
                let named = rec.pose.iter().map(|(n, &v)| (n.as_str(), v));
                // A pose the skeleton refuses leaves the frame out; the check against
                // `subsample` below then reports it.
                if let Ok(pose) = Pose::from_named(sk, named) {
                    frames.push((k, f.clone()));
                    poses.push(pose);
                }
            }
            rec
        },
        |_| {},
    )?;
    let chosen = subsample(&usable, every);
    anyhow::ensure!(
        chosen == frames.iter().map(|(k, _)| *k).collect::<Vec<_>>(),
        "offline frame choice disagrees with honline_calib::subsample"
    );
    let kept: Vec<PreprocessedFrame> = frames.into_iter().map(|(_, f)| f).collect();
    let cal = calibrate_offline_from(&base, start, &kept, &poses, config, Some(&prior))?;
    Ok(OfflineRun {
        beta: cal.beta,
        truth: truth.to_vec(),
        subset: size_subset(&basis),
        frames: chosen,
        seconds: cal.seconds,
    })
}

/// Track subject `truth` moving as `motion` with the Ch. 3 sphere-mesh tracker (`config`) on the
/// subject's true template, from the true first pose: the reference of the online calibration.
pub fn run_true_template(
    spec: &SyntheticSpec,
    truth: &[f64],
    motion: &CalibrationMotion,
    config: TrackerConfig,
) -> anyhow::Result<SyntheticRun> {
    run_fixed_template(spec, truth, motion, config, None)
}

/// [`run_true_template`] with the default template instead of the subject's (no calibration at
/// all): the baseline that online calibration has to beat.
pub fn run_default_template(
    spec: &SyntheticSpec,
    truth: &[f64],
    motion: &CalibrationMotion,
    config: TrackerConfig,
) -> anyhow::Result<SyntheticRun> {
    run_fixed_template(spec, truth, motion, config, Some(default_right_hand()))
}

/// Track the rendering of subject `truth` with a fixed template: `template`, or the subject's own
/// when `None`.
fn run_fixed_template(
    spec: &SyntheticSpec,
    truth: &[f64],
    motion: &CalibrationMotion,
    config: TrackerConfig,
    template: Option<SphereMeshTemplate>,
) -> anyhow::Result<SyntheticRun> {
    let seq = calibration_sequence(spec, truth, motion)?;
    run_template_on(seq, motion, config, template)
}

/// Track `seq` (a hand moving as `motion`) with the Ch. 3 tracker on a fixed template:
/// `template`, or the rendered hand's own when `None`.
pub fn run_template_on(
    mut seq: SyntheticSequence,
    motion: &CalibrationMotion,
    config: TrackerConfig,
    template: Option<SphereMeshTemplate>,
) -> anyhow::Result<SyntheticRun> {
    let template = template.unwrap_or_else(|| seq.template().clone());
    let prior = PcaPrior::project_default();
    let mut tracker = Tracker::new(&template, config, Some(&prior))?;
    tracker.set_pose(&motion.pose_at(0.0))?;
    seq.run(|f, t| tracker.track(f, t.frame, t.timestamp), |_| {})
}

/// The mean keypoint error (mm) over the frames of the last third of `run` that have one (NaN
/// when none has).
pub fn last_third_error(run: &SyntheticRun) -> f64 {
    let e = run.mean_errors();
    let tail = &e[e.len() - e.len() / 3..];
    let v: Vec<f64> = tail.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subjects_are_valid_deterministic_and_scaled_by_sigma() {
        let basis = ShapeBasis::honline(&default_right_hand()).unwrap();
        let subset = size_subset(&basis);
        assert_eq!(subset.len(), 44);
        let template = basis.template_values();
        let spread = |sigma: f64| {
            let b = perturbed_subject(sigma, 3).unwrap();
            assert_eq!(b, perturbed_subject(sigma, 3).unwrap());
            subset
                .iter()
                .map(|&i| (b[i] / template[i] - 1.0).abs())
                .sum::<f64>()
                / subset.len() as f64
        };
        let (s1, s4) = (spread(0.1), spread(0.4));
        // E|ξ| = 0.8 for a standard normal (a little less truncated).
        assert!((0.04..0.12).contains(&s1), "{s1}");
        assert!(s4 > 2.5 * s1, "{s1} {s4}");
        assert!(perturbed_subject(1.5, 0).is_err());
        assert!(perturbed_subject(f64::NAN, 0).is_err());
    }

    #[test]
    fn the_motion_holds_the_digits_straight_then_bends_them() {
        let sk = &default_right_hand().skeleton;
        let m = CalibrationMotion::new(sk, 2.0, 1);
        let flex = |p: &Pose| {
            sk.dofs()
                .iter()
                .zip(&p.values)
                .filter(|(d, _)| d.name.contains("_flex") && !d.name.starts_with("wrist"))
                .map(|(_, v)| v.abs())
                .fold(0.0, f64::max)
        };
        let straight = (0..60).map(|k| flex(&m.pose_at(k as f64 / 30.0)));
        assert!(straight.fold(0.0, f64::max) < 1e-12);
        let bent = (90..300).map(|k| flex(&m.pose_at(k as f64 / 30.0)));
        assert!(bent.fold(0.0, f64::max) > 1.0);
        assert!(m.pose_at(f64::NAN).values.iter().all(|v| v.is_finite()));
    }
}
