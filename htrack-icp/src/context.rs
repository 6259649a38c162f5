//! The per-iteration context of the Ch. 2 tracker (STYLE practice 5): the posed cylinder model,
//! the sensor points and their front-facing correspondences (thesis §2.3.1 "3D
//! correspondences") with one IRLS weight each (§2.7.4 "Point cloud alignment"), and the
//! rendered silhouette `S_r` of the model with its per-pixel bone and 3D point (§2.3.1 "2D
//! correspondences", Eq. 2.3).
//!
//! Beyond the thesis, under depth noise the points can register where their camera rays enter
//! the model ([`TrackingCtx::set_ray_gate`]), as the sphere-mesh tracker's do: a closest point
//! is biased under noise along the rays (a noisy point in front of a cylinder finds its foot
//! point on the cylinder's side, one behind it is pulled to its silhouette), the ray's entry is
//! not. The entries come from the same rendering as `S_r`, extended to the points' pixels.

use hand_model::cylinder::{
    cast_camera_ray, CylinderModel, CylinderProjection, CylinderRaster, RasterHit, View, NO_SEED,
};
use hand_model::kinematics::{Pose, PosedSkeleton, Skeleton};
use hand_model::render::Intrinsics;
use hand_model::solver::{IrlsParams, IterInfo, LmCallback, PoseContext, TermError};
use nalgebra::Vector3;
use sensor_io::preprocess::PreprocessedFrame;
use sensor_io::SensorView;

/// The shared per-iteration state of the Ch. 2 tracker: the cylinder model, the current pose θ
/// and its forward kinematics, the sensor point cloud `𝒳_s` (camera frame, mm), for every point
/// its front-facing correspondence `y = Π_M(x, θ)` (§2.3.1) and its IRLS weight (§2.7.4).
///
/// With a sensor camera ([`SensorView::camera`]) and the silhouette enabled
/// ([`TrackingCtx::set_silhouette`], on by default) it also holds the rendered silhouette `S_r`
/// of the model (§2.3.1 "2D correspondences"): the posed model rasterized from the sensor camera
/// ([`CylinderRaster`]), per pixel the segment, its bone and the camera-frame surface point —
/// only for the pixels outside the sensor silhouette `S_s` (`S_r \ S_s`, all E2D needs) and,
/// with along-ray correspondences ([`TrackingCtx::set_ray_gate`]), the points' own pixels; the
/// others are not ray cast.
///
/// Refreshed by [`TrackingCtx::update`] (called by [`CorrespondenceCallback`] before every LM
/// iteration); nothing allocates once the buffers have held the current number of points and
/// image size.
#[derive(Clone, Debug)]
pub struct TrackingCtx<'m> {
    model: &'m CylinderModel,
    pose: Pose,
    posed: PosedSkeleton,
    points: Vec<Vector3<f64>>,
    correspondences: Vec<Option<CylinderProjection>>,
    /// Per point the segment of its last correspondence: the first segment searched at the
    /// next update (temporal coherence; the result does not depend on it).
    seeds: Vec<u16>,
    residuals: Vec<f64>,
    weights: Vec<f64>,
    reweighted: bool,
    rigid_only: bool,
    view: View,
    front_facing: bool,
    irls: IrlsParams,
    sensor: SensorView,
    silhouette: bool,
    raster: CylinderRaster,
    /// Along-ray correspondences: the largest distance from a point to its ray's entry.
    ray_gate: Option<f64>,
    /// The largest distance from the entry to the closest point it replaces.
    ray_slide: f64,
    /// Per point its linear pixel index in the sensor image (empty when the frame names none).
    pixels: Vec<u32>,
    /// Per pixel of the sensor image whether a point names it (the rendering's extra pixels).
    point_pixels: Vec<bool>,
}

/// The default of [`TrackingCtx::set_ray_slide`] (mm), the sphere-mesh tracker's too (its
/// own measurements in `hmodel_spheremesh::DEFAULT_RAY_SLIDE`). `hands track --model cylinders` from the default hand,
/// ToF sequences of 240 frames (mean keypoint error, mm; thesis' rule first, then slides 5 /
/// 7.5 / 10 / 15 / ∞): teaser 4.92 → 4.41 / 4.21 / 4.18 / 4.23 / 4.24, fist 6.57 → 5.18 /
/// 4.72 / 4.66 / 4.41 / 4.48, rotation_fast 11.65 → 7.74 / 6.27 / 5.82 / 5.35 / 5.35,
/// occlusion 22.03 → 11.77 / 8.90 / 8.59 / 20.40 / 20.66: beyond ≈ 10 mm the rays of the palm's
/// points enter a finger held in front of it and pull it down, so the default keeps a margin.
pub const DEFAULT_RAY_SLIDE: f64 = 7.5;

