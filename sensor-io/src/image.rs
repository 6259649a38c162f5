//! Depth and color images and frames.

use crate::error::{Result, SensorError};

/// A depth image: `u16` millimetres, row-major, 0 = no measurement.
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct DepthImage {
    /// Width (px).
    pub width: u32,
    /// Height (px).
    pub height: u32,
    /// Row-major depth values (mm).
    pub data: Vec<u16>,
}

impl DepthImage {
    /// An all-zero image.
    pub fn zeros(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            data: vec![0; width as usize * height as usize],
        }
    }

    /// Wrap data, checking the size.
    pub fn from_data(width: u32, height: u32, data: Vec<u16>) -> Result<Self> {
        if data.len() != width as usize * height as usize {
            return Err(SensorError::arg(
                "depth",
                format!("{} values for {width}×{height}", data.len()),
            ));
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// Depth at (u, v) (column, row).
    #[inline]
    pub fn get(&self, u: u32, v: u32) -> u16 {
        self.data[v as usize * self.width as usize + u as usize]
    }

    /// Number of valid (non-zero) pixels.
    pub fn valid_count(&self) -> usize {
        self.data.iter().filter(|&&d| d != 0).count()
    }
}

/// An 8-bit RGB image, row-major, 3 bytes per pixel.
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct ColorImage {
    /// Width (px).
    pub width: u32,
    /// Height (px).
    pub height: u32,
    /// R, G, B bytes.
    pub data: Vec<u8>,
}

impl ColorImage {
    /// A black image.
    pub fn zeros(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            data: vec![0; 3 * width as usize * height as usize],
        }
    }

    /// Wrap data, checking the size.
    pub fn from_data(width: u32, height: u32, data: Vec<u8>) -> Result<Self> {
        if data.len() != 3 * width as usize * height as usize {
            return Err(SensorError::arg(
                "color",
                format!("{} bytes for {width}×{height} RGB", data.len()),
            ));
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// RGB at (u, v).
    #[inline]
    pub fn get(&self, u: u32, v: u32) -> [u8; 3] {
        let i = 3 * (v as usize * self.width as usize + u as usize);
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }
}

/// One sensor frame: depth, optional registered color, index and timestamp (s).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Frame {
    /// Frame index in its sequence.
    pub index: u64,
    /// Capture time (s).
    pub timestamp: f64,
    /// Depth (mm).
    pub depth: DepthImage,
    /// Color registered to the depth image, when available.
    pub color: Option<ColorImage>,
}

/// A binary mask, row-major, one byte per pixel (0 or 1).
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct Mask {
    /// Width (px).
    pub width: u32,
    /// Height (px).
    pub height: u32,
    /// 0/1 per pixel.
    pub data: Vec<u8>,
}

impl Mask {
    /// An empty mask.
    pub fn zeros(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            data: vec![0; width as usize * height as usize],
        }
    }

    /// Whether (u, v) is set.
    #[inline]
    pub fn get(&self, u: u32, v: u32) -> bool {
        self.data[v as usize * self.width as usize + u as usize] != 0
    }

    /// Number of set pixels.
    pub fn count(&self) -> usize {
        self.data.iter().filter(|&&m| m != 0).count()
    }
}
