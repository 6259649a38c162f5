//! Contact sheets: a grid of depth frames with the ground-truth keypoints drawn, so a person can
//! judge the realism of a synthetic sequence at a glance (`hands synth --preview`).

use image::{Rgb, RgbImage};
use sensor_io::DepthImage;

/// Bones of the 21-keypoint skeleton (DESIGN.md order) drawn as lines.
const BONES: [(usize, usize); 20] = [
    (0, 1),
    (1, 2),
    (2, 3),
    (3, 4),
    (0, 5),
    (5, 6),
    (6, 7),
    (7, 8),
    (0, 9),
    (9, 10),
    (10, 11),
    (11, 12),
    (0, 13),
    (13, 14),
    (14, 15),
    (15, 16),
    (0, 17),
    (17, 18),
    (18, 19),
    (19, 20),
];
const DIGIT_COLORS: [[u8; 3]; 5] = [
    [230, 60, 50],
    [250, 160, 30],
    [240, 220, 40],
    [60, 190, 80],
    [60, 130, 240],
];

/// Depth as grey levels: near bright, far dark, holes black; the range adapts to the frame.
pub fn depth_to_rgb(depth: &DepthImage) -> RgbImage {
    let (lo, hi) = depth
        .data
        .iter()
        .filter(|&&d| d > 0)
        .fold((u16::MAX, 0u16), |(a, b), &d| (a.min(d), b.max(d)));
    let span = (hi.saturating_sub(lo)).max(1) as f64;
    RgbImage::from_fn(depth.width, depth.height, |u, v| {
        let d = depth.get(u, v);
        if d == 0 {
            Rgb([0, 0, 0])
        } else {
            let g = (235.0 - 200.0 * (d.min(hi) - lo) as f64 / span) as u8;
            Rgb([g, g, g])
        }
    })
}

fn line(img: &mut RgbImage, a: [f64; 2], b: [f64; 2], c: [u8; 3]) {
    if !(a.iter().chain(&b).all(|x| x.is_finite())) {
        return;
    }
    let n = ((b[0] - a[0]).abs().max((b[1] - a[1]).abs()).ceil() as usize).clamp(1, 4096);
    for k in 0..=n {
        let t = k as f64 / n as f64;
        let (x, y) = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]));
        if x >= 0.0 && y >= 0.0 && (x as u32) < img.width() && (y as u32) < img.height() {
            img.put_pixel(x as u32, y as u32, Rgb(c));
        }
    }
}

/// Draw the keypoint skeleton (pixel coordinates; non-finite points are skipped).
pub fn draw_keypoints(img: &mut RgbImage, keypoints_px: &[[f64; 2]]) {
    if keypoints_px.len() < 21 {
        return;
    }
    for (k, &(a, b)) in BONES.iter().enumerate() {
        line(img, keypoints_px[a], keypoints_px[b], DIGIT_COLORS[k / 4]);
    }
    for p in keypoints_px {
        if p.iter().all(|x| x.is_finite()) {
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let (x, y) = (p[0] as i64 + dx, p[1] as i64 + dy);
                    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
                        img.put_pixel(x as u32, y as u32, Rgb([255, 255, 255]));
                    }
                }
            }
        }
    }
}

/// A grid of tiles (all of the first tile's size) with `cols` columns.
pub fn contact_sheet(tiles: &[RgbImage], cols: u32) -> RgbImage {
    let cols = cols.max(1);
    let (tw, th) = tiles.first().map_or((1, 1), |t| (t.width(), t.height()));
    let rows = (tiles.len() as u32).div_ceil(cols).max(1);
    let mut sheet = RgbImage::from_pixel(
        cols * tw + (cols + 1) * 2,
        rows * th + (rows + 1) * 2,
        Rgb([40, 40, 48]),
    );
    for (k, tile) in tiles.iter().enumerate() {
        let (c, r) = (k as u32 % cols, k as u32 / cols);
        let (ox, oy) = (2 + c * (tw + 2), 2 + r * (th + 2));
        for (x, y, p) in tile.enumerate_pixels() {
            if x < tw && y < th {
                sheet.put_pixel(ox + x, oy + y, *p);
            }
        }
    }
    sheet
}
