//! The Handy / hmodel "teaser" / honline "guess-who" sequence layout (ANCHOR-FACTS §6.1): a
//! folder with, for frame k (from 0), `depth-%07d.png` (16-bit, mm, 320×240, SR300 QVGA,
//! [`Camera::sr300_qvga`]), optionally `color-%07d.png` (8-bit, registered to depth),
//! `sequence_length.txt` (first line = frame count) and `marker_positions.txt` (honline's
//! `GroundTruthLoader`: a frame count, then per frame 3·M marker coordinates; also read without
//! the count, one frame per line, as `write_model_marker_positions` writes it).
//!
//! The original recorder saved color with `cv::imwrite` from an R,G,B buffer, so the PNG's
//! blue channel holds red (ANCHOR-FACTS §0): [`HandySequence::read_color`] swaps it back.
//! Depth is stored already mirrored as the original trackers consumed it.

use std::path::{Path, PathBuf};

use sensor_io::io::{read_color_png, read_depth_png};
use sensor_io::{Camera, ColorImage, DepthImage, Frame};

use crate::error::Result;
use crate::text::{parse_error, parse_numbers, read_text};

/// Markers per frame of honline's TKACH (Handy) marker files.
pub const HANDY_MARKERS: usize = 25;

/// Frame rate of the SR300 recordings (Hz), for timestamps.
pub const HANDY_FPS: f64 = 60.0;

/// One sequence folder of the Handy layout.
#[derive(Clone, Debug)]
pub struct HandySequence {
    dir: PathBuf,
    frames: usize,
}

impl HandySequence {
    /// Open a folder. The frame count is the first line of `sequence_length.txt` when present,
    /// else the number of consecutive `depth-%07d.png` from 0. Refused: a missing folder, a
    /// bad `sequence_length.txt`, a folder without frame 0.
    pub fn open(dir: &Path) -> Result<Self> {
        if !dir.is_dir() {
            return Err(parse_error(dir, None, "not a Handy sequence folder"));
        }
        let len_file = dir.join("sequence_length.txt");
        let frames = if len_file.exists() {
            let text = read_text(&len_file)?;
            let first = text.lines().next().unwrap_or("");
            match parse_numbers(first, &len_file, 1)?.as_slice() {
                [n] if n.fract() == 0.0 && *n >= 1.0 => *n as usize,
                _ => {
                    return Err(parse_error(
                        &len_file,
                        Some(1),
                        "expected one positive frame count",
                    ))
                }
            }
        } else {
            (0..).take_while(|&k| depth_path(dir, k).exists()).count()
        };
        if frames == 0 {
            return Err(parse_error(
                &depth_path(dir, 0),
                None,
                "no frame 0 in the sequence folder",
            ));
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            frames,
        })
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.frames
    }

    /// Whether the sequence has no frame (never, once opened).
    pub fn is_empty(&self) -> bool {
        self.frames == 0
    }

    /// The camera of the recordings.
    pub fn camera(&self) -> Camera {
        Camera::sr300_qvga()
    }

    /// Depth of frame `k` (mm).
    pub fn read_depth(&self, k: usize) -> Result<DepthImage> {
        Ok(read_depth_png(&depth_path(&self.dir, k))?)
    }

    /// Color of frame `k` with the channels in R, G, B order, or `None` without a color file.
    pub fn read_color(&self, k: usize) -> Result<Option<ColorImage>> {
        let p = self.dir.join(format!("color-{k:07}.png"));
        if !p.exists() {
            return Ok(None);
        }
        let mut c = read_color_png(&p)?;
        for px in c.data.chunks_exact_mut(3) {
            px.swap(0, 2);
        }
        Ok(Some(c))
    }

    /// Frame `k`: depth, color when present, timestamp `k / 60` s.
    pub fn read_frame(&self, k: usize) -> Result<Frame> {
        Ok(Frame {
            index: k as u64,
            timestamp: k as f64 / HANDY_FPS,
            depth: self.read_depth(k)?,
            color: self.read_color(k)?,
        })
    }

    /// The ground-truth markers of `marker_positions.txt` ([`parse_marker_positions`]), or
    /// `None` when the folder has none.
    pub fn markers(&self, markers_per_frame: usize) -> Result<Option<Vec<Vec<[f64; 3]>>>> {
        let p = self.dir.join("marker_positions.txt");
        if !p.exists() {
            return Ok(None);
        }
        parse_marker_positions(&read_text(&p)?, &p, markers_per_frame).map(Some)
    }
}

/// The depth file of frame `k` in `dir`: `depth-%07d.png`.
pub fn depth_path(dir: &Path, k: usize) -> PathBuf {
    dir.join(format!("depth-{k:07}.png"))
}

/// Parse a marker file of `markers_per_frame` points per frame, in either layout: a first line
/// holding only the frame count N followed by N·3·M numbers (any line breaks), or one line of
/// 3·M numbers per frame. Refused, with the file and line named: a non-number, a frame count
/// that the numbers do not fill, a line of another length.
pub fn parse_marker_positions(
    text: &str,
    source: &Path,
    markers_per_frame: usize,
) -> Result<Vec<Vec<[f64; 3]>>> {
    let per_frame = 3 * markers_per_frame;
    if per_frame == 0 {
        return Err(parse_error(source, None, "zero markers per frame"));
    }
    let lines: Vec<(usize, Vec<f64>)> = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| parse_numbers(l, source, i + 1).map(|v| (i + 1, v)))
        .collect::<Result<_>>()?;
    let to_frame = |v: &[f64]| v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    match lines.first() {
        Some((_, head)) if head.len() == 1 && per_frame != 1 => {
            let n = head[0];
            if !(n.fract() == 0.0 && n >= 0.0) {
                return Err(parse_error(source, Some(1), "bad frame count"));
            }
            let values: Vec<f64> = lines[1..].iter().flat_map(|(_, v)| v.clone()).collect();
            let n = n as usize;
            if values.len() != n * per_frame {
                let last = lines.last().map_or(1, |(l, _)| *l);
                return Err(parse_error(
                    source,
                    Some(last),
                    format!(
                        "{} numbers for {n} frames × {markers_per_frame} markers (expected {})",
                        values.len(),
                        n * per_frame
                    ),
                ));
            }
            Ok(values.chunks_exact(per_frame).map(to_frame).collect())
        }
        _ => lines
            .iter()
            .map(|(l, v)| {
                if v.len() == per_frame {
                    Ok(to_frame(v))
                } else {
                    Err(parse_error(
                        source,
                        Some(*l),
                        format!("expected {per_frame} numbers, found {}", v.len()),
                    ))
                }
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn marker_files_in_both_layouts() {
        let f = Path::new("marker_positions.txt");
        let counted = "2\n1 2 3 4 5 6\n7 8 9\n10 11 12\n";
        let a = parse_marker_positions(counted, f, 2).unwrap();
        assert_eq!(
            a,
            vec![
                vec![[1., 2., 3.], [4., 5., 6.]],
                vec![[7., 8., 9.], [10., 11., 12.]]
            ]
        );
        let per_line = "1 2 3 4 5 6\n7 8 9 10 11 12\n";
        assert_eq!(parse_marker_positions(per_line, f, 2).unwrap(), a);
        let e = parse_marker_positions("3\n1 2 3 4 5 6\n", f, 2)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("marker_positions.txt, line 2") && e.contains("3 frames"),
            "{e}"
        );
        let e = parse_marker_positions("1 2 3 4 5 6\n7 8 9 10\n", f, 2)
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2") && e.contains("found 4"), "{e}");
        assert!(parse_marker_positions("1 2 x", f, 1).is_err());
    }
}
