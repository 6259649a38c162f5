//! `hands track`: run a tracker over a recorded or synthetic sequence and write the DESIGN.md
//! tracker output (`track.jsonl`, or the MCAP `/hand/track` channel).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use eval::markers::{frame_error, median};
use hand_model::cylinder::{default_right_hand_cylinders, CylinderModel};
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::SphereMeshTemplate;
use honline_calib::Estimator;
use sensor_io::io::{open_sequence, write_atomic, McapWriter, SequenceWriter, TRACK_TOPIC};
use sensor_io::preprocess::{
    DepthOnlyParams, PreprocessConfig, PreprocessedFrame, Preprocessor, Segmentation, SmoothParams,
    WristbandParams,
};

use crate::methods::{CylinderMethodModel, Cylinders, Method, MethodModel, TrackSettings};
use crate::trackers::FrameTracker;

/// Track a sequence (folder or `.mcap`) frame by frame.
///
/// Example: `hands track seq.mcap --model spheremesh --out track.jsonl --overlay overlay/`
#[derive(Args)]
pub struct TrackArgs {
    /// Input sequence: a folder or an `.mcap` file (see `hands synth`, `hands convert`).
    pub sequence: PathBuf,
    /// Tracking model: `spheremesh` (the Ch. 3 sphere-mesh tracker on `--template`), or the
    /// Ch. 2 cylinder tracker: `cylinders` (cylinders fitted to `--template`, default the default hand,
    /// with a wrist segment), `cylinders-htrack` (htrack's proportions, no wrist), an htrack
    /// `.calib` file, a sphere-mesh template `.json` or `subject:<name>` (a `hands synth`
    /// subject) — the last two give the cylinders fitted to that sphere-mesh.
    #[arg(long, default_value = "cylinders")]
    pub model: String,
    /// Online calibration of the sphere-mesh model while tracking (thesis Ch. 4):
    /// `online` (the joint cumulative IEKF), `online=iekf`, `online=kf` (split cumulative) or
    /// `online=per-frame`; with `--model spheremesh` (or `online`), starting from `--template`.
    /// The records carry the estimated β (`shape`) and its certainty (`shape_certainty`).
    #[arg(long, value_parser = parse_calibrate, value_name = "online[=iekf|kf|per-frame]")]
    pub calibrate: Option<Estimator>,
    /// The subject's sphere-mesh template when `--model` is a method name (`spheremesh`,
    /// `cylinders`: the cylinders are fitted to it): a template `.json` or `subject:<name>`
    /// (`subject:random:<seed>`: the random subject of `hands synth --subject random --seed
    /// <seed>`; default: the default hand).
    #[arg(long)]
    pub template: Option<String>,
    /// Output: `.jsonl` (one JSON object per frame, DESIGN.md "Tracker output") or `.mcap` (the
    /// input frames plus the records on `/hand/track`, for Foxglove).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write one PNG per frame into this folder: sensor depth in grey, the rendered model
    /// tinted blue, sensor points colored by their model distance (green 0 mm → red ≥ 10 mm).
    #[arg(long)]
    pub overlay: Option<PathBuf>,
    /// Tracker settings as JSON (any subset of the chosen tracker's fields, at any depth: the
    /// rest keep that tracker's defaults, the online calibrator's schedule included; the flags
    /// below override it).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// PCA pose prior: `project` (the project's own, embedded), a prior `.json` (`hands prior
    /// build`), `htrack:<dir>` (the original htrack files) or `none`.
    #[arg(long, default_value = "project")]
    pub prior: String,
    #[command(flatten)]
    pub pre: PreprocessArgs,
    /// Track at most this many frames.
    #[arg(long)]
    pub frames: Option<usize>,
    /// Plain closest-point correspondences instead of front-facing ones (Fig. 2.6, 3.9).
    #[arg(long)]
    pub no_front_facing: bool,
    /// No rigid-only first iteration (Fig. 2.17).
    #[arg(long)]
    pub no_rigid_first: bool,
    /// Cylinders: disable the 3D point-to-model term (Eq. 2.2).
    #[arg(long)]
    pub no_e3d: bool,
    /// Cylinders: disable the 2D silhouette term (Eq. 2.3).
    #[arg(long)]
    pub no_e2d: bool,
    /// Cylinders: disable the wristband term (Eq. 2.4).
    #[arg(long)]
    pub no_wrist: bool,
    /// Sphere-mesh: disable the data→model term (Eq. 3.4; the thesis never does: tracking is
    /// lost at once).
    #[arg(long)]
    pub no_d2m: bool,
    /// Sphere-mesh: disable the model→data term (Eq. 3.5).
    #[arg(long)]
    pub no_m2d: bool,
    /// Sphere-mesh: how E_m2d finds the model outside the silhouette: `render` (ray-cast the
    /// model, §3.3.2) or `centers` (projected sphere centers, §3.6).
    #[arg(long)]
    pub m2d: Option<String>,
    /// Register each point where its camera ray enters the model (either model) when that is
    /// within this many mm of it and of its closest point (point-to-plane, unbiased under depth
    /// noise), else at its closest point: `--ray-gate 20` on every frame, `--ray-gate off` for
    /// the thesis' correspondences everywhere. Default: 20 mm on frames whose measured depth
    /// noise is at least 1.5 mm (the config's `ray_gate`, `ray_gate_noise`).
    #[arg(long, value_name = "MM|off")]
    pub ray_gate: Option<String>,
    /// Disable the collision term (Eq. 2.7).
    #[arg(long)]
    pub no_collision: bool,
    /// Disable the PCA pose prior (Eq. 2.5–2.6).
    #[arg(long)]
    pub no_pose_prior: bool,
    /// Disable the joint limits (Eq. 2.8).
    #[arg(long)]
    pub no_joint_limits: bool,
    /// Disable the temporal prior (Eq. 2.9).
    #[arg(long)]
    pub no_temporal: bool,
}

