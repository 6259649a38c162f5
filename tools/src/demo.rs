//! `hands demo`: the main job on the embedded default — what the project can do so far, end to
//! end, with no input files: the default template (summary, mesh, preview), a synthetic
//! sequence with ground truth, the preprocessing of every frame and the Ch. 2 and Ch. 3
//! trackers, each scored against that truth. Calibration joins as its issues land.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use datasets::noise::SensorModel;
use datasets::sheet::{contact_sheet, depth_to_rgb, draw_keypoints};
use datasets::synth::{Part, SceneConfig, Synthesizer};
use datasets::MotionLibrary;
use hand_model::kinematics::Pose;
use hand_model::render::preview::{write_preview_png, PreviewOptions};
use hand_model::spheremesh::default_right_hand;
use sensor_io::io::{create_sequence, write_atomic};
use sensor_io::preprocess::{
    PreprocessConfig, PreprocessedFrame, Preprocessor, Segmentation, WristbandParams,
};
use sensor_io::Camera;

use eval::markers::{frame_error, MarkerSummary};
use hand_model::cylinder::CylinderModel;
use hand_model::solver::PcaPrior;
use htrack_icp::{Tracker, TrackerConfig};

/// Run the demo: synthesize → preprocess → score, writing everything under `--out`.
///
/// Example: `hands demo --out out/demo`
#[derive(Args)]
pub struct DemoArgs {
    /// Output folder.
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Number of frames of the teaser motion.
    #[arg(long, default_value_t = 120)]
    pub frames: usize,
    /// Seed.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Run `hands demo`.
pub fn run(args: DemoArgs) -> Result<()> {
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
    let motion = MotionLibrary::by_name_for("teaser", args.seed, &template.skeleton)?;
    let sensor = SensorModel::by_name("tof").context("tof model")?;
    let mut synth = Synthesizer::new(
        &template,
        &[],
        SceneConfig {
            camera: camera.clone(),
            sensor,
            seed: args.seed,
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
    let cylinders = CylinderModel::from_sphere_mesh_with_wrist(synth.template())?;
    let prior = PcaPrior::project_default();
    let mut tracker = Tracker::new(&cylinders, TrackerConfig::default(), Some(&prior))?;
    let subject = synth.template().clone();
    let mut sphere_mesh = hmodel_spheremesh::Tracker::new(
        &subject,
        hmodel_spheremesh::TrackerConfig::default(),
        Some(&prior),
    )?;
    let (mut sm_ms, mut sm_errors, mut sm_lines) = (Vec::new(), Vec::new(), String::new());
    let mut track_lines = String::new();
    let (mut track_ms, mut errors) = (Vec::new(), Vec::new());
    let (mut render_ms, mut pre_ms, mut ious) = (Vec::new(), Vec::new(), Vec::new());
    let mut tiles = Vec::new();
    let bar = crate::progress::frames_bar(Some(args.frames), "demo");
    let mut pose = Pose::zeros(&template.skeleton);
    for k in 0..args.frames {
        let t = k as f64 / 60.0;
        motion.pose_into(t, &mut pose);
        let t0 = Instant::now();
        let f = synth.render(k as u64, t, &pose)?;
        render_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        writer.write(&f.frame, Some(&f.truth))?;
        let t1 = Instant::now();
        pre.process(&f.frame, &camera, &mut out)?;
        pre_ms.push(t1.elapsed().as_secs_f64() * 1e3);
        let t2 = Instant::now();
        let rec = tracker.track(&out, k as u64, t);
        track_ms.push(t2.elapsed().as_secs_f64() * 1e3);
        if let Some(e) = frame_error(&rec.keypoints, &f.truth.keypoints) {
            errors.push(e);
        }
        track_lines.push_str(&serde_json::to_string(&rec)?);
        track_lines.push('\n');
        let t3 = Instant::now();
        let rec = sphere_mesh.track(&out, k as u64, t);
        sm_ms.push(t3.elapsed().as_secs_f64() * 1e3);
        if let Some(e) = frame_error(&rec.keypoints, &f.truth.keypoints) {
            sm_errors.push(e);
        }
        sm_lines.push_str(&serde_json::to_string(&rec)?);
        sm_lines.push('\n');
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
        "2. synthesized {} frames of `teaser` with time-of-flight noise: {}",
        args.frames,
        seq_path.display()
    );
    println!("   contact sheet: {}", sheet.display());
    println!(
        "   render median {:.2} ms/frame (320×240, one core)",
        median(&mut render_ms)
    );
    let mut sorted = ious.clone();
    let worst = sorted.iter().copied().fold(f64::INFINITY, f64::min);
    println!(
        "3. wristband segmentation vs ground truth: silhouette IoU median {:.3}, worst {:.3}; preprocessing median {:.2} ms/frame",
        median(&mut sorted),
        worst,
        median(&mut pre_ms)
    );
    let track_path = args.out.join("track.jsonl");
    write_atomic(&track_path, track_lines.as_bytes())?;
    let summary = MarkerSummary::new(&errors);
    println!(
        "4. Ch. 2 tracker (cylinders fitted to the subject, 1 rigid + 7 LM iterations): mean keypoint error {:.2} mm, {:.1}% of frames with max error < 25 mm; median {:.2} ms/frame; {}",
        summary.mean,
        100.0 * summary.frac_max_under_25,
        median(&mut track_ms),
        track_path.display()
    );
    let sm_path = args.out.join("track-spheremesh.jsonl");
    write_atomic(&sm_path, sm_lines.as_bytes())?;
    let sm = MarkerSummary::new(&sm_errors);
    println!(
        "5. Ch. 3 sphere-mesh tracker (the subject's template, 1 rigid + 7 LM iterations): mean keypoint error {:.2} mm, {:.1}% of frames with max error < 25 mm; median {:.2} ms/frame; {}",
        sm.mean,
        100.0 * sm.frac_max_under_25,
        median(&mut sm_ms),
        sm_path.display()
    );
    println!("6. online calibration and the evaluation reports: not built yet (issues 6–8; `hands calibrate` exists).");
    Ok(())
}
