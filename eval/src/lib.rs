//! # eval — metrics, reports and comparisons
//!
//! - [`markers`]: per-frame average and maximum marker errors, fraction of frames under ε
//!   (DESIGN.md "Metrics");
//! - [`plot`]: SVG line plots for reports;
//! - [`synthetic`]: scoring any tracker on a synthetic sequence with exact ground truth.
//!
//! Still to come (issue 7): E_d2m and E_m2d from sensor depth and a rendered model, E_β, the
//! dataset formats and `hands eval|compare`.

pub mod markers;
pub mod plot;
pub mod synthetic;
