//! # htrack-icp — robust articulated ICP with a cylinder model (thesis Ch. 2)
//!
//! Not built yet (issue 4). This crate will hold the energy terms of Tagliasacchi et al. 2015
//! (E3D with l1 IRLS and front-facing correspondences, E2D silhouette, wrist, PCA pose prior,
//! collisions, joint limits, temporal prior) and the Levenberg–Marquardt loop with a rigid-first
//! iteration, on the cylinder model and kinematics of `hand-model`.
