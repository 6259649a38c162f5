//! The per-iteration context of the sphere-mesh tracker (STYLE practice 5): the posed template
//! and its query geometry, the sensor points with their monocular front-facing correspondences
//! (thesis §3.3.1, Fig. 3.9) and IRLS weights, and the model→data push constraints of Eq. 3.5.

use std::borrow::Cow;
use std::time::Instant;

use hand_model::kinematics::{Pose, PosedSkeleton, Skeleton};
use hand_model::query::{Coherence, Projection, SphereMeshGeometry, View};
use hand_model::render::raycast::{cast_ray_prepared, Ray};
use hand_model::render::{DepthRenderer, Intrinsics, PixelHit, PixelRuns, PreparedElement};
use hand_model::shape::Element;
use hand_model::solver::{
    FrameStats, IrlsParams, IterInfo, LmCallback, LossParams, PoseContext, TermError,
};
use hand_model::spheremesh::{PosedSphereMesh, SphereMeshTemplate};
use hand_model::ModelError;
use nalgebra::{Vector2, Vector3};
use sensor_io::preprocess::PreprocessedFrame;
use sensor_io::{Camera, SensorView};
use serde::{Deserialize, Serialize};

use crate::jacobian::FootpointJacobian;

/// How the model→data term (Eq. 3.5) finds the model's parts outside the sensor silhouette.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum M2dMode {
    /// Render the model from the sensor camera (§3.3.2: tiled CPU ray casting, only the pixels
    /// outside the sensor silhouette) and push every rendered pixel outside it (the thesis).
    Render,
    /// The faster alternative of §3.6 "Downsampling": push the projected sphere centers that
    /// fall outside the sensor silhouette (no rendering).
    Centers,
}

/// One model→data constraint of Eq. 3.5: a model point that projects outside the sensor
/// silhouette, with the nearest silhouette pixel it is pushed to.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SilhouettePush {
    /// Element carrying the point.
    pub element: u32,
    /// Spheres and barycentric weights of the point (as in [`Projection`]), so that its
    /// Jacobian is exact on multi-bone elements.
    pub spheres: [u32; 3],
    /// Weights of `spheres`.
    pub weights: [f64; 3],
    /// The model point (camera frame, mm).
    pub point: Vector3<f64>,
    /// `Π_D(x)`: the center of the nearest sensor-silhouette pixel (distance transform).
    pub target: Vector2<f64>,
}

/// Shared state of one frame's solve (module docs), refreshed by [`TrackingCtx::update`] before
/// every LM iteration ([`CorrespondenceCallback`]); allocation-free once the buffers have held
/// the current number of points.
#[derive(Clone, Debug)]
pub struct TrackingCtx<'m> {
    /// Borrowed from the tracker, or owned after [`TrackingCtx::set_template`] (online
    /// calibration reshapes the model between iterations).
    template: Cow<'m, SphereMeshTemplate>,
    elements: Vec<Element>,
    jacobian: FootpointJacobian,
    /// Per sphere, an element that holds it (for the Jacobian of a sphere center).
    sphere_element: Vec<u32>,
    pose: Pose,
    posed: PosedSphereMesh,
    geometry: SphereMeshGeometry,
    points: Vec<Vector3<f64>>,
    correspondences: Vec<Option<Projection>>,
    /// Per point the element of its last plain projection and how far the other elements were:
    /// most points skip the next search (temporal coherence across iterations; results do not
    /// depend on it).
    coherence: Coherence,
    directions: Vec<Vector3<f64>>,
    residuals: Vec<f64>,
    weights: Vec<f64>,
    reweighted: bool,
    rigid_only: bool,
    view: View,
    front_facing: bool,
    /// Along-ray correspondences (see [`TrackingCtx::set_ray_gate`]): the largest distance
    /// along the camera ray at which a point is registered at the ray's entry into the model.
    ray_gate: Option<f64>,
    /// How far an along-ray footpoint may lie from the closest point (see
    /// [`TrackingCtx::set_ray_slide`]).
    ray_slide: f64,
    /// [`TrackingCtx::set_point_stride`].
    point_stride: usize,
    /// [`TrackingCtx::set_point_phase`].
    point_phase: usize,
    /// The posed elements prepared for [`TrackingCtx::set_ray_gate`]'s ray casts.
    prepared: Vec<Option<PreparedElement>>,
    /// `(pixel, point)` for every point of the frame, by pixel: the along-ray correspondences
    /// of these points come from one rendering of their pixels ([`DepthRenderer::render_hits`]
    /// with the model's per-element footprints) instead of one ray cast per point against
    /// every element; empty when the points do not name their pixels.
    ray_pixels: Vec<(u32, u32)>,
    /// The pixels of `ray_pixels`, built on the first along-ray registration of a frame.
    ray_mask: PixelRuns,
    ray_mask_valid: bool,
    ray_hits: Vec<PixelHit>,
    /// `(point, element, entry)` of the points whose camera ray enters the model.
    ray_entries: Vec<(u32, u32, Vector3<f64>)>,
    /// The points whose entry is cast one by one (no rendering, or off their pixel's ray).
    ray_cast: Vec<u32>,
    /// `(point, footpoint)` of the entries within the gate not yet registered.
    ray_pending: Vec<(u32, Projection)>,
    /// Per point, whether it was registered along its ray before the closest points were
    /// sought (and so has none; [`TrackingCtx::settle_entries`]).
    settled: Vec<bool>,
    /// How many points the last update registered along their rays.
    along_ray_points: usize,
    irls: IrlsParams,
    sensor: SensorView,
    m2d: Option<M2dMode>,
    m2d_stride: u32,
    renderer: DepthRenderer,
    /// The sensor pixels where [`M2dMode::Render`] casts its ray (on the stride grid and
    /// outside the sensor silhouette), built once per frame and stride: tested per footprint
    /// pixel of every element instead, it took four integer divisions each, ≈ 60 % of the
    /// rendering; as runs per row, the renderer skips the footprint pixels inside the
    /// silhouette (most of them) without visiting them.
    render_mask: PixelRuns,
    /// Whether `render_mask` is that of the current sensor data and stride.
    render_mask_valid: bool,
    hits: Vec<PixelHit>,
    pushes: Vec<SilhouettePush>,
    timing: UpdateTiming,
}

