//! The 21 keypoints compared across methods and against ground truth (DESIGN.md), and handedness.

use serde::{Deserialize, Serialize};

/// Number of keypoints.
pub const NUM_KEYPOINTS: usize = 21;

/// Keypoint names in DESIGN.md order: wrist; thumb CMC, MCP, IP, tip; then MCP, PIP, DIP, tip
/// for index, middle, ring and pinky.
pub const KEYPOINT_NAMES: [&str; NUM_KEYPOINTS] = [
    "wrist",
    "thumb_cmc",
    "thumb_mcp",
    "thumb_ip",
    "thumb_tip",
    "index_mcp",
    "index_pip",
    "index_dip",
    "index_tip",
    "middle_mcp",
    "middle_pip",
    "middle_dip",
    "middle_tip",
    "ring_mcp",
    "ring_pip",
    "ring_dip",
    "ring_tip",
    "pinky_mcp",
    "pinky_pip",
    "pinky_dip",
    "pinky_tip",
];

/// How one keypoint is read off a posed model.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum KeypointDef {
    /// A joint: the origin (rotation center) of a bone.
    Joint {
        /// The bone.
        bone: usize,
    },
    /// A fingertip: the far surface point of the tip sphere along the bone's +y axis.
    Tip {
        /// The distal bone.
        bone: usize,
        /// The tip sphere.
        sphere: usize,
    },
}

/// Which hand a template or sequence shows.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Handedness {
    /// Right hand: thumb toward −x in the model frame (DESIGN.md).
    Right,
    /// Left hand: thumb toward +x (the geometry of the original hmodel/honline files).
    Left,
}

impl Handedness {
    /// The other hand.
    pub fn other(self) -> Self {
        match self {
            Handedness::Right => Handedness::Left,
            Handedness::Left => Handedness::Right,
        }
    }
}

/// Refuse a keypoint list whose length is not [`NUM_KEYPOINTS`], naming the file and field.
pub(crate) fn check_keypoint_count(source: &std::path::Path, len: usize) -> crate::Result<()> {
    if len != NUM_KEYPOINTS {
        return Err(crate::ModelError::field(
            source,
            "keypoints",
            None,
            format!("{len} keypoints, expected {NUM_KEYPOINTS}"),
        ));
    }
    Ok(())
}
