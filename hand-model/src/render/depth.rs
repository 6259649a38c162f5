//! A small tiled CPU depth renderer for sphere-meshes: the CPU counterpart of the thesis' GPU
//! ray tracer (§3.3.2 "Rendering": one camera ray per pixel, intersected with the planar, conical
//! and spherical primitives of each element, closest hit kept; 320×240 in the thesis).
//!
//! The screen is cut into [`TILE`]×[`TILE`] tiles. Each element's bounding sphere is projected
//! to its exact screen rectangle; the element is listed in every tile that rectangle touches, and
//! the pixels of a tile cast their rays against that tile's list only, sorted front to back, with
//! bounding-sphere culling per ray (an element whose bounding sphere starts behind the current
//! hit is skipped). The result is bit-identical to casting every pixel's ray against all
//! elements with [`cast_ray`](super::cast_ray).

use nalgebra::Vector3;

use super::coverage::Footprint;
use super::pixels::KeptPixels;
use super::prepared::PreparedElement;
use super::raycast::{cast_prepared, Ray, RayHit};
use crate::error::{ModelError, Result};
use crate::shape::{Element, Sphere};

/// Tile side in pixels of the tiled renderer (the CPU stand-in for §3.3.2's fullscreen quad).
pub const TILE: usize = 16;

/// Largest accepted image side (pixels, §3.3.2 renders 320×240), so that a bad size cannot
/// request gigabytes.
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// Element id of a background pixel in [`DepthRender::element`] (no intersection, §3.3.2).
pub const NO_ELEMENT: u32 = u32::MAX;

/// Pinhole intrinsics of a camera without distortion, used to form each pixel's ray (§3.3.2:
/// "use the camera intrinsics to compute the camera ray"; DESIGN.md camera frame: x right, y down,
/// z forward; pixel `(u, v)` = column, row, with integer coordinates at pixel centers).
///
/// Deliberately minimal: the renderer's own camera until `sensor-io` owns the camera types.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Intrinsics {
    /// Focal length along x (pixels).
    pub fx: f64,
    /// Focal length along y (pixels).
    pub fy: f64,
    /// Principal point, column (pixels).
    pub cx: f64,
    /// Principal point, row (pixels).
    pub cy: f64,
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
}

impl Intrinsics {
    /// Check (§3.3.2 intrinsics) that focal lengths are finite and positive, the principal point finite and the size
    /// in `1..=MAX_IMAGE_SIDE`.
    pub fn validate(&self) -> Result<()> {
        let bad = |reason: String| {
            Err(ModelError::InvalidArgument {
                name: "intrinsics",
                reason,
            })
        };
        if !(self.fx.is_finite() && self.fx > 0.0 && self.fy.is_finite() && self.fy > 0.0) {
            return bad(format!(
                "focal lengths must be finite and > 0, got {} {}",
                self.fx, self.fy
            ));
        }
        if !(self.cx.is_finite() && self.cy.is_finite()) {
            return bad("principal point is not finite".into());
        }
        let side_ok = |s: u32| (1..=MAX_IMAGE_SIDE).contains(&s);
        if !(side_ok(self.width) && side_ok(self.height)) {
            return bad(format!(
                "image size {}×{} outside 1..={MAX_IMAGE_SIDE}",
                self.width, self.height
            ));
        }
        Ok(())
    }

    /// The camera ray `r(x)` of §3.3.2 through the center of pixel `(u, v)`: origin at the camera center, unit
    /// direction `normalize((u − cx)/fx, (v − cy)/fy, 1)`, `t ∈ [0, ∞)`.
    #[inline]
    pub fn pixel_ray(&self, u: f64, v: f64) -> Ray {
        let d = Vector3::new((u - self.cx) / self.fx, (v - self.cy) / self.fy, 1.0);
        Ray {
            origin: Vector3::zeros(),
            dir: d / d.norm(),
            t_min: 0.0,
            t_max: f64::INFINITY,
        }
    }

