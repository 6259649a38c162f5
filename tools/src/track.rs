//! `hands track`: run a tracker over a recorded or synthetic sequence and write the DESIGN.md
//! tracker output (`track.jsonl`, or the MCAP `/hand/track` channel).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use hand_model::cylinder::{default_right_hand_cylinders, CylinderModel};
use hand_model::solver::PcaPrior;
use htrack_icp::{Tracker, TrackerConfig};
use sensor_io::io::{open_sequence, write_atomic, McapWriter, SequenceWriter, TRACK_TOPIC};
use sensor_io::preprocess::{
    DepthOnlyParams, PreprocessConfig, PreprocessedFrame, Preprocessor, Segmentation,
    WristbandParams,
};
use sensor_io::record::HandRecord;

/// Track a sequence (folder or `.mcap`) frame by frame.
///
/// Example: `hands track seq.mcap --model cylinders --out track.jsonl`
#[derive(Args)]
pub struct TrackArgs {
    /// Input sequence: a folder or an `.mcap` file (see `hands synth`, `hands convert`).
    pub sequence: PathBuf,
    /// Tracking model (the Ch. 2 cylinder tracker): `cylinders` (cylinders fitted to the default
    /// sphere-mesh hand, with a wrist segment), `cylinders-htrack` (htrack's proportions, no
    /// wrist), an htrack `.calib` file, a sphere-mesh template `.json` or `subject:<name>` (a
    /// `hands synth` subject) — the last two give the cylinders fitted to that sphere-mesh.
    #[arg(long, default_value = "cylinders")]
    pub model: String,
    /// Output: `.jsonl` (one JSON object per frame, DESIGN.md "Tracker output") or `.mcap` (the
    /// input frames plus the records on `/hand/track`, for Foxglove).
    #[arg(long)]
    pub out: PathBuf,
    /// Tracker settings as JSON (any subset of the fields; the flags below override it).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// PCA pose prior: `project` (the project's own, embedded), a prior `.json` (`hands prior
    /// build`), `htrack:<dir>` (the original htrack files) or `none`.
    #[arg(long, default_value = "project")]
    pub prior: String,
    /// Segmentation: `auto` (the wristband where the frame has color and a band is found, else
    /// depth only), `wristband`, `depth`, `presegmented`.
    #[arg(long, default_value = "auto")]
    pub segmentation: String,
    /// Number of sensor points per frame (0 = every silhouette pixel).
    #[arg(long, default_value_t = 2500)]
    pub points: usize,
    /// Track at most this many frames.
    #[arg(long)]
    pub frames: Option<usize>,
    /// Plain closest-point correspondences instead of front-facing ones (Fig. 2.6).
    #[arg(long)]
    pub no_front_facing: bool,
    /// No rigid-only first iteration (Fig. 2.17).
    #[arg(long)]
    pub no_rigid_first: bool,
    /// Disable the 3D point-to-model term (Eq. 2.2).
    #[arg(long)]
    pub no_e3d: bool,
    /// Disable the 2D silhouette term (Eq. 2.3).
    #[arg(long)]
    pub no_e2d: bool,
    /// Disable the wristband term (Eq. 2.4).
    #[arg(long)]
    pub no_wrist: bool,
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

/// Load the tracking model named by `--model`.
fn load_model(name: &str) -> Result<CylinderModel> {
    match name {
        "cylinders" => Ok(CylinderModel::from_sphere_mesh_with_wrist(
            &hand_model::spheremesh::default_right_hand(),
        )?),
        "cylinders-htrack" => Ok(default_right_hand_cylinders()),
        p if p.ends_with(".calib") => Ok(hand_model::cylinder::load_htrack_calib(Path::new(p))?),
        p if p.ends_with(".json") => {
            let t = hand_model::spheremesh::SphereMeshTemplate::load(Path::new(p))?;
            Ok(CylinderModel::from_sphere_mesh_with_wrist(&t)?)
        }
        p if p.starts_with("subject:") => {
            let subject = datasets::subject_by_name(&p["subject:".len()..], 7)?;
            let base = hand_model::spheremesh::default_right_hand();
            let basis = hand_model::spheremesh::ShapeBasis::honline(&base)?;
            Ok(CylinderModel::from_sphere_mesh_with_wrist(&basis.apply(&base, &subject.beta)?)?)
        }
        other => bail!(
            "unknown --model `{other}`: use `cylinders`, `cylinders-htrack`, an htrack .calib file, a sphere-mesh .json or subject:<name> (the sphere-mesh \
             tracker is issue 5)"
        ),
    }
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

/// The tracker settings: defaults, then `--config`, then the switches.
fn tracker_config(args: &TrackArgs) -> Result<TrackerConfig> {
    let mut cfg: TrackerConfig = match &args.config {
        Some(p) => {
            let text =
                std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            serde_json::from_str(&text).with_context(|| format!("parsing {}", p.display()))?
        }
        None => TrackerConfig::default(),
    };
    cfg.front_facing &= !args.no_front_facing;
    if args.no_rigid_first {
        cfg.lm.rigid_iterations = 0;
    }
    let e = &mut cfg.enabled;
    e.e3d &= !args.no_e3d;
    e.e2d &= !args.no_e2d;
    e.wrist &= !args.no_wrist;
    e.collision &= !args.no_collision;
    e.pose_prior &= !args.no_pose_prior;
    e.joint_limits &= !args.no_joint_limits;
    e.temporal &= !args.no_temporal;
    Ok(cfg)
}

fn segmentation(name: &str) -> Result<Segmentation> {
    Ok(match name {
        "wristband" | "auto" => Segmentation::Wristband(WristbandParams::default()),
        "depth" => Segmentation::DepthOnly(DepthOnlyParams::default()),
        "presegmented" => Segmentation::Presegmented,
        other => bail!("unknown --segmentation `{other}`: auto, wristband, depth or presegmented"),
    })
}

/// Median of a non-empty list (NaN for an empty one).
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Ground-truth keypoint errors of one frame: (mean, max) over the 21 keypoints (mm).
fn keypoint_errors(track: &HandRecord, truth: &HandRecord) -> Option<(f64, f64)> {
    if track.keypoints.len() != truth.keypoints.len() || truth.keypoints.is_empty() {
        return None;
    }
    let d: Vec<f64> = track
        .keypoints
        .iter()
        .zip(&truth.keypoints)
        .map(|(a, b)| {
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        })
        .collect();
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    Some((mean, d.iter().copied().fold(0.0, f64::max)))
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
    let model = load_model(&args.model)?;
    let prior = load_prior(&args.prior)?;
    let config = tracker_config(&args)?;
    let mut reader = open_sequence(&args.sequence)
        .with_context(|| format!("opening {}", args.sequence.display()))?;
    let camera = reader.camera().clone();
    let mut pre = Preprocessor::new(PreprocessConfig {
        segmentation: segmentation(&args.segmentation)?,
        num_points: args.points,
        ..Default::default()
    });
    // `auto`: depth-only segmentation for the frames where the wristband finds no hand.
    let mut fallback = (args.segmentation == "auto").then(|| {
        Preprocessor::new(PreprocessConfig {
            segmentation: Segmentation::DepthOnly(DepthOnlyParams::default()),
            num_points: args.points,
            ..Default::default()
        })
    });
    let mut tracker = Tracker::new(&model, config, prior.as_ref())?;
    let total = match (reader.len(), args.frames) {
        (Some(n), Some(m)) => Some(n.min(m)),
        (n, m) => n.or(m),
    };
    let bar = crate::progress::frames_bar(total, "track");
    let mut mcap = match ext {
        Some("mcap") => Some(
            McapWriter::create_with_record_topic(&args.out, &camera, TRACK_TOPIC)
                .with_context(|| format!("creating {}", args.out.display()))?,
        ),
        _ => None,
    };
    let mut lines = String::new();
    let mut frame_pre = PreprocessedFrame::default();
    let mut stage_us: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    let mut flags: BTreeMap<String, usize> = BTreeMap::new();
    let (mut errors, mut frames) = (Vec::new(), 0usize);
    while let Some(item) = reader.next_frame() {
        if args.frames.is_some_and(|m| frames >= m) || crate::interrupt::requested() {
            break;
        }
        let (frame, truth) =
            item.with_context(|| format!("reading frame {frames} of {}", args.sequence.display()))?;
        let t0 = Instant::now();
        pre.process(&frame, &camera, &mut frame_pre)
            .with_context(|| format!("preprocessing frame {frames}"))?;
        if let Some(fb) = fallback.as_mut().filter(|_| frame_pre.hand.count == 0) {
            fb.process(&frame, &camera, &mut frame_pre)
                .with_context(|| format!("preprocessing frame {frames}"))?;
        }
        let pre_us = t0.elapsed().as_secs_f64() * 1e6;
        let index = truth.as_ref().map_or(frames as u64, |t| t.frame);
        let timestamp = truth.as_ref().map_or(0.0, |t| t.timestamp);
        let mut rec = tracker.track(&frame_pre, index, timestamp);
        rec.timing_us.insert("preprocess".into(), pre_us);
        for (k, v) in &rec.timing_us {
            stage_us.entry(k.clone()).or_default().push(*v);
        }
        for f in &rec.flags {
            *flags.entry(f.clone()).or_default() += 1;
        }
        if let Some(e) = truth.as_ref().and_then(|t| keypoint_errors(&rec, t)) {
            errors.push(e);
        }
        if !rec.is_finite() {
            bail!("frame {frames}: the tracker produced a non-finite record (a bug)");
        }
        match mcap.as_mut() {
            Some(w) => w
                .write(&frame, Some(&rec))
                .with_context(|| format!("writing {}", args.out.display()))?,
            None => {
                lines.push_str(&serde_json::to_string(&rec)?);
                lines.push('\n');
            }
        }
        frames += 1;
        bar.inc(1);
    }
    bar.finish_and_clear();
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
    let stages: Vec<String> = stage_us
        .into_iter()
        .map(|(k, v)| format!("{k} {:.0}", median(v)))
        .collect();
    eprintln!("median µs per frame: {}", stages.join(", "));
    if !flags.is_empty() {
        let f: Vec<String> = flags.iter().map(|(k, v)| format!("{k} {v}")).collect();
        eprintln!("flagged frames: {}", f.join(", "));
    }
    if !errors.is_empty() {
        let n = errors.len() as f64;
        let mean = errors.iter().map(|e| e.0).sum::<f64>() / n;
        let under = errors.iter().filter(|e| e.1 < 25.0).count() as f64 / n;
        eprintln!(
            "ground truth: mean keypoint error {mean:.2} mm, {:.1}% of frames with max error < 25 mm",
            under * 100.0
        );
    }
    Ok(())
}
