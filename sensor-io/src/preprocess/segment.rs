//! Hand segmentation: (a) by a colored wristband (thesis §2.2 "Preprocessing", Fig. 2.5;
//! ANCHOR-FACTS §5.6) and (b) depth-only, the nearest connected component grown from a seed
//! inside a 3D volume (Taylor et al. 2016 §3.4) with the forearm cut by a palm-size heuristic.

use std::collections::VecDeque;

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use crate::camera::Camera;
use crate::dt::DistanceTransform;
use crate::image::{ColorImage, DepthImage, Mask};

/// The segmented hand of one frame.
#[derive(Clone, Debug, Default)]
pub struct HandSegment {
    /// Silhouette `S_s`.
    pub mask: Mask,
    /// Number of silhouette pixels (0 = no hand found: trackers skip the frame with `no_hand`).
    pub count: usize,
    /// Estimated palm center (camera frame, mm), when a hand was found.
    pub palm_center: Option<Vector3<f64>>,
    /// The wristband (wristband segmentation), or the forearm cut of the depth-only
    /// segmentation standing in for one (its center the centroid of the arm's slice at the cut,
    /// its axis toward the hand, reach 0); used by the wrist term of Eq. 2.4 and to tell where
    /// the silhouette was cut ([`Wristband::hides`]).
    pub wristband: Option<Wristband>,
}

impl HandSegment {
    /// No hand, the mask sized to `depth` (keeps its allocation).
    fn clear(&mut self, depth: &DepthImage) {
        self.mask.width = depth.width;
        self.mask.height = depth.height;
        self.mask.data.clear();
        self.mask
            .data
            .resize(depth.width as usize * depth.height as usize, 0);
        self.count = 0;
        self.palm_center = None;
        self.wristband = None;
    }
}

/// The wristband found by [`segment_wristband`].
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Wristband {
    /// Mean 3D point of the band's pixels (camera frame, mm).
    pub center: Vector3<f64>,
    /// Unit axis from the band toward the hand.
    pub axis: Vector3<f64>,
    /// How far (mm) along `axis` from `center` the band's pixels reach (98th percentile): the
    /// silhouette starts there.
    pub reach: f64,
}

impl Wristband {
    /// Whether `p` lies where the segmentation cannot see the hand: under the band or on its
    /// forearm side. The silhouette is cut there whatever the hand looks like, so a model point
    /// there that falls outside the silhouette is no evidence against the model (the model's
    /// wrist may extend under the band; thesis §2.2 keeps only the hand side of the band).
    pub fn hides(&self, p: &Vector3<f64>) -> bool {
        (p - self.center).dot(&self.axis) < self.reach
    }
}

/// Reusable buffers of [`segment_depth_only`], so that segmenting a frame allocates nothing once
/// the buffers have grown to the image size, and the previous frame's palm center (a hint for
/// the next frame's): use one per sequence.
#[derive(Clone, Debug, Default)]
pub struct SegmentScratch {
    dt: DistanceTransform,
    queue: VecDeque<usize>,
    inv: Mask,
    pixels: Vec<usize>,
    pts: Vec<Vector3<f64>>,
    t: Vec<f64>,
    /// Component pixels where the component leaves the image or the growth volume.
    exits: Vec<usize>,
    /// Geodesic distance (mm) inside the component from the exits, per image pixel.
    geo: Vec<f32>,
    /// A region that may be an occluded hand part.
    region: Vec<usize>,
    /// The palm center of the last segmented frame (a hint for the next frame's; cleared by
    /// a frame without a hand).
    last_palm: Option<Vector3<f64>>,
    /// Where the last frame's forearm stump was taken (the centroid of its pixels) when its
    /// arm had no exit (see [`segment_depth_only`], step 2).
    last_stump: Option<Vector3<f64>>,
}

/// Parameters of the depth-only segmentation.
#[derive(Clone, Debug)]
pub struct DepthOnlyParams {
    /// Depths outside `[near, far]` mm are ignored.
    pub near: u16,
    /// Far limit (mm).
    pub far: u16,
    /// Radius of the growth volume around the seed (mm); Taylor 2016 uses a 19 cm volume around
    /// the hand position, our seed is the nearest surface point so the volume is larger.
    pub radius: f64,
    /// Largest depth step between 4-neighbours of the same component (mm).
    pub max_step: f64,
    /// Distance beyond the palm center at which the forearm is cut, in palm radii (the radius
    /// of the largest inscribed circle of the silhouette): the wrist crease lies ≈ 1.3 palm
    /// radii below the palm center, the wrist of the tracking models reaches ≈ 1 radius further.
    pub cut_palm_radii: f64,
    /// Bounds (mm) of the forearm cut distance from the palm center, for palms seen edge-on
    /// (small inscribed circle) or foreshortened forearms (large one).
    pub cut_range: [f64; 2],
    /// Minimum component size (px) to count as a hand.
    pub min_pixels: usize,
    /// Longest extent of a hand (mm): the palm center lies within `0.75 ×` this of the hand's
    /// far end (the fingertips, or the knuckles of a fist); a component without exits (it does
    /// not leave the image or the growth volume) that is longer than this carries a forearm.
    pub max_hand_length: f64,
}

impl Default for DepthOnlyParams {
    fn default() -> Self {
        Self {
            near: 150,
            far: 1500,
            radius: 300.0,
            max_step: 25.0,
            cut_palm_radii: 2.4,
            cut_range: [80.0, 110.0],
            min_pixels: 60,
            max_hand_length: 210.0,
        }
    }
}

/// Half-width (mm) of the slice of the arm at the forearm cut whose centroid stands in for a
/// wristband's center.
const SECTION_HALF_WIDTH_MM: f64 = 5.0;

/// Least share of a hand's outline that stands clear of what lies behind it ([`Outline`]). A
/// hand stands in front of the background; a patch that the growth cut out of a noisy surface
/// (a wall at 1.1 m under ToF noise, where neighbouring depths differ by more than the growth's
/// step) is bounded by more of the same surface. Measured on the synthetic library (ToF,
/// structured light, noise-free, two cameras): hands 0.80–1.00 in every frame; patches of the
/// wall behind a hand that had left the view 0.16–0.33.
const MIN_SEPARATION: f64 = 0.5;

/// Least share of a noisy surface patch's outline edges across which the outside is the nearer
/// side ([`Outline::nearer`]). A hand lies in front of what surrounds it, but where it occludes
/// itself (a finger across the palm): at most 0.13 of its outline in every frame of the
/// synthetic library; the wall patches of `leave_reenter` under ToF 0.19–0.40 (one in ≈ 1000,
/// 0.10). Without this test a hand less than twice the growth's step in front of a wall would
/// count as a patch of it (no clear outline).
const MIN_SURFACE_NEARER: f64 = 0.15;

