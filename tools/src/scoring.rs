//! What `hands eval`, `compare` and `demo` share: scoring tracked frames (the algorithm-agnostic
//! E_d2m / E_m2d from the sensor depth and the rendered model, marker errors against the ground
//! truth when there is one, energies, timings), keeping overlays of the worst frames, and
//! writing one report (metrics JSON, markdown table, SVG plots, contact sheet) for any number of
//! methods.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use datasets::sheet::{contact_sheet, draw_keypoints};
use eval::depth_metrics::{DepthMetricsScratch, ModelDepth};
use eval::markers::{frame_error, mean, median, FrameError, MarkerSummary};
use eval::plot::bar_plot_svg;
use eval::traces::energy_summary;
use image::RgbImage;
use sensor_io::io::write_atomic;
use sensor_io::preprocess::PreprocessedFrame;
use sensor_io::record::HandRecord;
use sensor_io::Camera;
use serde_json::{json, Value};

use crate::methods::RenderedModel;
use crate::report::{per_frame_plot, under_plot};

/// Largest ε (mm) of the "fraction of frames under ε" curves, as in the papers' figures.
pub const EPS_MAX_MM: f64 = 50.0;

/// How many worst frames per method the contact sheet shows.
pub const WORST_FRAMES: usize = 4;

/// One frame kept for the contact sheet of worst frames.
pub struct WorstFrame {
    /// The score that ranked it (max marker error, else E_d2m).
    pub score: f64,
    /// Position in the sequence.
    pub position: usize,
    /// The overlay (sensor depth, model tint, points, the method's keypoints).
    pub image: RgbImage,
}

/// One method's per-frame outcome on a sequence.
pub struct MethodRun {
    /// Method name.
    pub name: String,
    /// The records, in frame order.
    pub records: Vec<HandRecord>,
    /// Per frame E_d2m (mm; NaN where undefined: no sensor point or no model).
    pub d2m: Vec<f64>,
    /// Per frame E_m2d (px; NaN where undefined).
    pub m2d: Vec<f64>,
    /// Per frame keypoint errors against the ground truth (`None` without truth or keypoints).
    pub errors: Vec<Option<FrameError>>,
    /// Whether any frame had ground truth.
    pub has_truth: bool,
    /// The worst frames, worst first (at most [`WORST_FRAMES`]).
    pub worst: Vec<WorstFrame>,
    scratch: DepthMetricsScratch,
}

/// The sensor side of a frame as the metrics read it.
pub struct SensorFrame<'a> {
    /// Position in the sequence.
    pub position: usize,
    /// The preprocessed frame (depth, silhouette, distance transform, points).
    pub pre: &'a PreprocessedFrame,
    /// The ground truth, when the sequence has one.
    pub truth: Option<&'a HandRecord>,
}

/// E_d2m (mm, Eq. 3.15) and E_m2d (px, Eq. 3.16) of one frame from the sensor frame (its
/// depth and hand silhouette) and the rendered model only, by [`eval::depth_metrics`]; NaN
/// where a metric is undefined.
pub fn depth_metrics(
    pre: &PreprocessedFrame,
    camera: &Camera,
    model: &RenderedModel,
    scratch: &mut DepthMetricsScratch,
) -> Result<(f64, f64)> {
    let mut depth = vec![0.0f32; camera.width as usize * camera.height as usize];
    for (&k, &z) in model.pixels.iter().zip(&model.depth_mm) {
        if let Some(d) = depth.get_mut(k as usize) {
            *d = z as f32;
        }
    }
    let model = ModelDepth::from_f32(camera.width, camera.height, depth)?;
    let m =
        eval::depth_metrics::depth_metrics(&pre.depth, &pre.hand.mask, &model, camera, scratch)?;
    Ok((
        m.d2m.map_or(f64::NAN, |d| d.mean),
        m.m2d.map_or(f64::NAN, |d| d.mean),
    ))
}

impl MethodRun {
    /// An empty run of method `name`.
    pub fn new(name: &str) -> Self {
        Self {
            name: name.to_string(),
            records: Vec::new(),
            d2m: Vec::new(),
            m2d: Vec::new(),
            errors: Vec::new(),
            has_truth: false,
            worst: Vec::new(),
            scratch: DepthMetricsScratch::default(),
        }
    }

