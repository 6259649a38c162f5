//! # eval — metrics, reports and comparisons
//!
//! Not built yet (issue 7). This crate will hold the algorithm-agnostic metrics E_d2m and E_m2d
//! (from sensor depth and a rendered model depth), marker errors and the fraction-of-frames-under-ε
//! curves, E_β, and the reports and side-by-side comparisons written by `hands eval|compare`.
