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
    /// An empty record of frame `index` at `timestamp` (s; a non-finite one is written as 0).
    pub fn for_frame(index: u64, timestamp: f64) -> Self {
        Self {
            frame: index,
            timestamp: if timestamp.is_finite() {
                timestamp
            } else {
                0.0
            },
            ..Self::default()
        }
    }

    /// Add per-term energies, summing repeated names and skipping non-finite values (a record
    /// never holds NaN).
    pub fn add_energies<'a>(&mut self, energies: impl IntoIterator<Item = (&'a str, f64)>) {
        for (name, e) in energies {
            if e.is_finite() {
                *self.energies.entry(name.to_string()).or_default() += e;
            }
        }
    }

    /// The pose by DOF name and the keypoints (camera frame, mm).
    pub fn set_pose<'a>(
        &mut self,
        names: impl IntoIterator<Item = &'a str>,
        values: &[f64],
        keypoints: &[nalgebra::Vector3<f64>],
    ) {
        for (name, v) in names.into_iter().zip(values) {
            self.pose.insert(name.to_string(), *v);
        }
        self.keypoints = keypoints.iter().map(|k| [k.x, k.y, k.z]).collect();
    }

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
