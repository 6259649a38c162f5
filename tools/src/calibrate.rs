//! `hands calibrate`: multi-frame calibration of the sphere-mesh template from a recorded or
//! synthetic sequence of the user's hand — the Ch. 3 calibration (thesis §3.4, `spheremesh`)
//! or the Ch. 4 batch baselines Offline-Hard / Offline-Soft (§4.3.4, `honline_calib`).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use datasets::motion::KeyPose;
use datasets::prior::authored_samples;
use datasets::scans::{
    principal_extents, read_obj_points, scale_from_extents, sphere_principal_extents,
};
use eval::markers::median;
use eval::plot::{line_plot_svg, Series};
use hand_model::kinematics::names::DIGIT_DOFS;
use hand_model::kinematics::Pose;
use hand_model::query::SphereMeshGeometry;
use hand_model::render::preview::{write_preview_png, PreviewOptions};
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::{PosedSphereMesh, ShapeBasis, SphereMeshTemplate};
use hmodel_spheremesh::calibration::{
    calibrate, calibrate_clouds, select_frames, split_forearm, Calibration, CalibrationConfig,
    CalibrationFrame, CloudSearch, IterationRecord,
};
use hmodel_spheremesh::{Tracker, TrackerConfig};
use honline_calib::{
    calibrate_offline, guide, subsample, Offline, OfflineConfig, OnlineCalibrator, OnlineConfig,
    SUBSAMPLING,
};
use image::{GenericImage, RgbImage};
use nalgebra::Vector3;
use sensor_io::io::write_atomic;
use sensor_io::preprocess::PreprocessedFrame;

use crate::config::{read_config, read_config_over};
use crate::methods::{ModelRenderer, SphereMeshRenderer};
use crate::overlay;
use crate::track::{for_each_frame, load_sphere_mesh, PreprocessArgs};

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

