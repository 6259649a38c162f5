//! What the image-space terms of the trackers read of the current frame (thesis §2.3.1 "2D
//! correspondences", Eq. 2.3–2.4, Eq. 3.5): the camera, the sensor silhouette's distance
//! transform and the wristband.

use nalgebra::Vector3;

use crate::dt::NO_PIXEL;
use crate::preprocess::{PreprocessedFrame, Wristband};
use crate::Camera;

/// What the image-space terms (E2D Eq. 2.3, E_wrist Eq. 2.4) read of the current frame: the
/// camera of the processed images, for every pixel the linear index of the nearest sensor
/// silhouette pixel (the distance transform of `S_s`, ANCHOR-FACTS §5.4), and the wristband
/// axis when the segmentation found one.
#[derive(Clone, Debug, Default)]
pub struct SensorView {
    /// Camera of the processed images; `None` before the first frame (image terms then add no
    /// rows).
    pub camera: Option<Camera>,
    /// Per pixel (`v·width + u`) the nearest silhouette pixel; [`NO_PIXEL`] everywhere when the
    /// silhouette is empty. Empty before the first frame.
    pub nearest: Vec<u32>,
    /// The wristband of the frame, when the segmentation found one.
    pub wristband: Option<Wristband>,
}

impl SensorView {
    /// Take the camera, the silhouette distance transform and the wristband of a preprocessed
    /// frame, reusing the buffers. A distance transform whose size does not match the camera
    /// leaves no camera (the image terms then add nothing) rather than misreading indices.
    pub fn set_frame(&mut self, frame: &PreprocessedFrame) {
        self.camera.clone_from(&frame.camera);
        self.nearest.clear();
        let consistent = frame.camera.as_ref().is_some_and(|c| {
            frame.dt.width() == c.width
                && frame.dt.height() == c.height
                && frame.dt.nearest.len() == c.num_pixels()
        });
        if consistent {
            self.nearest.extend_from_slice(&frame.dt.nearest);
        } else {
            self.camera = None;
        }
        self.wristband = frame.hand.wristband;
    }

    /// Whether the segmentation hides `p` (camera frame, mm): under the wristband or beyond it
    /// ([`Wristband::hides`]); never without a band.
    #[inline]
    pub fn hides(&self, p: &Vector3<f64>) -> bool {
        self.wristband.as_ref().is_some_and(|b| b.hides(p))
    }

    /// Whether pixel `(u, v)` (inside the image) belongs to the sensor silhouette `S_s`.
    #[inline]
    pub fn in_silhouette(&self, u: u32, v: u32) -> bool {
        self.camera.as_ref().is_some_and(|c| {
            let i = (v * c.width + u) as usize;
            self.nearest.get(i).is_some_and(|&n| n as usize == i)
        })
    }

    /// Number of pixels of the sensor silhouette `S_s` (0 before the first frame): one pass
    /// over the image.
    pub fn silhouette_area(&self) -> usize {
        self.nearest
            .iter()
            .enumerate()
            .filter(|&(i, &n)| n as usize == i)
            .count()
    }

    /// The nearest silhouette pixel `(u, v)` of pixel `(u, v)`, `None` outside the image or
    /// when the silhouette is empty.
    #[inline]
    pub fn nearest_pixel(&self, u: u32, v: u32) -> Option<(u32, u32)> {
        let c = self.camera.as_ref()?;
        if u >= c.width || v >= c.height {
            return None;
        }
        let n = *self.nearest.get((v * c.width + u) as usize)?;
        (n != NO_PIXEL).then(|| (n % c.width, n / c.width))
    }
}