/// How a component of the growth is bounded, counted over its member pixels' 4-neighbours that
/// are not members (the image border aside).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
struct Outline {
    /// Neighbours the growth rejected for their depth (a step beyond its own, or out of range):
    /// the component's outline.
    edges: usize,
    /// Outline neighbours across a step beyond twice the growth's, or out of range.
    clear: usize,
    /// Outline neighbours nearer to the camera than the member pixel.
    nearer: usize,
    /// Neighbours the growth left out for its volume alone: where the arm leaves it.
    exits: usize,
}

impl Outline {
    fn of(
        depth: &DepthImage,
        params: &DepthOnlyParams,
        max_step: f64,
        mask: &[u8],
        pixels: &[usize],
    ) -> Self {
        let (w, h) = (depth.width as usize, depth.height as usize);
        let mut out = Self::default();
        for &i in pixels {
            let (u, v) = (i % w, i / w);
            let d0 = f64::from(depth.data[i]);
            let neighbours = [
                (u > 0).then(|| i - 1),
                (u + 1 < w).then(|| i + 1),
                (v > 0).then(|| i - w),
                (v + 1 < h).then(|| i + w),
            ];
            for j in neighbours.into_iter().flatten().filter(|&j| mask[j] == 0) {
                let d = depth.data[j];
                let out_of_range = d == 0 || d < params.near || d > params.far;
                let step = f64::from(d) - d0;
                if !out_of_range && step.abs() <= max_step {
                    out.exits += 1;
                } else {
                    out.edges += 1;
                    out.clear += usize::from(out_of_range || step > 2.0 * max_step);
                    out.nearer += usize::from(!out_of_range && step < 0.0);
                }
            }
        }
        out
    }

    /// Whether the component is a surface rather than a hand: bounded more by the growth volume
    /// than by an outline of its own (an exact wall or table: a hand leaves the volume only
    /// where its forearm does), or by an outline mostly on more of the same surface, nearer and
    /// farther alike ([`MIN_SEPARATION`], [`MIN_SURFACE_NEARER`]). Tracked, the wall behind a
    /// hand that had left the view was taken for a crumpled hand (synthetic `leave_reenter`:
    /// every frame out of view flagged `lost` with keypoints 700 mm deep in the wall, instead
    /// of `no_hand`).
    fn is_surface(&self) -> bool {
        let edges = self.edges as f64;
        self.exits > self.edges
            || ((self.clear as f64) < MIN_SEPARATION * edges
                && (self.nearer as f64) >= MIN_SURFACE_NEARER * edges)
    }
}

/// A component that reaches less far (mm) from the seed is a part of the hand alone — a thumb
/// tip in front of a fist seen end-on, beyond a depth step larger than the growth's — and is
/// grown again with the step doubled (up to `MAX_STEP_FACTOR` times the parameter's).
const MIN_HAND_EXTENT_MM: f64 = 60.0;
/// See [`MIN_HAND_EXTENT_MM`].
const MAX_STEP_FACTOR: f64 = 4.0;
/// How far (mm) the hand may reach from its palm center (fingertips, the forearm cut beyond
/// it): a palm center closer than this to the growth volume's surface means the volume —
/// centered on the nearest point, which may lie on a forearm pointing at the camera — may have
/// cut the hand, and the growth is repeated in the volume centered on the palm.
const HAND_REACH_MM: f64 = 150.0;

/// Length (mm) of the end of the principal axis taken as a forearm stump.
const STUMP_MM: f64 = 40.0;
/// An end whose widest inscribed circle is below this radius (mm) and this fraction of the
/// other end's is fingers, never a forearm stump: a forearm is 45–70 mm across, a finger
/// 15–20 mm; the knuckle end of a fist, also wide, never passes.
const THIN_END_MM: f64 = 15.0;
const THIN_END_RATIO: f64 = 0.6;
/// How far (mm) a forearm stump's centroid moves between frames at most (an arm at 1 m/s in
/// 30 Hz frames), for the stump's coherence from frame to frame.
const STUMP_MM_PER_FRAME: f64 = 35.0;

/// Largest depth step (mm) across an occluding contour inside the hand (a finger in front of
/// another, the thumb across the palm); the background and the body lie farther behind.
const OCCLUSION_STEP_MM: f64 = 80.0;
/// Largest hole (px) inside the component that [`fill_holes`] fills for the inscribed circles.
const MAX_FILLED_HOLE_PX: usize = 40;
/// Smallest hand part (px) that [`add_occluded_parts`] adds.
const MIN_PART_PIXELS: usize = 20;

/// How far (mm) the palm center may move from the previous frame's and still be preferred.
const PALM_COHERENCE_MM: f64 = 40.0;
/// How large (fraction of the largest) the circle near the previous palm must be to be chosen.
const PALM_COHERENCE_RATIO: f64 = 0.75;

/// Pixels from the image border within which a component pixel is an exit.
const BORDER_PX: usize = 2;
/// Growth steps over runs of fewer than this many invalid (zero) pixels.
const MAX_HOLE_PX: usize = 3;

fn point(depth: &DepthImage, camera: &Camera, i: usize) -> Vector3<f64> {
    let w = depth.width as usize;
    camera.backproject(
        (i % w) as f64,
        (i / w) as f64,
        depth.data[i] as f64 * camera.depth_unit_mm,
    )
}
/// The nearest valid pixel with enough similar-depth support around it (rejects isolated
/// flying pixels and speckle).
fn find_seed(depth: &DepthImage, near: u16, far: u16) -> Option<usize> {
    let (w, h) = (depth.width as i64, depth.height as i64);
    let supported = |i: usize| -> bool {
        let (u, v) = ((i as i64) % w, (i as i64) / w);
        let d0 = depth.data[i] as i64;
        let mut good = 0;
        for dv in -2..=2 {
            for du in -2..=2 {
                let (x, y) = (u + du, v + dv);
                if x >= 0 && y >= 0 && x < w && y < h {
                    let d = depth.data[(y * w + x) as usize] as i64;
                    if d != 0 && (d - d0).abs() < 30 {
                        good += 1;
                    }
                }
            }
        }
        good >= 15
    };
    let mut lo = near;
    while lo <= far {
        let hi = lo.saturating_add(30).min(far);
        let mut best: Option<usize> = None;
        let mut any_above = None::<u16>;
        for (i, &d) in depth.data.iter().enumerate() {
            if d >= lo && d <= hi {
                if best.is_none_or(|b| d < depth.data[b]) && supported(i) {
                    best = Some(i);
                }
            } else if d > hi && d <= far {
                any_above = Some(any_above.map_or(d, |a| a.min(d)));
            }
        }
        if best.is_some() {
            return best;
        }
        lo = any_above?;
    }
    None
}