/// Calibrate the sphere-mesh template to a sequence or to complete scans.
///
/// A sequence is tracked with the starting template, calibration frames are chosen
/// (`--frames`, `--auto N` by farthest-point sampling of the tracked poses, or `--every N`, the
/// first tracked frame of every N), and the template's shape is optimized jointly with those
/// frames' poses by `--method`. A folder of `.obj` scans (complete point clouds of one hand in
/// several poses, any unit) is calibrated from every scan: the unit is estimated (or given by
/// `--units-per-mm`), the forearm cut off, the handedness and each scan's pose found by a
/// hypothesis search with a per-digit refinement, alternated with the calibration
/// (`hmodel_spheremesh::calibration::calibrate_clouds`).
///
/// Examples: `hands calibrate seq.mcap --auto 8 --out me.json --report calib/`,
/// `hands calibrate scans/ --out me.json`
#[derive(Args)]
pub struct CalibrateArgs {
    /// Sequence (folder or `.mcap`) showing the hand in different poses, or a folder of `.obj`
    /// scans.
    pub sequence: PathBuf,
    /// Scan units per millimetre (scans only; default: estimated from the scans' hand extents
    /// against the starting template's).
    #[arg(long)]
    pub units_per_mm: Option<f64>,
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
    /// for the offline methods, whose `method` `--method` sets; missing fields, nested ones
    /// included, keep their defaults). A folder of scans lays it over
    /// `CalibrationConfig::clouds`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    #[command(flatten)]
    pub pre: PreprocessArgs,
    /// Read at most this many frames of the sequence.
    #[arg(long)]
    pub max_frames: Option<usize>,
    /// Calibration guidance (thesis §5.2) instead of an offline calibration: calibrate online
    /// (joint cumulative estimator) over the sequence, print the least-certain shape
    /// parameters and the pose of the prior's corpus whose expected information gain for them
    /// is largest, write the online estimate to `--out` and a rendering of the suggested pose
    /// beside it (`me.json` → `me.guide.png`).
    #[arg(long, conflicts_with_all = ["frames", "auto"])]
    pub guide: bool,
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
    if args.guide {
        return run_guide(&args, &base);
    }
    if let Some(scans) = scan_files(&args.sequence)? {
        if args.method != CalibrationMethod::Spheremesh {
            bail!(
                "--method {} calibrates from a depth sequence; scans take the spheremesh calibration",
                args.method.name()
            );
        }
        return run_scans(&args, &base, &scans);
    }
    let prior = PcaPrior::project_default();
    let mut tracker = Tracker::new(&base, TrackerConfig::default(), Some(&prior))?;
    let sk = &base.skeleton;
    let (mut poses, mut usable) = (Vec::new(), Vec::new());
    let read = for_each_frame(&args.sequence, &args.pre, args.max_frames, "track", |sf| {
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
    })?;
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
    let mut outcome = match args.method {
        CalibrationMethod::Spheremesh => spheremesh(&args, &base, &frames, &init)?,
        CalibrationMethod::OfflineHard => {
            offline_batch(&args, &base, &frames, &init, &prior, Offline::Hard)?
        }
        CalibrationMethod::OfflineSoft => {
            offline_batch(&args, &base, &frames, &init, &prior, Offline::Soft)?
        }
    };
    if let serde_json::Value::Object(details) = &mut outcome.details {
        details.insert("frames".into(), serde_json::json!(chosen));
    }
    finish(&args, &outcome, &format!("frames {chosen:?} of {read}"))?;
    if let Some(dir) = &args.report {
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

/// Parameters the guidance targets.
const GUIDE_TARGETS: usize = 5;

/// `hands calibrate --guide` (see [`CalibrateArgs::guide`]).
fn run_guide(args: &CalibrateArgs, base: &SphereMeshTemplate) -> Result<()> {
    let prior = PcaPrior::project_default();
    let mut calib = OnlineCalibrator::new(base, OnlineConfig::default(), Some(&prior))?;
    let mut camera = None;
    let read = for_each_frame(&args.sequence, &args.pre, args.max_frames, "online", |sf| {
        camera = sf.pre.camera.clone().or(camera.take());
        calib.track(sf.pre, sf.position as u64, 0.0);
        Ok(())
    })?;
    let camera = camera.context("no frame of the sequence has a camera")?;
    let sk = &base.skeleton;
    let digits = |place: &Pose, sample: &[f64]| {
        let mut p = place.clone();
        for (name, v) in DIGIT_DOFS.iter().zip(sample) {
            // Templates without a digit DOF keep it at its value.
            let _ = p.set(sk, name, *v);
        }
        p.clamp_to_limits(sk);
        p
    };
    let samples = authored_samples()?;
    let place = calib.pose().clone();
    let candidates: Vec<Pose> = samples.iter().map(|s| digits(&place, s)).collect();
    let g = guide(&mut calib, &candidates, &camera, GUIDE_TARGETS)
        .context("no corpus pose could be rendered in front of the sensor")?;
    println!("after {read} frames, the least certain shape parameters (certainty per mm²):");
    for (_, name, c) in &g.weakest {
        println!("  {name}: {c:.4}");
    }
    let name = KeyPose::ALL.get(g.best).map_or_else(
        || format!("corpus pose #{}", g.best),
        |k| format!("key pose `{}`", k.name()),
    );
    println!(
        "suggested next pose: {name} (expected gain {:.2}, median over the corpus {:.2})",
        g.gains[g.best],
        median(&g.gains)
    );
    calib
        .template()
        .save(&args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    let png = args.out.with_extension("").with_extension("guide.png");
    let shown = digits(&Pose::zeros(sk), &samples[g.best]);
    write_preview_png(&png, calib.template(), &shown, &PreviewOptions::default())
        .with_context(|| format!("writing {}", png.display()))?;
    eprintln!(
        "online estimate → {}, suggested pose → {}",
        args.out.display(),
        png.display()
    );
    Ok(())
}

/// Save the calibrated template, print the outcome (energies, weakly constrained parameters)
/// and, with `--report`, write `iterations.json` and `energy.svg`; `described` names the data
/// calibrated from.
fn finish(args: &CalibrateArgs, outcome: &Outcome, described: &str) -> Result<()> {
    outcome
        .template
        .save(&args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!(
        "calibrated ({}) from {described}: energy {:.1} → {:.1} in {} iterations ({:.2} s) → {}",
        args.method.name(),
        outcome.initial_energy,
        outcome.final_energy,
        outcome.iterations,
        outcome.seconds,
        args.out.display()
    );
    if !outcome.weak.is_empty() {
        eprintln!(
            "warning: the data barely constrain {} shape parameter(s); they stay near the starting template: {}",
            outcome.weak.len(),
            outcome.weak.join(", ")
        );
    }
    let Some(dir) = &args.report else {
        return Ok(());
    };
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut json = serde_json::json!({
        "method": args.method.name(),
        "data": described,
        "unconstrained": outcome.weak,
    });
    if let (Some(out), serde_json::Value::Object(details)) =
        (json.as_object_mut(), outcome.details.clone())
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
    Ok(())
}

/// The `.obj` files of `path` (sorted by name) when it is a folder holding some, else `None`.
fn scan_files(path: &Path) -> Result<Option<Vec<PathBuf>>> {
    if !path.is_dir() {
        return Ok(None);
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(path)
        .with_context(|| format!("reading {}", path.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().and_then(|e| e.to_str()) == Some("obj"))
        .collect();
    files.sort();
    Ok((!files.is_empty()).then_some(files))
}

/// Scan units per mm: the median over scans of the hand part's principal extents against the
/// starting template's rest extents (a hand of the template's size is assumed; the calibration
/// then fits the size in that unit).
fn estimate_units(base: &SphereMeshTemplate, scans: &[Vec<Vector3<f64>>]) -> Result<f64> {
    let rest = PosedSphereMesh::new(base, &Pose::zeros(&base.skeleton));
    let template = sphere_principal_extents(&rest.spheres)?;
    let mut units = scans
        .iter()
        .map(|s| {
            let hand = split_forearm(s).map_or_else(|| s.clone(), |h| h.hand);
            Ok(scale_from_extents(&principal_extents(&hand)?, &template)?)
        })
        .collect::<Result<Vec<f64>>>()?;
    units.sort_by(f64::total_cmp);
    Ok(units[units.len() / 2])
}

/// `hands calibrate <folder of .obj scans>` (see [`CalibrateArgs`]).
fn run_scans(args: &CalibrateArgs, base: &SphereMeshTemplate, files: &[PathBuf]) -> Result<()> {
    if files.len() < MIN_FRAMES {
        bail!(
            "{} scan(s) in {}; calibration needs at least {MIN_FRAMES} scans in different poses",
            files.len(),
            args.sequence.display()
        );
    }
    let scans = files
        .iter()
        .map(|f| read_obj_points(f).with_context(|| format!("reading {}", f.display())))
        .collect::<Result<Vec<_>>>()?;
    let estimated = estimate_units(base, &scans)?;
    let units = match args.units_per_mm {
        Some(u) if !(u.is_finite() && u > 0.0) => {
            bail!("--units-per-mm {u} is not a positive number")
        }
        Some(u) => {
            if !(0.67..=1.5).contains(&(u / estimated)) {
                eprintln!(
                    "warning: --units-per-mm {u} makes the hand {:.2}× the starting template's size (estimated unit: {estimated:.5} per mm); check the scans' unit",
                    estimated / u
                );
            }
            u
        }
        None => {
            eprintln!("scan unit estimated: {estimated:.5} per mm (a hand of the template's size)");
            estimated
        }
    };
    let mm: Vec<Vec<Vector3<f64>>> = scans
        .iter()
        .map(|s| s.iter().map(|p| p / units).collect())
        .collect();
    // The settings for complete clouds, with a settings file's fields laid over them.
    let config = read_config_over(args.config.as_deref(), CalibrationConfig::clouds())?;
    let run = calibrate_clouds(base, &mm, &CloudSearch::default(), &config)?;
    let init = &run.init;
    eprintln!(
        "{} hand (hypothesis energy {:.0} vs {:.0} mirrored); forearm removed: {:?} points",
        if init.mirrored {
            "mirror-image"
        } else {
            "starting"
        },
        init.energies[0],
        init.energies[1],
        scans
            .iter()
            .zip(&init.frames)
            .map(|(s, f)| s.len() - f.points.len())
            .collect::<Vec<_>>()
    );
    eprintln!(
        "calibration rounds (data energy, kept): {:?}",
        run.rounds
            .iter()
            .map(|(e, k)| (e.round(), *k))
            .collect::<Vec<_>>()
    );
    let poses: Vec<Pose> = init.poses.iter().map(|p| p.pose.clone()).collect();
    let cal = Outcome::from(run.calibration);
    let before = scan_d2m(&init.template, &poses, &init.frames)?;
    let after = scan_d2m(&cal.template, &cal.poses, &init.frames)?;
    for ((f, b), a) in files.iter().zip(&before).zip(&after) {
        eprintln!(
            "  {}: mean distance to the model {b:.2} → {a:.2} mm",
            f.file_name().unwrap_or_default().to_string_lossy()
        );
    }
    finish(args, &cal, &format!("{} scans", files.len()))?;
    if let Some(dir) = &args.report {
        for (k, frame) in init.frames.iter().enumerate() {
            let panels = [(&init.template, &poses[k]), (&cal.template, &cal.poses[k])]
                .map(|(t, p)| point_distances(t, p, &frame.points))
                .into_iter()
                .map(|d| d.map(|d| cloud_views(&frame.points, &d)))
                .collect::<Result<Vec<_>>>()?;
            let (w, h) = (panels[0].width(), panels[0].height());
            let mut image = RgbImage::new(w, 2 * h);
            for (side, panel) in panels.iter().enumerate() {
                image.copy_from(panel, 0, side as u32 * h)?;
            }
            let path = dir.join(format!("overlay-scan{k:02}.png"));
            hand_model::render::preview::write_png(&path, &image)
                .with_context(|| format!("writing {}", path.display()))?;
        }
        eprintln!("report → {}", dir.display());
    }
    Ok(())
}

/// Per scan the mean distance (mm) of its points to the model at its pose.
fn scan_d2m(
    template: &SphereMeshTemplate,
    poses: &[Pose],
    frames: &[CalibrationFrame],
) -> Result<Vec<f64>> {
    frames
        .iter()
        .zip(poses)
        .map(|(f, p)| {
            let d = point_distances(template, p, &f.points)?;
            Ok(d.iter().flatten().sum::<f64>() / f.points.len().max(1) as f64)
        })
        .collect()
}

/// Side of one view panel of [`cloud_views`] (pixels).
const VIEW: u32 = 320;

/// A complete cloud seen along its three principal axes (three panels side by side), each point
/// colored by its distance to the model ([`overlay::distance_color`]; magenta without one).
fn cloud_views(points: &[Vector3<f64>], distances: &[Option<f64>]) -> RgbImage {
    let mut image = RgbImage::new(3 * VIEW, VIEW);
    let Some((c, axes)) = hand_model::math::principal_axes(points) else {
        return image;
    };
    let local: Vec<Vector3<f64>> = points.iter().map(|p| axes.transpose() * (p - c)).collect();
    let reach = local.iter().map(|v| v.amax()).fold(1e-9, f64::max);
    let half = f64::from(VIEW) / 2.0;
    for (view, (a, b)) in [(0, 1), (0, 2), (1, 2)].into_iter().enumerate() {
        for (v, d) in local.iter().zip(distances) {
            let x = (v[a] / reach * (half - 2.0) + half) as u32;
            let y = (v[b] / reach * (half - 2.0) + half) as u32;
            let color = d.map_or([255, 0, 255], overlay::distance_color);
            image.put_pixel(
                view as u32 * VIEW + x.min(VIEW - 1),
                y.min(VIEW - 1),
                image::Rgb(color),
            );
        }
    }
    image
}

/// The preprocessed frames at the `chosen` positions, in that order (a second pass over the
/// sequence, up to the last chosen frame: the tracking pass keeps no depth images).
fn read_chosen(args: &CalibrateArgs, chosen: &[usize]) -> Result<Vec<PreprocessedFrame>> {
    let mut out: Vec<Option<PreprocessedFrame>> = vec![None; chosen.len()];
    let last = chosen.iter().max().map_or(0, |&m| m + 1);
    for_each_frame(
        &args.sequence,
        &args.pre,
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

/// The Ch. 3 calibration (thesis §3.4) of sequence frames.
fn spheremesh(
    args: &CalibrateArgs,
    base: &SphereMeshTemplate,
    frames: &[PreprocessedFrame],
    init: &[Pose],
) -> Result<Outcome> {
    let config: CalibrationConfig = read_config(args.config.as_deref())?;
    let cal_frames: Vec<CalibrationFrame> = frames.iter().map(CalibrationFrame::depth).collect();
    Ok(Outcome::from(calibrate(base, &cal_frames, init, &config)?))
}

impl From<Calibration> for Outcome {
    fn from(cal: Calibration) -> Self {
        type Part = fn(&IterationRecord) -> f64;
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
        Outcome {
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
            final_energy: cal.best_energy(),
            iterations: cal.iterations.len(),
            seconds: cal.seconds,
            template: cal.template,
            poses: cal.poses,
        }
    }
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
    let median = median(&active.iter().map(|&i| cal.certainty[i]).collect::<Vec<_>>());
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
        &args.pre,
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
    points: &[Vector3<f64>],
) -> Result<Vec<Option<f64>>> {
    let posed = PosedSphereMesh::new(template, pose);
    let elements: Vec<_> = template.elements.iter().map(|e| e.element).collect();
    let geometry = SphereMeshGeometry::new(&posed.spheres, &elements)?;
    Ok(points
        .iter()
        .map(|p| geometry.phi(p).map(f64::abs))
        .collect())
}