impl<'m> TrackingCtx<'m> {
    /// A context at the rest pose with no points; `view` is the camera model of the
    /// front-facing test (the thesis uses [`View::Orthographic`], `v = (0, 0, 1)`).
    pub fn new(model: &'m CylinderModel, view: View, irls: IrlsParams) -> Self {
        let pose = Pose::zeros(&model.skeleton);
        Self {
            model,
            posed: PosedSkeleton::new(&model.skeleton, &pose),
            pose,
            points: Vec::new(),
            correspondences: Vec::new(),
            seeds: Vec::new(),
            residuals: Vec::new(),
            weights: Vec::new(),
            reweighted: false,
            rigid_only: false,
            view,
            front_facing: true,
            irls,
            sensor: SensorView::default(),
            silhouette: true,
            raster: CylinderRaster::new(),
            ray_gate: None,
            ray_slide: DEFAULT_RAY_SLIDE,
            pixels: Vec::new(),
            point_pixels: Vec::new(),
        }
    }

    /// Along-ray correspondences (off by default, the thesis' front-facing closest points): a
    /// point whose camera ray enters the model within `gate` mm of it, and within
    /// [`TrackingCtx::set_ray_slide`] of its closest point, registers at that entry,
    /// point-to-plane with the surface normal there — zero-mean under depth noise along the rays,
    /// where the closest point is biased. `None`, or a gate that is not positive and finite, turns
    /// them off.
    pub fn set_ray_gate(&mut self, gate: Option<f64>) {
        self.ray_gate = gate.filter(|g| g.is_finite() && *g > 0.0);
    }

    /// The along-ray gate in force.
    pub fn ray_gate(&self) -> Option<f64> {
        self.ray_gate
    }

    /// How far (mm) an along-ray entry may lie from the closest point it replaces: where the pose
    /// puts one part in front of another's data, the rays enter the wrong part first; the closest
    /// point keeps those points. Not a number: [`DEFAULT_RAY_SLIDE`].
    pub fn set_ray_slide(&mut self, slide: f64) {
        self.ray_slide = if slide.is_nan() {
            DEFAULT_RAY_SLIDE
        } else {
            slide.max(0.0)
        };
    }

    /// Enable or disable the rendering of the silhouette `S_r` in [`TrackingCtx::update`] (on by
    /// default; rendering also needs a sensor camera). Disabled, [`TrackingCtx::raster`] is
    /// empty after the next update and E2D adds no rows.
    pub fn set_silhouette(&mut self, enabled: bool) {
        self.silhouette = enabled;
        if !enabled {
            self.raster.clear();
        }
    }

    /// The rendered model's area outside the sensor silhouette (`S_r \ S_s`, the pixels E2D
    /// pushes) as a fraction of the silhouette's area `|S_s|`, at the last update; `None`
    /// without a rendered silhouette or with an empty sensor silhouette.
    pub fn outside_fraction(&self) -> Option<f64> {
        if !self.silhouette || self.raster.width() == 0 {
            return None;
        }
        let area = self.sensor.silhouette_area();
        let nearest = &self.sensor.nearest;
        let outside = self
            .raster
            .hits()
            .iter()
            .filter(|&&k| nearest.get(k as usize).is_none_or(|&n| n != k))
            .count();
        (area > 0).then(|| outside as f64 / area as f64)
    }

    /// Whether [`TrackingCtx::update`] renders the silhouette.
    pub fn silhouette(&self) -> bool {
        self.silhouette
    }

    /// The rendered model at the last update (§2.3.1 "2D correspondences"): per pixel of the
    /// sensor camera the segment, bone and camera-frame point of the first hit, on the pixels
    /// outside the sensor silhouette and (along-ray correspondences) the points' pixels; empty
    /// without a camera, with neither enabled, or for a non-finite pose.
    pub fn raster(&self) -> &CylinderRaster {
        &self.raster
    }

    /// Take the sensor data of a preprocessed frame: its points `𝒳_s` ([`TrackingCtx::set_points`]),
    /// their pixels, camera, silhouette distance transform and wristband ([`SensorView`]).
    /// Reuses the buffers.
    pub fn set_frame(&mut self, frame: &PreprocessedFrame) {
        self.set_points(&frame.points);
        self.sensor.set_frame(frame);
        if let Some(c) = frame.camera.as_ref() {
            let n = c.width as usize * c.height as usize;
            if frame.pixels.len() == frame.points.len()
                && frame.pixels.iter().all(|&k| (k as usize) < n)
            {
                self.point_pixels.resize(n, false);
                for &k in &frame.pixels {
                    self.point_pixels[k as usize] = true;
                }
                self.pixels.extend_from_slice(&frame.pixels);
            }
        }
    }

