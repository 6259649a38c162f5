//! `hands calibrate`: multi-frame calibration of the sphere-mesh template from a recorded or
//! synthetic sequence of the user's hand — the Ch. 3 calibration (thesis §3.4, `spheremesh`)
//! or the Ch. 4 batch baselines Offline-Hard / Offline-Soft (§4.3.4, `honline_calib`).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use eval::plot::{line_plot_svg, Series};
use hand_model::kinematics::Pose;
use hand_model::query::SphereMeshGeometry;
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::{PosedSphereMesh, ShapeBasis, SphereMeshTemplate};
use hmodel_spheremesh::calibration::{
    calibrate, select_frames, CalibrationConfig, CalibrationFrame,
};
use hmodel_spheremesh::{Tracker, TrackerConfig};
use honline_calib::{calibrate_offline, subsample, Offline, OfflineConfig, SUBSAMPLING};
use image::{GenericImage, RgbImage};
use sensor_io::io::write_atomic;
use sensor_io::preprocess::PreprocessedFrame;

use crate::methods::{ModelRenderer, SphereMeshRenderer};
use crate::overlay;
use crate::track::{for_each_frame, load_sphere_mesh, read_config};

/// The calibration `hands calibrate` runs.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum CalibrationMethod {
    /// Ch. 3 (§3.4): the honline β and the rest orientations of the kinematic frames, jointly
    /// with the chosen frames' poses (default frames: `--auto 8`).
    Spheremesh,
    /// Ch. 4 (§4.3.4, Eq. 4.12): Offline-Hard, one β shared by all chosen frames (default
    /// frames: `--every 20`).
    OfflineHard,
    /// Ch. 4 (§4.3.4, Eq. 4.13): Offline-Soft, a β per frame tied to the common β by
    /// ω_β‖β_n − β‖², started from per-frame solves (default frames: `--every 20`).
    OfflineSoft,
}

impl CalibrationMethod {
    /// The name users type.
    fn name(self) -> &'static str {
        match self {
            Self::Spheremesh => "spheremesh",
            Self::OfflineHard => "offline-hard",
            Self::OfflineSoft => "offline-soft",
        }
    }
}

/// Calibrate the sphere-mesh template to a sequence: the sequence is tracked with the starting
/// template, calibration frames are chosen (`--frames`, `--auto N` by farthest-point sampling of
/// the tracked poses, or `--every N`, the first tracked frame of every N), and the template's
/// shape is optimized jointly with those frames' poses by `--method`.
///
/// Example: `hands calibrate seq.mcap --auto 8 --out me.json --report calib/`
#[derive(Args)]
pub struct CalibrateArgs {
    /// Sequence (folder or `.mcap`) showing the hand in different poses.
    pub sequence: PathBuf,
    /// The calibration: `spheremesh` (Ch. 3, thesis §3.4), `offline-hard` or `offline-soft`
    /// (the Ch. 4 batch calibrations of §4.3.4, Eq. 4.12–4.13).
    #[arg(long, value_enum, default_value = "spheremesh")]
    pub method: CalibrationMethod,
    /// Calibrate from these frame positions (comma-separated).
    #[arg(long, value_delimiter = ',', conflicts_with_all = ["auto", "every"])]
    pub frames: Option<Vec<usize>>,
    /// Choose this many frames automatically (the default for `spheremesh`, 8 frames).
    #[arg(long, conflicts_with = "every")]
    pub auto: Option<usize>,
    /// Choose the first tracked frame of every N (the default for the offline methods, N = 20:
    /// the thesis' ≈ 1/20 sub-sampling).
    #[arg(long)]
    pub every: Option<usize>,
    /// Starting template: a sphere-mesh `.json` or `subject:<name>` (default: the default hand).
    #[arg(long)]
    pub template: Option<String>,
    /// Output template (`.json`, the format `--template` of `hands track` reads).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write a report folder: per-iteration energies (`iterations.json`, `energy.svg`) and
    /// per chosen frame the model before and after calibration over the data
    /// (`overlay-NNNNNN.png`, left before, right after; points colored by their distance to
    /// the model, green 0 → red ≥ 10 mm).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Calibration settings (JSON of `CalibrationConfig` for `spheremesh`, of `OfflineConfig`
    /// for the offline methods, whose `method` `--method` sets; missing fields keep their
    /// defaults).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Hand segmentation: auto, wristband, depth, presegmented.
    #[arg(long, default_value = "auto")]
    pub segmentation: String,
    /// Sensor points per frame.
    #[arg(long, default_value_t = 2500)]
    pub points: usize,
    /// Read at most this many frames of the sequence.
    #[arg(long)]
    pub max_frames: Option<usize>,
}

