//! Image files and sequences on disk (DESIGN.md "Sequences on disk"): the folder format and the
//! MCAP format, behind one streaming reader/writer interface.

mod folder;
mod mcap_seq;
mod png;

use std::path::Path;

pub use folder::{parse_camera_json, read_camera_json, FolderReader, FolderWriter};
pub use mcap_seq::{
    McapReader, McapWriter, CALIBRATION_TOPIC, COLOR_TOPIC, DEPTH_TOPIC, GROUNDTRUTH_TOPIC,
    TRACK_TOPIC,
};
pub use png::{
    decode_depth_png, read_color_png, read_depth_png, write_atomic, write_color_png,
    write_depth_png,
};

use crate::camera::Camera;
use crate::error::Result;
use crate::image::Frame;
use crate::record::HandRecord;

/// A sequence read one frame at a time (never the whole sequence in memory).
pub trait SequenceReader {
    /// The camera of the depth images.
    fn camera(&self) -> &Camera;
    /// Number of frames, when known without reading them.
    fn len(&self) -> Option<usize>;
    /// Whether the sequence is known to be empty.
    fn is_empty(&self) -> bool {
        self.len() == Some(0)
    }
    /// The next frame and its ground truth (if any); `None` at the end.
    fn next_frame(&mut self) -> Option<Result<(Frame, Option<HandRecord>)>>;
}

/// A sequence written one frame at a time.
pub trait SequenceWriter {
    /// Append a frame and its record.
    fn write(&mut self, frame: &Frame, record: Option<&HandRecord>) -> Result<()>;
    /// Flush and move temporary files into place.
    fn finish(&mut self) -> Result<()>;
}

/// Open a sequence: an `.mcap` file or a folder.
pub fn open_sequence(path: &Path) -> Result<Box<dyn SequenceReader>> {
    if is_mcap(path) {
        return Ok(Box::new(McapReader::open(path)?));
    }
    Ok(Box::new(FolderReader::open(path)?))
}

/// Create a sequence writer: `.mcap` paths write MCAP, any other path a folder.
pub fn create_sequence(path: &Path, camera: &Camera) -> Result<Box<dyn SequenceWriter>> {
    if is_mcap(path) {
        return Ok(Box::new(McapWriter::create(path, camera)?));
    }
    Ok(Box::new(FolderWriter::create(path, camera)?))
}

/// Whether a path names an MCAP file (by extension).
pub fn is_mcap(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
}
