//! Offline multi-frame calibration of the sphere-mesh template (thesis §3.4): the shape
//! unknowns and their Jacobians ([`ShapeSpace`]) and the joint LM over all frames
//! ([`calibrate`]) and its initialization from complete scans ([`initialize_clouds`]); the
//! per-frame data rows over pose and shape ([`ShapeRows`], reused by the online and offline
//! calibrations of `honline-calib`) and the block-arrow normal equations of a multi-frame
//! calibration ([`BlockArrow`], reused by the offline ones).

mod block;
mod cloud;
mod rows;
mod select;
mod shape;
mod solve;

pub use block::{BlockArrow, Unknown};
pub use cloud::{
    calibrate_clouds, initialize_cloud_pose, initialize_clouds, place_pose, refine_digits,
    split_forearm, CloudCalibration, CloudInit, CloudPose, CloudSearch, ForearmSplit,
};
pub use rows::{DataEnergy, DataWeights, RowLayout, ShapeRows};
pub use select::select_frames;

pub use shape::{fit_rest_spheres, rest_sphere_errors, ShapeSpace, ShapeState, SphereTarget};
pub use solve::{
    calibrate, Calibration, CalibrationConfig, CalibrationError, CalibrationFrame, FrameKind,
    IterationRecord, LinearSolver, Schedule, Stage,
};
