//! # hmodel-spheremesh — sphere-mesh tracking and calibration (thesis Ch. 3)
//!
//! Not built yet (issues 5 and 6). This crate will hold the real-time sphere-mesh tracker
//! (d2m with closed-form pill/wedge correspondences and the monocular front-facing rule, m2d by
//! rendering and distance transform, priors) and the offline multi-frame calibration of centers,
//! radii and kinematic frames (Eq. 3.7–3.14), on the geometry of `hand-model`.
