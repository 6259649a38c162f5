//! Algorithm-agnostic depth metrics (thesis §3.5 "Comparison metrics", Eq. 3.15–3.16, and
//! §4.4.5, Eq. 4.17; DESIGN.md "Metrics").
//!
//! Both metrics read only the sensor depth `D` with its hand silhouette and a depth image `R` of
//! the tracking model rendered with the sensor's intrinsics, so any tracker that can render a
//! depth map can be scored:
//!
//! - **E_d2m** (data → model, Eq. 3.15 = Eq. 4.17): `|D|⁻¹ Σ_{p∈D} ‖p − Π_R(p)‖₂`, where `D` is the
//!   set of back-projected silhouette pixels with a depth and `Π_R` the closest point of the
//!   back-projected *rendered point cloud* (a kiddo kd-tree), in mm;
//! - **E_m2d** (model → data, Eq. 3.16): `|R∖∂D|⁻¹ Σ_{x∈R∖∂D} ‖x − Π_∂D(x)‖₂`, the mean 2D distance
//!   (px) from the rendered pixels outside the sensor silhouette to that silhouette, read from
//!   the distance transform of the silhouette ([`sensor_io::dt`]).
//!
//! Variants of the original code (ANCHOR-FACTS §6.3) are reported beside the thesis' numbers:
//! hmodel's robust weighting `3.5/√(d + 10⁻³)` of E3D and the `Σ(|dx| + |dy|)/(2N)` form of E2D.
//! The rendered model's background is depth 0 or any depth ≥ [`ModelDepth::FAR_MM`] (external
//! renderings use 5000, the original ray tracers 32767).
//!
//! # Example
//! ```
//! use eval::depth_metrics::{depth_metrics, silhouette, DepthMetricsScratch, ModelDepth};
//! use sensor_io::{Camera, DepthImage};
//!
//! let cam = Camera::sr300_qvga();
//! let mut sensor = DepthImage::zeros(cam.width, cam.height);
//! for v in 100..140 {
//!     for u in 140..180 {
//!         sensor.data[(v * cam.width + u) as usize] = 400;
//!     }
//! }
//! // A model rendered exactly where the sensor saw the hand scores zero on both metrics.
//! let model = ModelDepth::from_image(&sensor);
//! let mut scratch = DepthMetricsScratch::default();
//! let m = depth_metrics(&sensor, &silhouette(&sensor), &model, &cam, &mut scratch).unwrap();
//! assert_eq!(m.d2m.unwrap().mean, 0.0);
//! assert_eq!(m.m2d.unwrap().mean, 0.0);
//! ```

use hand_model::kinematics::Pose;
use hand_model::render::{render_depth, DepthRender};
use hand_model::spheremesh::{PosedSphereMesh, SphereMeshTemplate};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use sensor_io::dt::DistanceTransform;
use sensor_io::{Camera, DepthImage, Mask};

use crate::error::{EvalError, Result};

/// A rendered model depth image (mm, `f32` so that a renderer's sub-millimetre depth is kept).
/// A pixel is *rendered* when its depth is in `(0, FAR_MM)`.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelDepth {
    width: u32,
    height: u32,
    depth: Vec<f32>,
}

impl ModelDepth {
    /// Depths at or beyond this are background (ANCHOR-FACTS §6.3: 5000 in external renderings,
    /// 32767 for the original ray tracers' misses).
    pub const FAR_MM: f32 = 5000.0;

    /// From float depths (mm, row-major). Refused: a length other than `width·height`, and any
    /// NaN, infinite or negative depth (named by its pixel).
    pub fn from_f32(width: u32, height: u32, depth: Vec<f32>) -> Result<Self> {
        if depth.len() != width as usize * height as usize {
            return Err(EvalError::arg(
                "model depth",
                format!("{} values for {width}×{height} pixels", depth.len()),
            ));
        }
        if let Some(i) = depth.iter().position(|d| !(d.is_finite() && *d >= 0.0)) {
            return Err(EvalError::InvalidDepth {
                what: "model depth",
                u: (i % width as usize) as u32,
                v: (i / width as usize) as u32,
                value: depth[i],
            });
        }
        Ok(Self {
            width,
            height,
            depth,
        })
    }

