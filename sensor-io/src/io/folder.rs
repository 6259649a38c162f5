//! The folder sequence format of DESIGN.md: `camera.json`, `depth/000000.png` (16-bit mm),
//! optional `color/000000.png` (8-bit RGB) and `groundtruth.jsonl`. Streaming: frames are read
//! one at a time; the ground-truth file is read line by line alongside.

use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};

use super::png::{read_color_png, read_depth_png, write_atomic, write_color_png, write_depth_png};
use super::{SequenceReader, SequenceWriter};
use crate::camera::Camera;
use crate::error::{Result, SensorError};
use crate::image::Frame;
use crate::record::HandRecord;

/// Read `camera.json`, naming the missing or invalid field on error.
pub fn read_camera_json(path: &Path) -> Result<Camera> {
    let text = std::fs::read_to_string(path).map_err(|e| SensorError::io(path, e))?;
    parse_camera_json(&text, path)
}

/// [`read_camera_json`] on text already in memory; `path` names it in errors.
pub fn parse_camera_json(text: &str, path: &Path) -> Result<Camera> {
    let v: serde_json::Value = serde_json::from_str(text)
        .map_err(|e| SensorError::format(path, format!("invalid JSON: {e}")))?;
    let num = |k: &str| -> Result<f64> {
        v.get(k)
            .and_then(|x| x.as_f64())
            .ok_or_else(|| SensorError::field(path, k, "missing or not a number"))
    };
    let int = |k: &str| -> Result<u32> {
        v.get(k)
            .and_then(|x| x.as_u64())
            .and_then(|x| u32::try_from(x).ok())
            .ok_or_else(|| SensorError::field(path, k, "missing or not a positive integer"))
    };
    let mut cam = Camera::new(
        v.get("name").and_then(|n| n.as_str()).unwrap_or(""),
        int("width")?,
        int("height")?,
        num("fx")?,
        num("fy")?,
        num("cx")?,
        num("cy")?,
    )
    .map_err(|e| SensorError::field(path, "intrinsics", e.to_string()))?;
    if let Some(u) = v.get("depth_unit_mm") {
        cam.depth_unit_mm = u
            .as_f64()
            .filter(|u| u.is_finite() && *u > 0.0)
            .ok_or_else(|| {
                SensorError::field(path, "depth_unit_mm", "must be a positive number")
            })?;
    }
    Ok(cam)
}

/// Streaming reader of a folder sequence.
pub struct FolderReader {
    root: PathBuf,
    camera: Camera,
    depth_files: Vec<PathBuf>,
    has_color: bool,
    groundtruth: Option<std::io::Lines<BufReader<File>>>,
    next: usize,
}

impl FolderReader {
    /// Open a folder sequence (lists the depth files; reads no frame yet).
    pub fn open(root: &Path) -> Result<Self> {
        let camera = read_camera_json(&root.join("camera.json"))?;
        let depth_dir = root.join("depth");
        let mut depth_files: Vec<PathBuf> = std::fs::read_dir(&depth_dir)
            .map_err(|e| SensorError::io(&depth_dir, e))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "png"))
            .collect();
        depth_files.sort();
        let has_color = root.join("color").is_dir();
        let gt_path = root.join("groundtruth.jsonl");
        let groundtruth = if gt_path.exists() {
            Some(
                BufReader::new(File::open(&gt_path).map_err(|e| SensorError::io(&gt_path, e))?)
                    .lines(),
            )
        } else {
            None
        };
        Ok(Self {
            root: root.to_path_buf(),
            camera,
            depth_files,
            has_color,
            groundtruth,
            next: 0,
        })
    }
}

impl SequenceReader for FolderReader {
    fn camera(&self) -> &Camera {
        &self.camera
    }

    fn len(&self) -> Option<usize> {
        Some(self.depth_files.len())
    }

