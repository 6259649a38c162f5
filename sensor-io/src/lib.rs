//! # sensor-io — depth input for the `hands` workspace
//!
//! - [`camera`]: pinhole cameras (OpenCV optical frame) with projection, back-projection, the
//!   2×3 projection Jacobian and the presets of the papers;
//! - [`image`]: depth (`u16` mm), color and mask images, frames;
//! - [`dt`]: the exact Euclidean distance transform with closest-pixel indices;
//! - [`preprocess`]: downsampling, segmentation, normals, subsampling: the per-frame pipeline;
//! - [`view`]: [`SensorView`], what the trackers' image-space terms read of a frame.

pub mod camera;
pub mod dt;
pub mod error;
pub mod image;
pub mod io;
pub mod preprocess;
pub mod record;
pub mod view;

pub use camera::Camera;
pub use error::{Result, SensorError};
pub use image::{ColorImage, DepthImage, Frame, Mask};
pub use view::SensorView;