    /// From a DESIGN.md depth image (`u16` mm, 0 = none), e.g. a rendering saved as PNG.
    pub fn from_image(image: &DepthImage) -> Self {
        Self {
            width: image.width,
            height: image.height,
            depth: image.data.iter().map(|&d| d as f32).collect(),
        }
    }

    /// From the CPU renderer's output (§3.3.2); refused like [`ModelDepth::from_f32`].
    pub fn from_render(render: &DepthRender) -> Result<Self> {
        Self::from_f32(render.width, render.height, render.depth.clone())
    }

    /// Width (px).
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height (px).
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The depth of pixel `i` (row-major) when it is rendered.
    #[inline]
    fn rendered(&self, i: usize) -> Option<f32> {
        let d = self.depth[i];
        (d > 0.0 && d < Self::FAR_MM).then_some(d)
    }

    /// Number of rendered pixels.
    pub fn rendered_count(&self) -> usize {
        (0..self.depth.len())
            .filter(|&i| self.rendered(i).is_some())
            .count()
    }
}

/// E_d2m of one frame (Eq. 3.15 / 4.17), in mm.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct DataToModel {
    /// The thesis' metric: mean over sensor points of the distance to the nearest rendered point
    /// (honline's `with_robust_kernel = false`).
    pub mean: f64,
    /// hmodel's variant: mean of `w·d` with `w = 3.5/√(d + 10⁻³)` for `d > 10⁻³` (else 1).
    pub hmodel_weighted_mean: f64,
    /// Largest distance.
    pub max: f64,
    /// Number of sensor points `|D|` (silhouette pixels with a depth).
    pub sensor_points: usize,
    /// Number of rendered model points.
    pub model_points: usize,
}

/// E_m2d of one frame (Eq. 3.16), in pixels.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ModelToData {
    /// The thesis' metric: mean over the rendered pixels outside the sensor silhouette of the
    /// Euclidean distance to the silhouette; 0 when no rendered pixel is outside.
    pub mean: f64,
    /// The original code's variant: `Σ(|dx| + |dy|) / (2N)` over the same pixels.
    pub half_l1_mean: f64,
    /// The sum of the Euclidean distances divided by *all* rendered pixels (those inside count
    /// 0): a normalization that also grows with the fraction of the model that is outside.
    pub mean_over_rendered: f64,
    /// Largest distance.
    pub max: f64,
    /// Rendered pixels outside the silhouette, `|R∖∂D|`.
    pub outside_pixels: usize,
    /// Rendered pixels, `|R|`.
    pub model_pixels: usize,
}

/// Both metrics of one frame; a metric is `None` when it is undefined (see
/// [`data_to_model`] and [`model_to_data`]).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct DepthMetrics {
    /// E_d2m (mm).
    pub d2m: Option<DataToModel>,
    /// E_m2d (px).
    pub m2d: Option<ModelToData>,
}

/// Reusable buffers for scoring a sequence frame by frame.
#[derive(Clone, Debug, Default)]
pub struct DepthMetricsScratch {
    dt: DistanceTransform,
    model_points: Vec<[f64; 3]>,
}

fn check_inputs(
    camera: &Camera,
    depth: Option<&DepthImage>,
    mask: &Mask,
    model: &ModelDepth,
) -> Result<()> {
    camera
        .validate()
        .map_err(|e| EvalError::arg("camera", e.to_string()))?;
    let size = (camera.width, camera.height);
    if let Some(d) = depth {
        EvalError::check_size("sensor depth", size, (d.width, d.height))?;
        if d.data.len() != camera.num_pixels() {
            return Err(EvalError::arg("sensor depth", "data length ≠ width·height"));
        }
    }
    EvalError::check_size("sensor mask", size, (mask.width, mask.height))?;
    if mask.data.len() != camera.num_pixels() {
        return Err(EvalError::arg("sensor mask", "data length ≠ width·height"));
    }
    EvalError::check_size("model depth", size, (model.width, model.height))
}