/// Where [`TrackingCtx::update`] spends its time (µs, summed over the updates since the last
/// [`TrackingCtx::take_timing`]): the parts of a tracker's "correspondences" stage, so that a
/// benchmark can say which one a sensor's noise makes expensive.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct UpdateTiming {
    /// Re-posing the model and the (front-facing) closest points of the data points (Eq. 3.6,
    /// §3.3.1, with the silhouette substitutes of back-facing footpoints).
    pub closest_us: f64,
    /// The along-ray registration ([`TrackingCtx::set_ray_gate`]): zero where it is off.
    pub along_ray_us: f64,
    /// The model-to-data pushes of Eq. 3.5 (rendering the model outside the sensor silhouette).
    pub m2d_us: f64,
}

impl UpdateTiming {
    /// The parts as `timing_us` stages of the DESIGN.md record (sub-stages of
    /// `correspondences`).
    pub fn stages(&self) -> [(&'static str, f64); 3] {
        [
            ("closest_points", self.closest_us),
            ("along_ray", self.along_ray_us),
            ("m2d", self.m2d_us),
        ]
    }
}

/// The default of [`TrackingCtx::set_ray_slide`] (mm): 7.5, as the cylinder tracker's (5 until
/// session 18). Measured under ToF noise (slide 5 → 7.5 mm, one run each):
/// - random subjects 7–12 of `eval/tests/ch4_acceptance.rs` (calibration motion, 300 frames,
///   last-third mean keypoint error): true template 2.06 / 1.82 / 1.71 / 1.53 / 1.96 / 1.40 →
///   1.92 / 1.73 / 1.67 / 1.44 / 1.84 / 1.34 mm; online calibration from the default template
///   2.81 / 1.92 / 1.80 / 2.17 / 2.34 / 1.96 → 2.68 / 1.88 / 1.81 / 2.07 / 2.18 / 1.92 mm, its
///   E_β at the end 0.45 / 0.39 / 0.46 / 0.41 / 0.46 / 0.46 → 0.44 / 0.35 / 0.42 / 0.33 / 0.34 /
///   0.42 mm;
/// - `hands track`, default template, the nine ToF library sequences of 240 frames (teaser,
///   fist, rotation_fast, occlusion, pinch, random, flexion, calibration, crossing): sum of the
///   mean keypoint errors 49.29 → 48.67 mm (7 better, occlusion 7.36 → 7.39), with online
///   calibration 25.27 → 25.09 mm (teaser 1.75 → 1.57, occlusion 2.67 → 2.87, crossing 3.78 →
///   3.92). At 10 mm the online sum rose to 26.02, and beyond ≈ 10 mm the cylinder tracker
///   loses the ToF occlusion sequence (`htrack_icp::DEFAULT_RAY_SLIDE`).
pub const DEFAULT_RAY_SLIDE: f64 = 7.5;

/// The sensor camera as the renderer's intrinsics.
pub fn intrinsics(c: &Camera) -> Intrinsics {
    Intrinsics {
        fx: c.fx,
        fy: c.fy,
        cx: c.cx,
        cy: c.cy,
        width: c.width,
        height: c.height,
    }
}

impl<'m> TrackingCtx<'m> {
    /// A context at the rest pose with no points. `view` is the camera of the front-facing test
    /// (thesis: orthographic along +z; [`View::Perspective`] at the origin is the sensor's
    /// pinhole). An error for a template whose elements the Jacobian cannot hold or whose rest
    /// spheres are invalid.
    pub fn new(
        template: &'m SphereMeshTemplate,
        view: View,
        irls: IrlsParams,
    ) -> Result<Self, ModelError> {
        Self::with_template(Cow::Borrowed(template), view, irls)
    }

    /// As [`TrackingCtx::new`], owning its template (for a context that outlives the template it
    /// was built from, e.g. one reshaped by [`TrackingCtx::set_template`]).
    pub fn owned(
        template: SphereMeshTemplate,
        view: View,
        irls: IrlsParams,
    ) -> Result<TrackingCtx<'static>, ModelError> {
        TrackingCtx::with_template(Cow::Owned(template), view, irls)
    }

    fn with_template(
        cow: Cow<'m, SphereMeshTemplate>,
        view: View,
        irls: IrlsParams,
    ) -> Result<Self, ModelError> {
        let template: &SphereMeshTemplate = &cow;
        let pose = Pose::zeros(&template.skeleton);
        let posed = PosedSphereMesh::new(template, &pose);
        let elements: Vec<Element> = template.elements.iter().map(|e| e.element).collect();
        let geometry = SphereMeshGeometry::new(&posed.spheres, &elements).map_err(|e| {
            ModelError::InvalidArgument {
                name: "template",
                reason: e.to_string(),
            }
        })?;
        let mut sphere_element = vec![u32::MAX; template.spheres.len()];
        for (e, el) in elements.iter().enumerate() {
            for &s in el.spheres() {
                if sphere_element[s as usize] == u32::MAX {
                    sphere_element[s as usize] = e as u32;
                }
            }
        }
        let jacobian = FootpointJacobian::new(template)?;
        Ok(Self {
            template: cow,
            jacobian,
            elements,
            sphere_element,
            pose,
            posed,
            geometry,
            points: Vec::new(),
            correspondences: Vec::new(),
            coherence: Coherence::default(),
            directions: Vec::new(),
            residuals: Vec::new(),
            weights: Vec::new(),
            reweighted: false,
            rigid_only: false,
            view,
            front_facing: true,
            ray_gate: None,
            ray_slide: DEFAULT_RAY_SLIDE,
            point_stride: 1,
            point_phase: 0,
            prepared: Vec::new(),
            ray_pixels: Vec::new(),
            ray_mask: PixelRuns::default(),
            ray_mask_valid: false,
            ray_hits: Vec::new(),
            ray_entries: Vec::new(),
            ray_cast: Vec::new(),
            ray_pending: Vec::new(),
            settled: Vec::new(),
            along_ray_points: 0,
            irls,
            sensor: SensorView::default(),
            m2d: Some(M2dMode::Render),
            m2d_stride: 1,
            renderer: DepthRenderer::new(),
            render_mask: PixelRuns::default(),
            render_mask_valid: false,
            hits: Vec::new(),
            pushes: Vec::new(),
            timing: UpdateTiming::default(),
        })
    }