/// Fewer frames than this cannot tell shape from pose (thesis §3.4: "multiple measurements are
/// necessary").
const MIN_FRAMES: usize = 2;

/// A shape parameter whose data information is below this fraction of the median of its kind
/// is reported as unconstrained (`Calibration::unconstrained`).
const UNCONSTRAINED: f64 = 0.01;

/// What a calibration method hands back to the command.
struct Outcome {
    template: SphereMeshTemplate,
    poses: Vec<Pose>,
    initial_energy: f64,
    final_energy: f64,
    iterations: usize,
    seconds: f64,
    /// Shape parameters the chosen frames barely constrain.
    weak: Vec<String>,
    /// The method's own records for `iterations.json`.
    details: serde_json::Value,
    /// Energy curves over the accepted steps.
    series: Vec<Series>,
}

/// Run `hands calibrate`.
pub fn run(args: CalibrateArgs) -> Result<()> {
    if args.out.extension().and_then(|e| e.to_str()) != Some("json") {
        bail!("--out must end in .json, got {}", args.out.display());
    }
    if args.every == Some(0) {
        bail!("--every must be at least 1");
    }
    let base = match &args.template {
        Some(spec) => load_sphere_mesh(spec)?,
        None => hand_model::spheremesh::default_right_hand(),
    };
    let prior = PcaPrior::project_default();
    let mut tracker = Tracker::new(&base, TrackerConfig::default(), Some(&prior))?;
    let sk = &base.skeleton;
    let (mut poses, mut usable) = (Vec::new(), Vec::new());
    let read = for_each_frame(
        &args.sequence,
        &args.segmentation,
        args.points,
        args.max_frames,
        "track",
        |sf| {
            let rec = tracker.track(sf.pre, sf.position as u64, 0.0);
            usable.push(rec.flags.is_empty());
            poses.push(Pose {
                values: sk
                    .dofs()
                    .iter()
                    .map(|d| rec.pose.get(&d.name).copied().unwrap_or(0.0))
                    .collect(),
            });
            Ok(())
        },
    )?;
    let offline = args.method != CalibrationMethod::Spheremesh;
    let chosen = match (&args.frames, args.every, args.auto) {
        (Some(list), _, _) => {
            if let Some(&bad) = list.iter().find(|&&i| i >= read) {
                bail!("--frames {bad} is beyond the sequence ({read} frames read)");
            }
            list.clone()
        }
        (None, Some(n), _) => subsample(&usable, n),
        (None, None, Some(n)) => select_frames(sk, &poses, |i| usable[i], n),
        (None, None, None) if offline => subsample(&usable, SUBSAMPLING),
        (None, None, None) => select_frames(sk, &poses, |i| usable[i], 8),
    };
    if chosen.len() < MIN_FRAMES {
        bail!(
            "{} frame(s) chosen of {read} (automatic choice skips frames without a hand or with lost tracking); calibration needs at least {MIN_FRAMES} frames in different poses",
            chosen.len()
        );
    }
    let frames = read_chosen(&args, &chosen)?;
    let init: Vec<Pose> = chosen.iter().map(|&i| poses[i].clone()).collect();
    let outcome = match args.method {
        CalibrationMethod::Spheremesh => spheremesh(&args, &base, &frames, &init)?,
        CalibrationMethod::OfflineHard => {
            offline_batch(&args, &base, &frames, &init, &prior, Offline::Hard)?
        }
        CalibrationMethod::OfflineSoft => {
            offline_batch(&args, &base, &frames, &init, &prior, Offline::Soft)?
        }
    };
    outcome
        .template
        .save(&args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!(
        "calibrated ({}) from frames {chosen:?} of {read}: energy {:.1} → {:.1} in {} iterations ({:.2} s) → {}",
        args.method.name(),
        outcome.initial_energy,
        outcome.final_energy,
        outcome.iterations,
        outcome.seconds,
        args.out.display()
    );
    if !outcome.weak.is_empty() {
        eprintln!(
            "warning: the chosen frames barely constrain {} shape parameter(s); they stay near the starting template: {}",
            outcome.weak.len(),
            outcome.weak.join(", ")
        );
    }
    if let Some(dir) = &args.report {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let mut json = serde_json::json!({
            "method": args.method.name(),
            "frames": chosen,
            "unconstrained": outcome.weak,
        });
        if let (Some(out), serde_json::Value::Object(details)) =
            (json.as_object_mut(), outcome.details)
        {
            out.extend(details);
        }
        write_atomic(
            &dir.join("iterations.json"),
            serde_json::to_string_pretty(&json)?.as_bytes(),
        )?;
        let svg = line_plot_svg(
            "calibration energy (accepted steps)",
            "iteration",
            "energy",
            &outcome.series,
            None,
        )?;
        write_atomic(&dir.join("energy.svg"), svg.as_bytes())?;
        write_overlays(
            &args,
            dir,
            &chosen,
            (&base, &init),
            (&outcome.template, &outcome.poses),
        )?;
        eprintln!("report → {}", dir.display());
    }
    Ok(())
}

/// The preprocessed frames at the `chosen` positions, in that order (a second pass over the
/// sequence, up to the last chosen frame: the tracking pass keeps no depth images).
fn read_chosen(args: &CalibrateArgs, chosen: &[usize]) -> Result<Vec<PreprocessedFrame>> {
    let mut out: Vec<Option<PreprocessedFrame>> = vec![None; chosen.len()];
    let last = chosen.iter().max().map_or(0, |&m| m + 1);
    for_each_frame(
        &args.sequence,
        &args.segmentation,
        args.points,
        Some(args.max_frames.map_or(last, |m| m.min(last))),
        "read",
        |sf| {
            for (slot, _) in out
                .iter_mut()
                .zip(chosen)
                .filter(|(_, &c)| c == sf.position)
            {
                *slot = Some(sf.pre.clone());
            }
            Ok(())
        },
    )?;
    out.into_iter()
        .zip(chosen)
        .map(|(f, &c)| f.with_context(|| format!("frame {c} could not be read again")))
        .collect()
}

/// One energy curve over the accepted steps (`(iteration, energy)`).
fn series(label: &str, points: impl Iterator<Item = (usize, f64)>) -> Series {
    Series {
        label: label.into(),
        points: points.map(|(i, e)| (i as f64, e)).collect(),
    }
}

/// The Ch. 3 calibration (thesis §3.4).
fn spheremesh(
    args: &CalibrateArgs,
    base: &SphereMeshTemplate,
    frames: &[PreprocessedFrame],
    init: &[Pose],
) -> Result<Outcome> {
    let config: CalibrationConfig = read_config(args.config.as_deref())?;
    let cal_frames: Vec<CalibrationFrame> = frames.iter().map(CalibrationFrame::depth).collect();
    let cal = calibrate(base, &cal_frames, init, &config)?;
    let last = cal
        .iterations
        .iter()
        .rev()
        .find(|r| r.accepted)
        .map_or(cal.initial_energy, |r| r.energy);
    type Part = fn(&hmodel_spheremesh::calibration::IterationRecord) -> f64;
    let parts: [(&str, Part); 3] = [
        ("total", |r| r.energy),
        ("d2m", |r| r.d2m),
        ("m2d", |r| r.m2d),
    ];
    let accepted = || {
        cal.iterations
            .iter()
            .enumerate()
            .filter(|(_, r)| r.accepted)
    };
    Ok(Outcome {
        series: parts
            .iter()
            .map(|(name, f)| series(name, accepted().map(|(i, r)| (i, f(r)))))
            .collect(),
        weak: cal
            .unconstrained(UNCONSTRAINED)
            .into_iter()
            .map(String::from)
            .collect(),
        details: serde_json::json!({
            "iterations": cal.iterations,
            "information": cal.information,
        }),
        initial_energy: cal.initial_energy,
        final_energy: last,
        iterations: cal.iterations.len(),
        seconds: cal.seconds,
        template: cal.template,
        poses: cal.poses,
    })
}

/// Offline-Hard or Offline-Soft (thesis §4.3.4) with the tracker's PCA pose prior.
fn offline_batch(
    args: &CalibrateArgs,
    base: &SphereMeshTemplate,
    frames: &[PreprocessedFrame],
    init: &[Pose],
    prior: &PcaPrior,
    method: Offline,
) -> Result<Outcome> {
    let mut config: OfflineConfig = read_config(args.config.as_deref())?;
    config.method = method;
    let cal = calibrate_offline(base, frames, init, &config, Some(prior))?;
    let basis = ShapeBasis::honline(base)?;
    let active = config.frame.subset.indices(&basis);
    // Unconstrained: active entries whose data information is below UNCONSTRAINED of the
    // active entries' median.
    let mut sorted: Vec<f64> = active.iter().map(|&i| cal.certainty[i]).collect();
    sorted.sort_by(f64::total_cmp);
    let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
    let names: Vec<&str> = basis.names().collect();
    let by_name = |values: &[f64]| -> serde_json::Map<String, serde_json::Value> {
        names
            .iter()
            .zip(values)
            .map(|(n, v)| (n.to_string(), serde_json::json!(v)))
            .collect()
    };
    let accepted = || {
        cal.iterations
            .iter()
            .enumerate()
            .filter(|(_, r)| r.accepted)
    };
    let mut curves = vec![series("total", accepted().map(|(i, r)| (i, r.energy)))];
    let labels: Vec<&str> = cal
        .iterations
        .iter()
        .find(|r| r.accepted)
        .map(|r| r.terms.iter().map(|(n, _)| n.as_str()).collect())
        .unwrap_or_default();
    for (k, label) in labels.iter().enumerate() {
        curves.push(series(
            label,
            accepted().filter_map(|(i, r)| r.terms.get(k).map(|t| (i, t.1))),
        ));
    }
    Ok(Outcome {
        series: curves,
        weak: active
            .iter()
            .filter(|&&i| cal.certainty[i] < UNCONSTRAINED * median)
            .map(|&i| names[i].to_string())
            .collect(),
        details: serde_json::json!({
            "iterations": cal.iterations,
            "shape": by_name(&cal.beta),
            "shape_certainty": by_name(&cal.certainty),
        }),
        initial_energy: cal.initial_energy,
        final_energy: cal.final_energy(),
        iterations: cal.iterations.len(),
        seconds: cal.seconds,
        template: cal.template,
        poses: cal.poses,
    })
}

/// One image per chosen frame: the overlay of the starting template at its initial pose beside
/// the calibrated template at its optimized pose (the sequence is read a second time for the
/// chosen frames only, so the tracking pass keeps no depth images).
fn write_overlays(
    args: &CalibrateArgs,
    dir: &Path,
    chosen: &[usize],
    before: (&SphereMeshTemplate, &[Pose]),
    after: (&SphereMeshTemplate, &[Pose]),
) -> Result<()> {
    let mut renderers = [
        SphereMeshRenderer::new(before.0),
        SphereMeshRenderer::new(after.0),
    ];
    let poses = [before.1, after.1];
    let templates = [before.0, after.0];
    for_each_frame(
        &args.sequence,
        &args.segmentation,
        args.points,
        args.max_frames,
        "overlays",
        |sf| {
            let Some(k) = chosen.iter().position(|&c| c == sf.position) else {
                return Ok(());
            };
            let Some(camera) = sf.pre.camera.as_ref() else {
                return Ok(());
            };
            let mut panels = Vec::with_capacity(2);
            for side in 0..2 {
                let pose = &poses[side][k];
                let pixels = renderers[side].render(pose, camera)?.pixels.clone();
                let distances = point_distances(templates[side], pose, &sf.pre.points)?;
                panels.push(overlay::compose(sf.pre, &pixels, &distances));
            }
            let (w, h) = (panels[0].width(), panels[0].height());
            let mut image = RgbImage::new(2 * w, h);
            for (side, panel) in panels.iter().enumerate() {
                image.copy_from(panel, side as u32 * w, 0)?;
            }
            let path = dir.join(format!("overlay-{:06}.png", sf.position));
            hand_model::render::preview::write_png(&path, &image)
                .with_context(|| format!("writing {}", path.display()))
        },
    )?;
    Ok(())
}

/// Per point its unsigned distance to the surface of `template` at `pose` (Eq. 3.6's φ).
fn point_distances(
    template: &SphereMeshTemplate,
    pose: &Pose,
    points: &[nalgebra::Vector3<f64>],
) -> Result<Vec<Option<f64>>> {
    let posed = PosedSphereMesh::new(template, pose);
    let elements: Vec<_> = template.elements.iter().map(|e| e.element).collect();
    let geometry = SphereMeshGeometry::new(&posed.spheres, &elements)?;
    Ok(points
        .iter()
        .map(|p| geometry.phi(p).map(f64::abs))
        .collect())
}