    /// Pixel coordinates `(u, v)` of a camera-frame point with `z > 0` (pinhole model, §3.3.2).
    #[inline]
    pub fn project(&self, p: &Vector3<f64>) -> [f64; 2] {
        [self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy]
    }
}

/// One pixel that sees the model ([`DepthRenderer::render_hits`]).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct PixelHit {
    /// Linear pixel index `v·width + u`.
    pub pixel: u32,
    /// Index of the element hit.
    pub element: u32,
    /// The hit point in the camera frame (mm).
    pub point: Vector3<f64>,
    /// Outward unit normal at the hit.
    pub normal: Vector3<f64>,
}

/// A rendered frame (§3.3.2): per pixel (row-major, `v·width + u`) the depth, the element and
/// the normal.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DepthRender {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Depth `z` of the hit point in the camera frame (mm, `f32`); `0` = background.
    pub depth: Vec<f32>,
    /// Index of the element hit, [`NO_ELEMENT`] for background.
    pub element: Vec<u32>,
    /// Outward unit normal at the hit in the camera frame, `[0, 0, 0]` for background.
    pub normal: Vec<[f32; 3]>,
}

impl DepthRender {
    fn reset(&mut self, width: u32, height: u32) {
        let n = width as usize * height as usize;
        self.width = width;
        self.height = height;
        self.depth.clear();
        self.depth.resize(n, 0.0);
        self.element.clear();
        self.element.resize(n, NO_ELEMENT);
        self.normal.clear();
        self.normal.resize(n, [0.0; 3]);
    }

    /// Number of pixels that hit the model (the rendered silhouette of §3.3.2).
    pub fn hit_count(&self) -> usize {
        self.element.iter().filter(|&&e| e != NO_ELEMENT).count()
    }

    /// The depth as a DESIGN.md depth image (the synthetic sensor frame of §3.3.2): `u16` millimetres (rounded, saturated), 0 = none.
    pub fn depth_u16(&self) -> Vec<u16> {
        self.depth
            .iter()
            .map(|&z| z.round().clamp(0.0, u16::MAX as f32) as u16)
            .collect()
    }
}

/// The tiled ray-casting renderer of §3.3.2 on the CPU; owns its scratch (prepared elements, per-tile element lists) so that
/// rendering a sequence allocates only on the first frame.
#[derive(Clone, Debug, Default)]
pub struct DepthRenderer {
    prepared: Vec<PreparedElement>,
    tile_start: Vec<u32>,
    tile_items: Vec<u32>,
    rects: Vec<[u32; 4]>,
    fill: Vec<u32>,
    near: Vec<f64>,
    /// Per pixel the candidate elements of [`DepthRenderer::render_hits`] (bit e); all zero
    /// between calls.
    candidates: Vec<u64>,
    touched: Vec<u32>,
    /// Per pixel the element that [`DepthRenderer::render_hits`] last found there
    /// ([`NO_WINNER`] if none): cast first, its hit culls the elements behind it.
    winners: Vec<u8>,
}

/// [`DepthRenderer::render_hits`]'s winner of a pixel no element was found at.
const NO_WINNER: u8 = u8::MAX;

/// Exact pixel range `[lo, hi]` of `x/z` for a sphere entirely in front of the camera, along one
/// image axis (`coord` = the sphere center's x or y, `focal`, `principal`).
fn projected_range(coord: f64, z: f64, radius: f64, focal: f64, principal: f64) -> [f64; 2] {
    let dist = (coord * coord + z * z).sqrt();
    let center = coord.atan2(z);
    let half = (radius / dist).min(1.0).asin();
    [
        principal + focal * (center - half).tan(),
        principal + focal * (center + half).tan(),
    ]
}

impl DepthRenderer {
    /// A renderer with empty scratch (§3.3.2 renderer).
    pub fn new() -> Self {
        Self::default()
    }

