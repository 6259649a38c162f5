//! The per-frame record shared by `groundtruth.jsonl`, `track.jsonl` and the MCAP `/hand/*`
//! channels (DESIGN.md "Tracker output"). Unknown keys are ignored when reading.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// One frame of ground truth or tracker output.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct HandRecord {
    /// Frame index.
    pub frame: u64,
    /// Timestamp (s).
    pub timestamp: f64,
    /// Pose by DOF name.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub pose: BTreeMap<String, f64>,
    /// Shape by parameter name (when calibrating, or synthetic ground truth).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub shape: BTreeMap<String, f64>,
    /// Per-parameter certainty of the shape (diagonal of the information matrix).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub shape_certainty: BTreeMap<String, f64>,
    /// The 21 keypoints in the camera frame (mm), DESIGN.md order; empty when unknown.
    #[serde(default)]
    pub keypoints: Vec<[f64; 3]>,
    /// Energy per term.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub energies: BTreeMap<String, f64>,
    /// Solver iterations.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iterations: Option<u32>,
    /// Wall time per stage (µs).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub timing_us: BTreeMap<String, f64>,
    /// Flags such as `lost`, `reinitialized`, `no_hand`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub flags: Vec<String>,
}

impl HandRecord {
    /// Whether every number is finite (records with NaN are never written).
    pub fn is_finite(&self) -> bool {
        self.timestamp.is_finite()
            && self
                .pose
                .values()
                .chain(self.shape.values())
                .chain(self.shape_certainty.values())
                .chain(self.energies.values())
                .all(|v| v.is_finite())
            && self.keypoints.iter().flatten().all(|v| v.is_finite())
    }
}