/// E_d2m (Eq. 3.15 / 4.17): sensor points are the silhouette pixels with a depth, back-projected
/// with `camera`; the model cloud is every rendered pixel back-projected with the same camera.
///
/// `Ok(None)` when undefined: no sensor point (nothing to measure) or no rendered pixel (no
/// closest point). Refused: image sizes that differ from the camera's, a bad camera.
pub fn data_to_model(
    sensor_depth: &DepthImage,
    sensor_mask: &Mask,
    model: &ModelDepth,
    camera: &Camera,
    scratch: &mut DepthMetricsScratch,
) -> Result<Option<DataToModel>> {
    check_inputs(camera, Some(sensor_depth), sensor_mask, model)?;
    let w = camera.width as usize;
    let pixel = |i: usize| ((i % w) as f64, (i / w) as f64);
    let cloud = &mut scratch.model_points;
    cloud.clear();
    for i in 0..model.depth.len() {
        if let Some(z) = model.rendered(i) {
            let (u, v) = pixel(i);
            cloud.push(camera.backproject(u, v, z as f64).into());
        }
    }
    if cloud.is_empty() {
        return Ok(None);
    }
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(cloud)
        .map_err(|e| EvalError::arg("model depth", format!("kd-tree: {e:?}")))?;
    let (mut n, mut sum, mut weighted, mut max) = (0usize, 0.0, 0.0, 0.0f64);
    for (i, (&d, &m)) in sensor_depth.data.iter().zip(&sensor_mask.data).enumerate() {
        if m == 0 || d == 0 {
            continue;
        }
        let (u, v) = pixel(i);
        let p: [f64; 3] = camera
            .backproject(u, v, d as f64 * camera.depth_unit_mm)
            .into();
        let dist = tree
            .query(&p)
            .nearest_one::<SquaredEuclidean<f64>>()
            .execute()
            .distance
            .sqrt();
        n += 1;
        sum += dist;
        weighted += hmodel_weight(dist) * dist;
        max = max.max(dist);
    }
    Ok((n > 0).then(|| DataToModel {
        mean: sum / n as f64,
        hmodel_weighted_mean: weighted / n as f64,
        max,
        sensor_points: n,
        model_points: cloud.len(),
    }))
}

/// The robust weight of hmodel's rasterized E3D (ANCHOR-FACTS §6.3).
fn hmodel_weight(d: f64) -> f64 {
    if d > 1e-3 {
        3.5 / (d + 1e-3).sqrt()
    } else {
        1.0
    }
}

/// E_m2d (Eq. 3.16): over the rendered pixels outside `sensor_mask`, the distance (px) to the
/// nearest silhouette pixel, by the distance transform of the silhouette.
///
/// `Ok(None)` when undefined: no rendered pixel, or rendered pixels outside an empty silhouette
/// (no closest pixel). A model entirely inside the silhouette scores 0. Refused: sizes that
/// differ from the camera's, a bad camera.
pub fn model_to_data(
    sensor_mask: &Mask,
    model: &ModelDepth,
    camera: &Camera,
    scratch: &mut DepthMetricsScratch,
) -> Result<Option<ModelToData>> {
    check_inputs(camera, None, sensor_mask, model)?;
    let w = camera.width;
    let dt = &mut scratch.dt;
    dt.compute(sensor_mask);
    let (mut rendered, mut outside) = (0usize, 0usize);
    let (mut sum, mut sum_l1, mut max) = (0.0, 0.0, 0.0f64);
    for i in 0..model.depth.len() {
        if model.rendered(i).is_none() {
            continue;
        }
        rendered += 1;
        if sensor_mask.data[i] != 0 {
            continue;
        }
        let (u, v) = (i as u32 % w, i as u32 / w);
        let Some((nu, nv)) = dt.nearest_pixel(u, v) else {
            return Ok(None);
        };
        let (dx, dy) = (u.abs_diff(nu) as f64, v.abs_diff(nv) as f64);
        let dist = dx.hypot(dy);
        outside += 1;
        sum += dist;
        sum_l1 += dx + dy;
        max = max.max(dist);
    }
    if rendered == 0 {
        return Ok(None);
    }
    let per_outside = |s: f64| if outside > 0 { s / outside as f64 } else { 0.0 };
    Ok(Some(ModelToData {
        mean: per_outside(sum),
        half_l1_mean: per_outside(sum_l1) / 2.0,
        mean_over_rendered: sum / rendered as f64,
        max,
        outside_pixels: outside,
        model_pixels: rendered,
    }))
}

