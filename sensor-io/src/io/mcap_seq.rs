//! The MCAP sequence format of DESIGN.md.
//!
//! Channels: `/camera/depth` and `/camera/color` as `foxglove.RawImage` (`16UC1` mm, `rgb8`),
//! `/camera/calibration` as `foxglove.CameraCalibration` (once, at the first frame), and
//! `/hand/groundtruth` / `/hand/track` with the [`HandRecord`] schema `hands.HandRecord`.
//!
//! Encoding: JSON messages with JSON-Schema schemas. Foxglove opens JSON-encoded well-known
//! schemas (bytes fields as base64), the schemas are embedded in the file so it is
//! self-describing, and no protobuf code generation or descriptor sets are needed; the 4/3
//! base64 overhead is absorbed by the zstd chunk compression (a depth frame of hand data
//! compresses about 3× either way). Readers stream with `mcap::io::MessageReader` and hold one
//! frame at a time.

use std::fs::File;
use std::io::{BufReader, BufWriter};
use std::path::{Path, PathBuf};

use base64::Engine as _;
use serde_json::{json, Value};

use super::{SequenceReader, SequenceWriter};
use crate::camera::Camera;
use crate::error::{Result, SensorError};
use crate::image::{ColorImage, DepthImage, Frame};
use crate::record::HandRecord;

/// Largest MCAP record or chunk accepted when reading (bytes): far above a VGA depth frame in
/// JSON (≈ 0.8 MB) yet small enough that a corrupt length cannot exhaust memory.
pub const MAX_RECORD_BYTES: usize = 64 << 20;

/// Topic of depth images.
pub const DEPTH_TOPIC: &str = "/camera/depth";
/// Topic of color images.
pub const COLOR_TOPIC: &str = "/camera/color";
/// Topic of the camera calibration.
pub const CALIBRATION_TOPIC: &str = "/camera/calibration";
/// Topic of the ground truth.
pub const GROUNDTRUTH_TOPIC: &str = "/hand/groundtruth";
/// Topic of tracker output.
pub const TRACK_TOPIC: &str = "/hand/track";

const RAW_IMAGE_SCHEMA: &str = r#"{"title":"foxglove.RawImage","type":"object","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}},"frame_id":{"type":"string"},"width":{"type":"integer"},"height":{"type":"integer"},"encoding":{"type":"string"},"step":{"type":"integer"},"data":{"type":"string","contentEncoding":"base64"}}}"#;
const CALIBRATION_SCHEMA: &str = r#"{"title":"foxglove.CameraCalibration","type":"object","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}},"frame_id":{"type":"string"},"width":{"type":"integer"},"height":{"type":"integer"},"distortion_model":{"type":"string"},"D":{"type":"array","items":{"type":"number"}},"K":{"type":"array","items":{"type":"number"}},"R":{"type":"array","items":{"type":"number"}},"P":{"type":"array","items":{"type":"number"}}}}"#;
const HAND_SCHEMA: &str = r#"{"title":"hands.HandRecord","type":"object","properties":{"frame":{"type":"integer"},"timestamp":{"type":"number"},"pose":{"type":"object","additionalProperties":{"type":"number"}},"shape":{"type":"object","additionalProperties":{"type":"number"}},"shape_certainty":{"type":"object","additionalProperties":{"type":"number"}},"keypoints":{"type":"array","items":{"type":"array","items":{"type":"number"},"minItems":3,"maxItems":3}},"energies":{"type":"object","additionalProperties":{"type":"number"}},"iterations":{"type":"integer"},"timing_us":{"type":"object","additionalProperties":{"type":"number"}},"flags":{"type":"array","items":{"type":"string"}}}}"#;