    /// Render `elements` (indices into `spheres`, all in the camera frame) into `out`: one ray
    /// per pixel, closest intersection kept (§3.3.2).
    ///
    /// Errors: invalid intrinsics, an element index out of range, or a sphere used by an element
    /// that is non-finite or has a negative radius. The camera must be outside the model: rays
    /// start at the camera center, and an element containing it is not seen.
    pub fn render(
        &mut self,
        intrinsics: &Intrinsics,
        spheres: &[Sphere],
        elements: &[Element],
        out: &mut DepthRender,
    ) -> Result<()> {
        out.reset(intrinsics.width, intrinsics.height);
        self.for_each_hit(
            intrinsics,
            spheres,
            elements,
            |_| true,
            |k, hit| {
                out.depth[k] = hit.point.z as f32;
                out.element[k] = hit.element as u32;
                out.normal[k] = [
                    hit.normal.x as f32,
                    hit.normal.y as f32,
                    hit.normal.z as f32,
                ];
            },
        )
    }

    /// The pixels that see the model, as a list instead of an image (what the m2d term of
    /// Eq. 3.5 needs per solver iteration: no full-image buffers to clear): only the pixels
    /// `v·width + u` that `keep` keeps (a predicate or a [`PixelRuns`](super::PixelRuns) set)
    /// are ray cast, and each one that hits is appended to
    /// `out` (cleared first) in raster order. Same rays and hits as [`render`](Self::render),
    /// same errors.
    ///
    /// Instead of tiles, each element's conservative screen footprint (exact bounds of its
    /// spheres' perspective images, see `coverage.rs`) is scanned row by row, so a pixel is
    /// ray cast only if it is kept and may see an element, and only against those elements —
    /// the cost follows the kept part of the model's image, not the screen area around it
    /// (models of more than 64 elements use the tiles).
    pub fn render_hits(
        &mut self,
        intrinsics: &Intrinsics,
        spheres: &[Sphere],
        elements: &[Element],
        mut keep: impl KeptPixels,
        out: &mut Vec<PixelHit>,
    ) -> Result<()> {
        out.clear();
        let mut push = |k: usize, hit: &RayHit| {
            out.push(PixelHit {
                pixel: k as u32,
                element: hit.element as u32,
                point: hit.point,
                normal: hit.normal,
            })
        };
        if elements.len() > 64 {
            return self.for_each_hit(intrinsics, spheres, elements, keep, push);
        }
        intrinsics.validate()?;
        self.prepare(spheres, elements)?;
        // Candidates: the kept pixels of each element's conservative footprint
        // (super::coverage), as a bit set per pixel; then one ray per candidate pixel against
        // its candidates only, in element order (the tie rule of `cast_prepared`).
        let (w, h) = (intrinsics.width, intrinsics.height);
        self.candidates.resize(w as usize * h as usize, 0);
        self.touched.clear();
        let (candidates, touched) = (&mut self.candidates, &mut self.touched);
        let mut sph = [Sphere::new(Vector3::zeros(), 0.0); 3];
        for (e, el) in elements.iter().enumerate() {
            let ids = el.spheres();
            for (d, &i) in sph.iter_mut().zip(ids) {
                *d = spheres[i as usize];
            }
            let fp = Footprint::new(intrinsics, &sph[..ids.len()]);
            let Some((v0, v1)) = fp.rows(h) else { continue };
            let Some((c0, c1)) = fp.columns(w) else {
                continue;
            };
            for v in v0..=v1 {
                // Most rows of the footprint keep no pixel near it (the model's image mostly
                // lies inside the sensor silhouette): skipped before their span is worked out.
                if !keep.any_in_row(w, v, c0, c1) {
                    continue;
                }
                let Some((u0, u1)) = fp.span(v, w) else {
                    continue;
                };
                keep.for_each_in_row(w, v, u0, u1, |u| {
                    let k = (v * w + u) as usize;
                    if candidates[k] == 0 {
                        touched.push(k as u32);
                    }
                    candidates[k] |= 1 << e;
                });
            }
        }
        self.touched.sort_unstable();
        // A tracker renders the same pixels of a slightly moved model every solver iteration:
        // the pixel's last winner first usually leaves the others only a bounding-ball test.
        self.winners.resize(w as usize * h as usize, NO_WINNER);
        for &k in &self.touched {
            let k = k as usize;
            let mut bits = std::mem::take(&mut self.candidates[k]);
            let ray = intrinsics.pixel_ray((k % w as usize) as f64, (k / w as usize) as f64);
            let last = self.winners[k];
            let first = (last < 64 && bits & 1 << last != 0).then(|| {
                bits &= !(1 << last);
                usize::from(last)
            });
            let rest = std::iter::from_fn(|| {
                (bits != 0).then(|| {
                    let e = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    e
                })
            });
            let hit = cast_prepared(&ray, &self.prepared, first.into_iter().chain(rest));
            self.winners[k] = hit.map_or(NO_WINNER, |h| h.element as u8);
            if let Some(hit) = hit {
                push(k, &hit);
            }
        }
        Ok(())
    }

