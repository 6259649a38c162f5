//! The per-frame preprocessing pipeline: sensor point cloud `X_s` with normals, silhouette `S_s`
//! and its distance transform (thesis §2.2, §2.3.1; Taylor 2016 §3.4).

use nalgebra::Vector3;

use super::downsample::{clip_range, median_downsample};
use super::dropouts::{close_dropouts, DropoutScratch};
use super::noise::{is_noisy, NoiseMonitor};
use super::normals::depth_normals;
use super::segment::{
    segment_depth_only, segment_wristband, DepthOnlyParams, HandSegment, WristbandParams,
};
use super::smooth::{smooth_depth, SmoothParams};
use super::subsample::{subsample_uniform, FarthestSampler};
use crate::camera::Camera;
use crate::dt::DistanceTransform;
use crate::error::{Result, SensorError};
use crate::image::{DepthImage, Frame, Mask};

/// How the hand is segmented.
#[derive(Clone, Debug)]
pub enum Segmentation {
    /// Colored wristband (needs a color image; frames without one give an empty hand).
    Wristband(WristbandParams),
    /// Depth only.
    DepthOnly(DepthOnlyParams),
    /// Every valid depth pixel in range is the hand (pre-segmented data, synthetic sequences).
    Presegmented,
}

/// Point subsampling method.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Subsampling {
    /// Evenly spaced in raster order.
    Uniform,
    /// Stochastic farthest-point sampling (Taylor 2016).
    Farthest,
}

/// Preprocessing settings.
#[derive(Clone, Debug)]
pub struct PreprocessConfig {
    /// Median downsampling factor (2 turns VGA into QVGA; 1 keeps the resolution).
    pub downsample: u32,
    /// Depth range (mm).
    pub near: u16,
    /// Far limit (mm).
    pub far: u16,
    /// Segmentation method.
    pub segmentation: Segmentation,
    /// Number of points kept (0 = all silhouette pixels).
    pub num_points: usize,
    /// Subsampling method.
    pub subsampling: Subsampling,
    /// Normal window radius (px).
    pub normal_radius: u32,
    /// Seed of the stochastic subsampling.
    pub seed: u64,
    /// Edge-aware smoothing of the hand's depth before its points are made ([`smooth_depth`];
    /// `None`: the raw depth, as the thesis). Only the points are smoothed: the processed depth
    /// image keeps the sensor's depth, so that the noise the trackers measure on it
    /// ([`super::depth_noise`]) is the sensor's, and the normals are the raw depth's.
    pub smoothing: Option<SmoothParams>,
}

impl Default for PreprocessConfig {
    fn default() -> Self {
        Self {
            downsample: 1,
            near: 150,
            far: 1500,
            segmentation: Segmentation::DepthOnly(DepthOnlyParams::default()),
            num_points: 2500,
            subsampling: Subsampling::Uniform,
            normal_radius: 1,
            seed: 5001,
            smoothing: Some(SmoothParams::default()),
        }
    }
}

/// The result for one frame; buffers are reused from frame to frame.
#[derive(Clone, Debug, Default)]
pub struct PreprocessedFrame {
    /// The camera of the processed images (downsampled when requested).
    pub camera: Option<Camera>,
    /// Processed depth (downsampled, clipped).
    pub depth: DepthImage,
    /// Segmentation: silhouette `S_s`, palm center, wristband.
    pub hand: HandSegment,
    /// Distance transform of the silhouette with closest-pixel indices; the zero-depth pixels
    /// that the silhouette encloses (a structured-light sensor's dropouts and shadows) count
    /// as silhouette ([`close_dropouts`]).
    pub dt: DistanceTransform,
    /// Subsampled sensor points `X_s` (camera frame, mm).
    pub points: Vec<Vector3<f64>>,
    /// Unit normals of the points facing the camera (zero where undefined).
    pub normals: Vec<Vector3<f64>>,
    /// Linear pixel index of each point.
    pub pixels: Vec<u32>,
}

/// Runs the pipeline with reusable buffers; one per sequence (the smoothing follows the
/// sequence's depth noise and frame count, [`SmoothParams`]).
#[derive(Clone, Debug, Default)]
pub struct Preprocessor {
    /// Settings.
    pub config: PreprocessConfig,
    all_points: Vec<Vector3<f64>>,
    all_pixels: Vec<u32>,
    picks: Vec<usize>,
    sampler: FarthestSampler,
    segment_scratch: super::segment::SegmentScratch,
    dropout_scratch: DropoutScratch,
    /// The silhouette of the distance transform (the hand's, its enclosed dropouts closed).
    closed: Mask,
    /// The smoothed depth ([`PreprocessConfig::smoothing`]).
    smoothed: Vec<f64>,
    /// The depth noise of the frames so far, for [`SmoothParams::min_noise`].
    noise: NoiseMonitor,
    /// Frames processed so far, for [`SmoothParams::after_frames`].
    frames: usize,
}

