//! # hand-model — the shared foundation of `hands`
//!
//! Kinematics, geometry and templates shared by every tracker of the workspace:
//! - [`kinematics`]: bone trees with rest frames `T̄` and named DOFs, forward kinematics, the
//!   skeleton Jacobian `∂p/∂θ` (thesis Eq. 3.7) and the multiplicative global rotation update;
//! - [`shape`]: sphere-mesh shapes as plain data (spheres, pills, wedges; thesis §3.1);
//! - [`spheremesh`]: the sphere-mesh template, its posing, the honline shape vector β with its
//!   Jacobian `∂c/∂β` and latent scaling (Eq. 4.14), the JSON format and the hmodel/honline
//!   importers;
//! - [`cylinder`]: the Ch. 2 cylinder model (26 DOF) with its front-facing projection and the
//!   htrack `.calib` importer;
//! - [`keypoints`]: the 21 keypoints of DESIGN.md and handedness;
//! - [`query`]: closest points on pills and wedges, the implicit function φ (Eq. 3.1–3.2, 3.6),
//!   model-wide projection and the monocular front-facing correspondences (Fig. 3.9);
//! - [`render`]: exact ray casting of elements, a tiled CPU depth renderer (§3.3.2), mesh export
//!   (OBJ, GLB) and PNG previews;
//! - [`solver`]: normal equations, the one trait of every energy term, Levenberg–Marquardt
//!   (Eq. 2.11) with a rigid-first schedule, and the shared prior terms (joint limits, damping,
//!   temporal, projective PCA pose prior);
//! - [`testing`]: finite-difference helpers for Jacobian tests and a shared cylinder test pose.
//!
//! Units are millimetres and radians; frames follow `DESIGN.md` (model frame: origin at the back
//! of the palm near the wrist, +y toward the fingertips, palm facing −z; camera frame: OpenCV).

pub mod cylinder;
pub mod error;
pub mod keypoints;
pub mod kinematics;
pub mod math;
pub mod query;
pub mod render;
pub mod shape;
pub mod solver;
pub mod spheremesh;
pub mod testing;

pub use error::{ModelError, Result};
