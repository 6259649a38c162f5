//! # eval — metrics, reports and comparisons
//!
//! - [`depth_metrics`]: the algorithm-agnostic E_d2m (thesis Eq. 3.15 / 4.17, kd-tree to the
//!   rendered model's point cloud) and E_m2d (Eq. 3.16, distance transform of the sensor
//!   silhouette), from a sensor depth, its silhouette and a rendered model depth only;
//! - [`markers`]: per-frame average and maximum marker errors, fraction of frames under ε
//!   (DESIGN.md "Metrics");
//! - [`shape_error`]: E_β (Eq. 4.16), the mean absolute shape-parameter error over a subset;
//! - [`traces`]: per-term energy traces and timing summaries of tracker records;
//! - [`benchmarks`]: published numbers recomputed from published outputs (NYU mean 3D joint
//!   error, Dexter-1 fingertip error);
//! - [`real_frame`]: the sphere-mesh model fitted to one real depth frame without ground truth,
//!   and the documented mapping of its keypoints to NYU's 14 joints;
//! - [`plot`]: SVG line plots for reports, including the papers' "% frames with error < ε";
//! - [`synthetic`]: scoring any tracker on a synthetic sequence with exact ground truth;
//! - [`online`]: the synthetic experiments of the online calibration (thesis §4.4.2–4.4.3):
//!   σ-perturbed subjects, a teaser-like motion with an optional straight phase, runners.
//!
//! Still to come (issue 7): `hands eval|compare|demo`.

pub mod benchmarks;
pub mod depth_metrics;
pub mod error;
pub mod markers;
pub mod online;
pub mod plot;
pub mod real_frame;
pub mod shape_error;
pub mod synthetic;
pub mod traces;

pub use error::{EvalError, Result};