impl Preprocessor {
    /// A preprocessor with the given settings.
    pub fn new(config: PreprocessConfig) -> Self {
        Self {
            config,
            ..Default::default()
        }
    }

    /// Process one frame. Errors on a frame whose size disagrees with the camera; a frame with
    /// no valid depth or no hand in range yields an empty hand (`out.hand.count == 0`).
    pub fn process(
        &mut self,
        frame: &Frame,
        camera: &Camera,
        out: &mut PreprocessedFrame,
    ) -> Result<()> {
        if frame.depth.width != camera.width
            || frame.depth.height != camera.height
            || frame.depth.data.len() != camera.num_pixels()
        {
            return Err(SensorError::arg(
                "frame",
                format!(
                    "depth is {}×{}, camera is {}×{}",
                    frame.depth.width, frame.depth.height, camera.width, camera.height
                ),
            ));
        }
        let cfg = &self.config;
        let cam = if cfg.downsample > 1 {
            median_downsample(&frame.depth, cfg.downsample, &mut out.depth);
            camera.downsampled(cfg.downsample)
        } else {
            out.depth.clone_from(&frame.depth);
            camera.clone()
        };
        clip_range(&mut out.depth, cfg.near, cfg.far);
        match &cfg.segmentation {
            Segmentation::DepthOnly(p) => segment_depth_only(
                &out.depth,
                &cam,
                p,
                &mut out.hand,
                &mut self.segment_scratch,
            ),
            Segmentation::Wristband(p) => match &frame.color {
                Some(c) if cfg.downsample <= 1 => {
                    segment_wristband(&out.depth, c, &cam, p, &mut out.hand)
                }
                Some(c) => {
                    let small = downsample_color(c, cfg.downsample);
                    segment_wristband(&out.depth, &small, &cam, p, &mut out.hand)
                }
                None => {
                    out.hand = HandSegment {
                        mask: crate::image::Mask::zeros(cam.width, cam.height),
                        ..Default::default()
                    }
                }
            },
            Segmentation::Presegmented => {
                out.hand.mask.width = cam.width;
                out.hand.mask.height = cam.height;
                out.hand.mask.data.clear();
                out.hand
                    .mask
                    .data
                    .extend(out.depth.data.iter().map(|&d| (d != 0) as u8));
                out.hand.count = out.hand.mask.count();
                out.hand.wristband = None;
                out.hand.palm_center = None;
            }
        }
        let closed = close_dropouts(
            &out.depth,
            &out.hand.mask,
            &mut self.dropout_scratch,
            &mut self.closed,
        );
        out.dt
            .compute(if closed { &self.closed } else { &out.hand.mask });
        self.all_points.clear();
        self.all_pixels.clear();
        self.frames += 1;
        let frames = self.frames;
        let smoothing = cfg.smoothing.filter(|p| {
            self.noise.observe(&out.depth, &out.hand.mask);
            is_noisy(p.min_noise, self.noise.sigma()) && frames > p.after_frames
        });
        let smoothed = smoothing.is_some();
        if let Some(params) = &smoothing {
            smooth_depth(
                &out.depth,
                &out.hand.mask,
                params,
                cam.depth_unit_mm,
                &mut self.smoothed,
            );
        }
        let w = cam.width as usize;
        for (i, &m) in out.hand.mask.data.iter().enumerate() {
            if m != 0 && out.depth.data[i] != 0 {
                let z = if smoothed {
                    self.smoothed[i]
                } else {
                    f64::from(out.depth.data[i])
                };
                self.all_points.push(cam.backproject(
                    (i % w) as f64,
                    (i / w) as f64,
                    z * cam.depth_unit_mm,
                ));
                self.all_pixels.push(i as u32);
            }
        }
        let n = if cfg.num_points == 0 {
            self.all_points.len()
        } else {
            cfg.num_points
        };
        match cfg.subsampling {
            Subsampling::Uniform => subsample_uniform(self.all_points.len(), n, &mut self.picks),
            Subsampling::Farthest => {
                self.sampler
                    .sample(&self.all_points, n, 5, cfg.seed, &mut self.picks)
            }
        }
        out.points.clear();
        out.normals.clear();
        out.pixels.clear();
        for &k in &self.picks {
            let px = self.all_pixels[k];
            out.points.push(self.all_points[k]);
            out.pixels.push(px);
            let n = depth_normals(
                &out.depth,
                &cam,
                px % cam.width,
                px / cam.width,
                cfg.normal_radius,
                20.0,
            )
            .unwrap_or_else(Vector3::zeros);
            out.normals.push(n);
        }
        out.camera = Some(cam);
        Ok(())
    }
}

fn downsample_color(c: &crate::image::ColorImage, f: u32) -> crate::image::ColorImage {
    let (w, h) = (c.width / f, c.height / f);
    let mut out = crate::image::ColorImage::zeros(w, h);
    for v in 0..h {
        for u in 0..w {
            let p = c.get(u * f, v * f);
            let i = 3 * (v * w + u) as usize;
            out.data[i..i + 3].copy_from_slice(&p);
        }
    }
    out
}