/// Depth-only segmentation, for sequences without a color image:
/// 1. seed at the nearest supported pixel, 4-connected growth across depth steps below
///    `max_step` inside a sphere of `radius` around the seed; component pixels on the image
///    border or next to a pixel rejected only by the sphere are *exits*, where the arm leaves
///    the view or the volume (the forearm continues to the elbow and body on real data);
/// 2. geodesic distances inside the component from the exits (8-connected, in mm at each
///    pixel's depth), so that the far end of the component is the hand whatever the wrist
///    bend, rotation or fist; without exits, when the component is longer than
///    `max_hand_length`, the last 40 mm of the principal axis at the end farther from the
///    widest inscribed circle (the palm or the fist is wider than the forearm) are taken as the
///    forearm stump — unless that end is the thinner one by far (fingers: a stump shorter than
///    the fingers leaves the palm nearer to it), or, when neither end is, unless the last
///    frame's stump lay at the other end (a structured-light sensor's shadows across the palm
///    left the forearm with the widest circle); otherwise the whole component is the hand;
/// 3. palm center: the largest inscribed circle among pixels within `0.75 max_hand_length`
///    geodesically of the far end (excludes a foreshortened forearm near the exits);
/// 4. forearm cut: the plane perpendicular to the palm→wrist direction (the palm to the
///    centroid of the pixels 30–110 mm geodesically closer to the exits) at
///    `cut_palm_radii` palm radii (within `cut_range`) from the palm center; only pixels
///    geodesically closer to the exits than the palm center are cut, so fingers folded back
///    across the plane are kept; the cut is reported as [`HandSegment::wristband`] (a band at
///    the cut, reach 0), so that the trackers treat it as they treat a band;
/// 5. hand parts that an occlusion separates from the component (a finger whose base hides
///    behind the thumb folded across the palm) are added: regions across a depth step below
///    80 mm, of 20 pixels or more, wholly within 150 mm of the palm and on the hand's side of
///    the cut.
///
/// The growth is repeated with the depth step doubled when the component reaches less than
/// 60 mm from the seed (a thumb tip in front of a fist seen end-on, up to 4 times the
/// step), and once in the volume centered on the palm when the
/// palm lies within 150 mm of the volume's surface (the nearest point, the first
/// center, may lie on a forearm pointing at the camera). The inscribed circles are measured
/// with small holes (up to 40 px) filled. The palm center prefers a circle near the previous
/// frame's (kept in `scratch`: use one scratch per sequence) when it is nearly as large as the
/// largest (a hand turning edge-on).
///
/// Measured (`datasets/tests/depth_segmentation.rs`, 360 frames; before → after the repeated
/// growth, the occluded parts, the filled holes and the palm hint): precision p10 0.883 →
/// 0.938, recall p10 0.910 → 0.946; the worst recall 0.024 → 0.75 (a fist seen end-on: the
/// thumb tip alone). Tracking on it: `eval/tests/depth_only_tracking.rs`.
///
/// An empty segment (count 0) when nothing hand-sized is in range, and when the component is a
/// surface rather than a hand (`Outline::is_surface`): bounded more by the growth volume than
/// by an outline of its own, or by an outline mostly on more of the same surface, nearer and
/// farther alike. Synthetic `leave_reenter` at 60 Hz (the hand out of view for ≈ 5 s, a wall at
/// 1.1 m behind it), frames out of view that a tracker was given a "hand" on, before → after:
/// 323–345 → 0–2 of ≈ 730 under ToF noise and structured light (seeds 8, 9, 10); no frame with
/// the hand wholly in view lost. Allocation-free once the buffers of `out` and `scratch` have
/// grown to the image size.
pub fn segment_depth_only(
    depth: &DepthImage,
    camera: &Camera,
    params: &DepthOnlyParams,
    out: &mut HandSegment,
    scratch: &mut SegmentScratch,
) {
    let Some(seed) = find_seed(depth, params.near, params.far) else {
        out.clear(depth);
        scratch.last_palm = None;
        scratch.last_stump = None;
        return;
    };
    let mut growth = Growth {
        seed,
        center: point(depth, camera, seed),
        max_step: params.max_step,
    };
    let mut recentered = false;
    loop {
        let Some(extent) = segment_pass(depth, camera, params, &growth, out, scratch) else {
            out.clear(depth);
            scratch.last_palm = None;
            scratch.last_stump = None;
            return;
        };
        if extent < MIN_HAND_EXTENT_MM && growth.max_step < MAX_STEP_FACTOR * params.max_step {
            growth.max_step *= 2.0;
            continue;
        }
        match out.palm_center {
            Some(palm)
                if !recentered && (palm - growth.center).norm() > params.radius - HAND_REACH_MM =>
            {
                growth.center = palm;
                recentered = true;
            }
            _ => {
                scratch.last_palm = out.palm_center;
                return;
            }
        }
    }
}

/// Where one pass of [`segment_depth_only`] grows: from `seed` across depth steps below
/// `max_step`, inside the sphere of the parameters' radius around `center`.
struct Growth {
    seed: usize,
    center: Vector3<f64>,
    max_step: f64,
}

