//! Per-frame preprocessing (thesis §2.2 "Preprocessing", Fig. 2.5; §3.6 "Downsampling";
//! Taylor et al. 2016 §3.4): median downsampling, range clipping, hand segmentation (wristband or
//! depth-only), edge-aware smoothing of the hand's depth (beyond the thesis, [`smooth_depth`]),
//! normals from the depth image, point subsampling, and the silhouette's distance
//! transform, assembled by [`Preprocessor`]; the depth noise measured from the data
//! ([`depth_noise`]).

mod downsample;
mod dropouts;
mod noise;
mod normals;
mod pipeline;
mod segment;
mod smooth;
mod subsample;

pub use downsample::{clip_range, median_downsample};
pub use dropouts::{close_dropouts, DropoutScratch, CLOSE_PX, DROPOUT_GATE_PX};
pub use noise::{
    depth_noise, depth_noise_with, gate_for_noise, is_noisy, noise_scale, slide_for_noise,
    NoiseMonitor,
};
pub use normals::depth_normals;
pub use pipeline::{PreprocessConfig, PreprocessedFrame, Preprocessor, Segmentation, Subsampling};
pub use segment::{
    rgb_to_hsv, segment_depth_only, segment_wristband, DepthOnlyParams, HandSegment,
    SegmentScratch, Wristband, WristbandParams,
};
pub use smooth::{smooth_depth, SmoothParams};
pub use subsample::{subsample_uniform, FarthestSampler};
