//! Shaded PNG previews of a sphere-mesh, the visual check of thesis §3.3.2 ("rendering … for
//! visual verification", Fig. 3.2, Fig. 3.4): the [`depth`](super::depth) renderer's normals are
//! shaded with a Lambert head light (light at the camera), each element colored by its bone, on a
//! dark background, with a camera placed to frame the model.

use std::path::Path;

use image::{ExtendedColorType, ImageEncoder, RgbImage};
use nalgebra::{Matrix3, Vector3};

use super::atomic::write_atomic;
use super::depth::{DepthRender, DepthRenderer, Intrinsics, NO_ELEMENT};
use crate::error::{ModelError, Result};
use crate::kinematics::Pose;
use crate::math::Rigid3;
use crate::shape::{Element, Sphere};
use crate::spheremesh::{PosedSphereMesh, SphereMeshTemplate};

/// The side of the model frame the preview camera looks from (visual verification, §3.3.2).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Default)]
pub enum ViewSide {
    /// From −z toward +z: the palm faces the camera (DESIGN.md model frame), fingers up; a right
    /// hand shows its thumb on the image's right.
    #[default]
    Palm,
    /// From +z toward −z: the back of the hand, fingers up.
    Back,
}

/// Options of [`render_preview`] (§3.3.2 visual verification).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct PreviewOptions {
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Viewing side.
    pub side: ViewSide,
    /// Background color (RGB).
    pub background: [u8; 3],
}

impl Default for PreviewOptions {
    fn default() -> Self {
        Self {
            width: 640,
            height: 480,
            side: ViewSide::Palm,
            background: [22, 24, 30],
        }
    }
}

/// A camera that frames a model (§3.3.2 rendering): intrinsics and the model → camera transform.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Framing {
    /// Pinhole intrinsics (`fx = fy = width`, principal point at the image center).
    pub intrinsics: Intrinsics,
    /// `camera_from_model`: maps model-frame points into the camera frame.
    pub camera_from_model: Rigid3,
}

impl Framing {
    /// The spheres moved from the model frame into this camera's frame.
    pub fn spheres_in_camera(&self, spheres: &[Sphere]) -> Vec<Sphere> {
        spheres
            .iter()
            .map(|s| Sphere::new(self.camera_from_model.transform_point(&s.center), s.radius))
            .collect()
    }
}

/// Place a camera (§3.3.2 rendering) that looks at `spheres` (model frame) from `side`, with fingers (+y) up, so
/// that the box of the spheres fills about 90 % of the tighter image side.
///
/// Errors: no sphere, a non-finite sphere, or invalid image size.
pub fn frame_model(spheres: &[Sphere], width: u32, height: u32, side: ViewSide) -> Result<Framing> {
    let rotation = match side {
        ViewSide::Palm => Matrix3::from_diagonal(&Vector3::new(-1.0, -1.0, 1.0)),
        ViewSide::Back => Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0)),
    };
    let mut lo = Vector3::repeat(f64::INFINITY);
    let mut hi = Vector3::repeat(f64::NEG_INFINITY);
    for s in spheres {
        if !(s.center.iter().all(|x| x.is_finite()) && s.radius.is_finite()) {
            return Err(ModelError::InvalidArgument {
                name: "spheres",
                reason: "non-finite sphere".into(),
            });
        }
        let c = rotation * s.center;
        let r = s.radius.max(0.0);
        lo = lo.inf(&(c - Vector3::repeat(r)));
        hi = hi.sup(&(c + Vector3::repeat(r)));
    }
    if spheres.is_empty() {
        return Err(ModelError::InvalidArgument {
            name: "spheres",
            reason: "nothing to frame".into(),
        });
    }
    let f = width as f64;
    let intrinsics = Intrinsics {
        fx: f,
        fy: f,
        cx: (width as f64 - 1.0) * 0.5,
        cy: (height as f64 - 1.0) * 0.5,
        width,
        height,
    };
    intrinsics.validate()?;
    let center = (lo + hi) * 0.5;
    let half = ((hi - lo) * 0.5).map(|x| x.max(1.0));
    let distance =
        half.z + (f * half.x / (0.45 * width as f64)).max(f * half.y / (0.45 * height as f64));
    Ok(Framing {
        intrinsics,
        camera_from_model: Rigid3::new(rotation, Vector3::new(0.0, 0.0, distance) - center),
    })
}

