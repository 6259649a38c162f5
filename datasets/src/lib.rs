//! # datasets — dataset readers and synthetic ground truth
//!
//! The synthetic side of issue 3 and the dataset side of issue 7:
//! - [`motion`]: a library of named, seeded, smooth hand motions (the Handy sub-sequences and
//!   the three axes of thesis Fig. 3.16) producing the pose of a sphere-mesh template at any
//!   time, with speed statistics and the automatic choice of calibration frames;
//! - [`subjects`]: hand shapes as honline β vectors over the default template — fixed named
//!   subjects and seeded random ones within anatomical ranges.
//!
//! - [`noise`]: depth-sensor models (noise-free, quantized, time of flight, structured light);
//! - [`synth`]: synthetic depth + RGB frames (hand, forearm, blue wristband, wall) with exact
//!   ground truth (pose, shape and the 21 keypoints of DESIGN.md);
//! - [`sheet`]: contact sheets of depth frames with keypoints;
//! - [`animbank`]: the RealSense recorded-pose corpus, retargeted to our digit DOFs;
//! - [`prior`]: the pose corpus and the project's own PCA pose prior (thesis §2.3.2);
//! - [`scans`]: OBJ photogrammetry scans and the original authors' fitted sphere-meshes, the
//!   real data of offline multi-frame calibration (issue 6, thesis §3.4).
//!
//!
//! Dataset readers (issue 7), each refusing truncated or corrupt files with the file and line
//! named:
//! - [`handy`]: the Handy/teaser sequence layout (`depth-%07d.png`, `color-%07d.png`,
//!   `marker_positions.txt`);
//! - [`nyu`]: NYU depth PNGs (`(G << 8) | B`) and 14-joint uvd labels → camera-frame mm;
//! - [`dexter`]: Dexter-1 Pos3D fingertip ground truth, ToF depth frames and htrack's 24-joint
//!   outputs;
//! - [`text`]: the numeric text parsing they share; [`reference`](mod@reference): where tests find
//!   `shared/reference`.

pub mod animbank;
pub mod dexter;
pub mod error;
pub mod handy;
pub mod mesh;
pub mod motion;
pub mod noise;
pub mod nyu;
pub mod prior;
pub mod reference;
pub mod scans;
pub mod sheet;
pub mod subjects;
pub mod synth;
pub mod text;

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
