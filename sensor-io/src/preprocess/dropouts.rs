//! The silhouette that the model→data term (Eq. 3.5) pushes the model into, with a
//! structured-light sensor's dropouts closed.
//!
//! Structured light leaves pixels without depth inside the hand: shadows of the projector
//! beside nearer fingers and dropouts at grazing angles (thesis §2.2, Fig. 2.2). Taken as
//! background, they pull the model's silhouette away from data that is merely unmeasured (on
//! the real scans under the structured-light model, a claw tracked with online calibration
//! ended 22.9 mm off at the fingertips against 10.2 mm noise-free). When the silhouette encloses
//! such pixels, the zero-depth pixels that a morphological closing of the silhouette covers are
//! counted in; a silhouette without enclosed dropouts (noise-free and ToF frames, whose
//! silhouettes are complete) is left as it is. Pixels with a depth are never added, so a gap
//! between fingers through which a background is measured stays open. An unmeasured
//! background that the hand encloses (a claw against nothing in range) is indistinguishable
//! from dropouts and is closed too: on the scanned claw, noise-free, online calibration went
//! 10.2 → 8.0 mm with it.

use std::collections::VecDeque;

use super::segment::flood;
use crate::image::{DepthImage, Mask};

/// Enclosed zero-depth pixels from which a silhouette counts as carrying dropouts.
pub const DROPOUT_GATE_PX: usize = 20;
/// Radius (px) of the closing's square: gaps up to `2·CLOSE_PX` wide are closed.
pub const CLOSE_PX: usize = 2;

/// Reusable buffers of [`close_dropouts`].
#[derive(Clone, Debug, Default)]
pub struct DropoutScratch {
    /// The mask's bounding box with a one-pixel frame, for the flood of `enclosed_dropouts`.
    framed: Vec<u8>,
    queue: VecDeque<usize>,
    rows: Vec<u8>,
    dilated: Vec<u8>,
}

/// When `mask` encloses at least [`DROPOUT_GATE_PX`] zero-depth pixels, writes to `out` the
/// mask with the zero-depth pixels of its closing by a `(2·CLOSE_PX + 1)²` square added, and
/// returns true; otherwise (also for a `depth` of another size) leaves `out` alone and returns
/// false.
pub fn close_dropouts(
    depth: &DepthImage,
    mask: &Mask,
    scratch: &mut DropoutScratch,
    out: &mut Mask,
) -> bool {
    if depth.data.len() != mask.data.len() {
        return false;
    }
    let Some(bbox) = bounding_box(mask) else {
        return false;
    };
    if enclosed_dropouts(depth, mask, bbox, scratch) < DROPOUT_GATE_PX {
        return false;
    }
    out.clone_from(mask);
    let (w, h) = (mask.width as usize, mask.height as usize);
    let r = CLOSE_PX;
    // The closing reaches 2r beyond the mask at most: work in that window, separably. Beyond
    // the image counts as dilated, so that the closing does not open at the image border.
    let (u0, v0) = (bbox.0.saturating_sub(2 * r), bbox.1.saturating_sub(2 * r));
    let (u1, v1) = ((bbox.2 + 2 * r).min(w - 1), (bbox.3 + 2 * r).min(h - 1));
    let (ww, wh) = (u1 - u0 + 1, v1 - v0 + 1);
    let DropoutScratch { rows, dilated, .. } = scratch;
    rows.clear();
    rows.resize(ww * wh, 0);
    for y in 0..wh {
        let row = &mask.data[(v0 + y) * w + u0..(v0 + y) * w + u0 + ww];
        rows[y * ww..(y + 1) * ww].copy_from_slice(row);
    }
    dilated.resize(ww * wh, 0);
    // Dilation, then erosion, each a pass along the rows and one along the columns.
    for (dilate, along_rows) in [(true, true), (true, false), (false, true), (false, false)] {
        window_pass(rows, dilated, (ww, wh), r, dilate, along_rows);
        std::mem::swap(rows, dilated);
    }
    for y in 0..wh {
        for x in 0..ww {
            let i = (v0 + y) * w + u0 + x;
            if rows[y * ww + x] != 0 && depth.data[i] == 0 {
                out.data[i] = 1;
            }
        }
    }
    true
}

/// One separable pass of a `(2r + 1)`-wide window over `src` (`size` = width, height) into
/// `dst`, along rows or columns: `any` (dilation) or `all` (erosion; window positions beyond the
/// edge are left out, i.e. count as set).
fn window_pass(
    src: &[u8],
    dst: &mut [u8],
    (ww, wh): (usize, usize),
    r: usize,
    dilate: bool,
    along_rows: bool,
) {
    let (len, lines, step, stride) = if along_rows {
        (ww, wh, 1, ww)
    } else {
        (wh, ww, ww, 1)
    };
    for line in 0..lines {
        let base = line * stride;
        for c in 0..len {
            let (lo, hi) = (c.saturating_sub(r), (c + r).min(len - 1));
            let mut window = (lo..=hi).map(|k| src[base + k * step] != 0);
            let value = if dilate {
                window.any(|b| b)
            } else {
                window.all(|b| b)
            };
            dst[base + c * step] = u8::from(value);
        }
    }
}