/// Both metrics of one frame ([`data_to_model`] and [`model_to_data`]).
pub fn depth_metrics(
    sensor_depth: &DepthImage,
    sensor_mask: &Mask,
    model: &ModelDepth,
    camera: &Camera,
    scratch: &mut DepthMetricsScratch,
) -> Result<DepthMetrics> {
    Ok(DepthMetrics {
        d2m: data_to_model(sensor_depth, sensor_mask, model, camera, scratch)?,
        m2d: model_to_data(sensor_mask, model, camera, scratch)?,
    })
}

/// A posed sphere-mesh template rendered from `camera` by the CPU ray caster (§3.3.2): the model
/// depth the metrics compare with the sensor. Refused: a camera the renderer rejects.
pub fn render_sphere_mesh(
    template: &SphereMeshTemplate,
    pose: &Pose,
    camera: &Camera,
) -> Result<ModelDepth> {
    let posed = PosedSphereMesh::new(template, pose);
    let elements: Vec<_> = template.elements.iter().map(|e| e.element).collect();
    let render = render_depth(
        &hmodel_spheremesh::intrinsics(camera),
        &posed.spheres,
        &elements,
    )
    .map_err(|e| EvalError::arg("camera", e.to_string()))?;
    ModelDepth::from_render(&render)
}

