//! # hand-model — the shared foundation of `hands`
//!
//! Kinematics, geometry and templates shared by every tracker of the workspace:
//! - [`shape`]: sphere-mesh shapes as plain data (spheres, pills, wedges; thesis §3.1).
//!
//! Units are millimetres and radians; frames follow `DESIGN.md` (model frame: origin at the back
//! of the palm near the wrist, +y toward the fingertips, palm facing −z; camera frame: OpenCV).

pub mod query;
pub mod shape;