/// The display color of a bone (kinematic chain of Fig. 3.8a) from its name: thumb red, index orange, middle yellow, ring green,
/// pinky blue, palm skin, wrist grey; phalanx `_1`/`_2`/`_3` get darker to lighter; other names
/// get a hue hashed from the name.
pub fn bone_color(name: &str) -> [u8; 3] {
    let (digit, segment) = match name.rsplit_once('_') {
        Some((d, s)) if s.parse::<u32>().is_ok() => (d, s.parse::<u32>().unwrap_or(2)),
        _ => (name, 2),
    };
    let base: [f64; 3] = match digit {
        "thumb" => [225.0, 85.0, 75.0],
        "index" => [235.0, 150.0, 55.0],
        "middle" => [215.0, 205.0, 75.0],
        "ring" => [85.0, 195.0, 115.0],
        "pinky" => [80.0, 150.0, 230.0],
        "palm" | "root" => [225.0, 188.0, 165.0],
        "wrist" => [165.0, 150.0, 145.0],
        other => {
            let h = other
                .bytes()
                .fold(7u32, |h, b| h.wrapping_mul(31).wrapping_add(b as u32));
            let hue = (h % 360) as f64 / 60.0;
            let x = 1.0 - (hue % 2.0 - 1.0).abs();
            let (r, g, b) = match hue as u32 {
                0 => (1.0, x, 0.0),
                1 => (x, 1.0, 0.0),
                2 => (0.0, 1.0, x),
                3 => (0.0, x, 1.0),
                4 => (x, 0.0, 1.0),
                _ => (1.0, 0.0, x),
            };
            [60.0 + 170.0 * r, 60.0 + 170.0 * g, 60.0 + 170.0 * b]
        }
    };
    let k = match segment {
        1 => 0.85,
        3 => 1.12,
        _ => 1.0,
    };
    base.map(|c| (c * k).clamp(0.0, 255.0) as u8)
}

/// Shade a §3.3.2 render: Lambert with a head light, `0.2 + 0.8·max(0, −n·d)` times the element's
/// color (`colors[element]`, grey when missing), `background` elsewhere. Pixels beyond the
/// shortest of the render's buffers stay background.
pub fn shade(
    render: &DepthRender,
    intrinsics: &Intrinsics,
    colors: &[[u8; 3]],
    background: [u8; 3],
) -> RgbImage {
    let mut img = RgbImage::from_pixel(render.width, render.height, image::Rgb(background));
    let pixels = (render.width as usize * render.height as usize).min(render.normal.len());
    for (k, &e) in render.element.iter().take(pixels).enumerate() {
        if e == NO_ELEMENT {
            continue;
        }
        let (u, v) = (k as u32 % render.width, k as u32 / render.width);
        let d = intrinsics.pixel_ray(u as f64, v as f64).dir;
        let n = render.normal[k];
        let lambert = -(n[0] as f64 * d.x + n[1] as f64 * d.y + n[2] as f64 * d.z);
        let light = 0.2 + 0.8 * lambert.clamp(0.0, 1.0);
        let base = colors.get(e as usize).copied().unwrap_or([180, 180, 180]);
        img.put_pixel(
            u,
            v,
            image::Rgb(base.map(|c| (c as f64 * light).round() as u8)),
        );
    }
    img
}

