//! `hands track --overlay`: one PNG per frame for visual checks of a tracker — the sensor depth
//! in grey, the model rendered from the sensor camera tinted blue over it, and the sensor points
//! colored by their point-to-model (d2m) distance, green at 0 mm to red at [`RED_AT_MM`] and
//! beyond (magenta without a correspondence). Where a track drifts, the red points show which
//! data the model no longer explains and the tint shows model parts with no data under them.

use std::path::Path;

use anyhow::{Context, Result};
use image::{Rgb, RgbImage};
use sensor_io::preprocess::PreprocessedFrame;

/// Distance (mm) drawn fully red: about a finger radius, beyond which a point is clearly
/// explained by the wrong part or by nothing.
pub const RED_AT_MM: f64 = 10.0;

/// Tint of the rendered model.
const MODEL_TINT: [u8; 3] = [60, 120, 255];

/// Color of a point without a correspondence.
const NO_CORRESPONDENCE: [u8; 3] = [255, 0, 255];

/// The overlay image of one tracked frame (see the module docs). `distances` is per point of
/// `frame.points` (ignored unless it has one entry per point).
pub fn compose(
    frame: &PreprocessedFrame,
    model_pixels: &[u32],
    distances: &[Option<f64>],
) -> RgbImage {
    let depth = &frame.depth;
    let (w, h) = (depth.width, depth.height);
    // Grey scale over the measured range of this frame, near = bright.
    let (lo, hi) = depth
        .data
        .iter()
        .filter(|&&d| d > 0)
        .fold((u16::MAX, 0u16), |(lo, hi), &d| (lo.min(d), hi.max(d)));
    let span = f64::from(hi.saturating_sub(lo).max(1));
    let mut img = RgbImage::new(w, h);
    for (k, &d) in depth.data.iter().enumerate() {
        let g = if d == 0 {
            0
        } else {
            (230.0 - 170.0 * f64::from(d - lo) / span) as u8
        };
        put(&mut img, k, [g, g, g]);
    }
    for &k in model_pixels {
        if let Some(p) = pixel(&img, k as usize) {
            let under = img.get_pixel(p.0, p.1).0;
            let mixed =
                [0, 1, 2].map(|c| ((u16::from(under[c]) + u16::from(MODEL_TINT[c])) / 2) as u8);
            img.put_pixel(p.0, p.1, Rgb(mixed));
        }
    }
    let distances = (distances.len() == frame.pixels.len()).then_some(distances);
    for (i, &k) in frame.pixels.iter().enumerate() {
        let color = match distances.map(|d| d[i]) {
            Some(Some(d)) => distance_color(d),
            Some(None) => NO_CORRESPONDENCE,
            None => [255, 255, 255],
        };
        put(&mut img, k as usize, color);
    }
    img
}

/// Green (0 mm) → yellow → red (≥ [`RED_AT_MM`]).
pub fn distance_color(d_mm: f64) -> [u8; 3] {
    let t = if d_mm.is_finite() {
        (d_mm / RED_AT_MM).clamp(0.0, 1.0)
    } else {
        1.0
    };
    let r = (255.0 * (2.0 * t).min(1.0)) as u8;
    let g = (255.0 * (2.0 - 2.0 * t).min(1.0)) as u8;
    [r, g, 0]
}

fn pixel(img: &RgbImage, k: usize) -> Option<(u32, u32)> {
    let w = img.width() as usize;
    (w > 0 && k < w * img.height() as usize).then(|| ((k % w) as u32, (k / w) as u32))
}

fn put(img: &mut RgbImage, k: usize, c: [u8; 3]) {
    if let Some((u, v)) = pixel(img, k) {
        img.put_pixel(u, v, Rgb(c));
    }
}

/// Write the overlay of frame `index` into `dir` as `NNNNNN.png` (atomically).
pub fn write(dir: &Path, index: u64, image: &RgbImage) -> Result<()> {
    let path = dir.join(format!("{index:06}.png"));
    hand_model::render::preview::write_png(&path, image)
        .with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colors_run_from_green_to_red() {
        assert_eq!(distance_color(0.0), [0, 255, 0]);
        assert_eq!(distance_color(RED_AT_MM / 2.0), [255, 255, 0]);
        assert_eq!(distance_color(50.0), [255, 0, 0]);
        assert_eq!(distance_color(f64::NAN), [255, 0, 0]);
    }
}