    fn next_frame(&mut self) -> Option<Result<(Frame, Option<HandRecord>)>> {
        let path = self.depth_files.get(self.next)?.clone();
        let index = self.next as u64;
        self.next += 1;
        Some((|| {
            let depth = read_depth_png(&path)?;
            if depth.width != self.camera.width || depth.height != self.camera.height {
                return Err(SensorError::format(
                    &path,
                    format!(
                        "{}×{} image, camera.json says {}×{}",
                        depth.width, depth.height, self.camera.width, self.camera.height
                    ),
                ));
            }
            let color = if self.has_color {
                let cpath = self
                    .root
                    .join("color")
                    .join(path.file_name().unwrap_or_default());
                if cpath.exists() {
                    let c = read_color_png(&cpath)?;
                    if c.width != depth.width || c.height != depth.height {
                        return Err(SensorError::format(&cpath, "color and depth sizes differ"));
                    }
                    Some(c)
                } else {
                    None
                }
            } else {
                None
            };
            let gt = match self.groundtruth.as_mut().and_then(|l| l.next()) {
                Some(line) => {
                    let gt_path = self.root.join("groundtruth.jsonl");
                    let line = line.map_err(|e| SensorError::io(&gt_path, e))?;
                    let rec: HandRecord = serde_json::from_str(&line).map_err(|e| {
                        SensorError::format(&gt_path, format!("line {}: {e}", index + 1))
                    })?;
                    Some(rec)
                }
                None => None,
            };
            let timestamp = gt.as_ref().map_or(index as f64 / 60.0, |g| g.timestamp);
            Ok((
                Frame {
                    index,
                    timestamp,
                    depth,
                    color,
                },
                gt,
            ))
        })())
    }
}

/// Writer of a folder sequence; `groundtruth.jsonl` is written to a temporary file and moved in
/// place by [`SequenceWriter::finish`], so an interrupted job never leaves a truncated file.
pub struct FolderWriter {
    root: PathBuf,
    gt: Option<BufWriter<File>>,
    gt_tmp: PathBuf,
    count: u64,
}

impl FolderWriter {
    /// Create the folder (and `depth/`, `color/`) and write `camera.json`.
    pub fn create(root: &Path, camera: &Camera) -> Result<Self> {
        for d in [root.to_path_buf(), root.join("depth")] {
            std::fs::create_dir_all(&d).map_err(|e| SensorError::io(&d, e))?;
        }
        let json = serde_json::to_vec_pretty(camera)
            .map_err(|e| SensorError::format(root, e.to_string()))?;
        write_atomic(&root.join("camera.json"), &json)?;
        Ok(Self {
            root: root.to_path_buf(),
            gt: None,
            gt_tmp: root.join(".groundtruth.jsonl.tmp"),
            count: 0,
        })
    }
}

impl SequenceWriter for FolderWriter {
    fn write(&mut self, frame: &Frame, record: Option<&HandRecord>) -> Result<()> {
        let name = format!("{:06}.png", self.count);
        write_depth_png(&self.root.join("depth").join(&name), &frame.depth)?;
        if let Some(c) = &frame.color {
            let dir = self.root.join("color");
            std::fs::create_dir_all(&dir).map_err(|e| SensorError::io(&dir, e))?;
            write_color_png(&dir.join(&name), c)?;
        }
        if let Some(r) = record {
            if !r.is_finite() {
                return Err(SensorError::arg(
                    "record",
                    format!("frame {} holds a non-finite value", r.frame),
                ));
            }
            if self.gt.is_none() {
                let f = File::create(&self.gt_tmp).map_err(|e| SensorError::io(&self.gt_tmp, e))?;
                self.gt = Some(BufWriter::new(f));
            }
            let w = self.gt.as_mut().expect("just created");
            serde_json::to_writer(&mut *w, r)
                .map_err(|e| SensorError::format(&self.gt_tmp, e.to_string()))?;
            w.write_all(b"\n")
                .map_err(|e| SensorError::io(&self.gt_tmp, e))?;
        }
        self.count += 1;
        Ok(())
    }

    fn finish(&mut self) -> Result<()> {
        if let Some(mut w) = self.gt.take() {
            w.flush().map_err(|e| SensorError::io(&self.gt_tmp, e))?;
            let dst = self.root.join("groundtruth.jsonl");
            std::fs::rename(&self.gt_tmp, &dst).map_err(|e| SensorError::io(&dst, e))?;
        }
        Ok(())
    }
}
