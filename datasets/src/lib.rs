//! # datasets — dataset readers and synthetic ground truth
//!
//! Not built yet (issues 3 and 7). This crate will hold readers for the Handy/teaser layout,
//! NYU and Dexter-1, and the generator of synthetic depth sequences with exact ground truth
//! (pose, shape and the 21 keypoints of DESIGN.md) rendered from the `hand-model` templates.