    /// Take the points, camera, silhouette distance transform and wristband of a preprocessed
    /// frame (reusing the buffers). When the frame names the pixel of every point (as
    /// preprocessed frames do), each point inherits the closest-point memory of the previous
    /// frame's point at the same or an adjacent pixel ([`Coherence::carry_to_pixels`]): the
    /// first iteration of the frame then skips the search for the points whose surface barely
    /// moved, with the same correspondences (bit for bit) as a fresh search.
    pub fn set_frame(&mut self, frame: &PreprocessedFrame) {
        self.load_points(&frame.points);
        match frame.camera.as_ref() {
            Some(c) if frame.pixels.len() == frame.points.len() => {
                self.coherence
                    .carry_to_pixels(&frame.pixels, c.width, c.height);
                self.ray_pixels
                    .extend(frame.pixels.iter().zip(0u32..).map(|(&k, i)| (k, i)));
                self.ray_pixels.sort_unstable();
            }
            _ => self.coherence.clear(),
        }
        self.sensor.set_frame(frame);
        self.render_mask_valid = false;
    }

    /// Replace the sensor points (camera frame, mm); correspondences are stale until the next
    /// [`TrackingCtx::update`].
    pub fn set_points(&mut self, points: &[Vector3<f64>]) {
        self.load_points(points);
        self.coherence.clear();
    }

    /// [`TrackingCtx::set_points`] but for the closest-point memory.
    fn load_points(&mut self, points: &[Vector3<f64>]) {
        let n = points.len();
        self.ray_pixels.clear();
        self.ray_mask_valid = false;
        self.points.clear();
        self.points.extend_from_slice(points);
        self.correspondences.clear();
        self.correspondences.resize(n, None);
        self.directions.clear();
        self.directions.resize(n, Vector3::zeros());
        self.residuals.clear();
        self.residuals.resize(n, 0.0);
        self.weights.clear();
        self.weights.resize(n, 0.0);
    }

    /// The sensor data of the image-space terms.
    pub fn sensor(&self) -> &SensorView {
        &self.sensor
    }

    /// Mutable sensor data (tests and callers that build frames by hand).
    pub fn sensor_mut(&mut self) -> &mut SensorView {
        self.render_mask_valid = false;
        &mut self.sensor
    }

    /// Choose the model→data mode (`None`: no push constraints are computed).
    pub fn set_m2d(&mut self, mode: Option<M2dMode>) {
        self.m2d = mode;
        if mode.is_none() {
            self.pushes.clear();
        }
    }

    /// The model→data mode.
    pub fn m2d(&self) -> Option<M2dMode> {
        self.m2d
    }

    /// Ray cast only every `stride`-th pixel along each image axis in [`M2dMode::Render`] (the
    /// integral of Eq. 3.5 sampled on a coarser grid: each push then stands for `stride²`
    /// pixels, see [`TrackingCtx::m2d_pixel_weight`]); 1 (the default) renders every pixel.
    pub fn set_m2d_stride(&mut self, stride: u32) {
        self.m2d_stride = stride.clamp(1, 16);
        self.render_mask_valid = false;
    }

    /// How many sensor pixels one push stands for (`stride²` when rendering, 1 for centers).
    pub fn m2d_pixel_weight(&self) -> f64 {
        match self.m2d {
            Some(M2dMode::Render) => f64::from(self.m2d_stride * self.m2d_stride),
            _ => 1.0,
        }
    }

    /// How the last update fits the frame (loss detection, thesis §3.6): the points' distances
    /// to their correspondences (`|r|`; none: unexplained) and the model's area outside the
    /// sensor silhouette ([`TrackingCtx::outside_fraction`], where measured).
    pub fn frame_stats(&self, params: &LossParams) -> FrameStats {
        let d = self
            .residuals
            .iter()
            .zip(&self.correspondences)
            .map(|(r, c)| c.map(|_| r.abs()));
        let stats = FrameStats::from_distances(d, params);
        match self.outside_fraction() {
            Some(outside) => stats.with_outside(outside),
            None => stats,
        }
    }

    /// The model's area outside the sensor silhouette over the silhouette's area, at the last
    /// update: the m2d pushes (Eq. 3.5: rendered model pixels outside `S_s`, each standing for
    /// [`TrackingCtx::m2d_pixel_weight`] pixels) over the silhouette's pixels. `None` without
    /// the rendered m2d or without a silhouette.
    pub fn outside_fraction(&self) -> Option<f64> {
        if self.m2d != Some(M2dMode::Render) {
            return None;
        }
        let area = self.sensor.silhouette_area();
        (area > 0).then(|| self.pushes.len() as f64 * self.m2d_pixel_weight() / area as f64)
    }

    /// Front-facing correspondences (Fig. 3.9, default) or plain closest points (Eq. 3.6).
    pub fn set_front_facing(&mut self, front_facing: bool) {
        self.front_facing = front_facing;
    }

    /// Along-ray correspondences: a point `p` whose pixel's camera ray enters the model at `q`
    /// with `‖p − q‖ ≤ gate` (mm) is registered at `q`, point-to-plane (`u = n(q)`, `r = nᵀ(q −
    /// p)`); the others keep their closest (front-facing) point. Depth noise moves a point along
    /// its ray, so `r` is then linear in the noise and zero-mean at the true model, whereas the
    /// closest-point distance is biased outward on curved parts (by ≈ σ² sin²φ / 2r on a
    /// cylinder of radius r seen at angle φ) and the front-facing rule pulls the points behind
    /// a silhouette inward. `None` (the default): the thesis' correspondences.
    pub fn set_ray_gate(&mut self, gate: Option<f64>) {
        self.ray_gate = gate.filter(|g| g.is_finite() && *g > 0.0);
    }

    /// The along-ray gate in force (`None`: the thesis' closest points).
    pub fn ray_gate(&self) -> Option<f64> {
        self.ray_gate
    }