fn stamp(t: f64) -> Value {
    let ns = (t.max(0.0) * 1e9).round() as u64;
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

fn log_time(t: f64) -> u64 {
    (t.max(0.0) * 1e9).round() as u64
}

/// Streaming MCAP writer (to a temporary file renamed into place by `finish`).
pub struct McapWriter {
    path: PathBuf,
    tmp: PathBuf,
    writer: Option<mcap::Writer<BufWriter<File>>>,
    camera: Camera,
    channels: [u16; 5],
    sequence: u32,
    wrote_calibration: bool,
    record_topic: &'static str,
}

impl McapWriter {
    /// Create a writer; records go to `/hand/groundtruth`.
    pub fn create(path: &Path, camera: &Camera) -> Result<Self> {
        Self::create_with_record_topic(path, camera, GROUNDTRUTH_TOPIC)
    }

    /// Create a writer whose records go to `record_topic` (`/hand/groundtruth` or `/hand/track`).
    pub fn create_with_record_topic(
        path: &Path,
        camera: &Camera,
        record_topic: &'static str,
    ) -> Result<Self> {
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let tmp = dir.join(format!(
            ".{}.tmp{}",
            path.file_name().unwrap_or_default().to_string_lossy(),
            std::process::id()
        ));
        let file = File::create(&tmp).map_err(|e| SensorError::io(&tmp, e))?;
        let m = |e: mcap::McapError| SensorError::format(path, e.to_string());
        let mut w = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile("")
            .create(BufWriter::new(file))
            .map_err(m)?;
        let img = w
            .add_schema(
                "foxglove.RawImage",
                "jsonschema",
                RAW_IMAGE_SCHEMA.as_bytes(),
            )
            .map_err(m)?;
        let cal = w
            .add_schema(
                "foxglove.CameraCalibration",
                "jsonschema",
                CALIBRATION_SCHEMA.as_bytes(),
            )
            .map_err(m)?;
        let hand = w
            .add_schema("hands.HandRecord", "jsonschema", HAND_SCHEMA.as_bytes())
            .map_err(m)?;
        let meta = Default::default();
        let channels = [
            w.add_channel(img, DEPTH_TOPIC, "json", &meta).map_err(m)?,
            w.add_channel(img, COLOR_TOPIC, "json", &meta).map_err(m)?,
            w.add_channel(cal, CALIBRATION_TOPIC, "json", &meta)
                .map_err(m)?,
            w.add_channel(hand, record_topic, "json", &meta)
                .map_err(m)?,
            0,
        ];
        Ok(Self {
            path: path.to_path_buf(),
            tmp,
            writer: Some(w),
            camera: camera.clone(),
            channels,
            sequence: 0,
            wrote_calibration: false,
            record_topic,
        })
    }

    fn put(&mut self, channel: usize, t: f64, value: &Value) -> Result<()> {
        let data = serde_json::to_vec(value)
            .map_err(|e| SensorError::format(&self.path, e.to_string()))?;
        let header = mcap::records::MessageHeader {
            channel_id: self.channels[channel],
            sequence: self.sequence,
            log_time: log_time(t),
            publish_time: log_time(t),
        };
        self.sequence += 1;
        let w = self
            .writer
            .as_mut()
            .ok_or_else(|| SensorError::format(&self.path, "writer already finished"))?;
        w.write_to_known_channel(&header, &data)
            .map_err(|e| SensorError::format(&self.path, e.to_string()))
    }

    /// The topic that records are written to.
    pub fn record_topic(&self) -> &str {
        self.record_topic
    }
}

impl SequenceWriter for McapWriter {
    fn write(&mut self, frame: &Frame, record: Option<&HandRecord>) -> Result<()> {
        let t = frame.timestamp;
        if frame.depth.width != self.camera.width || frame.depth.height != self.camera.height {
            return Err(SensorError::arg(
                "frame",
                "depth size differs from the camera",
            ));
        }
        if !self.wrote_calibration {
            let c = &self.camera;
            let cal = json!({"timestamp": stamp(t), "frame_id": "camera", "width": c.width, "height": c.height, "distortion_model": "plumb_bob",
                "D": [0.0, 0.0, 0.0, 0.0, 0.0], "K": [c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0],
                "R": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], "P": [c.fx, 0.0, c.cx, 0.0, 0.0, c.fy, c.cy, 0.0, 0.0, 0.0, 1.0, 0.0]});
            self.put(2, t, &cal)?;
            self.wrote_calibration = true;
        }
        let bytes: Vec<u8> = frame
            .depth
            .data
            .iter()
            .flat_map(|d| d.to_le_bytes())
            .collect();
        let depth = json!({"timestamp": stamp(t), "frame_id": "camera", "width": frame.depth.width, "height": frame.depth.height,
            "encoding": "16UC1", "step": frame.depth.width * 2, "data": base64::engine::general_purpose::STANDARD.encode(&bytes)});
        self.put(0, t, &depth)?;
        if let Some(c) = &frame.color {
            let color = json!({"timestamp": stamp(t), "frame_id": "camera", "width": c.width, "height": c.height,
                "encoding": "rgb8", "step": c.width * 3, "data": base64::engine::general_purpose::STANDARD.encode(&c.data)});
            self.put(1, t, &color)?;
        }
        if let Some(r) = record {
            if !r.is_finite() {
                return Err(SensorError::arg(
                    "record",
                    format!("frame {} holds a non-finite value", r.frame),
                ));
            }
            let v = serde_json::to_value(r)
                .map_err(|e| SensorError::format(&self.path, e.to_string()))?;
            self.put(3, t, &v)?;
        }
        Ok(())
    }

    fn finish(&mut self) -> Result<()> {
        if let Some(mut w) = self.writer.take() {
            w.finish()
                .map_err(|e| SensorError::format(&self.path, e.to_string()))?;
            drop(w);
            std::fs::rename(&self.tmp, &self.path).map_err(|e| SensorError::io(&self.path, e))?;
        }
        Ok(())
    }
}

