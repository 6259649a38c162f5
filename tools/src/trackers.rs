//! The trackers (Ch. 2 cylinders, Ch. 3 sphere-meshes, Ch. 4 online calibration) behind one interface, so that
//! `hands track` and `hands report` drive either with the same frame loop, overlays and metrics
//! instead of one copy of each per model.

use anyhow::Result;
use hand_model::cylinder::CylinderModel;
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::{ShapeBasis, SphereMeshTemplate};
use honline_calib::{OnlineCalibrator, OnlineConfig};
use sensor_io::preprocess::PreprocessedFrame;
use sensor_io::record::HandRecord;
use sensor_io::Camera;

use crate::methods::{
    CylinderRenderer, ModelRenderer as _, RenderedModel, ShapedRenderer, SphereMeshRenderer,
};

/// A tracker as the shared loops see it: one call per frame, plus what the visual checks and
/// the self-evaluation metrics need to look at afterwards.
pub trait FrameTracker {
    /// Track one preprocessed frame (DESIGN.md record).
    fn track(&mut self, frame: &PreprocessedFrame, index: u64, timestamp: f64) -> HandRecord;

    /// The model at the current pose seen from `camera` (pixels and depth).
    fn model(&mut self, camera: &Camera) -> Result<&RenderedModel>;

    /// The pixels (linear indices `v·width + u`) where the model at the current pose is seen
    /// from `camera`: the rendered silhouette of E_m2d and of the overlays.
    fn model_pixels(&mut self, camera: &Camera) -> Result<&[u32]> {
        Ok(&self.model(camera)?.pixels)
    }

    /// Per sensor point of the last tracked frame, the unsigned point-to-model distance (mm) of
    /// its correspondence at the last linearization (`None` without one). Empty when the
    /// tracker did not take the frame's points (a frame without a hand).
    fn point_distances(&self) -> Vec<Option<f64>>;

    /// Lines about what the tracker learned over the sequence, printed after it (the online
    /// calibration's final shape); none by default.
    fn summary(&self) -> Vec<String> {
        Vec::new()
    }
}

/// Per-point distances of a sphere-mesh tracking context's correspondences.
fn distances(ctx: &hmodel_spheremesh::TrackingCtx<'_>) -> Vec<Option<f64>> {
    ctx.correspondences()
        .iter()
        .map(|c| c.map(|c| c.distance.abs()))
        .collect()
}

/// The Ch. 3 sphere-mesh tracker with a renderer for its silhouette.
pub struct SphereMeshTracker<'m> {
    tracker: hmodel_spheremesh::Tracker<'m>,
    view: SphereMeshRenderer<'m>,
}

impl<'m> SphereMeshTracker<'m> {
    /// A tracker of `template`.
    pub fn new(
        template: &'m SphereMeshTemplate,
        config: hmodel_spheremesh::TrackerConfig,
        prior: Option<&PcaPrior>,
    ) -> Result<Self> {
        Ok(Self {
            tracker: hmodel_spheremesh::Tracker::new(template, config, prior)?,
            view: SphereMeshRenderer::new(template),
        })
    }
}

impl FrameTracker for SphereMeshTracker<'_> {
    fn track(&mut self, frame: &PreprocessedFrame, index: u64, timestamp: f64) -> HandRecord {
        self.tracker.track(frame, index, timestamp)
    }

    fn model(&mut self, camera: &Camera) -> Result<&RenderedModel> {
        // The tracker's own posed mesh is at the last linearization, not at the returned pose.
        self.view.render(self.tracker.pose(), camera)
    }

    fn point_distances(&self) -> Vec<Option<f64>> {
        distances(self.tracker.context())
    }
}

/// The Ch. 4 online calibrator (sphere-mesh tracking with a shape estimate, placed and watched
/// by a Ch. 3 tracker of the starting template, [`honline_calib::watch`]) with a renderer of
/// the current estimate.
pub struct OnlineTracker<'m> {
    calib: OnlineCalibrator<'m>,
    view: ShapedRenderer<'m>,
    /// The last frame's estimate β̂ and its certainty (full basis order), and the frame count.
    last: Option<(Vec<f64>, Vec<f64>)>,
    frames: usize,
}

impl<'m> OnlineTracker<'m> {
    /// A calibrator starting from `template` (whose honline basis is `basis`) with `config`.
    pub fn new(
        template: &'m SphereMeshTemplate,
        basis: &'m ShapeBasis,
        config: OnlineConfig,
        prior: Option<&'m PcaPrior>,
    ) -> Result<Self> {
        Ok(Self {
            calib: OnlineCalibrator::new(template, config, prior)?,
            view: ShapedRenderer::new(template, basis),
            last: None,
            frames: 0,
        })
    }
}

