//! Offline multi-frame calibration of the sphere-mesh template (thesis §3.4): the shape
//! unknowns and their Jacobians ([`ShapeSpace`]) and the joint LM over all frames
//! ([`calibrate`]); the per-frame data rows over pose and shape ([`ShapeRows`]) that the
//! online calibration of `honline-calib` reuses.

mod block;
mod rows;
mod select;
mod shape;
mod solve;

pub use rows::{DataEnergy, DataWeights, RowLayout, ShapeRows};
pub use select::select_frames;

pub use shape::{rest_sphere_errors, ShapeSpace, ShapeState};
pub use solve::{
    calibrate, Calibration, CalibrationConfig, CalibrationError, CalibrationFrame, FrameKind,
    IterationRecord, LinearSolver, Schedule, Stage,
};
