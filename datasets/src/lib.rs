//! # datasets — dataset readers and synthetic ground truth
//!
//! The synthetic side of issue 3 and the dataset side of issue 7:
//! - [`motion`]: a library of named, seeded, smooth hand motions (the Handy sub-sequences and
//!   the three axes of thesis Fig. 3.16) producing the pose of a sphere-mesh template at any
//!   time, with speed statistics and the automatic choice of calibration frames;
//! - [`subjects`]: hand shapes as honline β vectors over the default template — fixed named
//!   subjects and seeded random ones within anatomical ranges.
//!
//! Still to come: readers for the Handy/teaser layout, NYU and Dexter-1, and the renderer of
//! synthetic depth sequences with exact ground truth (pose, shape and the 21 keypoints of
//! DESIGN.md).

pub mod error;
pub mod motion;
pub mod subjects;

pub use error::{DatasetError, Result};
pub use motion::{Motion, MotionLibrary};
pub use subjects::{subject_by_name, Subject};

use std::sync::OnceLock;

use hand_model::spheremesh::{default_right_hand, SphereMeshTemplate};

/// The default right-hand template, built once.
pub(crate) fn default_template() -> &'static SphereMeshTemplate {
    static T: OnceLock<SphereMeshTemplate> = OnceLock::new();
    T.get_or_init(default_right_hand)
}