    /// Score one frame: `record` is the method's output, `model` its model rendered at that
    /// record's pose (`None` when there is no pose to render), `distances` the per-point model
    /// distances for the overlay (may be empty).
    pub fn push(
        &mut self,
        frame: &SensorFrame<'_>,
        record: HandRecord,
        model: Option<&RenderedModel>,
        distances: &[Option<f64>],
    ) -> Result<()> {
        let (d2m, m2d) = match (model, frame.pre.camera.as_ref()) {
            (Some(m), Some(c)) => depth_metrics(frame.pre, c, m, &mut self.scratch)
                .with_context(|| format!("{}: metrics of frame {}", self.name, frame.position))?,
            _ => (f64::NAN, f64::NAN),
        };
        let error = frame
            .truth
            .and_then(|t| frame_error(&record.keypoints, &t.keypoints));
        self.has_truth |= frame.truth.is_some_and(|t| !t.keypoints.is_empty());
        // Rank by the max marker error where there is truth, else by E_d2m; a frame with
        // nothing to rank by is not shown.
        let score = if self.has_truth {
            error.map_or(f64::INFINITY, |e| e.max)
        } else {
            d2m
        };
        let enters = !score.is_nan()
            && (self.worst.len() < WORST_FRAMES
                || self.worst.last().is_some_and(|w| score > w.score));
        if enters {
            let pixels = model.map_or(&[][..], |m| &m.pixels[..]);
            let mut image = crate::overlay::compose(frame.pre, pixels, distances);
            if let Some(c) = frame.pre.camera.as_ref() {
                let px: Vec<[f64; 2]> = record
                    .keypoints
                    .iter()
                    .filter(|k| k[2] > 0.0)
                    .map(|k| {
                        let p = c.project(&nalgebra_point(k));
                        [p.x, p.y]
                    })
                    .collect();
                if px.len() == record.keypoints.len() {
                    draw_keypoints(&mut image, &px);
                }
            }
            self.worst.push(WorstFrame {
                score,
                position: frame.position,
                image,
            });
            self.worst.sort_by(|a, b| b.score.total_cmp(&a.score));
            self.worst.truncate(WORST_FRAMES);
        }
        self.d2m.push(d2m);
        self.m2d.push(m2d);
        self.errors.push(error);
        self.records.push(record);
        Ok(())
    }

    /// Per frame the maximum keypoint error (∞ where there is none).
    pub fn max_errors(&self) -> Vec<f64> {
        self.errors
            .iter()
            .map(|e| e.map_or(f64::INFINITY, |e| e.max))
            .collect()
    }

    /// Per frame the mean keypoint error (NaN where there is none).
    pub fn mean_errors(&self) -> Vec<f64> {
        self.errors
            .iter()
            .map(|e| e.map_or(f64::NAN, |e| e.mean))
            .collect()
    }

    /// Marker summary, `None` without ground truth.
    pub fn markers(&self) -> Option<MarkerSummary> {
        self.has_truth.then(|| {
            let e: Vec<FrameError> = self.errors.iter().flatten().copied().collect();
            let mut s = MarkerSummary::new(&e);
            // Frames without an error (lost keypoints) count as failures.
            s.frac_max_under_25 = eval::markers::fraction_under(&self.max_errors(), 25.0);
            s
        })
    }

    /// Per energy term its mean over the frames that report it.
    pub fn mean_energies(&self) -> BTreeMap<String, f64> {
        energy_summary(&self.records)
            .into_iter()
            .map(|(k, s)| (k, s.mean))
            .collect()
    }

    /// Median over frames of the time of `stage` (ms), NaN if never reported.
    pub fn median_ms(&self, stage: &str) -> f64 {
        let v: Vec<f64> = self
            .records
            .iter()
            .filter_map(|r| r.timing_us.get(stage).copied())
            .collect();
        median(&v) / 1e3
    }

    /// Number of frames flagged `flag`.
    pub fn flagged(&self, flag: &str) -> usize {
        self.records
            .iter()
            .filter(|r| r.flags.iter().any(|f| f == flag))
            .count()
    }
}

fn nalgebra_point(k: &[f64; 3]) -> nalgebra::Vector3<f64> {
    nalgebra::Vector3::new(k[0], k[1], k[2])
}

/// Mean of the finite values (NaN if none).
fn finite_mean(v: &[f64]) -> f64 {
    let f: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    mean(&f)
}

