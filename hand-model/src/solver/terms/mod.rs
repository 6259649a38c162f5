//! Reusable prior terms shared by the trackers (thesis §2.3.2 "Prior Energies"), one file each,
//! each with its serde-deserializable `…Params` carrying the thesis / original defaults.
//!
//! | term | energy | params default |
//! |---|---|---|
//! | [`JointLimits`] | Eq. 2.8 `ω₇ Σ χ(θᵢ − bound)²` | ω₇ = 1e7 (originals' convention) |
//! | [`Damping`] | §2.7.5 `Σ λᵢ δᵢ²` | λ = 100 (thesis) |
//! | [`Temporal`] | Eq. 2.9 `ω₈ Σ‖k̇‖² + ω₉ Σ‖k̈‖²` | ω₈ = ω₉ = 3 (thesis) |
//! | [`PosePrior`] | Eq. 2.5–2.6, closed form §2.7.1 | ω₄ = 1e3, ω₅ = 1 (thesis), 3 latents |
//! | [`PointTargets`] | `ω Σ‖pⱼ(θ) − tⱼ‖²` (IK, tests) | ω = 1 |

mod damping;
mod joint_limits;
mod point_targets;
mod pose_prior;
mod temporal;

pub use damping::{Damping, DampingParams};
pub use joint_limits::{JointLimits, JointLimitsParams};
pub use point_targets::{PointTargets, PointTargetsParams};
pub use pose_prior::{PosePrior, PosePriorForm, PosePriorParams, SUBSPACE_STIFFNESS};
pub use temporal::{Temporal, TemporalParams};