/// The bounding box `(u0, v0, u1, v1)` (inclusive) of the mask's pixels.
fn bounding_box(mask: &Mask) -> Option<(usize, usize, usize, usize)> {
    let w = (mask.width as usize).max(1);
    let mut bbox: Option<(usize, usize, usize, usize)> = None;
    for (v, row) in mask.data.chunks_exact(w).enumerate() {
        let (Some(a), Some(b)) = (
            row.iter().position(|&m| m != 0),
            row.iter().rposition(|&m| m != 0),
        ) else {
            continue;
        };
        bbox = Some(bbox.map_or((a, v, b, v), |(u0, v0, u1, _)| {
            (u0.min(a), v0, u1.max(b), v)
        }));
    }
    bbox
}

/// The zero-depth pixels that `mask` encloses: inside its bounding box `bbox` and not reached
/// from the box's border through pixels outside the mask (flooded in a copy of the box with a
/// one-pixel frame, as `segment_depth_only` finds its holes).
fn enclosed_dropouts(
    depth: &DepthImage,
    mask: &Mask,
    (u0, v0, u1, v1): (usize, usize, usize, usize),
    scratch: &mut DropoutScratch,
) -> usize {
    const OUTSIDE: u8 = 2;
    let w = mask.width as usize;
    let (bw, bh) = (u1 - u0 + 3, v1 - v0 + 3);
    let DropoutScratch { framed, queue, .. } = scratch;
    framed.clear();
    framed.resize(bw * bh, 1);
    for y in 0..=v1 - v0 {
        for x in 0..=u1 - u0 {
            framed[(y + 1) * bw + x + 1] = u8::from(mask.data[(v0 + y) * w + u0 + x] == 0);
        }
    }
    flood(
        framed,
        (bw, bh),
        0,
        OUTSIDE,
        queue,
        |m, _, _| m == 1,
        |_| {},
    );
    let mut enclosed = 0;
    for y in 0..=v1 - v0 {
        for x in 0..=u1 - u0 {
            let i = (v0 + y) * w + u0 + x;
            enclosed += usize::from(framed[(y + 1) * bw + x + 1] == 1 && depth.data[i] == 0);
        }
    }
    enclosed
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 40 × 30 image with a 20 × 14 block of hand at 400 mm; `cut` draws two 12-px lines of
    /// dropouts inside the block, `gap` a 3-px gap from its lower edge, measured at 900 mm (a
    /// background seen between fingers).
    fn scene(cut: bool, gap: bool) -> (DepthImage, Mask) {
        let (w, h) = (40u32, 30u32);
        let mut depth = DepthImage::zeros(w, h);
        let mut mask = Mask::zeros(w, h);
        for v in 8..22u32 {
            for u in 10..30u32 {
                let i = (v * w + u) as usize;
                if cut && (14..26).contains(&u) && (v == 12 || v == 16) {
                    continue;
                }
                if gap && (27..30).contains(&u) && v >= 15 {
                    depth.data[i] = 900;
                    continue;
                }
                depth.data[i] = 400;
                mask.data[i] = 1;
            }
        }
        (depth, mask)
    }

    #[test]
    fn enclosed_dropouts_are_closed_and_measured_gaps_kept() {
        let mut scratch = DropoutScratch::default();
        let mut out = Mask::default();
        // Two dropout lines of 12 px: 24 enclosed pixels, closed.
        let (depth, mask) = scene(true, false);
        let bbox = bounding_box(&mask).unwrap();
        assert_eq!(enclosed_dropouts(&depth, &mask, bbox, &mut scratch), 24);
        assert!(close_dropouts(&depth, &mask, &mut scratch, &mut out));
        assert_eq!(out.count(), mask.count() + 24);
        // A gap with a measured background is never added.
        let (depth, mask) = scene(true, true);
        assert!(close_dropouts(&depth, &mask, &mut scratch, &mut out));
        let background = (27..30).flat_map(|u| (15..22).map(move |v| v * 40 + u));
        assert!(background.clone().all(|i| out.data[i] == 0));
        // No enclosed dropouts, or mismatched sizes: nothing closed, `out` untouched.
        let (depth, mask) = scene(false, false);
        let mut untouched = Mask::zeros(1, 1);
        assert!(!close_dropouts(&depth, &mask, &mut scratch, &mut untouched));
        let mut short = depth.clone();
        short.data.pop();
        assert!(!close_dropouts(&short, &mask, &mut scratch, &mut untouched));
        assert_eq!(untouched, Mask::zeros(1, 1));
    }
}