/// A JSON number, or null for NaN/∞.
fn num(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        Value::Null
    }
}

/// The metrics of `runs` as JSON (see the report's README for the meaning of each field).
pub fn metrics_json(sequence: &str, runs: &[MethodRun], notes: &[String]) -> Value {
    let eps: Vec<f64> = (0..=50).map(|i| EPS_MAX_MM * f64::from(i) / 50.0).collect();
    let methods: Vec<Value> = runs
        .iter()
        .map(|r| {
            let markers = r.markers().map(|s| {
                let curve = eval::markers::under_curve(&r.max_errors(), &eps);
                json!({
                    "frames_with_error": s.frames,
                    "mean_mm": num(s.mean),
                    "median_mm": num(s.median),
                    "mean_max_mm": num(s.mean_max),
                    "fraction_max_under_25mm": num(s.frac_max_under_25),
                    "fraction_max_under_eps": eps.iter().zip(curve).map(|(e, f)| json!([e, f])).collect::<Vec<_>>(),
                    "per_frame_mean_mm": r.mean_errors().into_iter().map(num).collect::<Vec<_>>(),
                    "per_frame_max_mm": r.max_errors().into_iter().map(num).collect::<Vec<_>>(),
                })
            });
            json!({
                "method": r.name,
                "frames": r.records.len(),
                "e_d2m_mm": { "mean": num(finite_mean(&r.d2m)), "median": num(median(&finite(&r.d2m))), "per_frame": r.d2m.iter().copied().map(num).collect::<Vec<_>>() },
                "e_m2d_px": { "mean": num(finite_mean(&r.m2d)), "median": num(median(&finite(&r.m2d))), "per_frame": r.m2d.iter().copied().map(num).collect::<Vec<_>>() },
                "markers": markers.unwrap_or(Value::Null),
                "mean_energies": r.mean_energies(),
                "median_track_ms": num(r.median_ms("track")),
                "lost_frames": r.flagged("lost"),
                "worst_frames": r.worst.iter().map(|w| w.position).collect::<Vec<_>>(),
            })
        })
        .collect();
    json!({ "sequence": sequence, "notes": notes, "methods": methods })
}

fn finite(v: &[f64]) -> Vec<f64> {
    v.iter().copied().filter(|x| x.is_finite()).collect()
}

/// The markdown summary table of `runs` (marker columns only when some run has ground truth).
pub fn table(runs: &[MethodRun]) -> Result<String> {
    let truth = runs.iter().any(|r| r.has_truth);
    let mut md = String::new();
    write!(
        md,
        "| method | frames | mean E_d2m (mm) | mean E_m2d (px) |"
    )?;
    if truth {
        write!(
            md,
            " mean err (mm) | median err (mm) | mean max err (mm) | frames max < 25 mm |"
        )?;
    }
    writeln!(md, " lost frames | track ms/frame (median) |")?;
    let cols = if truth { 10 } else { 6 };
    writeln!(md, "|{}", "---|".repeat(cols))?;
    for r in runs {
        write!(
            md,
            "| {} | {} | {:.2} | {:.2} |",
            r.name,
            r.records.len(),
            finite_mean(&r.d2m),
            finite_mean(&r.m2d)
        )?;
        if truth {
            match r.markers() {
                Some(s) => write!(
                    md,
                    " {:.2} | {:.2} | {:.2} | {:.1}% |",
                    s.mean,
                    s.median,
                    s.mean_max,
                    100.0 * s.frac_max_under_25
                )?,
                None => write!(md, " – | – | – | – |")?,
            }
        }
        writeln!(md, " {} | {:.2} |", r.flagged("lost"), r.median_ms("track"))?;
    }
    Ok(md)
}

