//! Dexter-1 (Sridhar et al. 2013; `shared/reference` README, ANCHOR-FACTS §6.3): the "Pos3D"
//! fingertip ground truth and htrack's per-frame outputs on it.
//!
//! - ground truth `<seq>.txt`: per frame 6 lines `x, y, z` (mm; the 5 fingertips, then the
//!   palm), frames separated by a blank line; frames without annotation hold values > 1000;
//! - htrack output `<seq>.txt`: one line per frame of 72 numbers, 24 joints × (x, y, z) mm; the
//!   fingertips are joints 8, 24, 20, 16, 12 (1-based, [`HTRACK_FINGERTIPS`]), paired in that
//!   order with the 5 ground-truth fingertips, whose x must be negated (the dataset's camera is
//!   mirrored with respect to htrack's);
//! - ToF depth frames `%04d.png` (16-bit, mm, 320×240, Creative Senz3D:
//!   [`sensor_io::Camera::creative_qvga`]), where values ≥ [`TOF_NO_DEPTH`] mark pixels without a
//!   measurement (honline's SRIDHAR loader keeps `depth < 32001` as the silhouette candidates).

use std::path::{Path, PathBuf};

use sensor_io::io::read_depth_png;
use sensor_io::DepthImage;

use crate::error::Result;
use crate::text::{parse_error, parse_point_rows, parse_points, read_text};

/// The seven Dexter-1 sequences.
pub const DEXTER_SEQUENCES: [&str; 7] = [
    "adbadd",
    "fingercount",
    "fingerwave",
    "flexex1",
    "pinch",
    "random",
    "tigergrasp",
];

/// ToF depth values at or above this carry no measurement.
pub const TOF_NO_DEPTH: u16 = 32001;

/// The depth file of frame `k` in a sequence folder: `%04d.png`.
pub fn tof_depth_path(dir: &Path, k: usize) -> PathBuf {
    dir.join(format!("{k:04}.png"))
}

/// Read a ToF depth frame (16-bit PNG, mm) with the no-measurement values (≥ [`TOF_NO_DEPTH`])
/// set to 0, the DESIGN.md "no depth". Refused: unreadable, corrupt or non-16-bit PNGs (named).
pub fn read_tof_depth(path: &Path) -> Result<DepthImage> {
    let mut d = read_depth_png(path)?;
    for v in &mut d.data {
        if *v >= TOF_NO_DEPTH {
            *v = 0;
        }
    }
    Ok(d)
}

/// Points per ground-truth frame (5 fingertips + palm).
pub const DEXTER_POINTS: usize = 6;

/// Fingertips per ground-truth frame (its first 5 points).
pub const DEXTER_FINGERTIPS: usize = 5;

/// Joints per htrack output line.
pub const HTRACK_JOINTS: usize = 24;

/// The 0-based htrack joints paired with the ground-truth fingertips 0..5 (1-based 8, 24, 20,
/// 16, 12).
pub const HTRACK_FINGERTIPS: [usize; DEXTER_FINGERTIPS] = [7, 23, 19, 15, 11];

/// Ground-truth coordinates above this (mm, in absolute value) mark an unannotated frame.
pub const INVALID_ABOVE_MM: f64 = 1000.0;

/// One ground-truth frame: 5 fingertips then the palm (mm, as stored).
pub type DexterFrame = [[f64; 3]; DEXTER_POINTS];

/// One htrack output frame: 24 joints (mm).
pub type HtrackJoints = [[f64; 3]; HTRACK_JOINTS];

/// Parse a Pos3D ground-truth file: blocks of 6 `x, y, z` lines separated by blank lines.
/// Refused, with the file and line named: a line without 3 numbers, a block of other than 6
/// lines (a truncated last frame included).
pub fn parse_ground_truth(text: &str, source: &Path) -> Result<Vec<DexterFrame>> {
    let mut frames = Vec::new();
    let mut block: Vec<[f64; 3]> = Vec::with_capacity(DEXTER_POINTS);
    let mut start = 0;
    let mut close = |block: &mut Vec<[f64; 3]>, start: usize| -> Result<()> {
        if block.is_empty() {
            return Ok(());
        }
        let frame: DexterFrame = block.as_slice().try_into().map_err(|_| {
            parse_error(
                source,
                Some(start),
                format!(
                    "frame {} starting here has {} points, expected {DEXTER_POINTS}",
                    frames.len(),
                    block.len()
                ),
            )
        })?;
        frames.push(frame);
        block.clear();
        Ok(())
    };
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            close(&mut block, start)?;
            continue;
        }
        if block.is_empty() {
            start = i + 1;
        }
        block.push(parse_points::<1>(line, source, i + 1)?[0]);
        if block.len() > DEXTER_POINTS {
            return Err(parse_error(
                source,
                Some(i + 1),
                format!("more than {DEXTER_POINTS} points without a blank line"),
            ));
        }
    }
    close(&mut block, start)?;
    Ok(frames)
}