    /// The sensor data of the image-space terms.
    pub fn sensor(&self) -> &SensorView {
        &self.sensor
    }

    /// Mutable sensor data (tests and callers that build frames by hand).
    pub fn sensor_mut(&mut self) -> &mut SensorView {
        &mut self.sensor
    }

    /// Replace the sensor points `𝒳_s` (camera frame, mm); keeps the buffers' capacity. The
    /// correspondences are stale until the next [`TrackingCtx::update`].
    pub fn set_points(&mut self, points: &[Vector3<f64>]) {
        for &k in &self.pixels {
            self.point_pixels[k as usize] = false;
        }
        self.pixels.clear();
        self.points.clear();
        self.points.extend_from_slice(points);
        self.correspondences.clear();
        self.correspondences.resize(points.len(), None);
        self.seeds.clear();
        self.seeds.resize(points.len(), NO_SEED);
        self.residuals.clear();
        self.residuals.resize(points.len(), 0.0);
        self.weights.clear();
        self.weights.resize(points.len(), 0.0);
    }

    /// Re-pose the model at `pose`, recompute every front-facing correspondence `y` (§2.3.1),
    /// its point-to-plane residual `r = nᵀ(y − x)` and its IRLS weight (§2.7.4; 1 when the
    /// iteration is not reweighted, see [`IrlsParams`]), and render the silhouette `S_r` from the
    /// sensor camera when enabled. A pose of the wrong length is an error; a non-finite pose
    /// value makes every correspondence `None` and the silhouette empty.
    pub fn update(&mut self, pose: &Pose, rigid_only: bool) -> Result<(), TermError> {
        let nd = self.model.skeleton.num_dofs();
        if pose.values.len() != nd {
            return Err(TermError::ShapeMismatch {
                expected: nd,
                found: pose.values.len(),
            });
        }
        self.pose.values.clone_from(&pose.values);
        self.rigid_only = rigid_only;
        self.reweighted = self.irls.reweight && (!rigid_only || self.irls.reweight_rigid);
        if !pose.values.iter().all(|v| v.is_finite()) {
            self.correspondences.fill(None);
            self.raster.clear();
            return Ok(());
        }
        self.posed.update(&self.model.skeleton, &self.pose);
        let along = self.ray_gate.is_some() && !self.pixels.is_empty();
        match (&self.sensor.camera, self.silhouette || along) {
            (Some(c), true) => {
                let intrinsics = Intrinsics {
                    fx: c.fx,
                    fy: c.fy,
                    cx: c.cx,
                    cy: c.cy,
                    width: c.width,
                    height: c.height,
                };
                // Only pixels outside S_s can carry an E2D push constraint; the points' own
                // pixels give their rays' entries.
                let (nearest, silhouette) = (&self.sensor.nearest, self.silhouette);
                let outside = |i: usize| nearest.get(i).is_none_or(|&n| n as usize != i);
                let points = &self.point_pixels;
                let keep = |i: usize| {
                    (silhouette && outside(i)) || (along && points.get(i).copied().unwrap_or(false))
                };
                if self
                    .raster
                    .render_where(self.model, &self.posed, &intrinsics, keep)
                    .is_err()
                {
                    return Err(TermError::Failed("invalid sensor camera"));
                }
            }
            _ => self.raster.clear(),
        }
        if self
            .model
            .project_points_seeded(
                &self.posed,
                &self.points,
                self.front_facing.then_some(self.view),
                &mut self.seeds,
                &mut self.correspondences,
            )
            .is_err()
        {
            return Err(TermError::Failed("correspondence buffer size mismatch"));
        }
        for ((c, x), (r, w)) in self
            .correspondences
            .iter()
            .zip(&self.points)
            .zip(self.residuals.iter_mut().zip(self.weights.iter_mut()))
        {
            (*r, *w) = match c {
                Some(c) => {
                    let res = c.normal.dot(&(c.point - x));
                    let weight = if self.reweighted {
                        self.irls.weight(res)
                    } else {
                        1.0
                    };
                    (res, weight)
                }
                None => (0.0, 0.0),
            };
        }
        if let Some(gate) = self.ray_gate {
            self.register_along_rays(gate);
        }
        Ok(())
    }