/// A preview (§3.3.2 visual verification, like Fig. 3.2): the shaded image, the depth render it came from and the camera used.
#[derive(Clone, Debug)]
pub struct Preview {
    /// The shaded RGB image.
    pub image: RgbImage,
    /// Depth, element ids and normals.
    pub render: DepthRender,
    /// The camera.
    pub framing: Framing,
}

/// Pose `template` at `pose` (Eq. 3.7), frame it from `options.side` and shade it (colors per bone).
///
/// The framing uses the posed spheres as if the pose's global transform were the model frame, so
/// any global rotation changes the view; use zero global DOFs for the canonical views.
pub fn render_preview(
    template: &SphereMeshTemplate,
    pose: &Pose,
    options: &PreviewOptions,
) -> Result<Preview> {
    let colors: Vec<[u8; 3]> = template
        .elements
        .iter()
        .map(|e| {
            template
                .skeleton
                .bones()
                .get(e.bone)
                .map_or([180, 180, 180], |b| bone_color(&b.name))
        })
        .collect();
    render_preview_colored(template, pose, options, &colors)
}

/// [`render_preview`] with one color per element of `template` (e.g. a quantity mapped to a
/// color scale; grey where `colors` is short).
pub fn render_preview_colored(
    template: &SphereMeshTemplate,
    pose: &Pose,
    options: &PreviewOptions,
    colors: &[[u8; 3]],
) -> Result<Preview> {
    if pose.values.len() != template.skeleton.num_dofs()
        || pose.values.iter().any(|v| !v.is_finite())
    {
        return Err(ModelError::InvalidArgument {
            name: "pose",
            reason: "wrong length or non-finite value".into(),
        });
    }
    let posed = PosedSphereMesh::new(template, pose);
    let framing = frame_model(&posed.spheres, options.width, options.height, options.side)?;
    let spheres = framing.spheres_in_camera(&posed.spheres);
    let elements: Vec<Element> = template.elements.iter().map(|e| e.element).collect();
    let mut render = DepthRender::default();
    DepthRenderer::new().render(&framing.intrinsics, &spheres, &elements, &mut render)?;
    let image = shade(&render, &framing.intrinsics, colors, options.background);
    Ok(Preview {
        image,
        render,
        framing,
    })
}

/// PNG bytes of an RGB image (a §3.3.2 preview).
pub fn encode_png(image: &RgbImage) -> Result<Vec<u8>> {
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(
            image.as_raw(),
            image.width(),
            image.height(),
            ExtendedColorType::Rgb8,
        )
        .map_err(|e| ModelError::InvalidArgument {
            name: "image",
            reason: e.to_string(),
        })?;
    Ok(bytes)
}

/// Write an RGB image (a §3.3.2 preview) as PNG, atomically (temporary file in the same folder, then rename).
pub fn write_png(path: &Path, image: &RgbImage) -> Result<()> {
    write_atomic(path, &encode_png(image)?)
}