/// Write the report of `runs` into `out` (created): `metrics.json`, `README.md`, the SVG plots
/// and `worst-frames.png`. Returns the markdown table.
pub fn write_report(
    out: &Path,
    title: &str,
    sequence: &str,
    runs: &[MethodRun],
    notes: &[String],
) -> Result<String> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let json = serde_json::to_string_pretty(&metrics_json(sequence, runs, notes))?;
    let path = out.join("metrics.json");
    write_atomic(&path, json.as_bytes()).with_context(|| format!("writing {}", path.display()))?;
    let tab = table(runs)?;
    let mut md = format!("# {title}\n\nSequence: `{sequence}`.\n\n{tab}\n");
    for n in notes {
        writeln!(md, "- {n}")?;
    }
    writeln!(
        md,
        "\nE_d2m (thesis Eq. 3.15): mean distance (mm) from the sensor points to the model rendered \
         at the method's pose; E_m2d (Eq. 3.16): mean 2D distance (px) from the rendered model pixels \
         outside the sensor silhouette to it. Both read only the sensor depth and the rendered model.\n"
    )?;
    let named = |f: &dyn Fn(&MethodRun) -> Vec<f64>| -> Vec<(String, Vec<f64>)> {
        runs.iter().map(|r| (r.name.clone(), f(r))).collect()
    };
    per_frame_plot(
        out,
        "d2m",
        "E_d2m per frame",
        "mm",
        &named(&|r| r.d2m.clone()),
        Some(30.0),
    )?;
    per_frame_plot(
        out,
        "m2d",
        "E_m2d per frame",
        "px",
        &named(&|r| r.m2d.clone()),
        Some(30.0),
    )?;
    writeln!(
        md,
        "![E_d2m per frame](d2m.svg)\n![E_m2d per frame](m2d.svg)"
    )?;
    if runs.iter().any(|r| r.has_truth) {
        per_frame_plot(
            out,
            "error",
            "mean keypoint error per frame",
            "mm",
            &named(&|r| r.mean_errors()),
            Some(EPS_MAX_MM),
        )?;
        under_plot(
            out,
            "error-under",
            "frames with max keypoint error < ε",
            "ε (mm)",
            EPS_MAX_MM,
            &named(&|r| r.max_errors()),
        )?;
        writeln!(
            md,
            "![keypoint error per frame](error.svg)\n![frames under ε](error-under.svg)"
        )?;
    }
    let energies: Vec<BTreeMap<String, f64>> = runs.iter().map(MethodRun::mean_energies).collect();
    let mut terms: Vec<String> = energies.iter().flat_map(|e| e.keys().cloned()).collect();
    terms.sort();
    terms.dedup();
    if !terms.is_empty() {
        let groups: Vec<(String, Vec<f64>)> = runs
            .iter()
            .zip(&energies)
            .map(|(r, e)| {
                (
                    r.name.clone(),
                    terms
                        .iter()
                        .map(|t| e.get(t).copied().unwrap_or(0.0))
                        .collect(),
                )
            })
            .collect();
        let svg = bar_plot_svg("mean energy per term", "energy", &terms, &groups)?;
        let path = out.join("energies.svg");
        write_atomic(&path, svg.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
        writeln!(md, "![mean energy per term](energies.svg)")?;
    }
    let rows: Vec<&MethodRun> = runs.iter().filter(|r| !r.worst.is_empty()).collect();
    if !rows.is_empty() {
        let blank = rows
            .iter()
            .flat_map(|r| r.worst.first())
            .map(|w| RgbImage::new(w.image.width(), w.image.height()))
            .next()
            .unwrap_or_default();
        let mut tiles = Vec::new();
        for r in &rows {
            for k in 0..WORST_FRAMES {
                tiles.push(
                    r.worst
                        .get(k)
                        .map_or_else(|| blank.clone(), |w| w.image.clone()),
                );
            }
        }
        let sheet = contact_sheet(&tiles, WORST_FRAMES as u32);
        let path = out.join("worst-frames.png");
        hand_model::render::preview::write_png(&path, &sheet)
            .with_context(|| format!("writing {}", path.display()))?;
        writeln!(
            md,
            "\n## Worst frames\n\n![worst frames](worst-frames.png)\n\nOne row per method ({}), worst first; \
             ranked by the max keypoint error (by E_d2m without ground truth). Sensor depth in grey, the \
             model tinted blue, the method's keypoints drawn.\n",
            rows.iter().map(|r| r.name.as_str()).collect::<Vec<_>>().join(", ")
        )?;
        for r in &rows {
            let frames: Vec<String> = r
                .worst
                .iter()
                .map(|w| format!("{} ({:.1})", w.position, w.score))
                .collect();
            writeln!(md, "- {}: frames {}", r.name, frames.join(", "))?;
        }
    }
    let path = out.join("README.md");
    write_atomic(&path, md.as_bytes()).with_context(|| format!("writing {}", path.display()))?;
    Ok(tab)
}