    /// Prepare every element (exact ray casting, §3.3.2).
    fn prepare(&mut self, spheres: &[Sphere], elements: &[Element]) -> Result<()> {
        self.prepared.clear();
        for (i, e) in elements.iter().enumerate() {
            let p = PreparedElement::new(spheres, e).ok_or_else(|| ModelError::InvalidArgument {
                name: "elements",
                reason: format!(
                    "element {i} refers to a sphere that is missing, non-finite or of negative radius"
                ),
            })?;
            self.prepared.push(p);
        }
        Ok(())
    }

    /// The tile loop shared by the renderers: bins the elements, casts the ray of every kept
    /// pixel of a non-empty tile and reports each hit with its linear pixel index.
    fn for_each_hit(
        &mut self,
        intrinsics: &Intrinsics,
        spheres: &[Sphere],
        elements: &[Element],
        mut keep: impl KeptPixels,
        mut on_hit: impl FnMut(usize, &RayHit),
    ) -> Result<()> {
        intrinsics.validate()?;
        self.prepare(spheres, elements)?;
        let (w, h) = (intrinsics.width as usize, intrinsics.height as usize);
        let (tw, th) = (w.div_ceil(TILE), h.div_ceil(TILE));
        self.bin(intrinsics, tw, th);

        for ty in 0..th {
            for tx in 0..tw {
                let tile = ty * tw + tx;
                let items = &self.tile_items
                    [self.tile_start[tile] as usize..self.tile_start[tile + 1] as usize];
                if items.is_empty() {
                    continue;
                }
                for v in ty * TILE..((ty + 1) * TILE).min(h) {
                    for u in tx * TILE..((tx + 1) * TILE).min(w) {
                        let k = v * w + u;
                        if !keep.keeps(k) {
                            continue;
                        }
                        let ray = intrinsics.pixel_ray(u as f64, v as f64);
                        let hit =
                            cast_prepared(&ray, &self.prepared, items.iter().map(|&i| i as usize));
                        if let Some(hit) = hit {
                            on_hit(k, &hit);
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// Fill the per-tile element lists (CSR: `tile_start`, `tile_items`), sorted front to back.
    fn bin(&mut self, intr: &Intrinsics, tw: usize, th: usize) {
        let (w, h) = (intr.width as f64, intr.height as f64);
        self.rects.clear();
        for p in &self.prepared {
            let b = p.bounds();
            let c = b.center;
            // Pixel rectangle [u0, u1] × [v0, v1] (inclusive), or empty.
            let rect = if c.z - b.radius > 1e-9 {
                let [ulo, uhi] = projected_range(c.x, c.z, b.radius, intr.fx, intr.cx);
                let [vlo, vhi] = projected_range(c.y, c.z, b.radius, intr.fy, intr.cy);
                // One pixel of slack on each side covers rounding in the projection.
                let (ulo, uhi, vlo, vhi) = (
                    ulo.floor() - 1.0,
                    uhi.ceil() + 1.0,
                    vlo.floor() - 1.0,
                    vhi.ceil() + 1.0,
                );
                if uhi < 0.0 || vhi < 0.0 || ulo > w - 1.0 || vlo > h - 1.0 {
                    None
                } else {
                    Some([
                        ulo.max(0.0) as u32,
                        uhi.min(w - 1.0) as u32,
                        vlo.max(0.0) as u32,
                        vhi.min(h - 1.0) as u32,
                    ])
                }
            } else if c.z + b.radius > 0.0 {
                // The bounding sphere straddles the camera plane: every pixel may see it.
                Some([0, intr.width - 1, 0, intr.height - 1])
            } else {
                None
            };
            self.rects.push(rect.map_or([1, 0, 1, 0], |r| {
                [
                    r[0] / TILE as u32,
                    r[1] / TILE as u32,
                    r[2] / TILE as u32,
                    r[3] / TILE as u32,
                ]
            }));
        }
        self.tile_start.clear();
        self.tile_start.resize(tw * th + 1, 0);
        for r in &self.rects {
            for ty in r[2]..=r[3].min(th as u32 - 1) {
                for tx in r[0]..=r[1].min(tw as u32 - 1) {
                    self.tile_start[ty as usize * tw + tx as usize + 1] += 1;
                }
            }
        }
        for i in 0..tw * th {
            self.tile_start[i + 1] += self.tile_start[i];
        }
        self.tile_items.clear();
        self.tile_items.resize(self.tile_start[tw * th] as usize, 0);
        self.fill.clear();
        self.fill.extend_from_slice(&self.tile_start[..tw * th]);
        for (e, r) in self.rects.iter().enumerate() {
            for ty in r[2]..=r[3].min(th as u32 - 1) {
                for tx in r[0]..=r[1].min(tw as u32 - 1) {
                    let t = ty as usize * tw + tx as usize;
                    self.tile_items[self.fill[t] as usize] = e as u32;
                    self.fill[t] += 1;
                }
            }
        }
        // Front-to-back within each tile (by the nearest point of the bounding sphere), so that
        // most rays cull the elements behind their first hit.
        self.near.clear();
        self.near.extend(
            self.prepared
                .iter()
                .map(|p| p.bounds().center.norm() - p.bounds().radius),
        );
        for t in 0..tw * th {
            let items =
                &mut self.tile_items[self.tile_start[t] as usize..self.tile_start[t + 1] as usize];
            items.sort_unstable_by(|&a, &b| {
                self.near[a as usize]
                    .total_cmp(&self.near[b as usize])
                    .then(a.cmp(&b))
            });
        }
    }
}

/// Render a depth image (§3.3.2) with a fresh [`DepthRenderer`] (see [`DepthRenderer::render`]).
pub fn render_depth(
    intrinsics: &Intrinsics,
    spheres: &[Sphere],
    elements: &[Element],
) -> Result<DepthRender> {
    let mut out = DepthRender::default();
    DepthRenderer::new().render(intrinsics, spheres, elements, &mut out)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::Pose;
    use crate::render::{cast_ray, PixelRuns};
    use crate::spheremesh::{default_right_hand, PosedSphereMesh};

    fn intrinsics(width: u32, height: u32, f: f64) -> Intrinsics {
        Intrinsics {
            fx: f,
            fy: f * 1.02,
            cx: width as f64 * 0.5 - 0.3,
            cy: height as f64 * 0.5 + 0.7,
            width,
            height,
        }
    }

    fn posed_hand() -> (Vec<Sphere>, Vec<Element>) {
        let t = default_right_hand();
        let mut pose = Pose::zeros(&t.skeleton);
        for (name, v) in [
            ("global_tz", 420.0),
            ("global_ty", -60.0),
            ("global_rx", 0.3),
            ("global_ry", -0.5),
            ("index_mcp_flex", 0.6),
            ("middle_pip_flex", 1.0),
            ("thumb_cmc_abd", 0.3),
        ] {
            pose.set(&t.skeleton, name, v).unwrap();
        }
        let posed = PosedSphereMesh::new(&t, &pose);
        (
            posed.spheres,
            t.elements.iter().map(|e| e.element).collect(),
        )
    }

    fn brute(intr: &Intrinsics, spheres: &[Sphere], elements: &[Element]) -> DepthRender {
        let mut out = DepthRender::default();
        out.reset(intr.width, intr.height);
        for v in 0..intr.height as usize {
            for u in 0..intr.width as usize {
                let ray = intr.pixel_ray(u as f64, v as f64);
                if let Some(hit) = cast_ray(&ray, spheres, elements) {
                    let k = v * intr.width as usize + u;
                    out.depth[k] = hit.point.z as f32;
                    out.element[k] = hit.element as u32;
                    out.normal[k] = [
                        hit.normal.x as f32,
                        hit.normal.y as f32,
                        hit.normal.z as f32,
                    ];
                }
            }
        }
        out
    }

    #[test]
    fn hit_list_equals_the_image_on_kept_pixels() {
        let (spheres, elements) = posed_hand();
        // Also an element straddling the camera plane (a footprint everywhere) and one behind.
        let (mut s2, mut e2) = (spheres.clone(), elements.clone());
        let n = s2.len() as u32;
        s2.push(Sphere::new(Vector3::new(-150.0, 80.0, -20.0), 10.0));
        s2.push(Sphere::new(Vector3::new(-90.0, 60.0, 200.0), 12.0));
        s2.push(Sphere::new(Vector3::new(0.0, 0.0, -300.0), 10.0));
        e2.push(Element::Pill([n, n + 1]));
        e2.push(Element::Pill([n + 2, n + 2]));
        let mut renderer = DepthRenderer::new();
        for (spheres, elements) in [(spheres, elements), (s2, e2)] {
            for intr in [intrinsics(160, 120, 150.0), intrinsics(101, 77, 80.0)] {
                let mut image = DepthRender::default();
                renderer
                    .render(&intr, &spheres, &elements, &mut image)
                    .unwrap();
                // Every pixel, two of three, and the outside of an ellipse around the model
                // (a sensor silhouette's outside: many rows keep nothing near an element).
                let (w, hh) = (intr.width as usize, intr.height as usize);
                for modulus in [1usize, 3, 0] {
                    let keep = |k: usize| {
                        let (u, v) = ((k % w) as f64 / w as f64, (k / w) as f64 / hh as f64);
                        match modulus {
                            0 => {
                                (k / w) % 17 != 0
                                    && ((u - 0.5) / 0.3).powi(2) + ((v - 0.5) / 0.4).powi(2) > 1.0
                            }
                            3 => k % 3 != 0,
                            _ => true,
                        }
                    };
                    let mut hits = Vec::new();
                    renderer
                        .render_hits(&intr, &spheres, &elements, keep, &mut hits)
                        .unwrap();
                    let expected: Vec<usize> = (0..image.element.len())
                        .filter(|&k| keep(k) && image.element[k] != NO_ELEMENT)
                        .collect();
                    let got: Vec<usize> = hits.iter().map(|h| h.pixel as usize).collect();
                    assert_eq!(got, expected);
                    for h in &hits {
                        let k = h.pixel as usize;
                        assert_eq!(h.element, image.element[k]);
                        assert_eq!(h.point.z as f32, image.depth[k]);
                    }
                    // The same pixels as runs: the same hits.
                    let mut runs = PixelRuns::default();
                    runs.set(intr.width, intr.height, keep);
                    let mut from_runs = Vec::new();
                    renderer
                        .render_hits(&intr, &spheres, &elements, &runs, &mut from_runs)
                        .unwrap();
                    assert_eq!(from_runs, hits);
                }
            }
        }
    }

    #[test]
    fn tiled_render_equals_per_pixel_ray_casting() {
        let (mut spheres, mut elements) = posed_hand();
        // An element straddling the camera plane (every tile) and one behind the camera.
        let n = spheres.len() as u32;
        spheres.push(Sphere::new(Vector3::new(-150.0, 80.0, -20.0), 10.0));
        spheres.push(Sphere::new(Vector3::new(-90.0, 60.0, 200.0), 12.0));
        spheres.push(Sphere::new(Vector3::new(0.0, 0.0, -300.0), 10.0));
        elements.push(Element::Pill([n, n + 1]));
        elements.push(Element::Pill([n + 2, n + 2]));
        let mut renderer = DepthRenderer::new();
        let mut out = DepthRender::default();
        for intr in [
            intrinsics(160, 120, 150.0),
            intrinsics(101, 77, 80.0),
            intrinsics(16, 16, 20.0),
        ] {
            renderer
                .render(&intr, &spheres, &elements, &mut out)
                .unwrap();
            let expect = brute(&intr, &spheres, &elements);
            assert_eq!(out, expect);
            let hits = out.hit_count();
            assert!(hits > (intr.width * intr.height / 20) as usize, "{hits}");
            assert!(hits < (intr.width * intr.height) as usize);
        }
    }

    #[test]
    fn single_sphere_has_analytic_depth() {
        let c = Vector3::new(10.0, -5.0, 400.0);
        let spheres = [Sphere::new(c, 30.0)];
        let intr = intrinsics(64, 48, 60.0);
        let out = render_depth(&intr, &spheres, &[Element::Pill([0, 0])]).unwrap();
        let mut inside = 0;
        for v in 0..48 {
            for u in 0..64 {
                let d = intr.pixel_ray(u as f64, v as f64).dir;
                let b = d.dot(&c);
                let disc = 900.0 - (c - d * b).norm_squared();
                let k = v * 64 + u;
                if disc > 1e-3 {
                    inside += 1;
                    let z = (b - disc.sqrt()) * d.z;
                    assert!(
                        (out.depth[k] as f64 - z).abs() < 1e-3,
                        "{u} {v}: {} vs {z}",
                        out.depth[k]
                    );
                    assert_eq!(out.element[k], 0);
                    let p = d * (b - disc.sqrt());
                    let n = (p - c) / 30.0;
                    let got = Vector3::from(out.normal[k].map(|x| x as f64));
                    assert!((got - n).norm() < 1e-5);
                } else if disc < -1e-3 {
                    assert_eq!((out.depth[k], out.element[k]), (0.0, NO_ELEMENT));
                }
            }
        }
        assert!(inside > 20, "{inside}");
        assert_eq!(
            out.depth_u16()[24 * 64 + 32],
            out.depth[24 * 64 + 32].round() as u16
        );
    }

    #[test]
    fn rejects_invalid_input() {
        let spheres = [Sphere::new(Vector3::new(0.0, 0.0, 100.0), 5.0)];
        let ok = intrinsics(32, 32, 30.0);
        for bad in [
            Intrinsics { fx: f64::NAN, ..ok },
            Intrinsics { fy: -1.0, ..ok },
            Intrinsics {
                cx: f64::INFINITY,
                ..ok
            },
            Intrinsics { width: 0, ..ok },
            Intrinsics {
                height: MAX_IMAGE_SIDE + 1,
                ..ok
            },
        ] {
            assert!(render_depth(&bad, &spheres, &[]).is_err());
        }
        assert!(render_depth(&ok, &spheres, &[Element::Pill([0, 1])]).is_err());
        let nan = [Sphere::new(Vector3::new(0.0, f64::NAN, 100.0), 5.0)];
        assert!(render_depth(&ok, &nan, &[Element::Pill([0, 0])]).is_err());
        let empty = render_depth(&ok, &spheres, &[]).unwrap();
        assert_eq!(empty.hit_count(), 0);
    }
}