/// [`render_preview`] then [`write_png`]: a §3.3.2 preview on disk.
pub fn write_preview_png(
    path: &Path,
    template: &SphereMeshTemplate,
    pose: &Pose,
    options: &PreviewOptions,
) -> Result<()> {
    write_png(path, &render_preview(template, pose, options)?.image)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spheremesh::default_right_hand;

    /// Mean pixel `(u, v)` of the elements whose bone name starts with `digit`.
    fn mean_pixel(template: &SphereMeshTemplate, r: &DepthRender, digit: &str) -> (f64, f64) {
        let (mut su, mut sv, mut n) = (0.0, 0.0, 0.0);
        for (k, &e) in r.element.iter().enumerate() {
            let bone = e != NO_ELEMENT
                && template.skeleton.bones()[template.elements[e as usize].bone]
                    .name
                    .starts_with(digit);
            if bone {
                su += (k as u32 % r.width) as f64;
                sv += (k as u32 / r.width) as f64;
                n += 1.0;
            }
        }
        assert!(n > 20.0, "{digit}: {n} pixels");
        (su / n, sv / n)
    }

    #[test]
    fn default_hand_preview_is_plausible_and_decodes() {
        let template = default_right_hand();
        let pose = Pose::zeros(&template.skeleton);
        let preview = render_preview(&template, &pose, &PreviewOptions::default()).unwrap();
        let r = &preview.render;
        let fraction = r.hit_count() as f64 / (r.width * r.height) as f64;
        assert!((0.08..0.6).contains(&fraction), "hand covers {fraction}");
        // Palm view of a right hand: the thumb is on the image's right of the pinky, fingers up.
        let m = |d| mean_pixel(&template, r, d);
        let (thumb, pinky, middle, wrist) = (m("thumb"), m("pinky"), m("middle"), m("wrist"));
        assert!(thumb.0 > pinky.0 + 50.0, "thumb {thumb:?} pinky {pinky:?}");
        assert!(
            middle.1 < wrist.1 - 100.0,
            "middle {middle:?} wrist {wrist:?}"
        );
        // Hand pixels face the camera: their normals point back toward it.
        for (k, &e) in r.element.iter().enumerate() {
            if e != NO_ELEMENT {
                let d = preview
                    .framing
                    .intrinsics
                    .pixel_ray((k as u32 % r.width) as f64, (k as u32 / r.width) as f64)
                    .dir;
                let n = r.normal[k];
                assert!(n[0] as f64 * d.x + n[1] as f64 * d.y + n[2] as f64 * d.z <= 1e-6);
            }
        }

        let dir = std::env::temp_dir().join(format!("hands-preview-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("hand.png");
        write_preview_png(&path, &template, &pose, &PreviewOptions::default()).unwrap();
        let decoded = image::load_from_memory_with_format(
            &std::fs::read(&path).unwrap(),
            image::ImageFormat::Png,
        )
        .unwrap();
        assert_eq!((decoded.width(), decoded.height()), (640, 480));
        assert_eq!(decoded.to_rgb8(), preview.image);
        assert_eq!(
            *preview.image.get_pixel(0, 0),
            image::Rgb(PreviewOptions::default().background)
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn back_view_shows_the_thumb_on_the_left() {
        let template = default_right_hand();
        let pose = Pose::zeros(&template.skeleton);
        let palm = render_preview(
            &template,
            &pose,
            &PreviewOptions {
                width: 160,
                height: 120,
                ..Default::default()
            },
        )
        .unwrap();
        let back = render_preview(
            &template,
            &pose,
            &PreviewOptions {
                width: 160,
                height: 120,
                side: ViewSide::Back,
                ..Default::default()
            },
        )
        .unwrap();
        // About the same silhouette, mirrored (perspective and the different near sides differ).
        let (a, b) = (
            palm.render.hit_count() as f64,
            back.render.hit_count() as f64,
        );
        assert!((a - b).abs() < 0.2 * a, "{a} vs {b}");
        let (thumb, pinky) = (
            mean_pixel(&template, &back.render, "thumb"),
            mean_pixel(&template, &back.render, "pinky"),
        );
        assert!(thumb.0 < pinky.0 - 10.0, "thumb {thumb:?} pinky {pinky:?}");
    }

    #[test]
    fn invalid_input_is_rejected() {
        let template = default_right_hand();
        let mut pose = Pose::zeros(&template.skeleton);
        pose.values[7] = f64::NAN;
        assert!(render_preview(&template, &pose, &PreviewOptions::default()).is_err());
        let pose = Pose::zeros(&template.skeleton);
        assert!(render_preview(
            &template,
            &pose,
            &PreviewOptions {
                width: 0,
                ..Default::default()
            }
        )
        .is_err());
        assert!(frame_model(&[], 64, 48, ViewSide::Palm).is_err());
        assert_eq!(bone_color("thumb_2"), [225, 85, 75]);
        assert_ne!(bone_color("mystery"), bone_color("other"));
    }
}
