//! A CPU rasterizer of the posed cylinder model: the rendered silhouette `S_r` of thesis Eq. 2.3
//! (§2.3.1 "2D correspondences": "rendering the hand model from the viewpoint of the sensor,
//! caching the bone identifier and the 3D location associated with each pixel in a texture").
//!
//! htrack draws the cylinders with OpenGL into a joint-id texture and a camera-space xyz texture
//! (ANCHOR-FACTS §5.4). Here every pixel's ray through its center (pinhole
//! [`Intrinsics`], DESIGN.md camera frame, y down) is cast exactly against the segments
//! ([`Segment::cast_local_ray`](super::Segment::cast_local_ray): closed-form caps, root-isolated side, see [`super::raycast`]),
//! and the first hit is kept, with its segment and the camera-frame surface point. Each segment
//! only scans its projected bounding rectangle: the exact screen rectangles of the two spheres of
//! radius `max(r1, r2, r1y, r2y)` around its axis end points, which enclose its projection (the
//! segment lies in the capsule they span, and a capsule's projection lies in the convex hull of
//! its end spheres' projections). A segment not entirely in front of the camera scans the whole
//! image.
//!
//! The buffers are reused: after the first frame of a given size [`CylinderRaster::render`]
//! allocates nothing; only the rectangle touched by the previous frame is cleared. For a lower
//! resolution, render with downsampled intrinsics (`fx/k`, `fy/k`, `(c + ½)/k − ½`, size `/k`).

use nalgebra::Vector3;

use super::model::CylinderModel;
use crate::error::Result;
use crate::kinematics::PosedSkeleton;
use crate::render::Intrinsics;

/// Segment id of a background pixel in [`CylinderRaster`].
pub const NO_SEGMENT: u32 = u32::MAX;

/// One rendered pixel: the first segment hit by the pixel's ray and the hit point.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct RasterHit {
    /// Index into [`CylinderModel::segments`].
    pub segment: usize,
    /// The bone carrying the segment (the point is rigidly attached to it).
    pub bone: usize,
    /// The surface point in the camera frame (mm), on the ray through the pixel center.
    pub point: Vector3<f64>,
}

/// Half-open pixel rectangle `[u0, u1) × [v0, v1)`.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
struct Rect {
    u0: u32,
    v0: u32,
    u1: u32,
    v1: u32,
}

impl Rect {
    fn union(self, o: Rect) -> Rect {
        Rect {
            u0: self.u0.min(o.u0),
            v0: self.v0.min(o.v0),
            u1: self.u1.max(o.u1),
            v1: self.v1.max(o.v1),
        }
    }
}

/// The rendered cylinder model (thesis §2.3.1): per pixel (row-major, `v·width + u`) the
/// segment hit first ([`NO_SEGMENT`] for background) and the camera-frame surface point, plus
/// the list of rendered pixels. Reusable between frames.
#[derive(Clone, Debug, Default)]
pub struct CylinderRaster {
    width: u32,
    height: u32,
    segment: Vec<u32>,
    point: Vec<Vector3<f64>>,
    hits: Vec<u32>,
    bones: Vec<usize>,
    order: Vec<(f64, usize)>,
    dirty: Option<Rect>,
}

impl CylinderRaster {
    /// An empty raster (0×0 until the first render).
    pub fn new() -> Self {
        Self::default()
    }

    /// Image width of the last render.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height of the last render.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Per pixel the segment hit first, [`NO_SEGMENT`] for background.
    pub fn segments(&self) -> &[u32] {
        &self.segment
    }

    /// The rendered pixels (linear indices `v·width + u`, increasing): the silhouette `S_r`.
    pub fn hits(&self) -> &[u32] {
        &self.hits
    }

    /// The hit at linear pixel index `i`, `None` for background or outside the image.
    #[inline]
    pub fn hit(&self, i: usize) -> Option<RasterHit> {
        let s = *self.segment.get(i)?;
        (s != NO_SEGMENT).then(|| RasterHit {
            segment: s as usize,
            bone: self.bones[s as usize],
            point: self.point[i],
        })
    }

    /// The hit at pixel `(u, v)`.
    #[inline]
    pub fn hit_at(&self, u: u32, v: u32) -> Option<RasterHit> {
        if u >= self.width || v >= self.height {
            return None;
        }
        self.hit((v * self.width + u) as usize)
    }

