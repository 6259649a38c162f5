//! `hands synth`: synthetic depth sequences with exact ground truth.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use datasets::noise::SensorModel;
use datasets::sheet::{contact_sheet, depth_to_rgb, draw_keypoints};
use datasets::synth::{SceneConfig, Synthesizer};
use datasets::{subject_by_name, MotionLibrary};
use hand_model::kinematics::Pose;
use hand_model::spheremesh::default_right_hand;
use sensor_io::io::create_sequence;
use sensor_io::Camera;

/// Render a synthetic sequence (depth, RGB with a blue wristband, ground-truth pose, shape and
/// 21 keypoints) of the default hand reshaped to a subject, moving along a library motion.
///
/// Example: `hands synth --motion teaser --frames 600 --noise tof --seed 7 --out seq.mcap --preview sheet.png`
/// (`--start 2.5` begins 2.5 s into the motion)
#[derive(Args)]
pub struct SynthArgs {
    /// Motion name (see `--list`).
    #[arg(long, default_value = "teaser")]
    pub motion: String,
    /// Number of frames (default: the whole motion from `--start` on).
    #[arg(long)]
    pub frames: Option<usize>,
    /// Start this many seconds into the motion (frames are numbered from 0, timestamps are
    /// the motion's time): a sequence that a tracker meets mid-motion, for cold starts.
    #[arg(long, default_value_t = 0.0)]
    pub start: f64,
    /// Frame rate (Hz).
    #[arg(long, default_value_t = 60.0)]
    pub fps: f64,
    /// Sensor model: none, quantized, tof, structured.
    #[arg(long, default_value = "none")]
    pub noise: String,
    /// Seed of the motion, the random subject and the noise.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Subject: a named subject (see `--list`) or `random` (drawn from the seed).
    #[arg(long, default_value = "default")]
    pub subject: String,
    /// Camera preset: sr300, creative, nyu.
    #[arg(long, default_value = "sr300")]
    pub camera: String,
    /// Output: a path ending in `.mcap` writes MCAP, any other path a folder.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also write a contact sheet (PNG) of depth frames with the keypoints drawn.
    #[arg(long)]
    pub preview: Option<PathBuf>,
    /// No background wall.
    #[arg(long)]
    pub no_wall: bool,
    /// List motions, subjects and sensor models, then exit.
    #[arg(long)]
    pub list: bool,
}

/// Run `hands synth`.
pub fn run(args: SynthArgs) -> Result<()> {
    if args.list {
        println!("motions:  {}", MotionLibrary::names().join(", "));
        println!(
            "subjects: {}, random",
            datasets::Subject::names().join(", ")
        );
        println!("noise:    {}", SensorModel::names().join(", "));
        return Ok(());
    }
    if !(args.fps.is_finite() && args.fps > 0.0 && args.fps <= 1000.0) {
        bail!("--fps must be in (0, 1000], got {}", args.fps);
    }
    if !(args.start.is_finite() && args.start >= 0.0) {
        bail!("--start must be a time ≥ 0 s, got {}", args.start);
    }
    if args.out.is_none() && args.preview.is_none() {
        bail!("nothing to do: give --out <seq.mcap|folder> and/or --preview sheet.png");
    }
    let sensor = SensorModel::by_name(&args.noise).with_context(|| {
        format!(
            "unknown --noise `{}` (one of {})",
            args.noise,
            SensorModel::names().join(", ")
        )
    })?;
    let camera = Camera::preset(&args.camera)?;
    let template = default_right_hand();
    let subject = subject_by_name(&args.subject, args.seed)?;
    let motion = MotionLibrary::by_name_for(&args.motion, args.seed, &template.skeleton)?;
    let skipped = (args.start * args.fps).round() as usize;
    let frames = args
        .frames
        .unwrap_or_else(|| motion.num_frames(args.fps).saturating_sub(skipped));
    if frames == 0 || frames > 1_000_000 {
        bail!("--frames must be in 1..=1000000 (the motion may end before --start)");
    }
    let config = SceneConfig {
        camera: camera.clone(),
        sensor,
        wall_mm: (!args.no_wall).then_some(1100.0),
        forearm: true,
        seed: args.seed,
    };
    let mut synth = Synthesizer::new(&template, &subject.beta, config)?;
    let mut writer = match &args.out {
        Some(p) => {
            Some(create_sequence(p, &camera).with_context(|| format!("creating {}", p.display()))?)
        }
        None => None,
    };
    let sheet_every = (frames / 12).max(1);
    let mut tiles = Vec::new();
    let bar = crate::progress::frames_bar(Some(frames), "synth");
    let mut pose = Pose::zeros(&template.skeleton);
    let mut times = Vec::with_capacity(frames);
    for k in 0..frames {
        if crate::interrupt::requested() {
            eprintln!("interrupted after {k} frames; the sequence holds those");
            break;
        }
        let t = args.start + k as f64 / args.fps;
        motion.pose_into(t, &mut pose);
        let t0 = Instant::now();
        let f = synth.render(k as u64, t, &pose)?;
        times.push(t0.elapsed().as_secs_f64());
        if let Some(w) = writer.as_mut() {
            w.write(&f.frame, Some(&f.truth))?;
        }
        if args.preview.is_some() && k % sheet_every == 0 && tiles.len() < 12 {
            let mut img = depth_to_rgb(&f.frame.depth);
            draw_keypoints(&mut img, &f.keypoints_px);
            tiles.push(img);
        }
        bar.inc(1);
    }
    if let Some(w) = writer.as_mut() {
        w.finish()?;
    }
    bar.finish_and_clear();
    times.sort_by(f64::total_cmp);
    let median_ms = times.get(times.len() / 2).map_or(f64::NAN, |t| t * 1e3);
    eprintln!(
        "synthesized {frames} frames of `{}` for subject `{}` ({} noise, {}×{}): median {median_ms:.2} ms/frame (render + noise)",
        args.motion, subject.name, args.noise, camera.width, camera.height
    );
    if let Some(p) = &args.out {
        eprintln!("wrote {}", p.display());
    }
    if let Some(p) = &args.preview {
        let sheet = contact_sheet(&tiles, 4);
        let mut bytes = std::io::Cursor::new(Vec::new());
        sheet.write_to(&mut bytes, image::ImageFormat::Png)?;
        sensor_io::io::write_atomic(p, bytes.get_ref())?;
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}
