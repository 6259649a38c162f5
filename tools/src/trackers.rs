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

/// The Ch. 4 online calibrator (sphere-mesh tracking with a shape estimate) with a renderer of
/// the current estimate.
pub struct OnlineTracker<'m> {
    calib: OnlineCalibrator,
    /// The Ch. 3 tracker of the starting template: its re-initialization hypotheses give the
    /// calibrator's pose whenever the calibrator is not placed (the first frame, after a frame
    /// without a hand or a lost run; the calibrator itself only places the PCA mean pose on
    /// the points, which is also what happens should the seed fail to build). It then keeps
    /// tracking beside the calibrator for a while ([`Shadow`]).
    seed: Option<hmodel_spheremesh::Tracker<'m>>,
    /// `Some` while the seed, having placed the hand, tracks beside the calibrator.
    shadow: Option<Shadow>,
    template: &'m SphereMeshTemplate,
    prior: Option<&'m PcaPrior>,
    /// Whether the last frame had no hand.
    hand_left: bool,
    view: ShapedRenderer<'m>,
    /// The last frame's estimate β̂ and its certainty (full basis order), and the frame count.
    last: Option<(Vec<f64>, Vec<f64>)>,
    frames: usize,
}

/// The seed's watch over the calibrator after placing the hand (beyond the thesis, whose
/// calibrator started from a known pose, §4.4.2). The first frames of the calibrator are solved
/// from the placement, which may be wrong (a fist placed as the open mean pose), and its shape,
/// uncertain at the start, bends to fit the wrong pose and then holds it. The seed's fixed
/// template cannot bend, so the seed converges where the calibrator does not: the ToF `fist`
/// sequence started at its 60th frame, online calibration 16.57 mm mean keypoint error, the
/// seed alone 2.01 mm.
///
/// For [`SHADOW_FRAMES`] frames after placing the hand (after the seed's last placement: its
/// own re-initializations count too), the seed goes on tracking; when the
/// calibrator fits clearly worse than the seed ([`hand_model::solver::FrameStats::score`] above
/// [`SHADOW_RATIO`] times the seed's and by more than [`SHADOW_MARGIN`]) for [`SHADOW_RUN`]
/// frames in a row, the calibrator restarts from the seed's pose with the starting shape and
/// vague certainty (flag `shape_reset`), and the watch starts over. A calibrator that fits as
/// well as the seed is never touched, so a good start tracks bit for bit as without the watch
/// (the library's 32 noise-free and ToF sequences and 30 random-subject runs, noise-free, ToF
/// and structured light: all unchanged).
///
/// Measured on 28 ToF cold starts (library motions of the default hand and random subjects,
/// tracked from frame 45–250 on): the watch restarted the calibrator on 9 of them, mean
/// keypoint error without → with it: `rotating_fist` from frame 60 17.19 → 3.80 mm, from 150
/// 25.39 → 7.69, from 45 4.59 → 2.49; `rotation_fast` from 165 74.11 → 21.28, from 60 1.69 →
/// 1.76 (the one loss); a random subject's calibration motion from 250 28.72 → 6.04, its
/// teaser from 100 3.13 → 2.51. The cost is the seed's frames: `hands bench --model online`
/// (ToF, 240 frames) 76 → 70 frames/s of wall time, the median frame unchanged.
///
/// Counting from the seed's last placement (session 28): on a synthetic `leave_reenter` (30 Hz,
/// ToF, seed 8) the hand came back partly in view and the seed, placing it again on its own,
/// fitted clearly better than the calibrator only from the 27th frame of the watch on (score
/// 8.7 against 16.0), too late for five frames in a row. Counted from the seed's last
/// placement, the watch restarted the calibrator from it: mean keypoint error over the frames
/// with the hand wholly in view 12.10 → 6.83 mm. The 74 ToF cold-start cuts tracked with online
/// calibration: all unchanged.
#[derive(Clone, Copy, Debug, Default)]
struct Shadow {
    /// Frames watched since the placement, the seed's last placement of its own or the last
    /// reset.
    frames: usize,
    /// Consecutive frames in which the calibrator fitted clearly worse.
    worse: usize,
}

