//! `hands compare`: several methods on the same recording, side by side in one report — each
//! frame is read and preprocessed once and handed to every method's tracker; every method is
//! scored the same way (`scoring`), whatever it is: methods come from the `methods` registry.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::SphereMeshTemplate;

use crate::methods::{Method, MethodModel, TrackSettings};
use crate::scoring::{write_report, MethodRun, SensorFrame};
use crate::track::PreprocessArgs;

/// Compare methods on one sequence.
///
/// Example: `hands compare seq.mcap --methods cylinders,spheremesh --out report/`
#[derive(Args)]
pub struct CompareArgs {
    /// Input sequence: a folder or an `.mcap` file.
    pub sequence: PathBuf,
    /// Comma-separated method names, or `all`.
    #[arg(long, default_value = "all")]
    pub methods: String,
    /// The subject's sphere-mesh template every method starts from: a template `.json` or
    /// `subject:<name>` (default: the default hand).
    #[arg(long)]
    pub template: Option<String>,
    #[command(flatten)]
    pub pre: PreprocessArgs,
    /// Compare on at most this many frames.
    #[arg(long)]
    pub frames: Option<usize>,
    /// Output folder.
    #[arg(long, default_value = "report")]
    pub out: PathBuf,
}

/// How the frames of a comparison are read: preprocessed as in `hands track`, at most `frames`
/// frames, a progress bar named `label`.
pub struct FrameOptions<'a> {
    /// Segmentation, sensor points, smoothing.
    pub pre: &'a PreprocessArgs,
    /// Frame limit.
    pub frames: Option<usize>,
    /// Progress bar label.
    pub label: &'static str,
}

/// Track `sequence` with each of `methods` (their models of `template`, default settings and
/// `prior`) and score every frame.
pub fn compare_methods(
    sequence: &Path,
    methods: &[&dyn Method],
    template: &SphereMeshTemplate,
    prior: Option<&PcaPrior>,
    opts: &FrameOptions<'_>,
) -> Result<Vec<MethodRun>> {
    let models: Vec<Box<dyn MethodModel>> = methods
        .iter()
        .map(|m| {
            m.model(template)
                .with_context(|| format!("method {}", m.name()))
        })
        .collect::<Result<_>>()?;
    let settings = TrackSettings::default();
    let mut trackers = models
        .iter()
        .map(|m| m.tracker(prior, &settings))
        .collect::<Result<Vec<_>>>()?;
    let mut runs: Vec<MethodRun> = methods.iter().map(|m| MethodRun::new(m.name())).collect();
    crate::track::for_each_frame(sequence, opts.pre, opts.frames, opts.label, |sf| {
        let index = sf.truth.map_or(sf.position as u64, |t| t.frame);
        let timestamp = sf.truth.map_or(0.0, |t| t.timestamp);
        let camera = sf.pre.camera.as_ref().context("no camera (a bug)")?;
        let frame = SensorFrame {
            position: sf.position,
            pre: sf.pre,
            truth: sf.truth,
        };
        for (t, run) in trackers.iter_mut().zip(runs.iter_mut()) {
            let mut rec = t.track(sf.pre, index, timestamp);
            rec.timing_us.insert("preprocess".into(), sf.preprocess_us);
            let distances = t.point_distances();
            let model = t
                .model(camera)
                .with_context(|| format!("{}: rendering frame {}", run.name, sf.position))?;
            run.push(&frame, rec, Some(model), &distances)?;
        }
        Ok(())
    })?;
    Ok(runs)
}

/// Run `hands compare`.
pub fn run(args: CompareArgs) -> Result<()> {
    let methods = crate::methods::parse_list(&args.methods).context("--methods")?;
    let template = match &args.template {
        Some(spec) => crate::track::load_sphere_mesh(spec)?,
        None => hand_model::spheremesh::default_right_hand(),
    };
    let prior = PcaPrior::project_default();
    let runs = compare_methods(
        &args.sequence,
        &methods,
        &template,
        Some(&prior),
        &FrameOptions {
            pre: &args.pre,
            frames: args.frames,
            label: "compare",
        },
    )?;
    let mut notes = vec![format!(
        "every method starts from the template `{}` with its default settings and the project's PCA prior",
        args.template.as_deref().unwrap_or("default")
    )];
    if runs.iter().all(|r| !r.has_truth) {
        notes.push(format!(
            "no ground truth in {}: marker metrics omitted",
            args.sequence.display()
        ));
    }
    if crate::interrupt::requested() {
        notes.push("interrupted: the report covers the frames tracked so far".into());
    }
    let table = write_report(
        &args.out,
        "Method comparison",
        &args.sequence.display().to_string(),
        &runs,
        &notes,
    )?;
    println!("{table}");
    eprintln!("report → {}", args.out.join("README.md").display());
    Ok(())
}
