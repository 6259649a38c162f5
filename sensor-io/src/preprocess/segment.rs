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
    /// The wristband (wristband segmentation only); used by the wrist term of Eq. 2.4 and to
    /// tell where the silhouette was cut.
    pub wristband: Option<Wristband>,
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
/// the buffers have grown to the image size.
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
///    bend, rotation or fist; without exits, the end of the principal axis whose last 40 mm
///    hold the wider inscribed circle is taken as the forearm stump when the component is
///    longer than `max_hand_length`, and otherwise the whole component is the hand;
/// 3. palm center: the largest inscribed circle among pixels within `0.75 max_hand_length`
///    geodesically of the far end (excludes a foreshortened forearm near the exits);
/// 4. forearm cut: the plane perpendicular to the palm→wrist direction (the palm to the
///    centroid of the pixels 30–110 mm geodesically closer to the exits) at
///    `cut_palm_radii` palm radii (within `cut_range`) from the palm center; only pixels
///    geodesically closer to the exits than the palm center are cut, so fingers folded back
///    across the plane are kept.
///
/// An empty segment (count 0) when nothing hand-sized is in range. Allocation-free once the
/// buffers of `out` and `scratch` have grown to the image size.
pub fn segment_depth_only(
    depth: &DepthImage,
    camera: &Camera,
    params: &DepthOnlyParams,
    out: &mut HandSegment,
    scratch: &mut SegmentScratch,
) {
    let SegmentScratch {
        dt,
        queue,
        inv,
        pixels,
        pts,
        t,
        exits,
        geo,
    } = scratch;
    let (w, h) = (depth.width as usize, depth.height as usize);
    out.mask.width = depth.width;
    out.mask.height = depth.height;
    out.mask.data.clear();
    out.mask.data.resize(w * h, 0);
    out.count = 0;
    out.palm_center = None;
    out.wristband = None;
    let Some(seed) = find_seed(depth, params.near, params.far) else {
        return;
    };
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
                    || (d as f64 - d0).abs() > params.max_step
                {
                    break;
                }
                if (point(depth, camera, j) - seed_p).norm_squared() > r2 {
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
        return;
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
    dt.compute(inv);
    let dt = &*dt;
    let mm_per_px = |i: usize| depth.data[i] as f64 * camera.depth_unit_mm / camera.fx;
    let radius_mm = |i: usize| {
        let (u, v) = (i % w - u0 + 1, i / w - v0 + 1);
        (dt.dist2[v * cw + u].sqrt() as f64) * mm_per_px(i)
    };
    pts.clear();
    pts.extend(pixels.iter().map(|&i| point(depth, camera, i)));
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
            let stump_hi = t[widest] - t_min < t_max - t[widest];
            exits.extend(pixels.iter().zip(t.iter()).filter_map(|(&i, &x)| {
                let stump = if stump_hi {
                    x > t_max - 40.0
                } else {
                    x < t_min + 40.0
                };
                stump.then_some(i)
            }));
        }
    }
    let palm_k;
    let mut palm_r = 0.0;
    if exits.is_empty() {
        // A hand alone: the largest inscribed circle, no cut.
        palm_k = (0..pixels.len())
            .map(|k| (k, radius_mm(pixels[k])))
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map_or(0, |(k, r)| {
                palm_r = r;
                k
            });
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
        palm_k = (0..pixels.len())
            .filter(|&k| geo[pixels[k]].is_finite() && geo[pixels[k]] as f64 >= far_end - reach)
            .map(|k| (k, radius_mm(pixels[k])))
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map_or(0, |(k, r)| {
                palm_r = r;
                k
            });
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
            for (k, &i) in pixels.iter().enumerate() {
                if (geo[i] as f64) < g_palm && (pts[k] - palm).dot(&dir) > cut {
                    out.mask.data[i] = 0;
                }
            }
        }
    }
    out.count = out.mask.count();
    out.palm_center = Some(pts[palm_k]);
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
    if color.width != depth.width || color.height != depth.height {
        return;
    }
    let in_range = |v: u8, r: [u8; 2]| v >= r[0] && v <= r[1];
    let band: Vec<bool> = (0..w * h)
        .map(|i| {
            let [hh, s, v] = rgb_to_hsv(color.get((i % w) as u32, (i / w) as u32));
            in_range(hh, params.hue) && in_range(s, params.saturation) && in_range(v, params.value)
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
            let (u, v) = (i % w, i / w);
            let nbrs = [
                (u > 0).then(|| i - 1),
                (u + 1 < w).then(|| i + 1),
                (v > 0).then(|| i - w),
                (v + 1 < h).then(|| i + w),
            ];
            for j in nbrs.into_iter().flatten() {
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