impl FrameTracker for OnlineTracker<'_> {
    fn track(&mut self, frame: &PreprocessedFrame, index: u64, timestamp: f64) -> HandRecord {
        let out = self.calib.track(frame, index, timestamp);
        // The calibrator only outputs shapes the basis accepts; were one refused, the view
        // would keep the previous shape.
        let _ = self.view.set_beta(&out.beta);
        self.last = Some((out.beta, out.certainty));
        self.frames += 1;
        out.record
    }

    fn model(&mut self, camera: &Camera) -> Result<&RenderedModel> {
        self.view.render(self.calib.pose(), camera)
    }

    fn point_distances(&self) -> Vec<Option<f64>> {
        distances(self.calib.context())
    }

    fn summary(&self) -> Vec<String> {
        let Some((beta, certainty)) = &self.last else {
            return Vec::new();
        };
        shape_summary(
            self.calib.basis(),
            &self.calib.layout().active,
            beta,
            certainty,
            &format!(
                "online calibration ({}), {} frames",
                self.calib.config().estimator,
                self.frames
            ),
        )
    }
}

/// How many parameters each line of [`shape_summary`] lists.
const SUMMARY_TOP: usize = 5;

/// The final-shape lines of `hands track --calibrate`: the estimated parameters (`active`) that
/// moved most from the template values of `basis`, and the least certain ones.
pub fn shape_summary(
    basis: &ShapeBasis,
    active: &[usize],
    beta: &[f64],
    certainty: &[f64],
    title: &str,
) -> Vec<String> {
    let name = |i: usize| basis.params.get(i).map_or("?", |p| p.name.as_str());
    let template = basis.template_values();
    let mut moved: Vec<(usize, f64)> = active
        .iter()
        .filter_map(|&i| Some((i, beta.get(i)? - template.get(i)?)))
        .collect();
    moved.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
    let mut unsure: Vec<(usize, f64)> = active
        .iter()
        .filter_map(|&i| Some((i, *certainty.get(i)?)))
        .collect();
    unsure.sort_by(|a, b| a.1.total_cmp(&b.1));
    let mean_abs = if moved.is_empty() {
        0.0
    } else {
        moved.iter().map(|m| m.1.abs()).sum::<f64>() / moved.len() as f64
    };
    let list = |items: &[(usize, f64)], f: &dyn Fn(f64) -> String| {
        items
            .iter()
            .take(SUMMARY_TOP)
            .map(|&(i, v)| format!("{} {}", name(i), f(v)))
            .collect::<Vec<_>>()
            .join(", ")
    };
    vec![
        format!(
            "{title}: {} of {} shape parameters estimated, mean |β̂ − template| {mean_abs:.2} mm",
            active.len(),
            basis.len()
        ),
        format!(
            "  largest changes vs the template: {}",
            list(&moved, &|d| format!("{d:+.2} mm"))
        ),
        format!(
            "  least certain (information per mm²): {}",
            list(&unsure, &|c| format!("{c:.3}"))
        ),
    ]
}

/// The Ch. 2 cylinder tracker with a raster for its silhouette.
pub struct CylinderTracker<'m> {
    tracker: htrack_icp::Tracker<'m>,
    view: CylinderRenderer<'m>,
}

impl<'m> CylinderTracker<'m> {
    /// A tracker of `model`.
    pub fn new(
        model: &'m CylinderModel,
        config: htrack_icp::TrackerConfig,
        prior: Option<&PcaPrior>,
    ) -> Result<Self> {
        Ok(Self {
            tracker: htrack_icp::Tracker::new(model, config, prior)?,
            view: CylinderRenderer::new(model),
        })
    }
}

impl FrameTracker for CylinderTracker<'_> {
    fn track(&mut self, frame: &PreprocessedFrame, index: u64, timestamp: f64) -> HandRecord {
        self.tracker.track(frame, index, timestamp)
    }

    fn model(&mut self, camera: &Camera) -> Result<&RenderedModel> {
        self.view.render(self.tracker.pose(), camera)
    }

    fn point_distances(&self) -> Vec<Option<f64>> {
        let ctx = self.tracker.context();
        ctx.correspondences()
            .iter()
            .map(|c| c.map(|c| c.distance.abs()))
            .collect()
    }
}

/// E_m2d of thesis Eq. 3.16 for one frame: the mean over the rendered model pixels of the 2D
/// distance (px) to the sensor silhouette (0 inside it), from the frame's distance transform.
/// NaN when nothing is rendered or the frame has no silhouette.
pub fn e_m2d(model_pixels: &[u32], frame: &PreprocessedFrame) -> f64 {
    let dist2 = &frame.dt.dist2;
    if model_pixels.is_empty() || frame.hand.count == 0 {
        return f64::NAN;
    }
    let sum: f64 = model_pixels
        .iter()
        .map(|&k| dist2.get(k as usize).map_or(0.0, |&d| f64::from(d).sqrt()))
        .sum();
    sum / model_pixels.len() as f64
}