/// Read a Pos3D ground-truth file ([`parse_ground_truth`]).
pub fn read_ground_truth(path: &Path) -> Result<Vec<DexterFrame>> {
    parse_ground_truth(&read_text(path)?, path)
}

/// Parse an htrack output file: one line of 72 numbers per frame. Refused, with the file and
/// line named: a line of another length, a token that is not a finite number.
pub fn parse_htrack_output(text: &str, source: &Path) -> Result<Vec<HtrackJoints>> {
    parse_point_rows::<HTRACK_JOINTS>(text, source)
}

/// Read an htrack output file ([`parse_htrack_output`]).
pub fn read_htrack_output(path: &Path) -> Result<Vec<HtrackJoints>> {
    parse_htrack_output(&read_text(path)?, path)
}

/// Whether a ground-truth frame is annotated (no coordinate above [`INVALID_ABOVE_MM`]).
pub fn is_annotated(frame: &DexterFrame) -> bool {
    frame.iter().flatten().all(|c| c.abs() <= INVALID_ABOVE_MM)
}

/// The 5 ground-truth fingertips in htrack's camera frame (x negated).
pub fn fingertips_for_htrack(frame: &DexterFrame) -> [[f64; 3]; DEXTER_FINGERTIPS] {
    std::array::from_fn(|k| [-frame[k][0], frame[k][1], frame[k][2]])
}

/// htrack's 5 fingertips of one output frame, in ground-truth order.
pub fn htrack_fingertips(joints: &HtrackJoints) -> [[f64; 3]; DEXTER_FINGERTIPS] {
    HTRACK_FINGERTIPS.map(|j| joints[j])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gt_block(base: f64) -> String {
        (0..6)
            .map(|k| format!("{}, {}, {}\n", base + k as f64, -2.5, 300))
            .collect()
    }

    #[test]
    fn ground_truth_blocks_and_errors() {
        let f = Path::new("seq.txt");
        let text = format!(
            "{}\n{}\n{}",
            gt_block(1.0),
            gt_block(10.0),
            gt_block(2000.0)
        );
        let frames = parse_ground_truth(&text, f).unwrap();
        assert_eq!(frames.len(), 3);
        assert_eq!(frames[1][5], [15.0, -2.5, 300.0]);
        assert!(is_annotated(&frames[0]) && !is_annotated(&frames[2]));
        assert_eq!(fingertips_for_htrack(&frames[0])[1], [-2.0, -2.5, 300.0]);
        // A truncated last frame names its first line.
        let cut = format!("{}\n1, 2, 3\n4, 5, 6\n", gt_block(1.0));
        let e = parse_ground_truth(&cut, f).unwrap_err().to_string();
        assert!(
            e.contains("seq.txt, line 8") && e.contains("2 points"),
            "{e}"
        );
        let bad = format!("{}\n1, 2\n", gt_block(1.0));
        let e = parse_ground_truth(&bad, f).unwrap_err().to_string();
        assert!(e.contains("line 8"), "{e}");
        let run_on = format!("{}{}", gt_block(1.0), gt_block(1.0));
        assert!(parse_ground_truth(&run_on, f).is_err());
        assert!(parse_ground_truth("", f).unwrap().is_empty());
    }

    #[test]
    fn tof_depth_fixture() {
        let dir = std::env::temp_dir().join(format!("dexter-tof-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let d = DepthImage::from_data(3, 1, vec![450, 32001, 65535]).unwrap();
        let p = tof_depth_path(&dir, 7);
        assert!(p.ends_with("0007.png"));
        sensor_io::io::write_depth_png(&p, &d).unwrap();
        assert_eq!(read_tof_depth(&p).unwrap().data, vec![450, 0, 0]);
        std::fs::write(&p, b"not a png").unwrap();
        let e = read_tof_depth(&p).unwrap_err().to_string();
        assert!(e.contains("0007.png"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn htrack_rows_and_fingertips() {
        let f = Path::new("out.txt");
        let row: Vec<String> = (0..72).map(|i| i.to_string()).collect();
        let text = format!("{}\n{}\n", row.join(" "), row.join("  "));
        let frames = parse_htrack_output(&text, f).unwrap();
        assert_eq!(frames.len(), 2);
        // Joint 8 (1-based) holds columns 21..24.
        assert_eq!(htrack_fingertips(&frames[0])[0], [21.0, 22.0, 23.0]);
        assert_eq!(htrack_fingertips(&frames[0])[1], [69.0, 70.0, 71.0]);
        let e = parse_htrack_output(&format!("{}\n1 2 3\n", row.join(" ")), f)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("out.txt, line 2") && e.contains("expected 72"),
            "{e}"
        );
    }
}
