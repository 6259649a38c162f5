//! `hands calibrate`: offline multi-frame calibration of the sphere-mesh template (thesis §3.4)
//! from a recorded or synthetic sequence of the user's hand.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use eval::plot::{line_plot_svg, Series};
use hand_model::kinematics::Pose;
use hand_model::query::SphereMeshGeometry;
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::{PosedSphereMesh, SphereMeshTemplate};
use hmodel_spheremesh::calibration::{
    calibrate, select_frames, CalibrationConfig, CalibrationFrame,
};
use hmodel_spheremesh::{Tracker, TrackerConfig};
use image::{GenericImage, RgbImage};
use sensor_io::io::write_atomic;

use crate::methods::{ModelRenderer, SphereMeshRenderer};
use crate::overlay;
use crate::track::{for_each_frame, load_sphere_mesh, read_config};

/// Calibrate the sphere-mesh template to a sequence: the sequence is tracked with the starting
/// template, calibration frames are chosen (`--frames`, or `--auto N` by farthest-point
/// sampling of the tracked poses), and the template's shape (honline β, rest orientations of
/// the kinematic frames) is optimized jointly with those frames' poses.
///
/// Example: `hands calibrate seq.mcap --auto 8 --out me.json --report calib/`
#[derive(Args)]
pub struct CalibrateArgs {
    /// Sequence (folder or `.mcap`) showing the hand in different poses.
    pub sequence: PathBuf,
    /// Calibrate from these frame positions (comma-separated).
    #[arg(long, value_delimiter = ',', conflicts_with = "auto")]
    pub frames: Option<Vec<usize>>,
    /// Choose this many frames automatically (default 8 when `--frames` is not given).
    #[arg(long)]
    pub auto: Option<usize>,
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
    /// Calibration settings (JSON of `CalibrationConfig`; missing fields keep their defaults).
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

/// Run `hands calibrate`.
pub fn run(args: CalibrateArgs) -> Result<()> {
    if args.out.extension().and_then(|e| e.to_str()) != Some("json") {
        bail!("--out must end in .json, got {}", args.out.display());
    }
    let base = match &args.template {
        Some(spec) => load_sphere_mesh(spec)?,
        None => hand_model::spheremesh::default_right_hand(),
    };
    let config: CalibrationConfig = read_config(args.config.as_deref())?;
    let prior = PcaPrior::project_default();
    let mut tracker = Tracker::new(&base, TrackerConfig::default(), Some(&prior))?;
    let sk = &base.skeleton;
    let (mut frames, mut poses, mut usable) = (Vec::new(), Vec::new(), Vec::new());
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
            frames.push(CalibrationFrame::depth(sf.pre));
            Ok(())
        },
    )?;
    let chosen = match &args.frames {
        Some(list) => {
            if let Some(&bad) = list.iter().find(|&&i| i >= read) {
                bail!("--frames {bad} is beyond the sequence ({read} frames read)");
            }
            list.clone()
        }
        None => select_frames(sk, &poses, |i| usable[i], args.auto.unwrap_or(8)),
    };
    if chosen.len() < MIN_FRAMES {
        bail!(
            "{} frame(s) chosen of {read} (automatic choice skips frames without a hand or with lost tracking); calibration needs at least {MIN_FRAMES} frames in different poses",
            chosen.len()
        );
    }
    let cal_frames: Vec<CalibrationFrame> = chosen.iter().map(|&i| frames[i].clone()).collect();
    let init: Vec<Pose> = chosen.iter().map(|&i| poses[i].clone()).collect();
    let cal = calibrate(&base, &cal_frames, &init, &config)?;
    let last = cal
        .iterations
        .iter()
        .rev()
        .find(|r| r.accepted)
        .map_or(cal.initial_energy, |r| r.energy);
    cal.template
        .save(&args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!(
        "calibrated from frames {chosen:?} of {read}: energy {:.1} → {last:.1} in {} iterations ({:.2} s) → {}",
        cal.initial_energy,
        cal.iterations.len(),
        cal.seconds,
        args.out.display()
    );
    let weak = cal.unconstrained(UNCONSTRAINED);
    if !weak.is_empty() {
        eprintln!(
            "warning: the chosen frames barely constrain {} shape parameter(s); they stay near the starting template: {}",
            weak.len(),
            weak.join(", ")
        );
    }
    if let Some(dir) = &args.report {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let json = serde_json::to_string_pretty(&serde_json::json!({
            "frames": chosen,
            "iterations": cal.iterations,
            "information": cal.information,
            "unconstrained": weak,
        }))?;
        write_atomic(&dir.join("iterations.json"), json.as_bytes())?;
        let series =
            |name: &str, f: &dyn Fn(&hmodel_spheremesh::calibration::IterationRecord) -> f64| {
                Series {
                    label: name.into(),
                    points: cal
                        .iterations
                        .iter()
                        .enumerate()
                        .filter(|(_, r)| r.accepted)
                        .map(|(i, r)| (i as f64, f(r)))
                        .collect(),
                }
            };
        let svg = line_plot_svg(
            "calibration energy (accepted steps)",
            "iteration",
            "energy",
            &[
                series("total", &|r| r.energy),
                series("d2m", &|r| r.d2m),
                series("m2d", &|r| r.m2d),
            ],
            None,
        )?;
        write_atomic(&dir.join("energy.svg"), svg.as_bytes())?;
        write_overlays(
            &args,
            dir,
            &chosen,
            (&base, &init),
            (&cal.template, &cal.poses),
        )?;
        eprintln!("report → {}", dir.display());
    }
    Ok(())
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