/// One pass of [`segment_depth_only`]; returns the component's extent (mm, the largest
/// distance of its points from the seed; 0 when it is too small to count), or `None` when the
/// component is a surface rather than a hand ([`Outline::is_surface`]).
fn segment_pass(
    depth: &DepthImage,
    camera: &Camera,
    params: &DepthOnlyParams,
    growth: &Growth,
    out: &mut HandSegment,
    scratch: &mut SegmentScratch,
) -> Option<f64> {
    let SegmentScratch {
        dt,
        queue,
        inv,
        pixels,
        pts,
        t,
        exits,
        geo,
        region,
        last_palm,
        last_stump,
    } = scratch;
    let (w, h) = (depth.width as usize, depth.height as usize);
    out.clear(depth);
    let seed = growth.seed;
    let seed_p = point(depth, camera, seed);
    let r2 = params.radius * params.radius;
    queue.clear();
    exits.clear();
    queue.push_back(seed);
    out.mask.data[seed] = 1;
    while let Some(i) = queue.pop_front() {
        let (u, v) = (i % w, i / w);
        let d0 = depth.data[i] as f64;
        // Within `BORDER_PX` of the image border: sensors often leave the outermost columns
        // and rows invalid, so the arm "leaves the image" there too.
        let mut exit = u < BORDER_PX || v < BORDER_PX || u + BORDER_PX >= w || v + BORDER_PX >= h;
        for (du, dv) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
            // Step over up to `MAX_HOLE_PX - 1` invalid pixels (structured-light dropouts on
            // fingers and at finger–palm boundaries) to the next valid one.
            for k in 1..=MAX_HOLE_PX as i64 {
                let (x, y) = (u as i64 + k * du, v as i64 + k * dv);
                if x < 0 || y < 0 || x >= w as i64 || y >= h as i64 {
                    exit = true;
                    break;
                }
                let j = y as usize * w + x as usize;
                let d = depth.data[j];
                if d == 0 {
                    continue;
                }
                if out.mask.data[j] != 0
                    || d < params.near
                    || d > params.far
                    || (d as f64 - d0).abs() > growth.max_step
                {
                    break;
                }
                if (point(depth, camera, j) - growth.center).norm_squared() > r2 {
                    exit = true;
                    break;
                }
                out.mask.data[j] = 1;
                queue.push_back(j);
                break;
            }
        }
        if exit {
            exits.push(i);
        }
    }
    pixels.clear();
    pixels.extend((0..w * h).filter(|&i| out.mask.data[i] != 0));
    if pixels.len() < params.min_pixels {
        out.mask.data.iter_mut().for_each(|m| *m = 0);
        return Some(0.0);
    }
    let outline = Outline::of(depth, params, growth.max_step, &out.mask.data, pixels);
    if outline.is_surface() {
        return None;
    }
    // Inscribed radius of every silhouette pixel: distance to the background, computed on the
    // component's bounding box (plus a background border) rather than the whole image.
    let (mut u0, mut v0, mut u1, mut v1) = (w, h, 0, 0);
    for &i in pixels.iter() {
        let (u, v) = (i % w, i / w);
        u0 = u0.min(u);
        v0 = v0.min(v);
        u1 = u1.max(u);
        v1 = v1.max(v);
    }
    let (cw, ch) = (u1 - u0 + 3, v1 - v0 + 3);
    inv.width = cw as u32;
    inv.height = ch as u32;
    inv.data.clear();
    inv.data.resize(cw * ch, 1);
    for &i in pixels.iter() {
        inv.data[(i / w - v0 + 1) * cw + (i % w - u0 + 1)] = 0;
    }
    fill_holes(inv, queue, region);
    dt.compute(inv);
    let dt = &*dt;
    let mm_per_px = |i: usize| depth.data[i] as f64 * camera.depth_unit_mm / camera.fx;
    let radius_mm = |i: usize| {
        let (u, v) = (i % w - u0 + 1, i / w - v0 + 1);
        (dt.dist2[v * cw + u].sqrt() as f64) * mm_per_px(i)
    };
    pts.clear();
    pts.extend(pixels.iter().map(|&i| point(depth, camera, i)));
    let extent = pts.iter().map(|p| (p - seed_p).norm()).fold(0.0, f64::max);
    let had_stump = last_stump.take();
    if exits.is_empty() {
        // No exit: the whole arm part is in view and in range. Short: a hand alone; long: a
        // forearm stump, at the end of the principal axis farther from the widest inscribed
        // circle (the palm or the fist is wider than the forearm).
        let n = pts.len() as f64;
        let mean = pts.iter().sum::<Vector3<f64>>() / n;
        let cov = pts
            .iter()
            .map(|p| (p - mean) * (p - mean).transpose())
            .sum::<Matrix3<f64>>()
            / n;
        let eig = SymmetricEigen::new(cov);
        let axis = eig.eigenvectors.column(eig.eigenvalues.imax()).into_owned();
        t.clear();
        t.extend(pts.iter().map(|p| (p - mean).dot(&axis)));
        let (t_min, t_max) = t
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        if t_max - t_min > params.max_hand_length {
            let widest = (0..pixels.len())
                .max_by(|&a, &b| radius_mm(pixels[a]).total_cmp(&radius_mm(pixels[b])))
                .unwrap_or(0);
            // Whether `x` along the axis lies in the last 40 mm of the high or the low end.
            let at_end = |hi: bool, x: f64| {
                if hi {
                    x > t_max - STUMP_MM
                } else {
                    x < t_min + STUMP_MM
                }
            };
            // The widest inscribed circle of each end.
            let end_width = |hi: bool| {
                pixels
                    .iter()
                    .zip(t.iter())
                    .filter(|&(_, &x)| at_end(hi, x))
                    .map(|(&i, _)| radius_mm(i))
                    .fold(0.0, f64::max)
            };
            let mut stump_hi = t[widest] - t_min < t_max - t[widest];
            let thin = |far: f64, near: f64| far < THIN_END_MM && far < THIN_END_RATIO * near;
            let (far, near) = (end_width(stump_hi), end_width(!stump_hi));
            let ends = [false, true].map(|hi| end_centroid(pts, t, at_end, hi));
            let coherent =
                had_stump.map(|last| ends.map(|c| (c - last).norm() <= STUMP_MM_PER_FRAME));
            if thin(far, near) {
                // A short stump leaves the palm nearer to it than to the fingertips: the end
                // farther from the palm is then the fingers, far thinner than a forearm.
                stump_hi = !stump_hi;
            } else if thin(near, far) {
                // The other end is the fingers: the widest circle chose well.
            } else if let Some([lo, hi]) = coherent.filter(|[lo, hi]| lo != hi) {
                // The palm and the forearm are about as wide (a structured-light sensor's
                // shadows across the palm made the widest circle jump to the forearm): the arm
                // moves little between frames, so the stump is the end where the last one was.
                stump_hi = hi && !lo;
            }
            *last_stump = Some(ends[usize::from(stump_hi)]);
            exits.extend(
                pixels
                    .iter()
                    .zip(t.iter())
                    .filter_map(|(&i, &x)| at_end(stump_hi, x).then_some(i)),
            );
        }
    }
    let palm_k;
    if exits.is_empty() {
        // A hand alone: the largest inscribed circle, no cut.
        (palm_k, _) = pick_palm(
            (0..pixels.len()).map(|k| (k, radius_mm(pixels[k]))),
            pts,
            *last_palm,
        );
    } else {
        // Geodesic distance from the exits (label-correcting BFS, 8-connected).
        // Only component pixels are read: reset those.
        geo.resize(w * h, f32::INFINITY);
        for &i in pixels.iter() {
            geo[i] = f32::INFINITY;
        }
        queue.clear();
        for &i in exits.iter() {
            if geo[i] != 0.0 {
                geo[i] = 0.0;
                queue.push_back(i);
            }
        }
        while let Some(i) = queue.pop_front() {
            let (u, v) = ((i % w) as i64, (i / w) as i64);
            let step = mm_per_px(i) as f32;
            for (du, dv, f) in [
                (-1i64, 0i64, 1.0f32),
                (1, 0, 1.0),
                (0, -1, 1.0),
                (0, 1, 1.0),
                (-1, -1, std::f32::consts::SQRT_2),
                (1, -1, std::f32::consts::SQRT_2),
                (-1, 1, std::f32::consts::SQRT_2),
                (1, 1, std::f32::consts::SQRT_2),
            ] {
                // Across the same holes as the growth.
                for k in 1..=MAX_HOLE_PX as i64 {
                    let (x, y) = (u + k * du, v + k * dv);
                    if x < 0 || y < 0 || x >= w as i64 || y >= h as i64 {
                        break;
                    }
                    let j = y as usize * w + x as usize;
                    if out.mask.data[j] == 0 {
                        if depth.data[j] == 0 {
                            continue;
                        }
                        break;
                    }
                    let g = geo[i] + step * f * k as f32;
                    if g < geo[j] {
                        geo[j] = g;
                        queue.push_back(j);
                    }
                    break;
                }
            }
        }
        let far_end = pixels
            .iter()
            .map(|&i| geo[i])
            .filter(|g| g.is_finite())
            .fold(0.0f32, f32::max) as f64;
        let reach = 0.75 * params.max_hand_length;
        let palm_r;
        (palm_k, palm_r) = pick_palm(
            (0..pixels.len())
                .filter(|&k| geo[pixels[k]].is_finite() && geo[pixels[k]] as f64 >= far_end - reach)
                .map(|k| (k, radius_mm(pixels[k]))),
            pts,
            *last_palm,
        );
        let palm = pts[palm_k];
        let g_palm = geo[pixels[palm_k]] as f64;
        // Toward the wrist: the pixels 30–110 mm geodesically closer to the exits than the
        // palm center, or the exits themselves when the palm is that close to them.
        let (mut sum, mut n) = (Vector3::zeros(), 0usize);
        for (k, &i) in pixels.iter().enumerate() {
            let dg = g_palm - geo[i] as f64;
            if (30.0..=110.0).contains(&dg) {
                sum += pts[k];
                n += 1;
            }
        }
        if n == 0 {
            for &i in exits.iter() {
                sum += point(depth, camera, i);
                n += 1;
            }
        }
        let to_wrist = sum / n as f64 - palm;
        if to_wrist.norm() > 1e-6 {
            let dir = to_wrist.normalize();
            let cut =
                (params.cut_palm_radii * palm_r).clamp(params.cut_range[0], params.cut_range[1]);
            let (mut section, mut n_section) = (Vector3::zeros(), 0usize);
            for (k, &i) in pixels.iter().enumerate() {
                if (geo[i] as f64) >= g_palm {
                    continue;
                }
                let along = (pts[k] - palm).dot(&dir);
                if along > cut {
                    out.mask.data[i] = 0;
                }
                if (along - cut).abs() <= SECTION_HALF_WIDTH_MM {
                    section += pts[k];
                    n_section += 1;
                }
            }
            // The cut stands in for a wristband: the wrist term gets the forearm's line and
            // the model's wrist beyond the cut is not evidence against the model.
            out.wristband = Some(Wristband {
                center: if n_section > 0 {
                    section / n_section as f64
                } else {
                    palm + dir * cut
                },
                axis: -dir,
                reach: 0.0,
            });
        }
    }
    let palm = pts[palm_k];
    out.palm_center = Some(palm);
    add_occluded_parts(
        depth,
        camera,
        growth.max_step,
        palm,
        out,
        pixels,
        queue,
        region,
    );
    out.count = out.mask.count();
    Some(extent)
}