    /// [`TrackingCtx::set_ray_gate`]'s correspondences over the closest points already found:
    /// the entries of the points' pixels from the rendering, a cast of their own for points
    /// without a rendered pixel or moved off its ray.
    fn register_along_rays(&mut self, gate: f64) {
        let rendered = !self.pixels.is_empty() && self.raster.width() > 0;
        let camera = self.sensor.camera.as_ref();
        for i in 0..self.points.len() {
            let (x, Some(c)) = (self.points[i], self.correspondences[i]) else {
                continue;
            };
            let pixel_entry = match (rendered, camera) {
                (true, Some(cam)) => {
                    let k = self.pixels[i];
                    let (u, v) = (f64::from(k % cam.width), f64::from(k / cam.width));
                    let dir = Vector3::new((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0);
                    let on_ray = x.cross(&dir).norm() <= 1e-9 * x.norm() * dir.norm();
                    on_ray.then(|| self.raster.hit(k as usize))
                }
                _ => None,
            };
            let hit = match pixel_entry {
                Some(hit) => hit,
                None => cast_camera_ray(self.model, &self.posed, &x),
            };
            let Some(RasterHit { segment, point, .. }) = hit else {
                continue;
            };
            if (point - x).norm() > gate || (point - c.point).norm() > self.ray_slide {
                continue;
            }
            let seg = &self.model.segments[segment];
            let Some(mut q) = self
                .posed
                .globals
                .get(seg.bone)
                .and_then(|g| seg.project_point(g, &point))
            else {
                continue;
            };
            // The palm's foot points are htrack's approximation: keep the entry itself.
            let d = x - point;
            q.segment = segment;
            q.point = point;
            q.distance = d.norm().copysign(q.normal.dot(&d));
            let res = q.normal.dot(&(q.point - x));
            self.residuals[i] = res;
            self.weights[i] = if self.reweighted {
                self.irls.weight(res)
            } else {
                1.0
            };
            self.correspondences[i] = Some(q);
        }
    }

    /// The cylinder model.
    pub fn model(&self) -> &'m CylinderModel {
        self.model
    }

    /// The sensor points `𝒳_s`.
    pub fn points(&self) -> &[Vector3<f64>] {
        &self.points
    }

    /// Per point its front-facing correspondence `y = Π_M(x, θ)` (§2.3.1), `None` when there
    /// is none (non-finite point).
    pub fn correspondences(&self) -> &[Option<CylinderProjection>] {
        &self.correspondences
    }

    /// Per point the point-to-plane residual `r = nᵀ(y − x)` (0 without correspondence).
    pub fn residuals(&self) -> &[f64] {
        &self.residuals
    }

    /// Per point the IRLS weight `w` (§2.7.4; see [`IrlsParams`]); 1 on non-reweighted
    /// iterations, 0 without correspondence.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Whether the current weights are IRLS weights (the energy is then the Huber-ℓ1 of
    /// Eq. 2.2) rather than 1 (the energy is then `Σ r²`).
    pub fn reweighted(&self) -> bool {
        self.reweighted
    }

    /// Whether the current iteration only moves the global DOFs.
    pub fn rigid_only(&self) -> bool {
        self.rigid_only
    }

    /// The IRLS settings.
    pub fn irls(&self) -> &IrlsParams {
        &self.irls
    }

    /// Use front-facing correspondences (§2.3.1, default) or plain closest points (the
    /// comparison of Fig. 2.6/2.8).
    pub fn set_front_facing(&mut self, front_facing: bool) {
        self.front_facing = front_facing;
    }

    /// Whether correspondences are front-facing.
    pub fn front_facing(&self) -> bool {
        self.front_facing
    }

    /// The camera model of the front-facing test.
    pub fn view(&self) -> View {
        self.view
    }
}

impl PoseContext for TrackingCtx<'_> {
    fn skeleton(&self) -> &Skeleton {
        &self.model.skeleton
    }
    fn pose(&self) -> &Pose {
        &self.pose
    }
    fn posed(&self) -> &PosedSkeleton {
        &self.posed
    }
}

/// The [`LmCallback`] of the tracker: before every iteration, [`TrackingCtx::update`] at the
/// current pose (re-pose, front-facing correspondences, IRLS weights; the rigid-only flag from
/// [`IterInfo`]).
#[derive(Copy, Clone, Debug, Default)]
pub struct CorrespondenceCallback;

impl LmCallback<TrackingCtx<'_>> for CorrespondenceCallback {
    fn prepare(
        &mut self,
        pose: &Pose,
        ctx: &mut TrackingCtx<'_>,
        info: IterInfo,
    ) -> Result<(), TermError> {
        ctx.update(pose, info.rigid_only)
    }
}