    /// The largest distance (mm) between a point's along-ray footpoint and its closest point
    /// for the along-ray registration to replace the closest one (default
    /// [`DEFAULT_RAY_SLIDE`]; a negative or NaN value turns the registration off, infinity
    /// lifts the limit). Depth noise slides the footpoint along the surface by `ε·sin φ` (ε
    /// along the ray at viewing angle φ); a ray that enters *another* part of the model first
    /// — a finger the pose has put in front of the palm points — moves it farther, and
    /// registering there pulls that part onto data that belongs to the one behind it: on a
    /// synthetic sequence where the hand turns so that its fingers overlap
    /// (`occlusion`, structured light, default template) the unlimited rule lost the hand
    /// (mean keypoint error 7.9 → 18.1 mm, online calibration 1.8 → 15.5 mm); with 5 mm
    /// it tracks as the thesis' rule (7.90 / 1.80 mm), with 7.5 mm too (7.90 / 1.82 mm).
    ///
    /// A footpoint within half the slide of its point is taken without its closest point (which
    /// then lies within the slide anyway, unless it is a front-facing substitute), and that
    /// closest point is not sought.
    pub fn set_ray_slide(&mut self, slide: f64) {
        self.ray_slide = if slide.is_nan() { -1.0 } else { slide };
    }

    /// Register every `stride`-th point only (1, the default: every point; 0 counts as 1): the
    /// others carry no correspondence at the next [`update`](Self::update)s, and each point
    /// registered weighs `stride`, so that the data term keeps its scale against the priors. A
    /// solve's early iterations only bring the pose near the data: with a stride there they
    /// cost a fraction of the closest-point search and of the data rows (the online
    /// calibrator's `early_point_stride`). The skipped points' coherence is worn by the motion
    /// they missed, so their next search is as exact as ever.
    pub fn set_point_stride(&mut self, stride: usize) {
        self.point_stride = stride.max(1);
    }

    /// Which points a [`set_point_stride`](Self::set_point_stride) registers: those whose
    /// index is `phase` modulo the stride (default 0). Stepping the phase from one iteration
    /// to the next lets every point pull on the pose over `stride` iterations; the online
    /// calibrator's early iterations do (a fixed share cost ≈ 5 % of its keypoint accuracy
    /// under ToF, none with the phase stepped).
    pub fn set_point_phase(&mut self, phase: usize) {
        self.point_phase = phase;
    }

    /// Whether point `i` is registered under the point stride.
    fn strided(&self, i: usize) -> bool {
        i % self.point_stride == self.point_phase % self.point_stride
    }

    /// Re-pose the model at `pose` and recompute, for every sensor point, its correspondence
    /// `q = Π_M(p)` (front-facing when enabled), the unit direction `u = (p − q)/‖p − q‖` of the
    /// residual (the surface normal where `p` lies on the surface), the residual `r = uᵀ(q − p)
    /// = −‖p − q‖` and its IRLS weight; then the push constraints of Eq. 3.5 when a sensor
    /// camera is set. A pose of the wrong length is an error; a non-finite pose leaves no
    /// correspondences and no pushes.
    pub fn update(&mut self, pose: &Pose, rigid_only: bool) -> Result<(), TermError> {
        let nd = self.template.skeleton.num_dofs();
        if pose.values.len() != nd {
            return Err(TermError::ShapeMismatch {
                expected: nd,
                found: pose.values.len(),
            });
        }
        let start = Instant::now();
        self.pose.values.clone_from(&pose.values);
        self.rigid_only = rigid_only;
        self.reweighted = self.irls.reweight && (!rigid_only || self.irls.reweight_rigid);
        self.pushes.clear();
        if !pose.values.iter().all(|v| v.is_finite()) {
            self.correspondences.fill(None);
            return Ok(());
        }
        self.posed.update(&self.template, &self.pose);
        if self.geometry.update(&self.posed.spheres).is_err() {
            self.correspondences.fill(None);
            return Err(TermError::Failed("posed spheres are not finite"));
        }
        let reposed = Instant::now();
        self.timing.closest_us += (reposed - start).as_secs_f64() * 1e6;
        // Along-ray entries first: a point registered at an entry near enough to it needs no
        // closest point (`settle_entries`).
        self.settled.clear();
        self.settled.resize(self.points.len(), false);
        if self.point_stride > 1 {
            for i in 0..self.points.len() {
                if self.strided(i) {
                    continue;
                }
                self.settled[i] = true;
                self.correspondences[i] = None;
                (self.residuals[i], self.weights[i]) = (0.0, 0.0);
            }
        }
        self.ray_entries.clear();
        self.ray_cast.clear();
        self.ray_pending.clear();
        self.along_ray_points = 0;
        if let Some(gate) = self.ray_gate {
            if !self.render_entries() {
                self.ray_cast.extend(0..self.points.len() as u32);
            }
            self.settle_entries(gate);
        }
        let settled = Instant::now();
        self.timing.along_ray_us += (settled - reposed).as_secs_f64() * 1e6;
        self.project_closest();
        let closest = Instant::now();
        self.timing.closest_us += (closest - settled).as_secs_f64() * 1e6;
        if let Some(gate) = self.ray_gate {
            self.register_along_rays(gate);
        }
        let along_ray = Instant::now();
        self.timing.along_ray_us += (along_ray - closest).as_secs_f64() * 1e6;
        let pushed = self.update_pushes();
        self.timing.m2d_us += along_ray.elapsed().as_secs_f64() * 1e6;
        pushed
    }

    /// The time [`TrackingCtx::update`] spent by part since the last call (then zeroed).
    pub fn take_timing(&mut self) -> UpdateTiming {
        std::mem::take(&mut self.timing)
    }

