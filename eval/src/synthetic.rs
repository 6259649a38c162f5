//! Scoring a tracker on a synthetic sequence with exact ground truth (issue 3's generator):
//! frames are rendered, preprocessed and tracked one at a time (nothing is held but the
//! per-frame records), and every tracked frame is scored against the true 21 keypoints.

use std::time::Instant;

use datasets::noise::SensorModel;
use datasets::synth::{SceneConfig, Synthesizer};
use datasets::{subject_by_name, Motion, MotionLibrary};
use hand_model::kinematics::Pose;
use hand_model::spheremesh::{default_right_hand, SphereMeshTemplate};
use sensor_io::preprocess::{
    PreprocessConfig, PreprocessedFrame, Preprocessor, Segmentation, WristbandParams,
};
use sensor_io::record::HandRecord;
use sensor_io::Camera;

use crate::markers::{frame_error, FrameError, MarkerSummary};

/// Which synthetic sequence (the `hands synth` settings) and how it is preprocessed.
#[derive(Clone, Debug)]
pub struct SyntheticSpec {
    /// Motion of the library (`teaser`, …).
    pub motion: String,
    /// Number of frames.
    pub frames: usize,
    /// Frame rate (Hz).
    pub fps: f64,
    /// Sensor model name (`none`, `quantized`, `tof`, `structured`).
    pub noise: String,
    /// Seed of motion, subject and noise.
    pub seed: u64,
    /// Subject name (`default`, …, `random`).
    pub subject: String,
    /// The camera.
    pub camera: Camera,
    /// Preprocessing (segmentation, number of points).
    pub preprocess: PreprocessConfig,
}

impl Default for SyntheticSpec {
    fn default() -> Self {
        Self {
            motion: "teaser".into(),
            frames: 600,
            fps: 60.0,
            noise: "none".into(),
            seed: 7,
            subject: "default".into(),
            camera: Camera::sr300_qvga(),
            preprocess: PreprocessConfig {
                segmentation: Segmentation::Wristband(WristbandParams::default()),
                ..PreprocessConfig::default()
            },
        }
    }
}

/// A pose function of time (s), writing into the pose.
type PoseFn = Box<dyn FnMut(f64, &mut Pose)>;

/// Where the poses of a sequence come from.
enum Poses {
    /// A motion of the library.
    Motion(Box<Motion>),
    /// A pose function.
    Custom(PoseFn),
}

/// A synthetic sequence ready to be tracked.
pub struct SyntheticSequence {
    spec: SyntheticSpec,
    synth: Synthesizer,
    poses: Poses,
    pose: Pose,
}

/// The outcome of tracking a synthetic sequence.
#[derive(Clone, Debug, Default)]
pub struct SyntheticRun {
    /// The tracker's record of every frame.
    pub records: Vec<HandRecord>,
    /// The ground truth of every frame.
    pub truth: Vec<HandRecord>,
    /// Per frame the keypoint errors (`None` when the record has no 21 finite keypoints).
    pub errors: Vec<Option<FrameError>>,
    /// Per frame the preprocessing time (µs).
    pub preprocess_us: Vec<f64>,
}

impl SyntheticRun {
    /// Summary of the frames with an error.
    pub fn summary(&self) -> MarkerSummary {
        let e: Vec<FrameError> = self.errors.iter().flatten().copied().collect();
        MarkerSummary::new(&e)
    }

    /// Fraction of frames carrying `flag`.
    pub fn flag_fraction(&self, flag: &str) -> f64 {
        if self.records.is_empty() {
            return 0.0;
        }
        let n = self
            .records
            .iter()
            .filter(|r| r.flags.iter().any(|f| f == flag))
            .count();
        n as f64 / self.records.len() as f64
    }

    /// Fraction of all frames whose maximum keypoint error is below `epsilon` (mm); a frame
    /// without an error (no keypoints) counts as above.
    pub fn fraction_max_under(&self, epsilon: f64) -> f64 {
        let maxes: Vec<f64> = self
            .errors
            .iter()
            .map(|e| e.map_or(f64::INFINITY, |e| e.max))
            .collect();
        crate::markers::fraction_under(&maxes, epsilon)
    }

    /// Per frame the mean keypoint error (NaN where there is none).
    pub fn mean_errors(&self) -> Vec<f64> {
        self.errors
            .iter()
            .map(|e| e.map_or(f64::NAN, |e| e.mean))
            .collect()
    }