/// The silhouette of a depth image: every pixel with a depth (a sensor frame already segmented
/// to the hand, or a rendering).
pub fn silhouette(depth: &DepthImage) -> Mask {
    Mask {
        width: depth.width,
        height: depth.height,
        data: depth.data.iter().map(|&d| u8::from(d > 0)).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn camera(w: u32, h: u32) -> Camera {
        Camera::new("test", w, h, 100.0, 100.0, w as f64 / 2.0, h as f64 / 2.0).unwrap()
    }

    /// Both metrics of `model` against `sensor` segmented by its own silhouette.
    fn score(sensor: &DepthImage, model: &ModelDepth, cam: &Camera) -> DepthMetrics {
        let mask = silhouette(sensor);
        depth_metrics(
            sensor,
            &mask,
            model,
            cam,
            &mut DepthMetricsScratch::default(),
        )
        .unwrap()
    }

    /// A depth image whose pixels inside `[u0, u1) × [v0, v1)` are at `z`.
    fn rect(w: u32, h: u32, [u0, u1, v0, v1]: [u32; 4], z: u16) -> DepthImage {
        let mut d = DepthImage::zeros(w, h);
        for v in v0..v1 {
            for u in u0..u1 {
                d.data[(v * w + u) as usize] = z;
            }
        }
        d
    }

    #[test]
    fn a_model_against_itself_scores_zero() {
        let cam = camera(40, 30);
        let sensor = rect(40, 30, [5, 30, 4, 25], 400);
        let model = ModelDepth::from_image(&sensor);
        let m = score(&sensor, &model, &cam);
        let (d2m, m2d) = (m.d2m.unwrap(), m.m2d.unwrap());
        assert_eq!(
            (d2m.mean, d2m.max, d2m.hmodel_weighted_mean),
            (0.0, 0.0, 0.0)
        );
        assert_eq!(d2m.sensor_points, 25 * 21);
        assert_eq!(
            (m2d.mean, m2d.outside_pixels, m2d.model_pixels),
            (0.0, 0, 25 * 21)
        );
    }

    #[test]
    fn a_plane_shifted_in_depth_scores_the_shift() {
        // The model is a fronto-parallel plane 7 mm behind a sensor plane and wider than it.
        // Every model point is ≥ 7 mm from every sensor point (the planes are 7 mm apart), and
        // each sensor point is within half a sampling diagonal (√2·4.07/2 mm at 407 mm, f = 100)
        // of a model sample's foot point: E_d2m ∈ [7, √(7² + 2.88²)].
        let cam = camera(60, 50);
        let sensor = rect(60, 50, [20, 40, 15, 35], 400);
        let mask = silhouette(&sensor);
        let model = ModelDepth::from_image(&rect(60, 50, [5, 55, 5, 45], 407));
        let mut s = DepthMetricsScratch::default();
        let d = data_to_model(&sensor, &mask, &model, &cam, &mut s)
            .unwrap()
            .unwrap();
        let bound = (49.0f64 + 2.0 * (4.07f64 / 2.0).powi(2)).sqrt();
        assert!(d.mean >= 7.0 - 1e-9 && d.max <= bound + 1e-9, "{d:?}");
        // Rendered on the sensor's own rays, each nearest model point lies on the same ray
        // 7 mm deeper: the distance is 7·‖(a, b, 1)‖ with (a, b) = ((u − cx)/f, (v − cy)/f).
        let model = ModelDepth::from_image(&rect(60, 50, [20, 40, 15, 35], 407));
        let d = data_to_model(&sensor, &mask, &model, &cam, &mut s)
            .unwrap()
            .unwrap();
        let mut expected = 0.0;
        for v in 15..35 {
            for u in 20..40 {
                let (a, b) = ((u as f64 - 30.0) / 100.0, (v as f64 - 25.0) / 100.0);
                expected += 7.0 * (1.0 + a * a + b * b).sqrt() / 400.0;
            }
        }
        assert!((d.mean - expected).abs() < 1e-9, "{} vs {expected}", d.mean);
        assert!((d.mean - 7.0).abs() < 0.05);
    }

    #[test]
    fn a_rendered_hand_against_its_own_u16_frame() {
        // The CPU renderer's float depth scored against its own rounding to u16 mm: every
        // sensor point is within 0.5 mm of depth (the rounding), i.e. 0.5·‖(a, b, 1)‖ mm along
        // its ray, of its own rendered point (‖(a, b, 1)‖ < 1.25 over this image), the mean is
        // about a quarter millimetre, and the silhouettes coincide.
        use hand_model::spheremesh::default_right_hand;
        let t = default_right_hand();
        let mut pose = Pose::zeros(&t.skeleton);
        for (name, v) in [
            ("global_tz", 420.0),
            ("global_rx", 0.3),
            ("index_mcp_flex", 0.6),
        ] {
            pose.set(&t.skeleton, name, v).unwrap();
        }
        let cam = Camera::sr300_qvga();
        let model = render_sphere_mesh(&t, &pose, &cam).unwrap();
        let hits = model.rendered_count();
        assert!(hits > 1000);
        let sensor = DepthImage::from_data(
            cam.width,
            cam.height,
            model.depth.iter().map(|&z| z.round() as u16).collect(),
        )
        .unwrap();
        let m = score(&sensor, &model, &cam);
        let d2m = m.d2m.unwrap();
        assert!(d2m.max <= 0.5 * 1.25 && d2m.mean < 0.3, "{d2m:?}");
        assert_eq!(d2m.sensor_points, hits);
        assert_eq!(m.m2d.unwrap().outside_pixels, 0);
    }

    #[test]
    fn kd_tree_matches_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(42);
        let cam = camera(32, 24);
        let mut s = DepthMetricsScratch::default();
        for _ in 0..10 {
            let mut sensor = DepthImage::zeros(32, 24);
            let mut model = DepthImage::zeros(32, 24);
            for (a, b) in sensor.data.iter_mut().zip(&mut model.data) {
                if rng.random_bool(0.4) {
                    *a = rng.random_range(300..500);
                }
                if rng.random_bool(0.3) {
                    *b = rng.random_range(300..500);
                }
            }
            let mask = silhouette(&sensor);
            let md = ModelDepth::from_image(&model);
            let d = data_to_model(&sensor, &mask, &md, &cam, &mut s)
                .unwrap()
                .unwrap();
            let pts = |img: &DepthImage| -> Vec<[f64; 3]> {
                (0..img.data.len())
                    .filter(|&i| img.data[i] > 0)
                    .map(|i| {
                        let (u, v) = ((i % 32) as f64, (i / 32) as f64);
                        cam.backproject(u, v, img.data[i] as f64).into()
                    })
                    .collect()
            };
            let model_pts = pts(&model);
            let brute: Vec<f64> = pts(&sensor)
                .iter()
                .map(|p| {
                    model_pts
                        .iter()
                        .map(|q| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>().sqrt())
                        .fold(f64::INFINITY, f64::min)
                })
                .collect();
            let mean = brute.iter().sum::<f64>() / brute.len() as f64;
            assert!((d.mean - mean).abs() < 1e-9, "{} vs {mean}", d.mean);
            assert_eq!(d.sensor_points, brute.len());
            assert_eq!(d.model_points, model_pts.len());
        }
    }

    #[test]
    fn model_to_data_by_hand() {
        // Silhouette: columns 10..20; model: columns 10..23 on 4 rows, so 3 columns stick out
        // by 1, 2 and 3 px: mean 2, half-L1 1, over all 13·4 rendered pixels 24/52.
        let cam = camera(30, 10);
        let mask = silhouette(&rect(30, 10, [10, 20, 0, 10], 500));
        let model = ModelDepth::from_image(&rect(30, 10, [10, 23, 3, 7], 500));
        let m = model_to_data(&mask, &model, &cam, &mut DepthMetricsScratch::default())
            .unwrap()
            .unwrap();
        assert_eq!((m.outside_pixels, m.model_pixels), (12, 52));
        assert_eq!((m.mean, m.half_l1_mean, m.max), (2.0, 1.0, 3.0));
        assert!((m.mean_over_rendered - 24.0 / 52.0).abs() < 1e-12);
        // A diagonal offset: one pixel at (+3, +4) from the silhouette's corner is 5 px away.
        let mut one = DepthImage::zeros(30, 10);
        one.data[(8 * 30 + 23) as usize] = 500;
        let mask = silhouette(&rect(30, 10, [10, 21, 0, 5], 500));
        let m = model_to_data(
            &mask,
            &ModelDepth::from_image(&one),
            &cam,
            &mut DepthMetricsScratch::default(),
        )
        .unwrap()
        .unwrap();
        assert_eq!((m.mean, m.half_l1_mean), (5.0, 3.5));
    }

    #[test]
    fn background_values_of_external_renderings_are_ignored() {
        let cam = camera(20, 10);
        let sensor = rect(20, 10, [2, 8, 2, 8], 300);
        let mut model = rect(20, 10, [2, 8, 2, 8], 300);
        model.data[0] = 5000;
        model.data[1] = 32767;
        let md = ModelDepth::from_image(&model);
        assert_eq!(md.rendered_count(), 36);
        let m = score(&sensor, &md, &cam);
        assert_eq!(m.d2m.unwrap().mean, 0.0);
        assert_eq!(m.m2d.unwrap().outside_pixels, 0);
    }

    #[test]
    fn bad_input_is_refused_or_undefined_never_nan() {
        let cam = camera(20, 10);
        let sensor = rect(20, 10, [2, 8, 2, 8], 300);
        let mask = silhouette(&sensor);
        let model = ModelDepth::from_image(&sensor);
        let mut s = DepthMetricsScratch::default();
        // Sizes.
        let small = DepthImage::zeros(10, 10);
        let e = data_to_model(&small, &mask, &model, &cam, &mut s).unwrap_err();
        assert!(
            e.to_string()
                .contains("sensor depth is 10×10, expected 20×10"),
            "{e}"
        );
        let e = model_to_data(&mask, &ModelDepth::from_image(&small), &cam, &mut s).unwrap_err();
        assert!(e.to_string().contains("model depth"), "{e}");
        // NaN / negative / wrong length model depths.
        let mut bad = vec![0.0f32; 200];
        bad[23] = f32::NAN;
        let e = ModelDepth::from_f32(20, 10, bad).unwrap_err();
        assert!(e.to_string().contains("pixel (3, 1)"), "{e}");
        assert!(ModelDepth::from_f32(20, 10, vec![-1.0; 200]).is_err());
        assert!(ModelDepth::from_f32(20, 10, vec![0.0; 3]).is_err());
        // Empty silhouettes and empty renderings: undefined, not NaN.
        let empty_mask = Mask::zeros(20, 10);
        let empty_model = ModelDepth::from_image(&DepthImage::zeros(20, 10));
        assert_eq!(
            data_to_model(&sensor, &empty_mask, &model, &cam, &mut s).unwrap(),
            None
        );
        assert_eq!(
            data_to_model(&sensor, &mask, &empty_model, &cam, &mut s).unwrap(),
            None
        );
        assert_eq!(
            model_to_data(&empty_mask, &model, &cam, &mut s).unwrap(),
            None
        );
        assert_eq!(
            model_to_data(&mask, &empty_model, &cam, &mut s).unwrap(),
            None
        );
        // A bad camera.
        let mut bad_cam = cam.clone();
        bad_cam.fx = f64::NAN;
        assert!(data_to_model(&sensor, &mask, &model, &bad_cam, &mut s).is_err());
    }
}