/// The 4-neighbours of pixel `i` in a `w × h` image.
fn neighbours4(i: usize, w: usize, h: usize) -> impl Iterator<Item = usize> {
    let (u, v) = (i % w, i / w);
    [
        (u > 0).then(|| i - 1),
        (u + 1 < w).then(|| i + 1),
        (v > 0).then(|| i - w),
        (v + 1 < h).then(|| i + w),
    ]
    .into_iter()
    .flatten()
}

/// Breadth-first flood of the `w × h` image `mask` from `start`: `start` and every pixel `k`
/// 4-connected to a flooded pixel `j` with `enters(mask[k], j, k)` are marked `mark` and handed
/// to `visit` in flooding order.
pub(super) fn flood(
    mask: &mut [u8],
    (w, h): (usize, usize),
    start: usize,
    mark: u8,
    queue: &mut VecDeque<usize>,
    enters: impl Fn(u8, usize, usize) -> bool,
    mut visit: impl FnMut(usize),
) {
    queue.clear();
    queue.push_back(start);
    mask[start] = mark;
    while let Some(j) = queue.pop_front() {
        visit(j);
        for k in neighbours4(j, w, h) {
            if enters(mask[k], j, k) {
                mask[k] = mark;
                queue.push_back(k);
            }
        }
    }
}

/// The centroid of the points in the last [`STUMP_MM`] of the principal axis at its high (`hi`)
/// or low end (`at_end`), `t` the points' positions along the axis.
fn end_centroid(
    pts: &[Vector3<f64>],
    t: &[f64],
    at_end: impl Fn(bool, f64) -> bool,
    hi: bool,
) -> Vector3<f64> {
    let (sum, n) = pts
        .iter()
        .zip(t)
        .filter(|&(_, &x)| at_end(hi, x))
        .fold((Vector3::zeros(), 0usize), |(s, n), (p, _)| (s + p, n + 1));
    sum / n.max(1) as f64
}

/// Turn the small holes of `inv` (background pixels, nonzero, that the background around the
/// component does not reach; zero = the component) into component pixels: the inscribed
/// circles are measured to the silhouette's outline, not to speckle inside it — flying pixels
/// at a fist's inner occluding contours punch holes that shrank the fist's circles below the
/// forearm's, and the palm was placed on the forearm. Holes larger than
/// [`MAX_FILLED_HOLE_PX`] (a gap enclosed by curled fingers) stay. `inv` has a background
/// border, where the flood starts.
fn fill_holes(inv: &mut Mask, queue: &mut VecDeque<usize>, hole: &mut Vec<usize>) {
    const OUTSIDE: u8 = 2;
    const HOLE: u8 = 3;
    let (w, h) = (inv.width as usize, inv.height as usize);
    let data = &mut inv.data;
    let background = |m: u8, _: usize, _: usize| m == 1;
    flood(data, (w, h), 0, OUTSIDE, queue, background, |_| {});
    for start in 0..data.len() {
        if data[start] == 1 {
            hole.clear();
            flood(data, (w, h), start, HOLE, queue, background, |i| {
                hole.push(i)
            });
            if hole.len() <= MAX_FILLED_HOLE_PX {
                hole.iter().for_each(|&i| data[i] = 0);
            }
        }
    }
    for m in data.iter_mut() {
        *m = u8::from(*m != 0);
    }
}

/// The palm center among `candidates` (point index, inscribed radius in mm): the largest
/// inscribed circle, unless the previous frame's palm `last` has a circle within
/// [`PALM_COHERENCE_MM`] at least [`PALM_COHERENCE_RATIO`] as large — a hand turning edge-on
/// shows a palm barely wider than its bunched fingers, and the largest circle then jumped to the
/// fingers and the forearm cut through the palm. `(0, 0.0)` when there is no candidate.
fn pick_palm(
    candidates: impl Iterator<Item = (usize, f64)>,
    pts: &[Vector3<f64>],
    last: Option<Vector3<f64>>,
) -> (usize, f64) {
    let (mut best, mut near) = ((0, f64::NEG_INFINITY), (0, f64::NEG_INFINITY));
    for (k, r) in candidates {
        if r > best.1 {
            best = (k, r);
        }
        if r > near.1 && last.is_some_and(|p| (pts[k] - p).norm() <= PALM_COHERENCE_MM) {
            near = (k, r);
        }
    }
    let chosen = if near.1 >= PALM_COHERENCE_RATIO * best.1 {
        near
    } else {
        best
    };
    (chosen.0, chosen.1.max(0.0))
}

/// Mask value of a pixel visited by [`add_occluded_parts`] and not taken.
const VISITED: u8 = 2;