    /// The closest (front-facing) point of every point not settled along its ray, with its
    /// residual and weight. Each point's previous element and margin give the same
    /// correspondences as a fresh search (bit for bit), most of them without searching.
    fn project_closest(&mut self) {
        if self.front_facing {
            self.geometry.project_points_front_facing_coherent_skipping(
                &self.points,
                &self.settled,
                &self.view,
                &mut self.coherence,
                &mut self.correspondences,
            );
        } else {
            self.geometry.project_points_coherent_skipping(
                &self.points,
                &self.settled,
                &mut self.coherence,
                &mut self.correspondences,
            );
        }
        for (i, (c, p)) in self.correspondences.iter().zip(&self.points).enumerate() {
            if self.settled[i] {
                continue;
            }
            let Some(c) = c else {
                (self.residuals[i], self.weights[i]) = (0.0, 0.0);
                continue;
            };
            let d = p - c.point;
            let len = d.norm();
            self.directions[i] = if len > 1e-9 { d / len } else { c.normal };
            self.residuals[i] = -len;
            self.weights[i] = self.point_weight(len);
        }
    }

    /// The footpoint of a point `i` at its ray's `entry` into `element`, when the entry lies
    /// within `gate` of the point.
    fn entry_footpoint(
        &self,
        i: usize,
        element: u32,
        entry: &Vector3<f64>,
        gate: f64,
    ) -> Option<Projection> {
        if (entry - self.points[i]).norm_squared() > gate * gate {
            return None;
        }
        self.geometry.project_on_element(element as usize, entry)
    }

    /// The weight of a point registered `distance` from its footpoint: its IRLS weight on
    /// reweighted iterations (else 1), times the point stride it stands for.
    fn point_weight(&self, distance: f64) -> f64 {
        let w = if self.reweighted {
            self.irls.weight(distance)
        } else {
            1.0
        };
        w * self.point_stride as f64
    }

    /// Registers point `i` at the along-ray footpoint `q`, point-to-plane.
    fn register_at(&mut self, i: usize, q: Projection) {
        let res = q.normal.dot(&(q.point - self.points[i]));
        self.directions[i] = q.normal;
        self.residuals[i] = res;
        self.weights[i] = self.point_weight(res.abs());
        self.correspondences[i] = Some(q);
        self.along_ray_points += 1;
    }

    /// Registers, before any closest point is sought, the rendered entries whose footpoint `q`
    /// lies within half the slide of its point `p` (flagged `settled`): the closest point `c`
    /// is then within the slide of `q` whatever it is, since `‖c − q‖ ≤ ‖c − p‖ + ‖p − q‖ ≤
    /// 2‖p − q‖ (`q` lies on the model's surface, and no element's surface point is nearer to
    /// `p` than its closest one, inside the model too). Under depth noise most points are
    /// settled so, and their closest points, the tracker's dearest query, are not sought. For
    /// a front-facing substitute the bound does not hold (a point behind a finger's middle,
    /// its ray entering the finger's front); such a point is registered at its entry as well:
    /// the slide guards against rays that enter another part in front, which lie farther.
    /// The other footpoints stay in `ray_pending` for [`TrackingCtx::register_along_rays`].
    fn settle_entries(&mut self, gate: f64) {
        self.take_footpoints(gate);
        let half = 0.5 * self.ray_slide;
        let mut pending = std::mem::take(&mut self.ray_pending);
        pending.retain(|&(i, q)| {
            let near = (q.point - self.points[i as usize]).norm() <= half;
            if near {
                self.register_at(i as usize, q);
                self.settled[i as usize] = true;
            }
            !near
        });
        self.ray_pending = pending;
    }

    /// Moves the entries of `ray_entries` into `ray_pending` as footpoints, those whose entry
    /// lies within `gate` of the point (each footpoint is worked out once).
    fn take_footpoints(&mut self, gate: f64) {
        let mut entries = std::mem::take(&mut self.ray_entries);
        for (i, element, entry) in entries.drain(..) {
            if !self.strided(i as usize) {
                continue;
            }
            if let Some(q) = self.entry_footpoint(i as usize, element, &entry, gate) {
                self.ray_pending.push((i, q));
            }
        }
        self.ray_entries = entries;
    }

    /// [`TrackingCtx::set_ray_gate`]'s correspondences for the points not settled, over the
    /// closest points found: the entries left by [`TrackingCtx::settle_entries`] and those
    /// cast one by one. The ray's entry is the first hit over the whole model (requiring it on
    /// the closest point's element instead mixed the two rules at the elements' junctions and
    /// lost most of the gain, see the `ray_gate` docs).
    fn register_along_rays(&mut self, gate: f64) {
        self.cast_entries();
        self.take_footpoints(gate);
        let half = 0.5 * self.ray_slide;
        let pending = std::mem::take(&mut self.ray_pending);
        for &(i, q) in &pending {
            let i = i as usize;
            let near = (q.point - self.points[i]).norm() <= half;
            let slid = |c: &Projection| (c.point - q.point).norm() > self.ray_slide;
            if !near && self.correspondences[i].is_some_and(|c| slid(&c)) {
                continue;
            }
            self.register_at(i, q);
        }
        self.ray_pending = pending;
    }

    /// The entries of the points' camera rays into the model, from one rendering of their
    /// pixels ([`DepthRenderer::render_hits`]: per-element footprints, each pixel cast only
    /// against the elements whose footprint holds it); false (nothing found) when the points
    /// do not name their pixels, there is no sensor camera or the rendering fails. Points off
    /// their pixel's ray (moved by a caller) are left to [`TrackingCtx::cast_entries`].
    fn render_entries(&mut self) -> bool {
        let Some(camera) = self.sensor.camera.as_ref() else {
            return false;
        };
        if self.ray_pixels.is_empty() {
            return false;
        }
        if !self.ray_mask_valid {
            self.ray_mask.set_sorted(
                camera.width,
                camera.height,
                self.ray_pixels.iter().map(|&(k, _)| k),
            );
            self.ray_mask_valid = true;
        }
        let rendered = self.renderer.render_hits(
            &intrinsics(camera),
            &self.posed.spheres,
            &self.elements,
            &self.ray_mask,
            &mut self.ray_hits,
        );
        if rendered.is_err() {
            return false;
        }
        // Both lists are in pixel order.
        let (w, fx, fy, cx, cy) = (camera.width, camera.fx, camera.fy, camera.cx, camera.cy);
        let mut hits = self.ray_hits.iter().peekable();
        for &(k, i) in &self.ray_pixels {
            while hits.next_if(|h| h.pixel < k).is_some() {}
            let p = &self.points[i as usize];
            let dir = Vector3::new(
                (f64::from(k % w) - cx) / fx,
                (f64::from(k / w) - cy) / fy,
                1.0,
            );
            if p.cross(&dir).norm() > 1e-9 * p.norm() * dir.norm() {
                self.ray_cast.push(i);
            } else if let Some(hit) = hits.peek().filter(|h| h.pixel == k) {
                if p.iter().all(|x| x.is_finite()) {
                    self.ray_entries.push((i, hit.element, hit.point));
                }
            }
        }
        true
    }