/// Streaming MCAP reader.
pub struct McapReader {
    path: PathBuf,
    camera: Camera,
    messages: Messages,
    pending: Option<mcap::Message<'static>>,
    index: u64,
}

fn decode_image(path: &Path, v: &Value) -> Result<(u32, u32, String, Vec<u8>)> {
    let field = |k: &str| {
        v.get(k)
            .ok_or_else(|| SensorError::field(path, k, "missing in an image message"))
    };
    let w = field("width")?
        .as_u64()
        .and_then(|x| u32::try_from(x).ok())
        .ok_or_else(|| SensorError::field(path, "width", "not an integer"))?;
    let h = field("height")?
        .as_u64()
        .and_then(|x| u32::try_from(x).ok())
        .ok_or_else(|| SensorError::field(path, "height", "not an integer"))?;
    let enc = field("encoding")?.as_str().unwrap_or_default().to_string();
    let data = field("data")?
        .as_str()
        .ok_or_else(|| SensorError::field(path, "data", "not a base64 string"))?;
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(data)
        .map_err(|e| SensorError::field(path, "data", e.to_string()))?;
    Ok((w, h, enc, bytes))
}

type Messages = mcap::io::MessageReader<BufReader<File>>;

/// The next message, with decoder errors and decoder panics (the `mcap` crate indexes slices with
/// unchecked lengths on some corrupt attachment records — a fuzzing find) turned into an error.
/// Callers stop reading at the first error (a failed frame leaves no pending message), so a
/// stream is never resumed after a decoder panic.
fn guarded_next(messages: &mut Messages, path: &Path) -> Option<Result<mcap::Message<'static>>> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| messages.next())) {
        Ok(None) => None,
        Ok(Some(Ok(m))) => Some(Ok(m)),
        Ok(Some(Err(e))) => Some(Err(SensorError::format(path, format!("corrupt MCAP: {e}")))),
        Err(_) => Some(Err(SensorError::format(
            path,
            "corrupt MCAP (decoder failure)",
        ))),
    }
}