/// Add the hand's parts that an occlusion separates from the grown component — a finger whose
/// base hides behind the thumb folded across the palm: the growth does not cross the depth
/// step at the occluding contour. A region next to the silhouette across a step below
/// [`OCCLUSION_STEP_MM`], itself grown across steps below `max_step`, is added when it has at
/// least [`MIN_PART_PIXELS`] pixels and lies wholly within [`HAND_REACH_MM`] of the palm center
/// and on the hand's side of the forearm cut (the background, the body and the forearm reach
/// beyond; flying pixels and speckle are smaller).
#[allow(clippy::too_many_arguments)]
fn add_occluded_parts(
    depth: &DepthImage,
    camera: &Camera,
    max_step: f64,
    palm: Vector3<f64>,
    out: &mut HandSegment,
    pixels: &[usize],
    queue: &mut VecDeque<usize>,
    region: &mut Vec<usize>,
) {
    let (w, h) = (depth.width as usize, depth.height as usize);
    let reach2 = HAND_REACH_MM * HAND_REACH_MM;
    let band = out.wristband;
    let on_hand = |j: usize| {
        let p = point(depth, camera, j);
        (p - palm).norm_squared() <= reach2 && !band.is_some_and(|b| b.hides(&p))
    };
    let mask = &mut out.mask.data;
    for &i in pixels {
        if mask[i] != 1 {
            continue;
        }
        for s in neighbours4(i, w, h) {
            let (d0, d) = (depth.data[i] as f64, depth.data[s]);
            if mask[s] != 0 || d == 0 || (d as f64 - d0).abs() > OCCLUSION_STEP_MM {
                continue;
            }
            // Grow the whole region from `s` (each pixel is visited once over all regions, so
            // a refused region cannot be entered again from another of its pixels).
            region.clear();
            let mut inside = true;
            let surface = |m: u8, j: usize, k: usize| {
                let (dj, dk) = (depth.data[j] as f64, depth.data[k]);
                m == 0 && dk != 0 && (dk as f64 - dj).abs() <= max_step
            };
            flood(mask, (w, h), s, VISITED, queue, surface, |j| {
                if inside {
                    inside = on_hand(j);
                    region.push(j);
                }
            });
            if inside && region.len() >= MIN_PART_PIXELS {
                region.iter().for_each(|&j| mask[j] = 1);
            }
        }
    }
    mask.iter_mut()
        .filter(|m| **m == VISITED)
        .for_each(|m| *m = 0);
}

/// Parameters of the wristband segmentation (ANCHOR-FACTS §5.6; OpenCV HSV ranges).
#[derive(Clone, Debug)]
pub struct WristbandParams {
    /// Hue range of the band, OpenCV scale [0, 180).
    pub hue: [u8; 2],
    /// Saturation range.
    pub saturation: [u8; 2],
    /// Value range.
    pub value: [u8; 2],
    /// Half-width of the depth slab around the band (mm).
    pub depth_range: f64,
    /// Radius of the crop sphere (mm).
    pub crop_radius: f64,
    /// Crop sphere center offset from the band center along the axis (mm): 150 − 10 in hmodel.
    pub crop_offset: f64,
    /// Minimum band size (px).
    pub min_band_pixels: usize,
}

impl Default for WristbandParams {
    fn default() -> Self {
        Self {
            hue: [94, 120],
            saturation: [111, 255],
            value: [37, 255],
            depth_range: 150.0,
            crop_radius: 150.0,
            crop_offset: 140.0,
            min_band_pixels: 40,
        }
    }
}

/// RGB → OpenCV 8-bit HSV (H in [0, 180), S and V in [0, 255]).
pub fn rgb_to_hsv(rgb: [u8; 3]) -> [u8; 3] {
    let [r, g, b] = rgb.map(|c| c as f64);
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    let delta = max - min;
    let s = if max > 0.0 { 255.0 * delta / max } else { 0.0 };
    let mut hdeg = if delta == 0.0 {
        0.0
    } else if max == r {
        60.0 * (g - b) / delta
    } else if max == g {
        120.0 + 60.0 * (b - r) / delta
    } else {
        240.0 + 60.0 * (r - g) / delta
    };
    if hdeg < 0.0 {
        hdeg += 360.0;
    }
    [
        ((hdeg / 2.0).round() as u32 % 180) as u8,
        s.round() as u8,
        max as u8,
    ]
}