    /// Remove every rendered pixel (keeps the size and the buffers).
    pub fn clear(&mut self) {
        self.reset(self.width, self.height);
    }

    /// Reset to an empty image of the given size, clearing only what the last render touched.
    fn reset(&mut self, width: u32, height: u32) {
        let n = width as usize * height as usize;
        if width != self.width || height != self.height || self.segment.len() != n {
            self.width = width;
            self.height = height;
            self.segment.clear();
            self.segment.resize(n, NO_SEGMENT);
            self.point.clear();
            self.point.resize(n, Vector3::zeros());
        } else if let Some(r) = self.dirty {
            for v in r.v0..r.v1 {
                let row = (v * width) as usize;
                self.segment[row + r.u0 as usize..row + r.u1 as usize].fill(NO_SEGMENT);
            }
        }
        self.dirty = None;
        self.hits.clear();
    }

    /// Render the posed model from a pinhole camera at the origin of the camera frame (the
    /// frame of `posed`). Returns the number of rendered pixels. An invalid camera is an error;
    /// a pose with non-finite frames renders nothing.
    pub fn render(
        &mut self,
        model: &CylinderModel,
        posed: &PosedSkeleton,
        camera: &Intrinsics,
    ) -> Result<usize> {
        self.render_where(model, posed, camera, |_| true)
    }

    /// As [`CylinderRaster::render`], casting rays only through the pixels `i = v·width + u`
    /// with `keep(i)`; the others stay empty. E2D (Eq. 2.3) only needs the rendered pixels
    /// *outside* the sensor silhouette, and while tracking succeeds most of the model projects
    /// inside it, so skipping those pixels saves most of the ray casts exactly.
    pub fn render_where(
        &mut self,
        model: &CylinderModel,
        posed: &PosedSkeleton,
        camera: &Intrinsics,
        keep: impl Fn(usize) -> bool,
    ) -> Result<usize> {
        camera.validate()?;
        self.reset(camera.width, camera.height);
        self.bones.clear();
        self.bones.extend(model.segments.iter().map(|s| s.bone));
        let frames_ok = model
            .segments
            .iter()
            .all(|s| posed.globals.get(s.bone).is_some_and(|g| g.is_finite()));
        if !frames_ok {
            return Ok(0);
        }
        let (w, h) = (camera.width, camera.height);
        // Front to back (by the nearest depth of the bounding capsule), so that the depth test
        // rejects most occluded rays at the capsule check.
        self.order.clear();
        self.order
            .extend(model.segments.iter().enumerate().map(|(si, seg)| {
                let g = &posed.globals[seg.bone];
                let reach = seg.r1.max(seg.r2).max(seg.r1y).max(seg.r2y);
                let end = g.transform_point(&seg.end_local());
                (g.translation.z.min(end.z) - reach, si)
            }));
        self.order.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        for k in 0..self.order.len() {
            let si = self.order[k].1;
            let seg = &model.segments[si];
            let g = &posed.globals[seg.bone];
            let rt = g.rotation.transpose();
            let origin = -(rt * g.translation);
            let reach = seg.r1.max(seg.r2).max(seg.r1y).max(seg.r2y);
            let start = g.translation;
            let end = g.transform_point(&seg.end_local());
            let Some(rect) = [start, end]
                .iter()
                .map(|c| sphere_rect(camera, c, reach))
                .try_fold(None::<Rect>, |acc, r| {
                    r.map(|r| Some(acc.map_or(r, |a| a.union(r))))
                })
                .unwrap_or(Some(Rect {
                    u0: 0,
                    v0: 0,
                    u1: w,
                    v1: h,
                }))
            else {
                continue;
            };
            if start.z + reach <= 0.0 && end.z + reach <= 0.0 {
                continue;
            }
            let rect = Rect {
                u0: rect.u0.min(w),
                v0: rect.v0.min(h),
                u1: rect.u1.min(w),
                v1: rect.v1.min(h),
            };
            if rect.u0 >= rect.u1 || rect.v0 >= rect.v1 {
                continue;
            }
            self.dirty = Some(self.dirty.map_or(rect, |d| d.union(rect)));
            // Rays with direction (x, y, 1): the ray parameter is the camera depth z, and the
            // bone-frame direction is affine in the pixel coordinates.
            let du = rt.column(0) / camera.fx;
            for v in rect.v0..rect.v1 {
                let y = (f64::from(v) - camera.cy) / camera.fy;
                let x0 = (f64::from(rect.u0) - camera.cx) / camera.fx;
                let mut dl = rt * Vector3::new(x0, y, 1.0);
                let row = (v * w) as usize;
                for u in rect.u0..rect.u1 {
                    let i = row + u as usize;
                    if !keep(i) {
                        dl += du;
                        continue;
                    }
                    let max_z = if self.segment[i] == NO_SEGMENT {
                        f64::INFINITY
                    } else {
                        self.point[i].z
                    };
                    if let Some(z) = seg.cast_local_ray(&origin, &dl, max_z) {
                        if z < max_z {
                            let x = (f64::from(u) - camera.cx) / camera.fx;
                            self.segment[i] = si as u32;
                            self.point[i] = Vector3::new(x * z, y * z, z);
                        }
                    }
                    dl += du;
                }
            }
        }
        if let Some(r) = self.dirty {
            for v in r.v0..r.v1 {
                let row = v * w;
                for u in r.u0..r.u1 {
                    if self.segment[(row + u) as usize] != NO_SEGMENT {
                        self.hits.push(row + u);
                    }
                }
            }
        }
        Ok(self.hits.len())
    }
}

