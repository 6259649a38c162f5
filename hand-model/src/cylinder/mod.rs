//! The cylinder hand model of thesis Ch. 2 (htrack, §2.2 "Tracking model").
//!
//! Sixteen sphere-capped, tapered cylinders with an elliptical cross-section, one per bone of a
//! 26-DOF skeleton (6 global + 20 articulations, §2.2). The model is plain data
//! ([`CylinderModel`], [`Segment`]); posing goes through the shared
//! [`crate::kinematics::PosedSkeleton`], so the skeleton Jacobian of any model point is
//! [`crate::kinematics::PosedSkeleton::column`] on the point's bone.
//!
//! - [`query`]: closest points (Eq. 2.2's projection `Π_M`) and the front-facing correspondences
//!   of §2.3.1 "3D correspondences".
//! - [`raycast`]: exact first hit of a ray with a segment ([`Segment::cast_local_ray`]).
//! - [`raster`]: the CPU rasterizer of the rendered silhouette `S_r` of Eq. 2.3 (§2.3.1 "2D
//!   correspondences"): per pixel the segment, bone and camera-frame surface point.
//! - [`default_right_hand_cylinders`]: the project's own right-hand template with the proportions
//!   of the htrack default model.
//! - [`CylinderModel::from_sphere_mesh`]: a cylinder model fitted to a sphere-mesh template
//!   (same bones and DOF names, keypoints that coincide at every pose), to track the synthetic
//!   sequences of sphere-mesh subjects with the Ch. 2 tracker.
//! - [`parse_htrack_calib`] / [`load_htrack_calib`]: the importer of htrack's `.calib` files.
//!
//! # Segment geometry
//! A [`Segment`] lives in the frame of its bone: its axis runs along the bone's local +y from the
//! bone origin to `(0, length, 0)`. At axial parameter `t ∈ [0, 1]` the cross-section is the
//! ellipse with half-axis `r(t) = (1−t)·r1 + t·r2` along local x and `ry(t) = (1−t)·r1y + t·r2y`
//! along local z. The two ends are closed by half-ellipsoids with half-axes `(r, ry, ry)` (local
//! x, y, z) centred on the axis end points; for a circular segment (`r = ry`) these are the
//! hemispheres of a sphere-capped cylinder. This is exactly the shape htrack renders (its
//! "icopill" mesh, scaled by `r` along x and by `ry` along y and z) and the shape its
//! closest-point code projects onto.
//!
//! # Conventions
//! Millimetres and radians; frames as in `DESIGN.md`. Flexion is positive toward the palm,
//! abduction positive toward the thumb side (htrack's signs are the opposite; the importer
//! converts).

mod calib;
mod default;
mod fit;
mod model;
pub mod query;
pub mod raster;
pub mod raycast;

pub use calib::{load_htrack_calib, parse_htrack_calib, HTRACK_PALM_OFFSET, HTRACK_THETA_LAYOUT};
pub use default::default_right_hand_cylinders;
pub use model::{CylinderKeypoint, CylinderModel, Segment, CYLINDER_DOF_NAMES};
pub use query::{CylinderPart, CylinderProjection, View, NO_SEED};
pub use raster::{cast_camera_ray, CylinderRaster, RasterHit, NO_SEGMENT};