impl McapReader {
    /// Open an MCAP sequence; the camera comes from the first calibration message, which must
    /// precede the first depth image.
    pub fn open(path: &Path) -> Result<Self> {
        let file = File::open(path).map_err(|e| SensorError::io(path, e))?;
        // Bound every record (and chunk, validated before use) so that a corrupt length field
        // gives an error instead of a huge allocation (found by the `mcap_sequence` fuzz target).
        let options = mcap::sans_io::LinearReaderOptions {
            record_length_limit: Some(MAX_RECORD_BYTES),
            prevalidate_chunk_crcs: true,
            ..Default::default()
        };
        let mut messages = mcap::io::MessageReader::new_with_options(BufReader::new(file), options);
        let mut camera = None;
        let mut pending = None;
        while let Some(m) = guarded_next(&mut messages, path) {
            let m = m?;
            match m.channel.topic.as_str() {
                CALIBRATION_TOPIC => {
                    let v: Value = serde_json::from_slice(&m.data)
                        .map_err(|e| SensorError::format(path, format!("calibration: {e}")))?;
                    let k: Vec<f64> = v
                        .get("K")
                        .and_then(|k| k.as_array())
                        .map(|a| a.iter().filter_map(|x| x.as_f64()).collect())
                        .unwrap_or_default();
                    let wh = |key: &str| {
                        v.get(key)
                            .and_then(|x| x.as_u64())
                            .and_then(|x| u32::try_from(x).ok())
                    };
                    let (Some(w), Some(h), 9) = (wh("width"), wh("height"), k.len()) else {
                        return Err(SensorError::field(
                            path,
                            "K",
                            "calibration needs width, height and a 9-entry K",
                        ));
                    };
                    camera = Some(
                        Camera::new("mcap", w, h, k[0], k[4], k[2], k[5])
                            .map_err(|e| SensorError::field(path, "K", e.to_string()))?,
                    );
                }
                DEPTH_TOPIC => {
                    pending = Some(m);
                    break;
                }
                _ => {}
            }
        }
        let camera = camera.ok_or_else(|| {
            SensorError::format(
                path,
                "no /camera/calibration message before the first depth image",
            )
        })?;
        Ok(Self {
            path: path.to_path_buf(),
            camera,
            messages,
            pending,
            index: 0,
        })
    }

    fn read_frame(
        &mut self,
        depth_msg: mcap::Message<'static>,
    ) -> Result<(Frame, Option<HandRecord>)> {
        let p = self.path.clone();
        let v: Value = serde_json::from_slice(&depth_msg.data)
            .map_err(|e| SensorError::format(&p, format!("depth message: {e}")))?;
        let (w, h, enc, bytes) = decode_image(&p, &v)?;
        if enc != "16UC1"
            || bytes.len() != 2 * w as usize * h as usize
            || w != self.camera.width
            || h != self.camera.height
        {
            return Err(SensorError::format(
                &p,
                format!(
                    "depth message {}: {w}×{h} `{enc}` with {} bytes does not match the camera",
                    self.index,
                    bytes.len()
                ),
            ));
        }
        let depth = DepthImage::from_data(
            w,
            h,
            bytes
                .chunks_exact(2)
                .map(|c| u16::from_le_bytes([c[0], c[1]]))
                .collect(),
        )?;
        let t = depth_msg.log_time;
        let mut frame = Frame {
            index: self.index,
            timestamp: t as f64 * 1e-9,
            depth,
            color: None,
        };
        let mut record = None;
        // Messages of the same frame share its log time; the next depth image starts a new frame.
        while let Some(m) = guarded_next(&mut self.messages, &p) {
            let m = m?;
            if m.channel.topic == DEPTH_TOPIC {
                self.pending = Some(m);
                break;
            }
            if m.log_time != t {
                continue;
            }
            match m.channel.topic.as_str() {
                COLOR_TOPIC => {
                    let v: Value = serde_json::from_slice(&m.data)
                        .map_err(|e| SensorError::format(&p, format!("color message: {e}")))?;
                    let (cw, ch, enc, bytes) = decode_image(&p, &v)?;
                    if enc != "rgb8" {
                        return Err(SensorError::format(
                            &p,
                            format!("color encoding `{enc}` (expected rgb8)"),
                        ));
                    }
                    frame.color = Some(ColorImage::from_data(cw, ch, bytes)?);
                }
                GROUNDTRUTH_TOPIC | TRACK_TOPIC => {
                    record = Some(serde_json::from_slice(&m.data).map_err(|e| {
                        SensorError::format(&p, format!("record of frame {}: {e}", self.index))
                    })?);
                }
                _ => {}
            }
        }
        self.index += 1;
        Ok((frame, record))
    }
}

impl SequenceReader for McapReader {
    fn camera(&self) -> &Camera {
        &self.camera
    }

    fn len(&self) -> Option<usize> {
        None
    }

    fn next_frame(&mut self) -> Option<Result<(Frame, Option<HandRecord>)>> {
        let m = self.pending.take()?;
        Some(self.read_frame(m))
    }
}