/// `--calibrate`: `online` or `online=<estimator>`.
fn parse_calibrate(value: &str) -> Result<Estimator, String> {
    match value.split_once('=') {
        None if value == "online" => Ok(Estimator::Iekf),
        Some(("online", e)) => e.parse(),
        _ => Err(format!(
            "unknown calibration `{value}`: use online, online=iekf, online=kf or online=per-frame"
        )),
    }
}

/// The `--no-<term>` switches and the energy term each disables.
fn disabled_terms(args: &TrackArgs) -> Vec<(&'static str, &'static str)> {
    [
        ("--no-e3d", "e3d", args.no_e3d),
        ("--no-e2d", "e2d", args.no_e2d),
        ("--no-wrist", "wrist", args.no_wrist),
        ("--no-d2m", "d2m", args.no_d2m),
        ("--no-m2d", "m2d", args.no_m2d),
        ("--m2d", "m2d", args.m2d.is_some()),
        ("--no-collision", "collision", args.no_collision),
        ("--no-pose-prior", "pose_prior", args.no_pose_prior),
        ("--no-joint-limits", "joint_limits", args.no_joint_limits),
        ("--no-temporal", "temporal", args.no_temporal),
    ]
    .into_iter()
    .filter(|(_, _, set)| *set)
    .map(|(flag, term, _)| (flag, term))
    .collect()
}

/// The method of `--model` and its settings from the switches. A switch for a term the method
/// does not have is an error naming the model, rather than a silently ignored ablation.
fn settings(args: &TrackArgs, method: &dyn Method) -> Result<TrackSettings> {
    let mut disabled = Vec::new();
    for (flag, term) in disabled_terms(args) {
        if !method.terms().contains(&term) {
            bail!(
                "{flag} does not apply to --model {}: its terms are {}",
                args.model,
                method.terms().join(", ")
            );
        }
        if flag != "--m2d" {
            disabled.push(term);
        }
    }
    Ok(TrackSettings {
        config: args.config.clone(),
        front_facing: !args.no_front_facing,
        rigid_first: !args.no_rigid_first,
        disabled,
        m2d: args.m2d.clone(),
        ray_gate: args.ray_gate.clone(),
        estimator: args.calibrate,
    })
}

/// A sphere-mesh template: a template `.json` or `subject:<name>` (the `hands synth` subject of
/// seed 7 applied to the default hand; `subject:random:<seed>` the random subject that `hands
/// synth --subject random --seed <seed>` renders).
pub(crate) fn load_sphere_mesh(spec: &str) -> Result<SphereMeshTemplate> {
    if let Some(name) = spec.strip_prefix("subject:") {
        let (name, seed) = match name.split_once(':') {
            Some(("random", seed)) => (
                "random",
                seed.parse::<u64>().with_context(|| {
                    format!("`{spec}`: the seed after `random:` must be an integer")
                })?,
            ),
            Some((name, _)) => bail!("`{spec}`: only `subject:random` takes a seed, not `{name}`"),
            None => (name, 7),
        };
        let subject = datasets::subject_by_name(name, seed)?;
        let base = hand_model::spheremesh::default_right_hand();
        let basis = hand_model::spheremesh::ShapeBasis::honline(&base)?;
        return Ok(basis.apply(&base, &subject.beta)?);
    }
    if spec.ends_with(".json") {
        return SphereMeshTemplate::load(Path::new(spec))
            .with_context(|| format!("loading the sphere-mesh template {spec}"));
    }
    bail!("unknown sphere-mesh template `{spec}`: use a template .json or subject:<name>")
}

