//! Pinhole cameras in the OpenCV optical frame (DESIGN.md): x right, y down, z forward; pixel
//! (u, v) = (column, row) from the top-left corner.

use nalgebra::{Matrix2x3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{Result, SensorError};

/// A pinhole camera without distortion.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Image width (px).
    pub width: u32,
    /// Image height (px).
    pub height: u32,
    /// Focal length along u (px).
    pub fx: f64,
    /// Focal length along v (px).
    pub fy: f64,
    /// Principal point u (px).
    pub cx: f64,
    /// Principal point v (px).
    pub cy: f64,
    /// Millimetres per depth unit (1 for the mm depth of every camera here).
    #[serde(default = "one")]
    pub depth_unit_mm: f64,
    /// Display name.
    #[serde(default)]
    pub name: String,
}

fn one() -> f64 {
    1.0
}

impl Camera {
    /// A camera, checked: positive size and focal lengths, finite principal point.
    pub fn new(
        name: &str,
        width: u32,
        height: u32,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
    ) -> Result<Self> {
        let c = Camera {
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            depth_unit_mm: 1.0,
            name: name.into(),
        };
        c.validate()?;
        Ok(c)
    }

    /// Check the intrinsics.
    pub fn validate(&self) -> Result<()> {
        if self.width == 0 || self.height == 0 || self.width > 16384 || self.height > 16384 {
            return Err(SensorError::arg(
                "camera",
                format!("bad size {}×{}", self.width, self.height),
            ));
        }
        let ok = |v: f64| v.is_finite();
        if !(ok(self.fx) && ok(self.fy) && self.fx > 0.0 && self.fy > 0.0) {
            return Err(SensorError::arg(
                "camera",
                "focal lengths must be finite and positive",
            ));
        }
        if !(ok(self.cx) && ok(self.cy) && ok(self.depth_unit_mm) && self.depth_unit_mm > 0.0) {
            return Err(SensorError::arg(
                "camera",
                "principal point and depth unit must be finite",
            ));
        }
        Ok(())
    }

    /// Intel SR300 / Handy / hmodel / honline QVGA (ANCHOR-FACTS §0: 320×240, f = 287.26,
    /// principal point at the integer image center).
    pub fn sr300_qvga() -> Self {
        Camera {
            width: 320,
            height: 240,
            fx: 287.26,
            fy: 287.26,
            cx: 160.0,
            cy: 120.0,
            depth_unit_mm: 1.0,
            name: "sr300-qvga".into(),
        }
    }

    /// Creative Gesture Camera / Dexter-1 (ANCHOR-FACTS §0 "Intel" mode: 320×240, fx = 224.502,
    /// fy = 230.494).
    pub fn creative_qvga() -> Self {
        Camera {
            width: 320,
            height: 240,
            fx: 224.502,
            fy: 230.494,
            cx: 160.0,
            cy: 120.0,
            depth_unit_mm: 1.0,
            name: "creative-qvga".into(),
        }
    }

    /// Kinect / NYU (640×480, fx = 588.03, fy = 587.07, c = (320, 240)).
    pub fn nyu_vga() -> Self {
        Camera {
            width: 640,
            height: 480,
            fx: 588.036865,
            fy: 587.075073,
            cx: 320.0,
            cy: 240.0,
            depth_unit_mm: 1.0,
            name: "nyu-vga".into(),
        }
    }

    /// A preset by name: `sr300`, `creative`, `nyu`.
    pub fn preset(name: &str) -> Result<Self> {
        match name {
            "sr300" | "sr300-qvga" | "handy" => Ok(Self::sr300_qvga()),
            "creative" | "creative-qvga" | "dexter" => Ok(Self::creative_qvga()),
            "nyu" | "nyu-vga" | "kinect" => Ok(Self::nyu_vga()),
            other => Err(SensorError::arg(
                "camera",
                format!("unknown preset `{other}` (sr300, creative, nyu)"),
            )),
        }
    }