/// Frames the seed tracks beside the calibrator after placing the hand ([`Shadow`]). 60
/// frames changed one more of the 28 probed cold starts (`rotating_fist` from its 165th frame,
/// 42.77 → 25.11 mm, the seed having converged after 28 frames) at twice the seed's cost.
const SHADOW_FRAMES: usize = 30;
/// The calibrator's score over the seed's above which it fits clearly worse ([`Shadow`]).
const SHADOW_RATIO: f64 = 1.3;
/// ... when also above the seed's by this much (score units: mm of mean distance, or 1 % of
/// the points unexplained or of the silhouette covered outside). Noise-free, the calibrator of
/// the default hand scores 0.5–0.6 where the seed scores 0.3–0.4 (its template is the truth):
/// a ratio alone restarted it every few frames.
const SHADOW_MARGIN: f64 = 2.0;
/// Consecutive clearly-worse frames that restart the calibrator ([`Shadow`]).
const SHADOW_RUN: usize = 5;

impl Shadow {
    /// Count one frame with the calibrator's and the seed's scores; true when the calibrator
    /// is to restart from the seed.
    fn observe(&mut self, calibrator: f64, seed: f64) -> bool {
        self.frames += 1;
        let worse = calibrator > SHADOW_RATIO * seed && calibrator - seed > SHADOW_MARGIN;
        self.worse = if worse { self.worse + 1 } else { 0 };
        self.worse >= SHADOW_RUN
    }
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
            seed: None,
            shadow: None,
            template,
            prior,
            hand_left: false,
            view: ShapedRenderer::new(template, basis),
            last: None,
            frames: 0,
        })
    }
}

impl OnlineTracker<'_> {
    /// One frame of the seed's [`Shadow`] after both tracked it: restarts the calibrator from
    /// the seed when it has fitted clearly worse for long enough (true then), and lets the
    /// seed go once the watch is over.
    fn watch(&mut self) -> bool {
        let (Some(seed), Some(shadow)) = (self.seed.as_ref(), self.shadow.as_mut()) else {
            return false;
        };
        let loss = self
            .calib
            .config()
            .tracker
            .loss
            .for_noise(self.calib.depth_noise());
        let score = |ctx: &hmodel_spheremesh::TrackingCtx<'_>| ctx.frame_stats(&loss).score();
        if shadow.observe(score(self.calib.context()), score(seed.context())) {
            let start = self.calib.basis().template_values();
            let reset =
                self.calib.set_shape(&start).is_ok() && self.calib.set_pose(seed.pose()).is_ok();
            *shadow = Shadow::default();
            return reset;
        }
        if shadow.frames >= SHADOW_FRAMES {
            (self.seed, self.shadow) = (None, None);
        }
        false
    }
}

