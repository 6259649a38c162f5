//! # honline-calib — online hand-model personalization (thesis Ch. 4)
//!
//! Not built yet (issue 8). This crate will hold the per-frame Laplace estimate, the split
//! cumulative (Kalman filter) and joint cumulative (IEKF/LMKF) shape estimators with uncertainty,
//! the Offline-Hard/Soft baselines, the shape-space prior and shape-validity barriers.
