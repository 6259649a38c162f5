//! The NYU hand pose dataset (Tompson et al. 2014; ANCHOR-FACTS §6.1, `shared/reference`
//! README): depth frames `depth_1_%07d.png` (camera 1, frames from 1) that store the depth in mm
//! as `(G << 8) | B` of an 8-bit RGB PNG, and the 14-joint test labels / published predictions,
//! one line per frame of 14 × (u, v, d) (pixel column, row from the top, depth mm).
//!
//! Joints are converted to the DESIGN.md camera frame (x right, y down, z forward, mm) with the
//! NYU intrinsics ([`Camera::nyu_vga`]: fx = 588.03, fy = 587.07, c = (320, 240)):
//! `x = (u − cx)·d/fx`, `y = (v − cy)·d/fy`, `z = d`.

use std::path::{Path, PathBuf};

use sensor_io::io::read_color_png;
use sensor_io::{Camera, DepthImage};

use crate::error::Result;
use crate::text::{parse_point_rows, read_text};

/// Joints per NYU label line.
pub const NYU_JOINTS: usize = 14;

/// The 14 evaluated joints in file order (the usual subset of NYU's 36: per finger from pinky
/// to index the tip and a middle joint, then the thumb's tip, middle and base, two wrist points
/// and the palm center).
pub const NYU_JOINT_NAMES: [&str; NYU_JOINTS] = [
    "pinky_tip",
    "pinky_mid",
    "ring_tip",
    "ring_mid",
    "middle_tip",
    "middle_mid",
    "index_tip",
    "index_mid",
    "thumb_tip",
    "thumb_mid",
    "thumb_base",
    "wrist_1",
    "wrist_2",
    "palm_center",
];

/// The 14 joints of one frame, each `[u, v, d]` (px, px, mm) or `[x, y, z]` (mm).
pub type NyuJoints = [[f64; 3]; NYU_JOINTS];

/// Parse a 14-joint uvd file (ground truth or predictions); `source` names it in errors.
/// Refused, with the file and line named: a line without exactly 42 numbers, a token that is
/// not a finite number. Blank lines are skipped.
pub fn parse_uvd_labels(text: &str, source: &Path) -> Result<Vec<NyuJoints>> {
    parse_point_rows::<NYU_JOINTS>(text, source)
}

/// Read a 14-joint uvd file ([`parse_uvd_labels`]).
pub fn read_uvd_labels(path: &Path) -> Result<Vec<NyuJoints>> {
    parse_uvd_labels(&read_text(path)?, path)
}

/// Joints (u, v, d) → camera frame (mm) with `camera`'s intrinsics (module docs).
pub fn uvd_to_xyz(joints: &NyuJoints, camera: &Camera) -> NyuJoints {
    joints.map(|[u, v, d]| camera.backproject(u, v, d).into())
}

/// Read a 14-joint uvd file and convert every frame to the camera frame with the NYU camera.
pub fn read_xyz_labels(path: &Path) -> Result<Vec<NyuJoints>> {
    let cam = Camera::nyu_vga();
    Ok(read_uvd_labels(path)?
        .iter()
        .map(|j| uvd_to_xyz(j, &cam))
        .collect())
}

/// The depth file of frame `frame` (1-based, as in the dataset) of camera `camera_index`
/// (1–3) in `dir`: `depth_<camera>_<frame:07>.png`.
pub fn depth_path(dir: &Path, camera_index: u32, frame: u32) -> PathBuf {
    dir.join(format!("depth_{camera_index}_{frame:07}.png"))
}

/// Read an NYU depth PNG: 8-bit RGB with depth (mm) = `(G << 8) | B`. The values are kept as
/// stored (NYU marks missing depth with large values, e.g. the 2001 mm background that the
/// original trackers zero). Refused: unreadable or non-RGB PNGs, named by path.
pub fn read_depth(path: &Path) -> Result<DepthImage> {
    let rgb = read_color_png(path)?;
    let data = rgb
        .data
        .chunks_exact(3)
        .map(|p| ((p[1] as u16) << 8) | p[2] as u16)
        .collect();
    Ok(DepthImage::from_data(rgb.width, rgb.height, data)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use sensor_io::io::write_color_png;
    use sensor_io::ColorImage;

    fn line(k: usize) -> String {
        (0..NYU_JOINTS)
            .map(|j| format!("{} {} {}", 300 + j + k, 200 + j, 700.5))
            .collect::<Vec<_>>()
            .join(" ")
    }

    #[test]
    fn labels_parse_convert_and_refuse_truncation() {
        let text = format!("{}\n{}\n", line(0), line(1));
        let f = Path::new("labels.txt");
        let frames = parse_uvd_labels(&text, f).unwrap();
        assert_eq!(frames.len(), 2);
        assert_eq!(frames[1][2], [303.0, 202.0, 700.5]);
        // The principal point back-projects onto the optical axis; one focal length off it
        // is at x = d.
        let cam = Camera::nyu_vga();
        let mut j = frames[0];
        j[0] = [cam.cx, cam.cy, 800.0];
        j[1] = [cam.cx + cam.fx, cam.cy - cam.fy, 500.0];
        let xyz = uvd_to_xyz(&j, &cam);
        assert_eq!(xyz[0], [0.0, 0.0, 800.0]);
        assert!((xyz[1][0] - 500.0).abs() < 1e-9 && (xyz[1][1] + 500.0).abs() < 1e-9);
        let truncated = format!("{}\n{}", line(0), &line(1)[..40]);
        let e = parse_uvd_labels(&truncated, f).unwrap_err().to_string();
        assert!(
            e.contains("labels.txt, line 2") && e.contains("expected 42"),
            "{e}"
        );
    }

    #[test]
    fn depth_png_round_trip() {
        let dir = std::env::temp_dir().join(format!("nyu-fixture-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut img = ColorImage::zeros(4, 2);
        for (k, px) in img.data.chunks_exact_mut(3).enumerate() {
            let d = 600 + 300 * k as u16; // crosses the 256 boundary of the G byte
            px.copy_from_slice(&[17, (d >> 8) as u8, (d & 0xff) as u8]);
        }
        let p = depth_path(&dir, 1, 1);
        assert!(p.ends_with("depth_1_0000001.png"));
        write_color_png(&p, &img).unwrap();
        let d = read_depth(&p).unwrap();
        assert_eq!((d.width, d.height), (4, 2));
        assert_eq!(d.data, (0..8).map(|k| 600 + 300 * k).collect::<Vec<u16>>());
        std::fs::write(dir.join("bad.png"), b"\x89PNG\r\n\x1a\ntruncated").unwrap();
        let e = read_depth(&dir.join("bad.png")).unwrap_err().to_string();
        assert!(e.contains("bad.png"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