impl FrameTracker for OnlineTracker<'_> {
    fn track(&mut self, frame: &PreprocessedFrame, index: u64, timestamp: f64) -> HandRecord {
        if !self.calib.is_placed() || self.hand_left {
            // Placed again (by a seed still watching, if there is one).
            self.shadow = None;
            if self.seed.is_none() {
                let config = self.calib.config().tracker.clone();
                self.seed = hmodel_spheremesh::Tracker::new(self.template, config, self.prior).ok();
            }
        }
        if let Some(seed) = self.seed.as_mut() {
            let rec = seed.track(frame, index, timestamp);
            let placed = !rec
                .flags
                .iter()
                .any(|f| f == "no_hand" || f == "solver_failed");
            if self.shadow.is_none() && placed && self.calib.set_pose(seed.pose()).is_ok() {
                self.shadow = Some(Shadow::default());
            } else if let Some(shadow) = self.shadow.as_mut() {
                // The seed placed the hand again (lost, or a better start at its second look):
                // the watch counts from there.
                if rec.flags.iter().any(|f| f == "reinitialized") {
                    shadow.frames = 0;
                }
            }
        }
        let mut out = self.calib.track(frame, index, timestamp);
        if self.watch() {
            out.record.flags.push("shape_reset".into());
        }
        // As the Ch. 3 tracker: a hand that comes back after a frame without one is placed
        // again rather than solved from the pose it left at.
        self.hand_left = out.record.flags.iter().any(|f| f == "no_hand");
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

#[cfg(test)]
mod tests {
    use super::*;
    use hand_model::kinematics::Pose;
    use hand_model::spheremesh::{default_right_hand, PosedSphereMesh};
    use hmodel_spheremesh::synthetic::rendered_frame;
    use nalgebra::Vector3;

    #[test]
    fn the_watch_restarts_after_a_run_of_clearly_worse_frames_only() {
        let mut s = Shadow::default();
        // Worse by the ratio but not by the margin (noise-free scores), then by both.
        assert!(!(0..20).any(|_| s.observe(0.6, 0.35)));
        for k in 1..SHADOW_RUN {
            assert!(!s.observe(13.0, 7.0), "frame {k}");
        }
        assert!(!s.observe(7.5, 7.0), "a fair frame ends the run");
        assert!(!(1..SHADOW_RUN).any(|_| s.observe(13.0, 7.0)));
        assert!(s.observe(13.0, 7.0));
        assert_eq!(s.frames, 20 + 2 * SHADOW_RUN);
    }

    /// A fist seen from a cold start: the seed places it as the open mean pose and converges
    /// within a few frames; the calibrator, placed there too, bends its uncertain shape to the
    /// wrong pose and holds it, until the watch restarts it from the seed. Measured after 45
    /// frames: 0.76 mm mean keypoint error with one restart, 28.55 mm without the watch.
    #[test]
    fn a_fist_from_a_cold_start_is_not_calibrated_to_the_wrong_pose() {
        let t = default_right_hand();
        let basis = ShapeBasis::honline(&t).unwrap();
        let prior = PcaPrior::project_default();
        let fist = Pose::from_named(
            &t.skeleton,
            [
                ("global_ry", -0.35),
                ("global_rz", 2.96),
                ("global_tx", -9.8),
                ("global_ty", 42.0),
                ("global_tz", 402.0),
                ("index_mcp_flex", 1.15),
                ("index_pip_flex", 1.32),
                ("index_dip_flex", 0.82),
                ("middle_mcp_flex", 1.08),
                ("middle_pip_flex", 1.24),
                ("middle_dip_flex", 0.75),
                ("ring_mcp_flex", 1.21),
                ("ring_pip_flex", 1.34),
                ("ring_dip_flex", 0.81),
                ("pinky_mcp_flex", 1.32),
                ("pinky_pip_flex", 1.41),
                ("pinky_dip_flex", 0.83),
                ("thumb_cmc_abd", 0.15),
                ("thumb_cmc_flex", 0.8),
                ("thumb_mcp_flex", 0.59),
                ("thumb_ip_flex", 0.34),
            ],
        )
        .unwrap();
        let frame = rendered_frame(&t, &fist, &Camera::sr300_qvga(), 2500).unwrap();
        let expected = PosedSphereMesh::new(&t, &fist).keypoints(&t);
        let error = |rec: &HandRecord| {
            rec.keypoints
                .iter()
                .zip(&expected)
                .map(|(k, e)| (Vector3::from(*k) - e).norm())
                .sum::<f64>()
                / 21.0
        };
        let mut online =
            OnlineTracker::new(&t, &basis, OnlineConfig::default(), Some(&prior)).unwrap();
        let mut seed =
            hmodel_spheremesh::Tracker::new(&t, Default::default(), Some(&prior)).unwrap();
        let (mut resets, mut last, mut seed_last) = (0, 0.0, 0.0);
        for f in 0..45 {
            let rec = online.track(&frame, f, f as f64 / 30.0);
            resets += rec.flags.iter().filter(|x| *x == "shape_reset").count();
            last = error(&rec);
            seed_last = error(&seed.track(&frame, f, f as f64 / 30.0));
        }
        println!(
            "fist from a cold start, 45 frames: online {last:.2} mm ({resets} reset), the Ch. 3 tracker {seed_last:.2} mm"
        );
        assert!(
            resets >= 1 && last < seed_last + 2.0,
            "{last} mm, {resets} resets"
        );
    }
}
