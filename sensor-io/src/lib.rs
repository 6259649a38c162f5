//! # sensor-io — depth input for the `hands` workspace
//!
//! Not built yet (issue 3). This crate will hold:
//! - depth (`u16` mm) and optional RGB frames with timestamps;
//! - pinhole cameras (OpenCV optical frame, DESIGN.md) with projection, back-projection and
//!   the 2×3 projection Jacobian, plus the presets of the papers (SR300/Handy, Creative/Dexter, NYU);
//! - streaming sequence I/O in the folder and MCAP formats of DESIGN.md;
//! - preprocessing: wristband and depth-only hand segmentation, median downsampling, point
//!   subsampling, normals, and the exact Euclidean distance transform of the silhouette.
