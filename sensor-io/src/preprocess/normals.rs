//! Normals from the depth image (Taylor et al. 2016 §3.4: "normalizing the average of a set of
//! normalized cross products in a region around the pixel").

use nalgebra::Vector3;

use crate::camera::Camera;
use crate::image::DepthImage;

/// Normal at pixel (u, v): the normalized mean of the normalized cross products of the central
/// differences at the pixels of a `(2r+1)²` window, oriented toward the camera. `None` when too
/// few neighbours are valid or depths jump by more than `max_jump` mm (an occluding edge).
pub fn depth_normals(
    depth: &DepthImage,
    camera: &Camera,
    u: u32,
    v: u32,
    r: u32,
    max_jump: f64,
) -> Option<Vector3<f64>> {
    let (w, h) = (depth.width as i64, depth.height as i64);
    let at = |x: i64, y: i64| -> Option<Vector3<f64>> {
        if x < 0 || y < 0 || x >= w || y >= h {
            return None;
        }
        let d = depth.data[(y * w + x) as usize];
        (d != 0).then(|| camera.backproject(x as f64, y as f64, d as f64 * camera.depth_unit_mm))
    };
    let center = at(u as i64, v as i64)?;
    let mut acc = Vector3::zeros();
    let mut count = 0;
    let r = r as i64;
    for dy in -r..=r {
        for dx in -r..=r {
            let (x, y) = (u as i64 + dx, v as i64 + dy);
            let (Some(l), Some(rr), Some(t), Some(b)) =
                (at(x - 1, y), at(x + 1, y), at(x, y - 1), at(x, y + 1))
            else {
                continue;
            };
            if (l.z - rr.z).abs() > max_jump
                || (t.z - b.z).abs() > max_jump
                || (l.z - center.z).abs() > 3.0 * max_jump
            {
                continue;
            }
            let n = (rr - l).cross(&(b - t));
            let norm = n.norm();
            if norm > 1e-12 {
                acc += n / norm;
                count += 1;
            }
        }
    }
    if count == 0 || acc.norm() < 1e-9 {
        return None;
    }
    let mut n = acc.normalize();
    if n.dot(&center) > 0.0 {
        n = -n;
    }
    Some(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_normal_is_recovered() {
        let cam = Camera::sr300_qvga();
        // Plane z = 400 + 0.5·x (mm): normal ∝ (0.5, 0, −1), facing the camera.
        let mut d = DepthImage::zeros(cam.width, cam.height);
        for v in 0..cam.height {
            for u in 0..cam.width {
                // Solve z = 400 + 0.5·(u − cx)·z/fx for z along the pixel ray.
                let k = (u as f64 - cam.cx) / cam.fx;
                let z = 400.0 / (1.0 - 0.5 * k);
                d.data[(v * cam.width + u) as usize] = z.round() as u16;
            }
        }
        let n = depth_normals(&d, &cam, 160, 120, 2, 30.0).expect("normal");
        let expected = Vector3::new(0.5, 0.0, -1.0).normalize();
        assert!(n.dot(&expected) > 0.995, "{n:?}");
    }
}
