//! The two trackers (Ch. 2 cylinders, Ch. 3 sphere-meshes) behind one interface, so that
//! `hands track` and `hands report` drive either with the same frame loop, overlays and metrics
//! instead of one copy of each per model.

use anyhow::Result;
use hand_model::cylinder::CylinderModel;
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::SphereMeshTemplate;
use sensor_io::preprocess::PreprocessedFrame;
use sensor_io::record::HandRecord;
use sensor_io::Camera;

use crate::methods::{CylinderRenderer, ModelRenderer as _, RenderedModel, SphereMeshRenderer};

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
        let ctx = self.tracker.context();
        ctx.correspondences()
            .iter()
            .map(|c| c.map(|c| c.distance.abs()))
            .collect()
    }
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