    /// [`TrackingCtx::render_entries`] for the points of `ray_cast`: one ray per point, the
    /// closest point's element cast first so that the others are culled by their bounding
    /// balls against that hit.
    fn cast_entries(&mut self) {
        if self.ray_cast.is_empty() {
            return;
        }
        let spheres = &self.posed.spheres;
        self.prepared.clear();
        self.prepared.extend(
            self.elements
                .iter()
                .map(|e| PreparedElement::new(spheres, e)),
        );
        for &i in &self.ray_cast {
            let (c, p) = (&self.correspondences[i as usize], &self.points[i as usize]);
            let (Some(seed), Some(ray)) = (c.map(|c| c.element), Ray::new(Vector3::zeros(), *p))
            else {
                continue;
            };
            if let Some(hit) = cast_ray_prepared(&ray, &self.prepared, seed as usize) {
                self.ray_entries.push((i, hit.element as u32, hit.point));
            }
        }
    }

    /// The push constraints of Eq. 3.5 at the current pose (see [`M2dMode`]). Model points
    /// that the segmentation hides (under or beyond the wristband, [`SensorView::hides`]) are
    /// not pushed: the silhouette is cut there whatever the hand's shape, and pushing them
    /// pulled a longer wrist up into the palm during calibration (thesis §3.4; honline likewise
    /// treats the wrist blocks apart, ANCHOR-FACTS §5.4).
    fn update_pushes(&mut self) -> Result<(), TermError> {
        let (Some(mode), Some(camera)) = (self.m2d, self.sensor.camera.as_ref()) else {
            return Ok(());
        };
        let sensor = &self.sensor;
        match mode {
            M2dMode::Render => {
                let nearest = &sensor.nearest;
                let (w, stride) = (camera.width as usize, self.m2d_stride as usize);
                let outside = |i: usize| nearest.get(i).is_none_or(|&n| n as usize != i);
                if !self.render_mask_valid {
                    // Without the divisions on the (default) full grid.
                    let on_grid =
                        |i: usize| stride == 1 || ((i % w) % stride == 0 && (i / w) % stride == 0);
                    self.render_mask
                        .set(camera.width, camera.height, |i| on_grid(i) && outside(i));
                    self.render_mask_valid = true;
                }
                self.renderer
                    .render_hits(
                        &intrinsics(camera),
                        &self.posed.spheres,
                        &self.elements,
                        &self.render_mask,
                        &mut self.hits,
                    )
                    .map_err(|_| TermError::Failed("invalid sensor camera"))?;
                for hit in &self.hits {
                    if sensor.hides(&hit.point) {
                        continue;
                    }
                    let (u, v) = (hit.pixel % camera.width, hit.pixel / camera.width);
                    let Some((nu, nv)) = sensor.nearest_pixel(u, v) else {
                        continue;
                    };
                    let Some(pr) = self
                        .geometry
                        .project_on_element(hit.element as usize, &hit.point)
                    else {
                        continue;
                    };
                    self.pushes.push(SilhouettePush {
                        element: hit.element,
                        spheres: pr.spheres,
                        weights: pr.weights,
                        point: pr.point,
                        target: Vector2::new(f64::from(nu), f64::from(nv)),
                    });
                }
            }
            M2dMode::Centers => {
                for (i, s) in self.posed.spheres.iter().enumerate() {
                    let e = self.sphere_element[i];
                    if e == u32::MAX || s.center.z <= 0.0 || sensor.hides(&s.center) {
                        continue;
                    }
                    let px = camera.project(&s.center);
                    let (u, v) = (px.x.round(), px.y.round());
                    if !(u >= 0.0 && v >= 0.0) {
                        continue;
                    }
                    let (u, v) = (u as u32, v as u32);
                    if u >= camera.width || v >= camera.height || sensor.in_silhouette(u, v) {
                        continue;
                    }
                    let Some((nu, nv)) = sensor.nearest_pixel(u, v) else {
                        continue;
                    };
                    self.pushes.push(SilhouettePush {
                        element: e,
                        spheres: [i as u32; 3],
                        weights: [1.0, 0.0, 0.0],
                        point: s.center,
                        target: Vector2::new(f64::from(nu), f64::from(nv)),
                    });
                }
            }
        }
        Ok(())
    }

    /// The template (as last set).
    pub fn template(&self) -> &SphereMeshTemplate {
        &self.template
    }

    /// Replace the template by a reshaped one of the same topology (same spheres, attachments,
    /// elements and skeleton DOFs; e.g. the template at another honline β, thesis §4.3): the
    /// element Jacobians only depend on the topology, so they are kept. The model is re-posed at
    /// the next [`TrackingCtx::update`]. An error when the topology differs.
    pub fn set_template(&mut self, template: SphereMeshTemplate) -> Result<(), ModelError> {
        let old = &*self.template;
        let same = template.spheres.len() == old.spheres.len()
            && template.elements.len() == old.elements.len()
            && template.skeleton.num_dofs() == old.skeleton.num_dofs()
            && template.skeleton.bones().len() == old.skeleton.bones().len()
            && template
                .elements
                .iter()
                .zip(&old.elements)
                .all(|(a, b)| a.element.spheres() == b.element.spheres());
        if !same {
            return Err(ModelError::InvalidArgument {
                name: "template",
                reason: "the new template has another topology".into(),
            });
        }
        self.template = Cow::Owned(template);
        Ok(())
    }

    /// The posed template at the last update.
    pub fn posed_mesh(&self) -> &PosedSphereMesh {
        &self.posed
    }

    /// The query geometry at the last update.
    pub fn geometry(&self) -> &SphereMeshGeometry {
        &self.geometry
    }

