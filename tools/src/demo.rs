//! `hands demo`: the main job — what the project can do, end to end, with no input files: the
//! default template (summary, preview), a short teaser-like synthetic sequence of a random
//! subject with time-of-flight noise and exact ground truth, the preprocessing of every frame,
//! then every available method (the `methods` registry) tracking it, each scored against the
//! truth, with a summary table and a report (`scoring`: metrics JSON, plots, worst frames).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use datasets::noise::SensorModel;
use datasets::sheet::{contact_sheet, depth_to_rgb, draw_keypoints};
use datasets::synth::{Part, SceneConfig, Synthesizer};
use datasets::{subject_by_name, MotionLibrary};
use eval::markers::median;
use hand_model::kinematics::Pose;
use hand_model::render::preview::{write_preview_png, PreviewOptions};
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::default_right_hand;
use sensor_io::io::{create_sequence, write_atomic};
use sensor_io::preprocess::{
    PreprocessConfig, PreprocessedFrame, Preprocessor, Segmentation, WristbandParams,
};
use sensor_io::Camera;

use crate::compare::{compare_methods, FrameOptions};
use crate::scoring::write_report;
use crate::track::PreprocessArgs;

/// Run the demo: synthesize → preprocess → track with every method → score, writing
/// everything under `--out`.
///
/// Example: `hands demo --out demo-report --frames 120 --seed 7`
#[derive(Args)]
pub struct DemoArgs {
    /// Output folder.
    #[arg(long, default_value = "demo-report")]
    pub out: PathBuf,
    /// Number of frames of the teaser motion (60 Hz).
    #[arg(long, default_value_t = 120)]
    pub frames: usize,
    /// Seed of the subject, motion and noise (default: drawn from the clock, and printed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Comma-separated methods to run, or `all`.
    #[arg(long, default_value = "all")]
    pub methods: String,
}

/// Run `hands demo`.
pub fn run(args: DemoArgs) -> Result<()> {
    anyhow::ensure!(
        (1..=100_000).contains(&args.frames),
        "--frames must be in 1..=100000, got {}",
        args.frames
    );
    let methods = crate::methods::parse_list(&args.methods).context("--methods")?;
    let seed = args.seed.unwrap_or_else(|| {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(7, |d| d.as_secs() % 100_000)
    });
    let started = Instant::now();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let template = default_right_hand();
    let (pills, wedges) = template.element_counts();
    println!(
        "1. template: {} ({} spheres, {pills} pills, {wedges} wedges, {} DOFs)",
        template.name,
        template.spheres.len(),
        template.skeleton.num_dofs()
    );
    let preview = args.out.join("template.png");
    write_preview_png(
        &preview,
        &template,
        &Pose::zeros(&template.skeleton),
        &PreviewOptions::default(),
    )?;
    println!("   preview: {}", preview.display());

    let camera = Camera::sr300_qvga();
    let subject = subject_by_name("random", seed)?;
    let motion = MotionLibrary::by_name_for("teaser", seed, &template.skeleton)?;
    let sensor = SensorModel::by_name("tof").context("tof model")?;
    let mut synth = Synthesizer::new(
        &template,
        &subject.beta,
        SceneConfig {
            camera: camera.clone(),
            sensor,
            seed,
            ..Default::default()
        },
    )?;
    let seq_path = args.out.join("teaser.mcap");
    let mut writer = create_sequence(&seq_path, &camera)?;
    let mut pre = Preprocessor::new(PreprocessConfig {
        segmentation: Segmentation::Wristband(WristbandParams::default()),
        ..Default::default()
    });
    let mut out = PreprocessedFrame::default();
    let (mut render_ms, mut pre_ms, mut ious) = (Vec::new(), Vec::new(), Vec::new());
    let mut tiles = Vec::new();
    let bar = crate::progress::frames_bar(Some(args.frames), "synthesize");
    let mut pose = Pose::zeros(&template.skeleton);
    for k in 0..args.frames {
        if crate::interrupt::requested() {
            break;
        }
        let t = k as f64 / 60.0;
        motion.pose_into(t, &mut pose);
        let t0 = Instant::now();
        let f = synth.render(k as u64, t, &pose)?;
        render_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        writer.write(&f.frame, Some(&f.truth))?;
        let t1 = Instant::now();
        pre.process(&f.frame, &camera, &mut out)?;
        pre_ms.push(t1.elapsed().as_secs_f64() * 1e3);
        let truth = f.parts.iter().map(|&p| p == Part::Hand);
        let (mut inter, mut union) = (0usize, 0usize);
        for (&m, h) in out.hand.mask.data.iter().zip(truth) {
            inter += (m != 0 && h) as usize;
            union += (m != 0 || h) as usize;
        }
        ious.push(if union > 0 {
            inter as f64 / union as f64
        } else {
            1.0
        });
        if k % (args.frames / 8).max(1) == 0 && tiles.len() < 8 {
            let mut img = depth_to_rgb(&f.frame.depth);
            draw_keypoints(&mut img, &f.keypoints_px);
            tiles.push(img);
        }
        bar.inc(1);
    }
    writer.finish()?;
    bar.finish_and_clear();
    let sheet = args.out.join("teaser-sheet.png");
    let mut bytes = std::io::Cursor::new(Vec::new());
    contact_sheet(&tiles, 4).write_to(&mut bytes, image::ImageFormat::Png)?;
    write_atomic(&sheet, bytes.get_ref())?;
    println!(
        "2. synthesized {} frames of `teaser` for the random subject `{}` (hand length {:.0} mm; seed {seed}) with time-of-flight noise: {}",
        ious.len(),
        subject.name,
        subject.hand_length()?,
        seq_path.display()
    );
    println!("   contact sheet: {}", sheet.display());
    println!(
        "   render median {:.2} ms/frame (320×240, one core)",
        median(&render_ms)
    );
    let worst = ious.iter().copied().fold(f64::INFINITY, f64::min);
    println!(
        "3. wristband segmentation vs ground truth: silhouette IoU median {:.3}, worst {:.3}; preprocessing median {:.2} ms/frame",
        median(&ious),
        worst,
        median(&pre_ms)
    );
    println!(
        "4. every method starting from the subject's true template (`online` refines it while tracking), scored against the ground truth:"
    );
    for m in &methods {
        println!("   - {}: {}", m.name(), m.summary());
    }
    let prior = PcaPrior::project_default();
    let runs = compare_methods(
        &seq_path,
        &methods,
        synth.template(),
        Some(&prior),
        &FrameOptions {
            pre: &PreprocessArgs::default(),
            frames: None,
            label: "track",
        },
    )?;
    for r in &runs {
        let path = args.out.join(format!("track-{}.jsonl", r.name));
        let mut lines = String::new();
        for rec in &r.records {
            lines.push_str(&serde_json::to_string(rec)?);
            lines.push('\n');
        }
        write_atomic(&path, lines.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let mut notes = vec![format!(
        "`hands demo --seed {seed} --frames {}`: random subject `{}`, teaser motion, ToF noise; every method tracks with the subject's true template",
        args.frames, subject.name
    )];
    if crate::interrupt::requested() {
        notes.push("interrupted: the report covers the frames done so far".into());
    }
    let table = write_report(
        &args.out,
        "hands demo",
        &seq_path.display().to_string(),
        &runs,
        &notes,
    )?;
    println!("\n{table}");
    println!(
        "5. report: {} (metrics.json, plots, worst-frames.png, track-<method>.jsonl) in {:.1} s",
        args.out.join("README.md").display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
