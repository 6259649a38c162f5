//! `hands eval`: score a track file (`track.jsonl` or the `/hand/track` channel of a
//! `track.mcap`) on its sequence — E_d2m / E_m2d from the sensor depth and the method's model
//! rendered at each recorded pose, marker errors when the sequence has ground truth — and write
//! the report (metrics JSON, markdown table, SVG plots, worst frames).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use hand_model::kinematics::Pose;
use sensor_io::io::{is_mcap, open_sequence};
use sensor_io::record::HandRecord;

use crate::scoring::{write_report, MethodRun, SensorFrame};
use crate::track::PreprocessArgs;

/// Evaluate a track against its sequence.
///
/// Example: `hands eval track.jsonl --sequence seq.mcap --model spheremesh --out eval/`
#[derive(Args)]
pub struct EvalArgs {
    /// The track: `.jsonl` (one record per frame) or `.mcap` (records on `/hand/track`).
    pub track: PathBuf,
    /// The sequence the track was computed from (folder or `.mcap`).
    #[arg(long)]
    pub sequence: PathBuf,
    /// The method that produced the track, whose model is rendered at the recorded poses
    /// (see `hands compare --help` for the list).
    #[arg(long)]
    pub model: String,
    /// The subject's sphere-mesh template the method tracked with: a template `.json` or
    /// `subject:<name>` (default: the default hand, as in `hands track`).
    #[arg(long)]
    pub template: Option<String>,
    /// The sensor frames' preprocessing (as in `hands track`; the points are E_d2m's).
    #[command(flatten)]
    pub pre: PreprocessArgs,
    /// Output folder.
    #[arg(long, default_value = "eval-report")]
    pub out: PathBuf,
}

/// The records of a track file, in order.
pub fn read_track(path: &Path) -> Result<Vec<HandRecord>> {
    if is_mcap(path) {
        let mut reader =
            open_sequence(path).with_context(|| format!("opening {}", path.display()))?;
        let mut out = Vec::new();
        while let Some(item) = reader.next_frame() {
            let (_, rec) = item.with_context(|| format!("reading {}", path.display()))?;
            let rec = rec.with_context(|| {
                format!(
                    "{}: frame {} has no /hand/track record",
                    path.display(),
                    out.len()
                )
            })?;
            out.push(rec);
        }
        return Ok(out);
    }
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            serde_json::from_str(l)
                .with_context(|| format!("{} line {}: not a track record", path.display(), i + 1))
        })
        .collect()
}

/// Run `hands eval`.
pub fn run(args: EvalArgs) -> Result<()> {
    let records = read_track(&args.track)?;
    let method = crate::methods::by_name(&args.model).context("--model")?;
    let template = match &args.template {
        Some(spec) => crate::track::load_sphere_mesh(spec)?,
        None => hand_model::spheremesh::default_right_hand(),
    };
    let model = method.model(&template)?;
    let seq_len = open_sequence(&args.sequence)
        .with_context(|| format!("opening {}", args.sequence.display()))?
        .len();
    let mismatch = |n: usize| {
        anyhow::anyhow!(
            "the track {} has {} frames but the sequence {} has {n}: evaluate a track on the sequence it was computed from (all of its frames)",
            args.track.display(),
            records.len(),
            args.sequence.display()
        )
    };
    if let Some(n) = seq_len.filter(|&n| n != records.len()) {
        return Err(mismatch(n));
    }
    let mut renderer = model.renderer();
    let mut run = MethodRun::new(method.name());
    let mut truth_frames = 0usize;
    let frames = crate::track::for_each_frame(&args.sequence, &args.pre, None, "eval", |sf| {
        let Some(rec) = records.get(sf.position) else {
            bail!(
                    "the track {} has {} frames but the sequence {} has more: evaluate a track on the sequence it was computed from (all of its frames)",
                    args.track.display(),
                    records.len(),
                    args.sequence.display()
                );
        };
        check_layout(&args, sf.position, rec, sf.truth)?;
        truth_frames += usize::from(sf.truth.is_some_and(|t| !t.keypoints.is_empty()));
        let rendered = if rec.pose.is_empty() {
            None
        } else {
            let pose = Pose::from_named(
                model.skeleton(),
                rec.pose.iter().map(|(k, &v)| (k.as_str(), v)),
            )
            .with_context(|| {
                format!(
                    "{} frame {}: the pose does not fit the `{}` model (is --model right?)",
                    args.track.display(),
                    sf.position,
                    method.name()
                )
            })?;
            let camera = sf.pre.camera.as_ref().context("no camera (a bug)")?;
            renderer.set_shape(&rec.shape).with_context(|| {
                format!("{} frame {}: its shape", args.track.display(), sf.position)
            })?;
            Some(renderer.render(&pose, camera)?.clone())
        };
        let frame = SensorFrame {
            position: sf.position,
            pre: sf.pre,
            truth: sf.truth,
        };
        run.push(&frame, rec.clone(), rendered.as_ref(), &[])?;
        Ok(())
    })?;
    if crate::interrupt::requested() {
        bail!("interrupted after {frames} frames: nothing written");
    }
    if frames != records.len() {
        return Err(mismatch(frames));
    }
    let mut notes = Vec::new();
    if truth_frames == 0 {
        notes.push(format!(
            "no ground truth in {}: marker metrics omitted",
            args.sequence.display()
        ));
    }
    let title = format!("Evaluation of {}", args.track.display());
    let table = write_report(
        &args.out,
        &title,
        &args.sequence.display().to_string(),
        std::slice::from_ref(&run),
        &notes,
    )?;
    println!("{table}");
    for n in &notes {
        println!("note: {n}");
    }
    eprintln!("report → {}", args.out.join("README.md").display());
    Ok(())
}

/// A record must carry 21 keypoints (or none, for a frame without a hand) and, with ground
/// truth, as many as the truth: else the track does not belong to this sequence.
fn check_layout(
    args: &EvalArgs,
    position: usize,
    rec: &HandRecord,
    truth: Option<&HandRecord>,
) -> Result<()> {
    let n = rec.keypoints.len();
    let expected = truth
        .map(|t| t.keypoints.len())
        .filter(|&k| k > 0)
        .unwrap_or(hand_model::keypoints::NUM_KEYPOINTS);
    if n != 0 && n != expected {
        bail!(
            "the track {} has {n} keypoints in frame {position} but the sequence {} has {expected} (DESIGN.md's 21-keypoint layout)",
            args.track.display(),
            args.sequence.display()
        );
    }
    Ok(())
}