/// The method and model named by `--model` (with `--template`): a method name (the method's
/// model of the template, default the default hand), else a cylinder model of the Ch. 2 method.
fn load_model(
    name: &str,
    template: Option<&str>,
) -> Result<(&'static dyn Method, Box<dyn MethodModel>)> {
    if let Ok(method) = crate::methods::by_name(name) {
        let template = match template {
            Some(spec) => load_sphere_mesh(spec)?,
            None => hand_model::spheremesh::default_right_hand(),
        };
        return Ok((method, method.model(&template)?));
    }
    if template.is_some() {
        bail!(
            "--template does not apply to --model {name}: it needs a method name ({})",
            crate::methods::names()
        );
    }
    let cylinders = match name {
        "cylinders-htrack" => default_right_hand_cylinders(),
        p if p.ends_with(".calib") => hand_model::cylinder::load_htrack_calib(Path::new(p))?,
        p if p.ends_with(".json") || p.starts_with("subject:") => {
            CylinderModel::from_sphere_mesh_with_wrist(&load_sphere_mesh(p)?)?
        }
        other => bail!(
            "unknown --model `{other}`: use a method ({}), `cylinders-htrack`, an htrack .calib file, a sphere-mesh .json or subject:<name>",
            crate::methods::names()
        ),
    };
    Ok((&Cylinders, Box::new(CylinderMethodModel(cylinders))))
}

/// Load the prior named by `--prior`.
fn load_prior(spec: &str) -> Result<Option<PcaPrior>> {
    match spec {
        "none" => Ok(None),
        "project" => Ok(Some(PcaPrior::project_default())),
        s if s.starts_with("htrack:") => Ok(Some(PcaPrior::load_htrack_dir(Path::new(
            &s["htrack:".len()..],
        ))?)),
        s if s.ends_with(".json") => Ok(Some(PcaPrior::load_json(Path::new(s))?)),
        other => {
            bail!("unknown --prior `{other}`: use project, a .json file, htrack:<dir> or none")
        }
    }
}

/// How the frames of a sequence are preprocessed: the options of every command that reads one.
#[derive(Args, Clone, Debug)]
pub struct PreprocessArgs {
    /// Segmentation: `auto` (the wristband where the frame has color and a band is found, else
    /// depth only), `wristband`, `depth`, `presegmented`.
    #[arg(long, default_value = "auto")]
    pub segmentation: String,
    /// Number of sensor points per frame (0 = every silhouette pixel).
    #[arg(long, default_value_t = 2500)]
    pub points: usize,
    /// Radius (px, 0–5) of the edge-aware smoothing of noisy depth before its points are made
    /// (beyond the thesis: `sensor_io::preprocess::smooth_depth`, from a sequence's 31st frame
    /// once the measured noise is ≥ 1.5 mm); 0: the raw depth, as the thesis.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(0..=5))]
    pub smoothing: u32,
}

impl Default for PreprocessArgs {
    fn default() -> Self {
        Self {
            segmentation: "auto".into(),
            points: 2500,
            smoothing: SmoothParams::default().radius,
        }
    }
}

impl PreprocessArgs {
    /// The preprocessor's settings with `segmentation` instead of the named one.
    fn config(&self, segmentation: Segmentation) -> PreprocessConfig {
        PreprocessConfig {
            segmentation,
            num_points: self.points,
            smoothing: (self.smoothing > 0).then(|| SmoothParams {
                radius: self.smoothing,
                ..SmoothParams::default()
            }),
            ..Default::default()
        }
    }
}

fn segmentation(name: &str) -> Result<Segmentation> {
    Ok(match name {
        "wristband" | "auto" => Segmentation::Wristband(WristbandParams::default()),
        "depth" => Segmentation::DepthOnly(DepthOnlyParams::default()),
        "presegmented" => Segmentation::Presegmented,
        other => bail!("unknown --segmentation `{other}`: auto, wristband, depth or presegmented"),
    })
}

