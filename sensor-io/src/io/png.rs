//! 16-bit depth and 8-bit RGB PNG files, written atomically.

use std::io::Write;
use std::path::Path;

use image::{DynamicImage, ImageBuffer, ImageFormat, Luma, Rgb};

use crate::error::{Result, SensorError};
use crate::image::{ColorImage, DepthImage};

/// Write `bytes` to `path` atomically: a temporary file in the same folder, then a rename, so a
/// reader never sees a half-written file and an interrupted job leaves the old file intact.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .ok_or_else(|| SensorError::format(path, "not a file path"))?;
    let tmp = dir.join(format!(
        ".{}.tmp{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(|e| SensorError::io(path, e))
}

fn decode(path: &Path) -> Result<DynamicImage> {
    let bytes = std::fs::read(path).map_err(|e| SensorError::io(path, e))?;
    decode_bytes(&bytes, path)
}

fn decode_bytes(bytes: &[u8], path: &Path) -> Result<DynamicImage> {
    image::load_from_memory_with_format(bytes, ImageFormat::Png)
        .map_err(|e| SensorError::format(path, format!("not a readable PNG: {e}")))
}

/// Read a 16-bit single-channel PNG of depths in mm. Refused: other bit depths or channel counts
/// (an 8-bit PNG would silently lose depth), corrupt or truncated files.
pub fn read_depth_png(path: &Path) -> Result<DepthImage> {
    let bytes = std::fs::read(path).map_err(|e| SensorError::io(path, e))?;
    decode_depth_png(&bytes, path)
}

/// [`read_depth_png`] on bytes already in memory; `path` names them in errors.
pub fn decode_depth_png(bytes: &[u8], path: &Path) -> Result<DepthImage> {
    match decode_bytes(bytes, path)? {
        DynamicImage::ImageLuma16(img) => {
            let (w, h) = img.dimensions();
            DepthImage::from_data(w, h, img.into_raw())
        }
        other => Err(SensorError::format(
            path,
            format!(
                "expected a 16-bit grayscale depth PNG, found {:?}",
                other.color()
            ),
        )),
    }
}

/// Write a depth image as a 16-bit grayscale PNG (atomically).
pub fn write_depth_png(path: &Path, depth: &DepthImage) -> Result<()> {
    let img: ImageBuffer<Luma<u16>, Vec<u16>> =
        ImageBuffer::from_raw(depth.width, depth.height, depth.data.clone())
            .ok_or_else(|| SensorError::arg("depth", "size mismatch"))?;
    let mut buf = std::io::Cursor::new(Vec::new());
    img.write_to(&mut buf, ImageFormat::Png)
        .map_err(|e| SensorError::format(path, e.to_string()))?;
    write_atomic(path, buf.get_ref())
}

/// Read an 8-bit RGB (or RGBA, alpha dropped) PNG.
pub fn read_color_png(path: &Path) -> Result<ColorImage> {
    match decode(path)? {
        DynamicImage::ImageRgb8(img) => {
            let (w, h) = img.dimensions();
            ColorImage::from_data(w, h, img.into_raw())
        }
        DynamicImage::ImageRgba8(img) => {
            let (w, h) = img.dimensions();
            let rgb = DynamicImage::ImageRgba8(img).to_rgb8();
            ColorImage::from_data(w, h, rgb.into_raw())
        }
        other => Err(SensorError::format(
            path,
            format!("expected an 8-bit RGB PNG, found {:?}", other.color()),
        )),
    }
}

/// Write an RGB image as PNG (atomically).
pub fn write_color_png(path: &Path, color: &ColorImage) -> Result<()> {
    let img: ImageBuffer<Rgb<u8>, Vec<u8>> =
        ImageBuffer::from_raw(color.width, color.height, color.data.clone())
            .ok_or_else(|| SensorError::arg("color", "size mismatch"))?;
    let mut buf = std::io::Cursor::new(Vec::new());
    img.write_to(&mut buf, ImageFormat::Png)
        .map_err(|e| SensorError::format(path, e.to_string()))?;
    write_atomic(path, buf.get_ref())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_round_trip_and_bad_files() {
        let dir = std::env::temp_dir().join(format!("hands-png-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp");
        let mut d = DepthImage::zeros(7, 5);
        d.data[3] = 65535;
        d.data[10] = 412;
        let p = dir.join("d.png");
        write_depth_png(&p, &d).expect("write");
        assert_eq!(read_depth_png(&p).expect("read"), d);
        // Truncated file.
        let bytes = std::fs::read(&p).expect("bytes");
        std::fs::write(dir.join("t.png"), &bytes[..bytes.len() / 2]).expect("w");
        assert!(read_depth_png(&dir.join("t.png")).is_err());
        // Wrong bit depth: an RGB PNG is not a depth image.
        let c = ColorImage::zeros(4, 4);
        write_color_png(&dir.join("c.png"), &c).expect("w");
        let err = read_depth_png(&dir.join("c.png")).expect_err("rgb as depth");
        assert!(err.to_string().contains("16-bit"), "{err}");
        assert!(read_depth_png(&dir.join("missing.png")).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