    /// The Jacobians of surface points.
    pub fn jacobian(&self) -> &FootpointJacobian {
        &self.jacobian
    }

    /// The sensor points.
    pub fn points(&self) -> &[Vector3<f64>] {
        &self.points
    }

    /// Per point its correspondence (`None`: non-finite point or pose).
    pub fn correspondences(&self) -> &[Option<Projection>] {
        &self.correspondences
    }

    /// Per point the unit residual direction `u`.
    pub fn directions(&self) -> &[Vector3<f64>] {
        &self.directions
    }

    /// Per point the residual `r = −‖p − q‖` (0 without correspondence).
    pub fn residuals(&self) -> &[f64] {
        &self.residuals
    }

    /// The d2m rows of the points with a correspondence: `(q, u, r, w)` — footpoint, unit
    /// residual direction, residual `−‖p − q‖` and IRLS weight (Eq. 3.4).
    pub fn d2m_rows(&self) -> impl Iterator<Item = (&Projection, &Vector3<f64>, f64, f64)> + '_ {
        self.correspondences
            .iter()
            .zip(&self.directions)
            .zip(self.residuals.iter().zip(&self.weights))
            .filter_map(|((c, u), (&r, &w))| c.as_ref().map(|c| (c, u, r, w)))
    }

    /// Per point the IRLS weight (1 on non-reweighted iterations, 0 without correspondence).
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Whether the weights are IRLS weights (energy: Huber-ℓ1) rather than 1 (energy: `Σ r²`).
    pub fn reweighted(&self) -> bool {
        self.reweighted
    }

    /// The IRLS settings.
    pub fn irls(&self) -> &IrlsParams {
        &self.irls
    }

    /// Replace the IRLS settings (they take effect at the next [`update`](Self::update)).
    pub fn set_irls(&mut self, irls: IrlsParams) {
        self.irls = irls;
    }

    /// Whether the current iteration moves only the global DOFs.
    pub fn rigid_only(&self) -> bool {
        self.rigid_only
    }

    /// The push constraints of Eq. 3.5 at the last update.
    pub fn pushes(&self) -> &[SilhouettePush] {
        &self.pushes
    }
}

impl PoseContext for TrackingCtx<'_> {
    fn skeleton(&self) -> &Skeleton {
        &self.template.skeleton
    }

    fn pose(&self) -> &Pose {
        &self.pose
    }
    fn posed(&self) -> &PosedSkeleton {
        &self.posed.skeleton
    }
}

