//! `hands report`: the reproduction reports of the thesis chapters, run on synthetic sequences
//! with exact ground truth and written as markdown + SVG plots. Every number in a report is
//! measured by the command; every verdict is computed from those numbers.
//!
//! This module holds what the chapters share: tracking several trackers on one rendered
//! sequence, the per-variant outcome, its table row, the plots and the verdict rule.

mod ch2;
mod ch3;
mod ch4;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use eval::markers::{frame_error, under_curve, MarkerSummary};
use eval::plot::{line_plot_svg, Series};
use eval::synthetic::{SyntheticRun, SyntheticSequence};
use sensor_io::io::write_atomic;

use crate::trackers::{e_m2d, FrameTracker};

/// Write a thesis chapter's reproduction report.
///
/// Example: `hands report ch3 --out docs/ch3 --frames 300`
#[derive(Args)]
pub struct ReportArgs {
    /// Which report: `ch2`, `ch3` or `ch4`.
    pub which: String,
    /// Output folder (README.md and SVG plots); default `docs/<which>`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Frames per sequence (at 60 Hz; `ch4` at 30 Hz).
    #[arg(long, default_value_t = 300)]
    pub frames: usize,
    /// Seed of motions, subject and noise.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
}

/// Run `hands report`.
pub fn run(args: ReportArgs) -> Result<()> {
    anyhow::ensure!(
        (3..=100_000).contains(&args.frames),
        "--frames must be in 3..=100000, got {}",
        args.frames
    );
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| Path::new("docs").join(&args.which));
    let write = match args.which.as_str() {
        "ch2" => ch2::write,
        "ch3" => ch3::write,
        "ch4" => ch4::write,
        other => anyhow::bail!("unknown report `{other}` (available: ch2, ch3, ch4)"),
    };
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let started = std::time::Instant::now();
    let md = write(&args, &out)?;
    let path = out.join("README.md");
    write_atomic(&path, md.as_bytes()).with_context(|| format!("writing {}", path.display()))?;
    eprintln!(
        "wrote {} in {:.0} s",
        path.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// One tracker's outcome on a synthetic sequence, with the self-evaluation energies.
pub struct Tracked {
    /// Records, truth and keypoint errors.
    pub run: SyntheticRun,
    /// Per frame E_m2d (px, thesis Eq. 3.16; NaN where nothing is rendered or measured).
    pub e_m2d: Vec<f64>,
}

impl Tracked {
    /// Per frame E_d2m (mm): the tracker's mean point-to-model distance (NaN where it did not
    /// track).
    pub fn e_d2m(&self) -> Vec<f64> {
        self.run
            .records
            .iter()
            .map(|r| {
                r.energies
                    .get("mean_distance_mm")
                    .copied()
                    .unwrap_or(f64::NAN)
            })
            .collect()
    }

    /// Per frame the maximum keypoint error (∞ where there is none, so that it counts as a
    /// failure in the "frames under ε" curves).
    pub fn max_errors(&self) -> Vec<f64> {
        self.run
            .errors
            .iter()
            .map(|e| e.map_or(f64::INFINITY, |e| e.max))
            .collect()
    }
}

/// Track every frame of `seq` with each of `trackers` (so that variants compare on identical
/// frames and the sequence is rendered and preprocessed only once). With `measure_m2d`, E_m2d
/// is measured per frame from each tracker's rendered silhouette.
pub fn track_sequence(
    seq: &mut SyntheticSequence,
    what: &str,
    trackers: &mut [&mut dyn FrameTracker],
    measure_m2d: bool,
) -> Result<Vec<Tracked>> {
    let bar = crate::progress::frames_bar(Some(seq.spec().frames), what);
    let mut out: Vec<Tracked> = trackers
        .iter()
        .map(|_| Tracked {
            run: SyntheticRun::default(),
            e_m2d: Vec::new(),
        })
        .collect();
    let mut failure = None;
    let shared = seq.run(
        |f, truth| {
            for (t, o) in trackers.iter_mut().zip(out.iter_mut()) {
                let rec = t.track(f, truth.frame, truth.timestamp);
                if measure_m2d {
                    let m2d = match f.camera.as_ref().map(|c| t.model_pixels(c)) {
                        Some(Ok(pixels)) => e_m2d(pixels, f),
                        Some(Err(e)) => {
                            failure.get_or_insert(e);
                            f64::NAN
                        }
                        None => f64::NAN,
                    };
                    o.e_m2d.push(m2d);
                }
                o.run
                    .errors
                    .push(frame_error(&rec.keypoints, &truth.keypoints));
                o.run.records.push(rec);
            }
            // The first tracker's record stands for the frame in the shared run (unused).
            out.first()
                .and_then(|o| o.run.records.last().cloned())
                .unwrap_or_default()
        },
        |_| bar.inc(1),
    )?;
    bar.finish_and_clear();
    if let Some(e) = failure {
        return Err(e.context(format!("{what}: rendering the model")));
    }
    for o in &mut out {
        o.run.truth.clone_from(&shared.truth);
        o.run.preprocess_us.clone_from(&shared.preprocess_us);
    }
    Ok(out)
}

/// The table columns of an outcome (mean/median keypoint error, frames with max error under
/// 25 mm, lost frames, median tracking time).
pub const OUTCOME_HEADER: &str =
    "mean err (mm) | median err (mm) | frames max < 25 mm | lost frames | track ms/frame (median)";

/// The cells of [`OUTCOME_HEADER`] for `run`.
pub fn outcome_cells(run: &SyntheticRun) -> String {
    let s: MarkerSummary = run.summary();
    format!(
        "{:.2} | {:.2} | {:.1}% | {:.1}% | {:.2}",
        s.mean,
        s.median,
        100.0 * run.fraction_max_under(25.0),
        100.0 * run.flag_fraction("lost"),
        run.median_stage_us("track") / 1e3
    )
}

/// Below this relative difference a single synthetic sequence cannot separate two variants.
pub const MARGIN: f64 = 0.03;

/// The verdict of "`a` scores lower (better) than `b`", computed from the two scores.
pub fn verdict(a_label: &str, a: f64, b_label: &str, b: f64) -> String {
    let rel = (b - a) / b.abs().max(1e-12);
    if !(a.is_finite() && b.is_finite()) {
        format!("**Inconclusive**: {a_label} scores {a:.3} vs {b:.3} for {b_label} (not finite).")
    } else if rel.abs() < MARGIN {
        format!(
            "**Inconclusive**: {a_label} scores {a:.3} vs {b:.3} for {b_label}, within {:.0}% of each other.",
            100.0 * MARGIN
        )
    } else if a < b {
        format!(
            "**Reproduces**: {a_label} scores {a:.3} vs {b:.3} for {b_label} ({:.0}% lower).",
            100.0 * (1.0 - a / b)
        )
    } else {
        format!("**Does not reproduce** here: {a_label} scores {a:.3} vs {b:.3} for {b_label}.")
    }
}

/// Write `series` (label, per-frame values) as a per-frame line plot `<name>.svg` in `out`.
pub fn per_frame_plot(
    out: &Path,
    name: &str,
    title: &str,
    y_label: &str,
    series: &[(String, Vec<f64>)],
    y_cap: Option<f64>,
) -> Result<()> {
    let s: Vec<Series> = series
        .iter()
        .map(|(label, v)| Series {
            label: label.clone(),
            points: v.iter().enumerate().map(|(i, &e)| (i as f64, e)).collect(),
        })
        .collect();
    write_svg(
        out,
        name,
        &line_plot_svg(title, "frame", y_label, &s, y_cap)?,
    )
}

/// Write "% of frames with value < ε" curves for ε in `0..=eps_max` as `<name>.svg` in `out`.
pub fn under_plot(
    out: &Path,
    name: &str,
    title: &str,
    x_label: &str,
    eps_max: f64,
    series: &[(String, Vec<f64>)],
) -> Result<()> {
    let eps: Vec<f64> = (0..=100).map(|i| eps_max * f64::from(i) / 100.0).collect();
    let s: Vec<Series> = series
        .iter()
        .map(|(label, v)| {
            // NaN (no measurement) counts as above every ε.
            let v: Vec<f64> = v
                .iter()
                .map(|&x| if x.is_nan() { f64::INFINITY } else { x })
                .collect();
            Series {
                label: label.clone(),
                points: eps
                    .iter()
                    .zip(under_curve(&v, &eps))
                    .map(|(&e, f)| (e, 100.0 * f))
                    .collect(),
            }
        })
        .collect();
    write_svg(
        out,
        name,
        &line_plot_svg(title, x_label, "% frames", &s, None)?,
    )
}

fn write_svg(out: &Path, name: &str, svg: &str) -> Result<()> {
    let path = out.join(format!("{name}.svg"));
    write_atomic(&path, svg.as_bytes()).with_context(|| format!("writing {}", path.display()))
}

/// Append a markdown image line for `<name>.svg`.
pub fn image(md: &mut String, alt: &str, name: &str) -> Result<()> {
    writeln!(md, "![{alt}]({name}.svg)")?;
    Ok(())
}