/// Run `hands track`.
pub fn run(args: TrackArgs) -> Result<()> {
    let ext = args.out.extension().and_then(|e| e.to_str());
    if !matches!(ext, Some("jsonl") | Some("mcap")) {
        bail!(
            "--out must end in .jsonl or .mcap, got {}",
            args.out.display()
        );
    }
    let prior = load_prior(&args.prior)?;
    let model_name = match (args.calibrate, args.model.as_str()) {
        (None, name) => name,
        (Some(_), "spheremesh" | "online") => "online",
        (Some(_), other) => bail!(
            "--calibrate calibrates the sphere-mesh model: use it with --model spheremesh, not --model {other}"
        ),
    };
    let (method, model) = load_model(model_name, args.template.as_deref())?;
    let settings = settings(&args, method)?;
    let mut tracker = model.tracker(prior.as_ref(), &settings)?;
    track_sequence(&args, tracker.as_mut())
}

/// The frame loop shared by both trackers: read, preprocess, track, write (and overlay), with
/// a progress bar, a partial write on Ctrl-C and a summary (timings, flags, ground-truth
/// errors when the sequence has them).
/// One frame of a sequence as [`for_each_frame`] hands it over.
pub(crate) struct SequenceFrame<'a> {
    /// Position in the sequence.
    pub position: usize,
    /// The raw frame.
    pub frame: &'a sensor_io::Frame,
    /// Its ground truth, when the sequence has one.
    pub truth: Option<&'a sensor_io::record::HandRecord>,
    /// The preprocessed frame.
    pub pre: &'a PreprocessedFrame,
    /// Preprocessing time (µs).
    pub preprocess_us: f64,
}