/// Wristband segmentation (Fig. 2.5): band pixels by HSV threshold, the largest 4-connected band
/// component, the depth slab around the band's mean depth, the forearm axis as the principal
/// direction of slab points within 100 mm of the band center (oriented toward the hand), and the
/// crop sphere ahead of the band. Band pixels themselves are excluded from the silhouette.
/// A color image of another size than the depth image's (or an image whose buffer does not
/// hold its size) finds no hand.
pub fn segment_wristband(
    depth: &DepthImage,
    color: &ColorImage,
    camera: &Camera,
    params: &WristbandParams,
    out: &mut HandSegment,
) {
    let (w, h) = (depth.width as usize, depth.height as usize);
    out.mask = Mask::zeros(depth.width, depth.height);
    out.count = 0;
    out.palm_center = None;
    out.wristband = None;
    if color.width != depth.width
        || color.height != depth.height
        || color.data.len() != 3 * w * h
        || depth.data.len() != w * h
    {
        return;
    }
    let in_range = |v: u8, r: [u8; 2]| v >= r[0] && v <= r[1];
    let is_band = |rgb: [u8; 3]| {
        let [hh, s, v] = rgb_to_hsv(rgb);
        in_range(hh, params.hue) && in_range(s, params.saturation) && in_range(v, params.value)
    };
    // Neighbouring pixels often share their color (flat regions, saturated areas): the test of
    // the previous pixel is reused for an equal color rather than converted again.
    let mut last = None;
    let band: Vec<bool> = color
        .data
        .chunks_exact(3)
        .map(|c| {
            let rgb = [c[0], c[1], c[2]];
            match last {
                Some((previous, answer)) if previous == rgb => answer,
                _ => {
                    let answer = is_band(rgb);
                    last = Some((rgb, answer));
                    answer
                }
            }
        })
        .collect();
    // Largest 4-connected band component.
    let mut label = vec![0u32; w * h];
    let (mut best_label, mut best_size, mut next) = (0u32, 0usize, 1u32);
    let mut stack = Vec::new();
    for s in 0..w * h {
        if !band[s] || label[s] != 0 {
            continue;
        }
        let mut size = 0;
        stack.push(s);
        label[s] = next;
        while let Some(i) = stack.pop() {
            size += 1;
            for j in neighbours4(i, w, h) {
                if band[j] && label[j] == 0 {
                    label[j] = next;
                    stack.push(j);
                }
            }
        }
        if size > best_size {
            best_size = size;
            best_label = next;
        }
        next += 1;
    }
    if best_size < params.min_band_pixels {
        return;
    }
    let band_px: Vec<usize> = (0..w * h)
        .filter(|&i| label[i] == best_label && depth.data[i] != 0)
        .collect();
    if band_px.is_empty() {
        return;
    }
    let center = band_px
        .iter()
        .map(|&i| point(depth, camera, i))
        .sum::<Vector3<f64>>()
        / band_px.len() as f64;
    let wrist_depth = center.z;
    let slab = |i: usize| {
        depth.data[i] != 0 && ((depth.data[i] as f64) - wrist_depth).abs() <= params.depth_range
    };
    let mut cov = Matrix3::zeros();
    let mut mean = Vector3::zeros();
    let mut n = 0.0;
    for i in (0..w * h).filter(|&i| slab(i)) {
        let p = point(depth, camera, i);
        if (p - center).norm() < 100.0 {
            mean += p;
            cov += p * p.transpose();
            n += 1.0;
        }
    }
    if n < 3.0 {
        return;
    }
    mean /= n;
    cov = cov / n - mean * mean.transpose();
    let eig = SymmetricEigen::new(cov);
    let k = eig.eigenvalues.imax();
    let mut dir = eig.eigenvectors.column(k).into_owned().normalize();
    // Orient toward the hand: the side holding more non-band slab points.
    let balance: f64 = (0..w * h)
        .filter(|&i| slab(i) && label[i] != best_label)
        .map(|i| (point(depth, camera, i) - center).dot(&dir).signum())
        .sum();
    if balance < 0.0 {
        dir = -dir;
    }
    let mut along: Vec<f64> = band_px
        .iter()
        .map(|&i| (point(depth, camera, i) - center).dot(&dir))
        .collect();
    along.sort_by(f64::total_cmp);
    let reach = along[(along.len() - 1) * 98 / 100].max(0.0);
    let crop_c = center + dir * params.crop_offset;
    let r2 = params.crop_radius * params.crop_radius;
    for (i, &l) in label.iter().enumerate() {
        if slab(i)
            && l != best_label
            && (point(depth, camera, i) - crop_c).norm_squared() <= r2
            && (point(depth, camera, i) - center).dot(&dir) > 0.0
        {
            out.mask.data[i] = 1;
        }
    }
    out.count = out.mask.count();
    out.wristband = Some(Wristband {
        center,
        axis: dir,
        reach,
    });
    if out.count > 0 {
        let c = (0..w * h)
            .filter(|&i| out.mask.data[i] != 0)
            .map(|i| point(depth, camera, i))
            .sum::<Vector3<f64>>()
            / out.count as f64;
        out.palm_center = Some(c);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An arm at 400 mm across the frame with a blue band around its middle, and its color
    /// image.
    fn banded_arm() -> (DepthImage, ColorImage) {
        let camera = Camera::sr300_qvga();
        let (w, h) = (camera.width, camera.height);
        let mut depth = DepthImage::zeros(w, h);
        let mut color = ColorImage::zeros(w, h);
        for v in 100..140 {
            for u in 40..280 {
                depth.data[(v * w + u) as usize] = 400;
                let rgb = if (150..165).contains(&u) {
                    [30, 60, 200]
                } else {
                    [200, 150, 120]
                };
                let i = 3 * (v * w + u) as usize;
                color.data[i..i + 3].copy_from_slice(&rgb);
            }
        }
        (depth, color)
    }

    #[test]
    fn the_band_is_found_and_a_color_buffer_of_the_wrong_size_finds_nothing() {
        let (depth, mut color) = banded_arm();
        let segment = |color: &ColorImage| {
            let mut out = HandSegment::default();
            let params = WristbandParams::default();
            segment_wristband(&depth, color, &Camera::sr300_qvga(), &params, &mut out);
            (out.wristband.is_some(), out.count)
        };
        let (band, count) = segment(&color);
        assert!(band && count > 0, "band {band}, {count} px");
        color.data.truncate(color.data.len() - 3);
        assert_eq!(segment(&color), (false, 0));
    }

    /// Five candidate circles along x: the largest at 100 mm, one of 0.8 of its radius at 0.
    fn candidates() -> (Vec<Vector3<f64>>, Vec<(usize, f64)>) {
        let pts = (0..5)
            .map(|i| Vector3::new(25.0 * i as f64, 0.0, 400.0))
            .collect();
        (pts, vec![(0, 8.0), (1, 5.0), (2, 6.0), (3, 7.0), (4, 10.0)])
    }

    #[test]
    fn palm_is_the_largest_circle_without_a_hint() {
        let (pts, c) = candidates();
        assert_eq!(pick_palm(c.into_iter(), &pts, None), (4, 10.0));
        assert_eq!(pick_palm(std::iter::empty(), &pts, None), (0, 0.0));
    }

    #[test]
    fn palm_stays_near_the_previous_one_when_nearly_as_large() {
        let (pts, c) = candidates();
        let near_first = Some(Vector3::new(5.0, 0.0, 400.0));
        assert_eq!(pick_palm(c.clone().into_iter(), &pts, near_first), (0, 8.0));
        // A circle near the hint that is too small loses to the largest.
        let near_second = Some(Vector3::new(50.0, 0.0, 400.0));
        assert_eq!(pick_palm(c.into_iter(), &pts, near_second), (4, 10.0));
    }

    /// A flat shape at depth `z` (mm) facing the camera: the pixels whose ray meets the plane
    /// at a point `(x, y)` that `inside` holds.
    fn flat_depth(camera: &Camera, z: f64, inside: impl Fn(f64, f64) -> bool) -> DepthImage {
        let (w, h) = (camera.width, camera.height);
        let mut depth = DepthImage::zeros(w, h);
        for v in 0..h {
            for u in 0..w {
                let p = camera.backproject(u as f64, v as f64, z);
                if inside(p.x, p.y) {
                    depth.data[(v * w + u) as usize] = z as u16;
                }
            }
        }
        depth
    }

    /// A flat hand at 400 mm, fingers up: a palm disc (45 mm), four 16 × 95 mm fingers, and a
    /// forearm stump 60 mm wide and 70 mm long, shorter than the fingers reach from the palm.
    #[test]
    fn a_short_forearm_stump_is_cut_and_the_fingers_kept() {
        let camera = Camera::sr300_qvga();
        let w = camera.width;
        let z = 400.0;
        let inside = |x: f64, y: f64| {
            let palm = x * x + y * y < 45.0 * 45.0;
            let finger = (y < -30.0 && y > -140.0)
                && [-33.0, -11.0, 11.0, 33.0]
                    .iter()
                    .any(|&c| (x - c).abs() < 8.0);
            let stump = y > 30.0 && y < 115.0 && x.abs() < 30.0;
            palm || finger || stump
        };
        let depth = flat_depth(&camera, z, inside);
        let (mut out, mut scratch) = (HandSegment::default(), SegmentScratch::default());
        segment_depth_only(
            &depth,
            &camera,
            &DepthOnlyParams::default(),
            &mut out,
            &mut scratch,
        );
        let pixel = |x: f64, y: f64| {
            let q = camera.project(&Vector3::new(x, y, z));
            (q.y.round() as u32 * w + q.x.round() as u32) as usize
        };
        for c in [-33.0, -11.0, 11.0, 33.0] {
            assert_eq!(
                out.mask.data[pixel(c, -135.0)],
                1,
                "fingertip at x = {c} kept"
            );
        }
        assert_eq!(
            out.mask.data[pixel(0.0, 110.0)],
            0,
            "the stump's end is cut"
        );
        assert_eq!(out.mask.data[pixel(0.0, 0.0)], 1);
    }

    /// The flat hand of [`a_short_forearm_stump_is_cut_and_the_fingers_kept`] at 400 mm.
    fn flat_hand(x: f64, y: f64) -> bool {
        let palm = x * x + y * y < 45.0 * 45.0;
        let finger = (y < -30.0 && y > -140.0)
            && [-33.0, -11.0, 11.0, 33.0]
                .iter()
                .any(|&c| (x - c).abs() < 8.0);
        palm || finger || (y > 30.0 && x.abs() < 30.0)
    }

    /// A wall at 1100 mm behind everything, with ToF-like noise of `sigma` mm (Gaussian by
    /// Box–Muller, seeded).
    fn wall_behind(depth: &mut DepthImage, sigma: f64, seed: u64) {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        for d in depth.data.iter_mut().filter(|d| **d == 0) {
            let (a, b): (f64, f64) = (rng.random(), rng.random());
            let gauss = (-2.0 * (1.0 - a).ln()).sqrt() * (std::f64::consts::TAU * b).cos();
            *d = (1100.0 + sigma * gauss).round() as u16;
        }
    }

    fn segment(depth: &DepthImage, camera: &Camera) -> HandSegment {
        let (mut out, mut scratch) = (HandSegment::default(), SegmentScratch::default());
        let params = DepthOnlyParams::default();
        segment_depth_only(depth, camera, &params, &mut out, &mut scratch);
        out
    }

    /// With no hand in view the nearest surface is a wall: exact, its patch is bounded by the
    /// growth volume alone; under noise whose neighbouring depths differ by more than the
    /// growth's step, its patches are bounded by more wall (low separation). Neither is a hand.
    /// A hand in front of the same walls is found, and so is one holding a ball wider than any
    /// palm (its outline stands clear of the wall).
    #[test]
    fn a_wall_is_not_a_hand_and_a_hand_before_it_is() {
        let camera = Camera::sr300_qvga();
        // 35 mm in front of an exact wall: beyond the growth's step, within twice it.
        let mut close = flat_depth(&camera, 400.0, flat_hand);
        let hand_pixels = close.data.iter().filter(|&&d| d > 0).count();
        close
            .data
            .iter_mut()
            .filter(|d| **d == 0)
            .for_each(|d| *d = 435);
        let found = segment(&close, &camera);
        assert!(found.count > hand_pixels / 2, "hand 35 mm before a wall");
        for (sigma, seed) in [(0.0, 1), (20.0, 2), (20.0, 3), (30.0, 4)] {
            let mut wall = DepthImage::zeros(camera.width, camera.height);
            wall_behind(&mut wall, sigma, seed);
            assert_eq!(
                segment(&wall, &camera).count,
                0,
                "wall with noise σ = {sigma} mm"
            );
            let ball = |x: f64, y: f64| (x - 60.0).powi(2) + (y + 40.0).powi(2) < 110.0 * 110.0;
            for (name, shape) in [
                ("hand", &flat_hand as &dyn Fn(f64, f64) -> bool),
                ("hand with a ball", &|x, y| flat_hand(x, y) || ball(x, y)),
            ] {
                let mut hand = flat_depth(&camera, 400.0, shape);
                let hand_pixels = hand.data.iter().filter(|&&d| d > 0).count();
                wall_behind(&mut hand, sigma, seed);
                let found = segment(&hand, &camera);
                assert!(
                    found.count > hand_pixels / 2 && found.palm_center.is_some(),
                    "{name} before a wall with noise σ = {sigma} mm: {} of {hand_pixels} pixels",
                    found.count
                );
            }
        }
    }

    /// A flat arm at 500 mm whose far end is a fist's knuckle block (not thin), its palm cut
    /// by two 1-px dropout lines (a structured-light shadow) in the second frame, which leaves
    /// the forearm with the widest inscribed circle: the stump stays where the first frame,
    /// with an intact palm, put it.
    #[test]
    fn the_stump_stays_at_the_forearm_when_shadows_cut_the_palm() {
        let camera = Camera::sr300_qvga();
        let w = camera.width;
        let z = 500.0;
        let frame = |shadows: bool| {
            let inside = |x: f64, y: f64| {
                let palm = x * x + y * y < 45.0 * 45.0;
                let knuckles = x.abs() < 30.0 && y < -20.0 && y > -95.0;
                let forearm = x.abs() < 34.0 && y > 30.0 && y < 160.0;
                let shadow = shadows && ((y + 15.0).abs() < 1.2 || (y - 15.0).abs() < 1.2);
                (palm || knuckles || forearm) && !shadow
            };
            flat_depth(&camera, z, inside)
        };
        let pixel = |x: f64, y: f64| {
            let q = camera.project(&Vector3::new(x, y, z));
            (q.y.round() as u32 * w + q.x.round() as u32) as usize
        };
        let segment = |depth: &DepthImage, scratch: &mut SegmentScratch| {
            let mut out = HandSegment::default();
            segment_depth_only(
                depth,
                &camera,
                &DepthOnlyParams::default(),
                &mut out,
                scratch,
            );
            let kept = |x, y| out.mask.data[pixel(x, y)] == 1;
            (kept(0.0, -90.0), kept(0.0, 155.0))
        };
        let (intact, shadowed) = (frame(false), frame(true));
        // Alone, the shadowed frame takes the knuckles for the stump.
        assert_eq!(
            segment(&shadowed, &mut SegmentScratch::default()),
            (false, true)
        );
        let mut scratch = SegmentScratch::default();
        assert_eq!(
            segment(&intact, &mut scratch),
            (true, false),
            "knuckles kept"
        );
        assert_eq!(
            segment(&shadowed, &mut scratch),
            (true, false),
            "knuckles still kept"
        );
    }

    #[test]
    fn small_holes_are_filled_and_large_ones_kept() {
        // A 12 × 12 background frame around a component with a 1-px hole and a 7 × 7 hole.
        let (w, h) = (12usize, 12usize);
        let mut inv = Mask::zeros(w as u32, h as u32);
        for v in 0..h {
            for u in 0..w {
                let border = u == 0 || v == 0 || u == w - 1 || v == h - 1;
                let big_hole = (3..10).contains(&u) && (3..10).contains(&v);
                inv.data[v * w + u] = u8::from(border || big_hole);
            }
        }
        inv.data[2 * w + 2] = 1; // the 1-px hole
        let (mut queue, mut hole) = (VecDeque::new(), Vec::new());
        fill_holes(&mut inv, &mut queue, &mut hole);
        assert_eq!(inv.data[2 * w + 2], 0, "the 1-px hole is filled");
        assert_eq!(inv.data[5 * w + 5], 1, "the 49-px hole stays background");
        assert_eq!(inv.data[0], 1);
    }
}