/// The [`LmCallback`] of the tracker: [`TrackingCtx::update`] before every iteration.
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::rendered_frame;
    use hand_model::render::KeptPixels;
    use hand_model::spheremesh::default_right_hand;

    /// The per-frame set of the rendered pixels is the per-pixel test it replaces (stride grid,
    /// outside the silhouette) at every pixel, and follows stride and frame changes: the
    /// pushes after them are those of a fresh context.
    #[test]
    fn render_mask_is_the_per_pixel_test() {
        let t = default_right_hand();
        let sk = &t.skeleton;
        let camera = Camera::sr300_qvga();
        let truth = Pose::from_named(sk, [("global_tz", 400.0), ("index_mcp_flex", 0.5)]).unwrap();
        let mut pose = truth.clone();
        pose.values[sk.dof_index("global_tx").unwrap()] += 10.0;
        let frames = [
            rendered_frame(&t, &truth, &camera, 2000).unwrap(),
            rendered_frame(&t, &pose, &camera, 2000).unwrap(),
        ];
        let view = View::Orthographic(Vector3::z());
        let mut ctx = TrackingCtx::new(&t, view, IrlsParams::default()).unwrap();
        for (frame, stride) in [(&frames[1], 1), (&frames[0], 1), (&frames[0], 3)] {
            ctx.set_frame(frame);
            ctx.set_m2d_stride(stride);
            ctx.update(&pose, false).unwrap();
            let (w, s) = (camera.width as usize, stride as usize);
            let nearest = &ctx.sensor().nearest;
            let got: Vec<bool> = (0..w * camera.height as usize)
                .map(|i| (&ctx.render_mask).keeps(i))
                .collect();
            let expected: Vec<bool> = (0..w * camera.height as usize)
                .map(|i| {
                    (i % w) % s == 0
                        && (i / w) % s == 0
                        && nearest.get(i).is_none_or(|&n| n as usize != i)
                })
                .collect();
            assert_eq!(got, expected, "stride {stride}");
            let mut fresh = TrackingCtx::new(&t, view, IrlsParams::default()).unwrap();
            fresh.set_frame(frame);
            fresh.set_m2d_stride(stride);
            fresh.update(&pose, false).unwrap();
            assert_eq!(ctx.pushes(), fresh.pushes(), "stride {stride}");
        }
        assert!(!ctx.pushes().is_empty());
    }

    /// A context that carries its closest-point memory from frame to frame by pixel
    /// (`set_frame` with the points' pixels) has, at every iteration of the next frame, the
    /// correspondences and pushes of a fresh context — bit for bit — while its first iteration
    /// skips searches; a frame without pixels forgets the memory.
    #[test]
    fn carried_coherence_gives_fresh_correspondences() {
        let t = default_right_hand();
        let sk = &t.skeleton;
        let camera = Camera::sr300_qvga();
        let at = |flex: f64, tx: f64| {
            Pose::from_named(
                sk,
                [
                    ("global_tz", 400.0),
                    ("global_tx", tx),
                    ("index_mcp_flex", flex),
                    ("middle_pip_flex", 0.5 * flex),
                ],
            )
            .unwrap()
        };
        let frames = [
            rendered_frame(&t, &at(0.3, 0.0), &camera, 2000).unwrap(),
            rendered_frame(&t, &at(0.32, 0.3), &camera, 2000).unwrap(),
        ];
        assert_eq!(frames[1].pixels.len(), frames[1].points.len());
        let mut without_pixels = frames[1].clone();
        without_pixels.pixels.clear();
        let view = View::Perspective {
            camera_center: Vector3::zeros(),
        };
        let mut ctx = TrackingCtx::new(&t, view, IrlsParams::default()).unwrap();
        ctx.set_frame(&frames[0]);
        for k in 0..4 {
            ctx.update(&at(0.3 + 0.01 * f64::from(k), 0.5), false)
                .unwrap();
        }
        for (frame, carried) in [(&frames[1], true), (&without_pixels, false)] {
            ctx.set_frame(frame);
            let mut fresh = TrackingCtx::new(&t, view, IrlsParams::default()).unwrap();
            fresh.set_points(&frame.points);
            fresh.set_frame(frame);
            for k in 0..3 {
                let pose = at(0.33 + 0.01 * f64::from(k), 0.5);
                ctx.update(&pose, k == 0).unwrap();
                fresh.update(&pose, k == 0).unwrap();
                assert_eq!(ctx.correspondences(), fresh.correspondences());
                assert_eq!(ctx.residuals(), fresh.residuals());
                assert_eq!(ctx.pushes(), fresh.pushes());
                if k == 0 {
                    let kept = ctx.coherence.kept();
                    assert_eq!(kept > frame.points.len() / 10, carried, "{kept}");
                    assert_eq!(fresh.coherence.kept(), 0);
                }
            }
            // Bitwise, beyond `==` (which equates 0 and −0).
            let bits = |c: &TrackingCtx<'_>| -> Vec<u64> {
                c.residuals().iter().map(|r| r.to_bits()).collect()
            };
            assert_eq!(bits(&ctx), bits(&fresh));
        }
    }

    /// The along-ray entries rendered from the points' pixels are the ray casts of the points
    /// one by one: the same elements and residuals (to rounding), with depth noise along the
    /// rays, points moved off their rays and points beyond the gate.
    #[test]
    fn rendered_ray_entries_equal_per_point_casts() {
        let t = default_right_hand();
        let sk = &t.skeleton;
        let camera = Camera::sr300_qvga();
        let pose = |flex: f64| {
            Pose::from_named(
                sk,
                [
                    ("global_tz", 400.0),
                    ("index_mcp_flex", flex),
                    ("thumb_mcp_flex", 0.4),
                ],
            )
            .unwrap()
        };
        let mut frame = rendered_frame(&t, &pose(0.5), &camera, 2000).unwrap();
        for (i, p) in frame.points.iter_mut().enumerate() {
            // Up to ±30 mm along the ray (some beyond the 20 mm gate); every 17th point off it.
            let along = 30.0 * (((i * 7919) % 101) as f64 / 50.0 - 1.0);
            *p += p.normalize() * along;
            if i % 17 == 0 {
                p.x += 0.5;
            }
        }
        let mut without_pixels = frame.clone();
        without_pixels.pixels.clear();
        let view = View::Perspective {
            camera_center: Vector3::zeros(),
        };
        let mut rendered = TrackingCtx::new(&t, view, IrlsParams::default()).unwrap();
        let mut cast = rendered.clone();
        rendered.set_frame(&frame);
        cast.set_frame(&without_pixels);
        for ctx in [&mut rendered, &mut cast] {
            ctx.set_ray_gate(Some(20.0));
            ctx.update(&pose(0.45), false).unwrap();
        }
        assert!(rendered.render_entries(), "the frame names its pixels");
        assert!(!cast.render_entries());
        let along = rendered.along_ray_points;
        assert!(along > frame.points.len() / 2, "{along} along-ray points");
        assert_eq!(along, cast.along_ray_points);
        for (i, (a, b)) in rendered
            .correspondences()
            .iter()
            .zip(cast.correspondences())
            .enumerate()
        {
            let (a, b) = (a.unwrap(), b.unwrap());
            // The element may differ where two elements share the hit sphere (a tie the two
            // casts break in different orders); the footpoint may not.
            assert!((a.point - b.point).norm() < 1e-9, "point {i}: {a:?} {b:?}");
            assert!(
                (rendered.residuals()[i] - cast.residuals()[i]).abs() < 1e-9,
                "point {i}"
            );
        }
    }

    /// With a point stride k only every k-th point is registered — those whose index is the
    /// phase modulo k — as it would be without the stride (the same footpoint and residual)
    /// and weighing k; the others carry nothing. With and without the along-ray registration,
    /// and back to stride 1 every point is again.
    #[test]
    fn a_point_stride_registers_every_kth_point_weighing_k() {
        let t = default_right_hand();
        let sk = &t.skeleton;
        let camera = Camera::sr300_qvga();
        let at = |flex: f64| {
            Pose::from_named(sk, [("global_tz", 400.0), ("index_mcp_flex", flex)]).unwrap()
        };
        let mut frame = rendered_frame(&t, &at(0.5), &camera, 2000).unwrap();
        for (i, p) in frame.points.iter_mut().enumerate() {
            *p += p.normalize() * (3.0 * (((i * 7919) % 101) as f64 / 50.0 - 1.0));
        }
        let view = View::Perspective {
            camera_center: Vector3::zeros(),
        };
        for gate in [None, Some(20.0)] {
            let mut full = TrackingCtx::new(&t, view, IrlsParams::default()).unwrap();
            full.set_frame(&frame);
            full.set_ray_gate(gate);
            let mut strided = full.clone();
            full.update(&at(0.45), false).unwrap();
            strided.set_point_stride(3);
            for phase in [0, 1, 5] {
                strided.set_point_phase(phase);
                strided.update(&at(0.45), false).unwrap();
                for i in 0..frame.points.len() {
                    let (a, b) = (full.correspondences()[i], strided.correspondences()[i]);
                    if i % 3 != phase % 3 {
                        assert!(b.is_none() && strided.weights()[i] == 0.0, "point {i}");
                        continue;
                    }
                    let (a, b) = (a.unwrap(), b.unwrap());
                    let at = format!("point {i}, gate {gate:?}, phase {phase}");
                    assert!((a.point - b.point).norm() < 1e-9, "{at}");
                    assert_eq!(full.residuals()[i], strided.residuals()[i], "{at}");
                    assert_eq!(3.0 * full.weights()[i], strided.weights()[i], "{at}");
                }
            }
            strided.set_point_stride(1);
            strided.update(&at(0.45), false).unwrap();
            assert_eq!(strided.correspondences(), full.correspondences());
            assert_eq!(strided.weights(), full.weights());
        }
    }
}