/// Read a sequence (folder or `.mcap`), preprocess every frame (segmentation `auto`: depth-only
/// where the wristband finds no hand) and hand it to `f`, with a progress bar labelled `label`,
/// stopping after `limit` frames or on Ctrl-C. Returns the number of frames.
pub(crate) fn for_each_frame(
    sequence: &Path,
    options: &PreprocessArgs,
    limit: Option<usize>,
    label: &'static str,
    mut f: impl FnMut(SequenceFrame<'_>) -> Result<()>,
) -> Result<usize> {
    let mut reader =
        open_sequence(sequence).with_context(|| format!("opening {}", sequence.display()))?;
    let camera = reader.camera().clone();
    let mut pre = Preprocessor::new(options.config(segmentation(&options.segmentation)?));
    let mut fallback = (options.segmentation == "auto").then(|| {
        Preprocessor::new(options.config(Segmentation::DepthOnly(DepthOnlyParams::default())))
    });
    let total = match (reader.len(), limit) {
        (Some(n), Some(m)) => Some(n.min(m)),
        (n, m) => n.or(m),
    };
    let bar = crate::progress::frames_bar(total, label);
    let mut frame_pre = PreprocessedFrame::default();
    let mut frames = 0usize;
    while let Some(item) = reader.next_frame() {
        if limit.is_some_and(|m| frames >= m) || crate::interrupt::requested() {
            break;
        }
        let (frame, truth) =
            item.with_context(|| format!("reading frame {frames} of {}", sequence.display()))?;
        let t0 = Instant::now();
        pre.process(&frame, &camera, &mut frame_pre)
            .with_context(|| format!("preprocessing frame {frames}"))?;
        if let Some(fb) = fallback.as_mut().filter(|_| frame_pre.hand.count == 0) {
            fb.process(&frame, &camera, &mut frame_pre)
                .with_context(|| format!("preprocessing frame {frames}"))?;
        }
        f(SequenceFrame {
            position: frames,
            frame: &frame,
            truth: truth.as_ref(),
            pre: &frame_pre,
            preprocess_us: t0.elapsed().as_secs_f64() * 1e6,
        })?;
        frames += 1;
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(frames)
}

fn track_sequence(args: &TrackArgs, tracker: &mut dyn FrameTracker) -> Result<()> {
    let ext = args.out.extension().and_then(|e| e.to_str());
    if let Some(dir) = &args.overlay {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let camera = open_sequence(&args.sequence)
        .with_context(|| format!("opening {}", args.sequence.display()))?
        .camera()
        .clone();
    let mut mcap = match ext {
        Some("mcap") => Some(
            McapWriter::create_with_record_topic(&args.out, &camera, TRACK_TOPIC)
                .with_context(|| format!("creating {}", args.out.display()))?,
        ),
        _ => None,
    };
    let mut lines = String::new();
    let mut stage_us: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    let mut flags: BTreeMap<String, usize> = BTreeMap::new();
    let mut errors = Vec::new();
    let frames = for_each_frame(&args.sequence, &args.pre, args.frames, "track", |sf| {
        let index = sf.truth.map_or(sf.position as u64, |t| t.frame);
        let timestamp = sf.truth.map_or(0.0, |t| t.timestamp);
        let mut rec = tracker.track(sf.pre, index, timestamp);
        rec.timing_us.insert("preprocess".into(), sf.preprocess_us);
        for (k, v) in &rec.timing_us {
            stage_us.entry(k.clone()).or_default().push(*v);
        }
        for f in &rec.flags {
            *flags.entry(f.clone()).or_default() += 1;
        }
        if let Some(e) = sf
            .truth
            .and_then(|t| frame_error(&rec.keypoints, &t.keypoints))
        {
            errors.push(e);
        }
        if !rec.is_finite() {
            bail!(
                "frame {}: the tracker produced a non-finite record (a bug)",
                sf.position
            );
        }
        if let Some(dir) = &args.overlay {
            write_overlay(dir, index, tracker, sf.pre)?;
        }
        match mcap.as_mut() {
            Some(w) => w
                .write(sf.frame, Some(&rec))
                .with_context(|| format!("writing {}", args.out.display()))?,
            None => {
                lines.push_str(&serde_json::to_string(&rec)?);
                lines.push('\n');
            }
        }
        Ok(())
    })?;
    match mcap.as_mut() {
        Some(w) => w.finish(),
        None => write_atomic(&args.out, lines.as_bytes()),
    }
    .with_context(|| format!("writing {}", args.out.display()))?;
    let note = if crate::interrupt::requested() {
        " (interrupted)"
    } else {
        ""
    };
    eprintln!("tracked {frames} frames{note} → {}", args.out.display());
    if let Some(dir) = &args.overlay {
        eprintln!("overlays → {}", dir.display());
    }
    let stages: Vec<String> = stage_us
        .into_iter()
        .map(|(k, v)| format!("{k} {:.0}", median(&v)))
        .collect();
    if !stages.is_empty() {
        eprintln!("median µs per frame: {}", stages.join(", "));
    }
    if !flags.is_empty() {
        let f: Vec<String> = flags.iter().map(|(k, v)| format!("{k} {v}")).collect();
        eprintln!("flagged frames: {}", f.join(", "));
    }
    for line in tracker.summary() {
        eprintln!("{line}");
    }
    if !errors.is_empty() {
        let n = errors.len() as f64;
        let mean = errors.iter().map(|e| e.mean).sum::<f64>() / n;
        let under = errors.iter().filter(|e| e.max < 25.0).count() as f64 / n;
        eprintln!(
            "ground truth: mean keypoint error {mean:.2} mm, {:.1}% of frames with max error < 25 mm",
            under * 100.0
        );
    }
    Ok(())
}

/// The overlay PNG of the frame just tracked (the model at the returned pose, the points'
/// distances at the last linearization).
fn write_overlay(
    dir: &Path,
    index: u64,
    tracker: &mut dyn FrameTracker,
    frame: &PreprocessedFrame,
) -> Result<()> {
    let camera = frame
        .camera
        .as_ref()
        .context("the preprocessed frame has no camera (a bug)")?;
    let distances = tracker.point_distances();
    let pixels = tracker
        .model_pixels(camera)
        .with_context(|| format!("rendering the model of frame {index}"))?;
    let image = crate::overlay::compose(frame, pixels, &distances);
    crate::overlay::write(dir, index, &image)
}

#[cfg(test)]
mod tests {
    use super::load_sphere_mesh;

    #[test]
    fn a_random_subject_template_takes_the_synth_seed() {
        let spheres = |spec: &str| load_sphere_mesh(spec).unwrap().spheres;
        let base = hand_model::spheremesh::default_right_hand();
        let basis = hand_model::spheremesh::ShapeBasis::honline(&base).unwrap();
        let beta = datasets::subject_by_name("random", 50).unwrap().beta;
        assert_eq!(
            spheres("subject:random:50"),
            basis.apply(&base, &beta).unwrap().spheres
        );
        assert_ne!(spheres("subject:random:50"), spheres("subject:random"));
        assert_eq!(spheres("subject:random:7"), spheres("subject:random"));
        let err = load_sphere_mesh("subject:random:x").unwrap_err();
        assert!(format!("{err:#}").contains("must be an integer"), "{err:#}");
        let err = load_sphere_mesh("subject:default:3").unwrap_err();
        assert!(
            format!("{err:#}").contains("only `subject:random`"),
            "{err:#}"
        );
    }
}