    /// The same camera at `1/factor` resolution (pixel centers preserved).
    pub fn downsampled(&self, factor: u32) -> Camera {
        let f = factor.max(1) as f64;
        Camera {
            width: self.width / factor.max(1),
            height: self.height / factor.max(1),
            fx: self.fx / f,
            fy: self.fy / f,
            cx: (self.cx + 0.5) / f - 0.5,
            cy: (self.cy + 0.5) / f - 0.5,
            depth_unit_mm: self.depth_unit_mm,
            name: format!("{}/{}", self.name, factor),
        }
    }

    /// The weight of one silhouette push (a model pixel outside the sensor silhouette: htrack's
    /// E2D, Eq. 2.3; hmodel's E_m2d, Eq. 3.5) in an image this wide, relative to one in a
    /// 320-pixel-wide image, the resolution at which the originals ran (they downsampled
    /// 640 × 480 frames to 320 × 240, ANCHOR-FACTS §0, §8) and their weights were set:
    /// `(320 / width)⁴`. At twice the resolution a silhouette has four times the pushes, each
    /// twice as long in pixels, so the term's share of the normal equations would grow
    /// sixteenfold against the fixed number of sensor points of the 3D term.
    pub fn qvga_share(&self) -> f64 {
        (320.0 / f64::from(self.width.max(1))).powi(4)
    }

    /// Pixel (u, v) of a camera-frame point (z > 0).
    #[inline]
    pub fn project(&self, p: &Vector3<f64>) -> Vector2<f64> {
        Vector2::new(self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy)
    }

    /// Camera-frame point of pixel (u, v) at depth z (mm).
    #[inline]
    pub fn backproject(&self, u: f64, v: f64, z: f64) -> Vector3<f64> {
        Vector3::new((u - self.cx) * z / self.fx, (v - self.cy) * z / self.fy, z)
    }

    /// The 2×3 projection Jacobian `∂(u, v)/∂p` (thesis §2.7.2), used by the 2D terms.
    #[inline]
    pub fn projection_jacobian(&self, p: &Vector3<f64>) -> Matrix2x3<f64> {
        let iz = 1.0 / p.z;
        Matrix2x3::new(
            self.fx * iz,
            0.0,
            -self.fx * p.x * iz * iz,
            0.0,
            self.fy * iz,
            -self.fy * p.y * iz * iz,
        )
    }

    /// Whether a pixel position lies inside the image.
    #[inline]
    pub fn contains(&self, u: f64, v: f64) -> bool {
        u >= -0.5 && v >= -0.5 && u < self.width as f64 - 0.5 && v < self.height as f64 - 0.5
    }

    /// Number of pixels.
    pub fn num_pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Twice the resolution: four times the pushes, each twice as long in pixels.
    #[test]
    fn silhouette_pushes_weigh_as_in_a_320_pixel_wide_image() {
        let with_width = |w: u32| Camera::new("t", w, w * 3 / 4, 300.0, 300.0, 1.0, 1.0).unwrap();
        assert_eq!(with_width(320).qvga_share(), 1.0);
        assert_eq!(with_width(640).qvga_share(), 1.0 / 16.0);
        assert_eq!(with_width(160).qvga_share(), 16.0);
    }

    #[test]
    fn projection_round_trip_and_jacobian() {
        let c = Camera::creative_qvga();
        let p = Vector3::new(30.0, -20.0, 400.0);
        let uv = c.project(&p);
        let q = c.backproject(uv.x, uv.y, p.z);
        assert!((p - q).norm() < 1e-9);
        let j = c.projection_jacobian(&p);
        for k in 0..3 {
            let mut d = Vector3::zeros();
            d[k] = 1e-4;
            let fd = (c.project(&(p + d)) - c.project(&(p - d))) / 2e-4;
            assert!((fd - j.column(k)).norm() < 1e-7);
        }
    }

    #[test]
    fn bad_intrinsics_are_refused() {
        assert!(Camera::new("x", 0, 240, 1.0, 1.0, 0.0, 0.0).is_err());
        assert!(Camera::new("x", 320, 240, f64::NAN, 1.0, 0.0, 0.0).is_err());
        assert!(Camera::new("x", 320, 240, -3.0, 1.0, 0.0, 0.0).is_err());
        assert!(Camera::preset("nope").is_err());
    }
}