    /// The median over frames of the tracker's time for `stage` (µs), NaN if never reported.
    pub fn median_stage_us(&self, stage: &str) -> f64 {
        let v: Vec<f64> = self
            .records
            .iter()
            .filter_map(|r| r.timing_us.get(stage).copied())
            .collect();
        crate::markers::median(&v)
    }
}

impl SyntheticSequence {
    /// Build the subject, the motion and the renderer of `spec`.
    pub fn new(spec: SyntheticSpec) -> anyhow::Result<Self> {
        let template = default_right_hand();
        let subject = subject_by_name(&spec.subject, spec.seed)?;
        let motion = MotionLibrary::by_name_for(&spec.motion, spec.seed, &template.skeleton)?;
        Self::build(spec, &subject.beta, Poses::Motion(Box::new(motion)))
    }

    /// A sequence of the subject `beta` (honline β of the default template, empty = the
    /// template itself) moving as `poses` says: `poses(t, pose)` writes the pose at time `t`
    /// (s) into `pose` (sized for the default skeleton). `spec.subject` and `spec.motion` are
    /// not used; the rest of `spec` is.
    pub fn custom(
        spec: SyntheticSpec,
        beta: &[f64],
        poses: impl FnMut(f64, &mut Pose) + 'static,
    ) -> anyhow::Result<Self> {
        Self::build(spec, beta, Poses::Custom(Box::new(poses)))
    }

    /// [`SyntheticSequence::custom`] for a hand outside the default template's β space:
    /// `hand` rendered as it is (a template of the default skeleton, whose pose `poses`
    /// writes) — another person's hand carried onto this skeleton, with its own rest rotations
    /// and sphere offsets.
    pub fn custom_hand(
        spec: SyntheticSpec,
        hand: &SphereMeshTemplate,
        poses: impl FnMut(f64, &mut Pose) + 'static,
    ) -> anyhow::Result<Self> {
        Self::build_for(spec, hand, &[], Poses::Custom(Box::new(poses)))
    }

    fn build(spec: SyntheticSpec, beta: &[f64], poses: Poses) -> anyhow::Result<Self> {
        Self::build_for(spec, &default_right_hand(), beta, poses)
    }

    fn build_for(
        spec: SyntheticSpec,
        template: &SphereMeshTemplate,
        beta: &[f64],
        poses: Poses,
    ) -> anyhow::Result<Self> {
        anyhow::ensure!(
            spec.fps.is_finite() && spec.fps > 0.0,
            "fps must be positive, got {}",
            spec.fps
        );
        let sensor = SensorModel::by_name(&spec.noise)
            .ok_or_else(|| anyhow::anyhow!("unknown noise model `{}`", spec.noise))?;
        let synth = Synthesizer::new(
            template,
            beta,
            SceneConfig {
                camera: spec.camera.clone(),
                sensor,
                seed: spec.seed,
                ..SceneConfig::default()
            },
        )?;
        let pose = Pose::zeros(&template.skeleton);
        Ok(Self {
            spec,
            synth,
            poses,
            pose,
        })
    }

    /// The subject's sphere-mesh template (what is rendered).
    pub fn template(&self) -> &SphereMeshTemplate {
        self.synth.template()
    }

    /// The settings.
    pub fn spec(&self) -> &SyntheticSpec {
        &self.spec
    }

    /// Render, preprocess and `track` every frame; `progress` is called after each frame.
    /// `track` gets the preprocessed frame and the ground truth (for the frame index and
    /// timestamp; a tracker must not read anything else of it).
    pub fn run(
        &mut self,
        mut track: impl FnMut(&PreprocessedFrame, &HandRecord) -> HandRecord,
        mut progress: impl FnMut(usize),
    ) -> anyhow::Result<SyntheticRun> {
        let mut pre = Preprocessor::new(self.spec.preprocess.clone());
        let mut out = PreprocessedFrame::default();
        let mut run = SyntheticRun::default();
        for k in 0..self.spec.frames {
            let t = k as f64 / self.spec.fps;
            match &mut self.poses {
                Poses::Motion(m) => m.pose_into(t, &mut self.pose),
                Poses::Custom(f) => f(t, &mut self.pose),
            }
            let f = self.synth.render(k as u64, t, &self.pose)?;
            let t0 = Instant::now();
            pre.process(&f.frame, &self.spec.camera, &mut out)?;
            run.preprocess_us.push(t0.elapsed().as_secs_f64() * 1e6);
            let rec = track(&out, &f.truth);
            run.errors
                .push(frame_error(&rec.keypoints, &f.truth.keypoints));
            run.records.push(rec);
            run.truth.push(f.truth);
            progress(k);
        }
        Ok(run)
    }
}