/// The first entry into the posed model of the camera ray through `through` (camera frame, in
/// front of the camera), as [`CylinderRaster`] renders it at a pixel: every segment cast, the
/// nearest kept. `None` when the ray misses or `through` is not strictly in front of the camera.
/// The rasterizer answers the same for a whole image at once; this is for single points that
/// lie off their pixel's ray.
pub fn cast_camera_ray(
    model: &CylinderModel,
    posed: &PosedSkeleton,
    through: &Vector3<f64>,
) -> Option<RasterHit> {
    if !(through.z > 0.0 && through.iter().all(|v| v.is_finite())) {
        return None;
    }
    let dir = through / through.z;
    let mut best: Option<RasterHit> = None;
    for (si, seg) in model.segments.iter().enumerate() {
        let g = posed.globals.get(seg.bone).filter(|g| g.is_finite())?;
        let rt = g.rotation.transpose();
        let max_z = best.map_or(f64::INFINITY, |b| b.point.z);
        if let Some(z) = seg.cast_local_ray(&-(rt * g.translation), &(rt * dir), max_z) {
            if z < max_z {
                best = Some(RasterHit {
                    segment: si,
                    bone: seg.bone,
                    point: dir * z,
                });
            }
        }
    }
    best
}

/// The pixel rectangle (half-open, clamped at 0, one pixel of margin) that contains the
/// projection of the sphere `(c, radius)`; `None` unless the sphere lies strictly in front of
/// the camera (then the caller scans the whole image).
fn sphere_rect(camera: &Intrinsics, c: &Vector3<f64>, radius: f64) -> Option<Rect> {
    let rad = radius * (1.0 + 1e-9) + 1e-9;
    if c.z.is_nan() || c.z <= rad {
        return None;
    }
    // Tangent lines x = m·z of the circle (c.x, c.z; rad) in the xz-plane, and likewise in yz:
    // (cx − m cz)² = rad²(1 + m²).
    let extent = |a: f64| {
        let den = c.z * c.z - rad * rad;
        let disc = rad * (a * a + den).sqrt();
        ((a * c.z - disc) / den, (a * c.z + disc) / den)
    };
    let (mx0, mx1) = extent(c.x);
    let (my0, my1) = extent(c.y);
    let to_px = |m: f64, f: f64, cc: f64| m * f + cc;
    let lo = |p: f64| (p.floor() - 1.0).max(0.0).min(f64::from(u32::MAX)) as u32;
    let hi = |p: f64| (p.ceil() + 2.0).max(0.0).min(f64::from(u32::MAX)) as u32;
    Some(Rect {
        u0: lo(to_px(mx0, camera.fx, camera.cx)),
        u1: hi(to_px(mx1, camera.fx, camera.cx)),
        v0: lo(to_px(my0, camera.fy, camera.cy)),
        v1: hi(to_px(my1, camera.fy, camera.cy)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cylinder::default_right_hand_cylinders;
    use crate::kinematics::Pose;

    fn camera() -> Intrinsics {
        Intrinsics {
            fx: 300.0,
            fy: 300.0,
            cx: 160.0,
            cy: 120.0,
            width: 320,
            height: 240,
        }
    }

    /// The pose of the htrack-icp tests.
    fn pose(model: &CylinderModel) -> Pose {
        crate::testing::cylinder_test_pose(model)
    }

    fn inside(model: &CylinderModel, posed: &PosedSkeleton, p: &Vector3<f64>) -> bool {
        model.segments.iter().any(|s| {
            let g = &posed.globals[s.bone];
            s.contains_local_point(&(g.rotation.transpose() * (p - g.translation)))
        })
    }

    /// Brute force: march every pixel ray through the depth range with `contains_local_point`
    /// and bisect the first inside sample to 1e-10 mm.
    fn march_pixel(
        model: &CylinderModel,
        posed: &PosedSkeleton,
        cam: &Intrinsics,
        u: u32,
        v: u32,
        (z0, z1): (f64, f64),
        step: f64,
    ) -> Option<Vector3<f64>> {
        let d = cam.pixel_ray(f64::from(u), f64::from(v)).dir;
        let (s0, s1) = (z0 / d.z, z1 / d.z);
        let (mut prev, mut s) = (s0, s0);
        while s <= s1 {
            if inside(model, posed, &(d * s)) {
                let (mut a, mut b) = (prev, s);
                while b - a > 1e-10 {
                    let m = 0.5 * (a + b);
                    if inside(model, posed, &(d * m)) {
                        b = m;
                    } else {
                        a = m;
                    }
                }
                return Some(d * b);
            }
            prev = s;
            s += step;
        }
        None
    }

    #[test]
    fn raster_matches_brute_force_marching() {
        let model = default_right_hand_cylinders();
        let posed = model.posed(&pose(&model)).unwrap();
        let cam = camera();
        let mut raster = CylinderRaster::new();
        let n = raster.render(&model, &posed, &cam).unwrap();
        assert!(n > 2000, "{n} pixels");
        assert_eq!(raster.hits().len(), n);
        let zs: Vec<f64> = raster
            .hits()
            .iter()
            .map(|&i| raster.hit(i as usize).unwrap().point.z)
            .collect();
        let zr = (
            zs.iter().fold(f64::MAX, |m, &z| m.min(z)) - 30.0,
            zs.iter().fold(f64::MIN, |m, &z| m.max(z)) + 30.0,
        );
        let (mut both, mut mask_diff, mut depth_diff) = (0, 0, 0);
        let mut worst = 0.0f64;
        // Every pixel of the image at stride 2 (odd offsets on alternate rows).
        for v in (0..cam.height).step_by(2) {
            for u in ((v / 2) % 2..cam.width).step_by(2) {
                let got = raster.hit_at(u, v);
                let want = march_pixel(&model, &posed, &cam, u, v, zr, 0.25);
                match (got, want) {
                    (Some(g), Some(p)) => {
                        both += 1;
                        let e = (g.point - p).norm();
                        if e > 1e-6 {
                            // A sliver thinner than the step in front of the marched hit.
                            depth_diff += 1;
                            assert!(g.point.z < p.z, "({u}, {v}): {:?} vs {p:?}", g.point);
                        } else {
                            worst = worst.max(e);
                        }
                        // The point is on the surface of its segment.
                        let s = &model.segments[g.segment];
                        let gb = &posed.globals[g.bone];
                        let local = gb.rotation.transpose() * (g.point - gb.translation);
                        let pr = s.project_local_point(&local).unwrap();
                        assert!(pr.distance.abs() < 1e-7, "{}", pr.distance);
                    }
                    (None, None) => {}
                    _ => mask_diff += 1,
                }
            }
        }
        eprintln!(
            "raster vs marching: {both} pixels hit by both, worst distance {worst:.1e} mm, \
             {depth_diff} depth and {mask_diff} mask differences"
        );
        assert!(both > 500);
        assert!(depth_diff <= 3 && mask_diff <= 3);
        assert!(worst < 1e-6);
    }

    /// The single-ray cast is the rasterizer's answer at every pixel (hit or miss): the same
    /// segment and, up to rounding, the same point.
    #[test]
    fn single_ray_casts_match_the_raster() {
        let model = default_right_hand_cylinders();
        let posed = model.posed(&pose(&model)).unwrap();
        let cam = camera();
        let mut raster = CylinderRaster::new();
        raster.render(&model, &posed, &cam).unwrap();
        let mut hits = 0;
        for v in 0..cam.height {
            for u in 0..cam.width {
                let dir = Vector3::new(
                    (f64::from(u) - cam.cx) / cam.fx,
                    (f64::from(v) - cam.cy) / cam.fy,
                    1.0,
                );
                let cast = cast_camera_ray(&model, &posed, &(dir * 123.0));
                let Some(h) = raster.hit_at(u, v) else {
                    assert!(cast.is_none(), "({u}, {v}): {cast:?}");
                    continue;
                };
                let c = cast.unwrap_or_else(|| panic!("({u}, {v}) missed"));
                assert_eq!((c.segment, c.bone), (h.segment, h.bone), "({u}, {v})");
                assert!((c.point - h.point).norm() < 1e-9, "({u}, {v})");
                hits += 1;
            }
        }
        assert!(hits > 2000, "{hits} hits");
        assert!(cast_camera_ray(&model, &posed, &Vector3::new(0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn render_reuses_buffers_and_survives_bad_input() {
        let model = default_right_hand_cylinders();
        let p = pose(&model);
        let posed = model.posed(&p).unwrap();
        let cam = camera();
        let mut raster = CylinderRaster::new();
        let n = raster.render(&model, &posed, &cam).unwrap();
        let snapshot = raster.segments().to_vec();
        let ptrs = (
            raster.segments().as_ptr(),
            raster.hits().as_ptr(),
            raster.point.as_ptr(),
        );
        // Another pose, then back: same image, same buffers.
        let mut moved = p.clone();
        moved.values[0] += 30.0;
        let m = raster
            .render(&model, &model.posed(&moved).unwrap(), &cam)
            .unwrap();
        assert!(m > 0 && raster.segments() != snapshot.as_slice());
        assert_eq!(raster.render(&model, &posed, &cam).unwrap(), n);
        assert_eq!(raster.segments(), snapshot.as_slice());
        assert_eq!(
            ptrs,
            (
                raster.segments().as_ptr(),
                raster.hits().as_ptr(),
                raster.point.as_ptr()
            )
        );
        // Every pixel's point projects back onto its pixel center.
        for &i in raster.hits() {
            let h = raster.hit(i as usize).unwrap();
            let [u, v] = cam.project(&h.point);
            let (pu, pv) = (i % cam.width, i / cam.width);
            assert!((u - f64::from(pu)).abs() < 1e-9 && (v - f64::from(pv)).abs() < 1e-9);
        }
        // Non-finite pose: nothing rendered; invalid camera: error; behind the camera: nothing.
        let mut bad = posed.clone();
        bad.globals[1].translation.x = f64::NAN;
        assert_eq!(raster.render(&model, &bad, &cam).unwrap(), 0);
        assert!(raster.segments().iter().all(|&s| s == NO_SEGMENT));
        let zero = Intrinsics { fx: 0.0, ..cam };
        assert!(raster.render(&model, &posed, &zero).is_err());
        let mut behind = p.clone();
        behind.values[2] = -400.0;
        let b = model.posed(&behind).unwrap();
        assert_eq!(raster.render(&model, &b, &cam).unwrap(), 0);
        // Straddling the camera plane: scans the whole image, finds only hits in front.
        let mut near = p.clone();
        near.values[2] = 10.0;
        let nr = model.posed(&near).unwrap();
        raster.render(&model, &nr, &cam).unwrap();
        assert!(raster
            .hits()
            .iter()
            .all(|&i| raster.hit(i as usize).unwrap().point.z > 0.0));
    }

    /// Prints the cost of one 320×240 render with the hand ~40 cm from the camera.
    #[test]
    fn render_timing() {
        let model = default_right_hand_cylinders();
        let posed = model.posed(&pose(&model)).unwrap();
        let cam = camera();
        let mut raster = CylinderRaster::new();
        let n = raster.render(&model, &posed, &cam).unwrap();
        let runs = 50;
        let start = std::time::Instant::now();
        for _ in 0..runs {
            raster.render(&model, &posed, &cam).unwrap();
        }
        let us = start.elapsed().as_secs_f64() * 1e6 / f64::from(runs);
        eprintln!("CylinderRaster::render 320×240: {us:.0} µs, {n} pixels rendered");
    }
}
