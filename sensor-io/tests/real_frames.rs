//! Issue 3, real-data checks: the depth-only segmentation on the real NYU test frame 1 (all 14
//! ground-truth joints inside or within 5 px of the silhouette; no segmented point farther than
//! 150 mm from the palm joint) and on two other real frames (one hand-sized blob each).
//! Each test says that it skipped when `../shared/reference` is absent.

use std::path::{Path, PathBuf};

use sensor_io::dt::DistanceTransform;
use sensor_io::io::read_depth_png;
use sensor_io::preprocess::{segment_depth_only, DepthOnlyParams, HandSegment, SegmentScratch};
use sensor_io::{Camera, DepthImage};

fn reference(rel: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/reference")
        .join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("skipped: {} absent", p.display());
        None
    }
}

/// NYU depth PNGs store depth = (G << 8) | B in an RGB image.
fn read_nyu_depth(path: &Path) -> DepthImage {
    let img = image::open(path).expect("nyu png").to_rgb8();
    let (w, h) = img.dimensions();
    let data = img
        .pixels()
        .map(|p| ((p[1] as u16) << 8) | p[2] as u16)
        .collect();
    DepthImage::from_data(w, h, data).expect("size")
}

fn segment(depth: &DepthImage, cam: &Camera) -> HandSegment {
    let mut seg = HandSegment::default();
    segment_depth_only(
        depth,
        cam,
        &DepthOnlyParams::default(),
        &mut seg,
        &mut SegmentScratch::default(),
    );
    seg
}

#[test]
fn nyu_frame_hand_is_isolated() {
    let (Some(png), Some(labels)) = (
        reference("nyu/depth_1_0000001.png"),
        reference("nyu/nyu_test_groundtruth_label_14joints_uvd.txt"),
    ) else {
        return;
    };
    let mut depth = read_nyu_depth(&png);
    // NYU marks missing depth with large values (background 2001 mm and beyond); keep [150, 1500].
    for d in &mut depth.data {
        if *d > 1500 {
            *d = 0;
        }
    }
    let cam = Camera::nyu_vga();
    let seg = segment(&depth, &cam);
    assert!(seg.count > 500, "no hand found ({} px)", seg.count);
    let line = std::fs::read_to_string(&labels).expect("labels");
    let first: Vec<f64> = line
        .lines()
        .next()
        .expect("line 1")
        .split_whitespace()
        .map(|t| t.parse().expect("number"))
        .collect();
    assert_eq!(first.len(), 42);
    let mut dt = DistanceTransform::default();
    dt.compute(&seg.mask);
    let mut worst_px: f32 = 0.0;
    for j in 0..14 {
        let (u, v) = (first[3 * j].round() as u32, first[3 * j + 1].round() as u32);
        let d = dt.distance(u.min(cam.width - 1), v.min(cam.height - 1));
        worst_px = worst_px.max(d);
        assert!(
            d <= 5.0,
            "joint {j} at ({u},{v}) is {d:.1} px from the silhouette"
        );
    }
    // Palm joint: the last of the 14 NYU joints (index 13) is the palm center.
    let palm = cam.backproject(first[39], first[40], first[41]);
    let w = cam.width as usize;
    let far = seg
        .mask
        .data
        .iter()
        .enumerate()
        .filter(|(_, &m)| m != 0)
        .map(|(i, _)| {
            (cam.backproject((i % w) as f64, (i / w) as f64, depth.data[i] as f64) - palm).norm()
        })
        .fold(0.0, f64::max);
    eprintln!("NYU frame 1: {} px, worst joint distance {worst_px:.1} px, farthest point {far:.1} mm from the palm joint", seg.count);
    assert!(
        far <= 150.0,
        "segmented point {far:.1} mm from the palm joint"
    );
}

#[test]
fn other_real_frames_give_one_hand_blob() {
    if let Some(bin) = reference("single-frames/kinect_640x480_u16le_mm.bin") {
        let bytes = std::fs::read(&bin).expect("bin");
        assert_eq!(bytes.len(), 640 * 480 * 2);
        let mut data: Vec<u16> = bytes
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .collect();
        data.iter_mut().filter(|d| **d >= 2001).for_each(|d| *d = 0);
        let depth = DepthImage::from_data(640, 480, data).expect("size");
        let seg = segment(&depth, &Camera::nyu_vga());
        report_blob("kinect frame", &seg, &depth, &Camera::nyu_vga());
    }
    if let Some(png) = reference("single-frames/hands2017_image_D00000030_u16_mm.png") {
        let depth = read_depth_png(&png).expect("hands2017 png");
        // HANDS2017 frames come from an Intel RealSense SR300 at 640×480 (intrinsics ≈ 475 px).
        let cam = Camera::new(
            "hands2017",
            depth.width,
            depth.height,
            475.065,
            475.065,
            315.944,
            245.287,
        )
        .expect("camera");
        let seg = segment(&depth, &cam);
        report_blob("HANDS2017 frame", &seg, &depth, &cam);
    }
}

fn report_blob(name: &str, seg: &HandSegment, depth: &DepthImage, cam: &Camera) {
    assert!(seg.count > 200, "{name}: no hand found");
    let w = cam.width as usize;
    let pts: Vec<_> = seg
        .mask
        .data
        .iter()
        .enumerate()
        .filter(|(_, &m)| m != 0)
        .map(|(i, _)| cam.backproject((i % w) as f64, (i / w) as f64, depth.data[i] as f64))
        .collect();
    let mut lo = pts[0];
    let mut hi = pts[0];
    for p in &pts {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let ext = hi - lo;
    eprintln!(
        "{name}: {} px, extent {:.0} × {:.0} × {:.0} mm",
        seg.count, ext.x, ext.y, ext.z
    );
    let diag = ext.norm();
    assert!(
        (60.0..=400.0).contains(&diag),
        "{name}: blob of {diag:.0} mm is not hand-sized"
    );
}
