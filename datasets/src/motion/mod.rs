//! Synthetic hand motions for ground-truth sequences (issue 3): a library of smooth, seeded,
//! joint-limit-respecting pose trajectories covering the Handy sub-sequences and the three axes
//! of thesis Fig. 3.16.
//!
//! # How a motion is built
//! A [`Motion`] holds one channel per joint DOF (the 22 of [`JOINT_DOFS`]) and six channels of
//! global placement ([`Placement`]). Each channel is a chain of keyframes taken from named key
//! poses ([`KeyPose`]: open hand, fist, pinch thumb–index, thumb–middle contact, crossed
//! index/middle, spread, point, …), blended by **minimum-jerk quintics** (`10u³ − 15u⁴ + 6u⁵`,
//! zero velocity and acceleration at each key, hence C² and never overshooting), plus
//! sinusoidal oscillators with minimum-jerk fade-in/out envelopes (continuous rotations, the
//! small natural wrist motion and global sway present in every motion). Every sample is clamped
//! to the skeleton's DOF limits (the keys already are, so the clamp is a safety net).
//!
//! The seed (a `ChaCha8Rng`) draws the timing jitter of every move (±12 %), a per-digit stagger
//! (fingers do not move in lock-step), the amplitude jitter of non-contact key poses (±8 % about
//! the relaxed hand), the oscillator frequencies (±10 %) and phases (large swings excepted: they
//! start in phase under their envelope) and, for `random`, the key poses themselves: same seed →
//! bit-identical poses, different seeds → different poses.
//!
//! # Frames and global placement
//! Camera frame of DESIGN.md (x right, y **down**, z forward). The global pose is written as
//! XYZ Euler angles `(pitch, yaw, π + roll)` — `R = Rx(pitch)·Ry(yaw)·Rz(π + roll)` — with the
//! translation chosen so that the palm center [`ANCHOR_MODEL`] sits at `position`:
//! - at `R = I` the model's palm (−z) already faces the camera but the fingers (+y) point
//!   **down** in the image; the library's neutral orientation is therefore `Rz(π)`: palm to the
//!   camera, fingers **up**, and (right hand) the thumb on the image's **right**;
//! - `yaw` turns the hand about the camera's vertical axis — with the hand upright this is
//!   forearm pronation/supination: +π/2 shows the thumb side, −π/2 the little-finger side,
//!   ±π the back of the hand; `pitch` tilts the fingers toward (+) or away from the camera;
//!   `roll` turns the hand in the image plane;
//! - the Euler values are generated directly (never extracted from a matrix), so they are
//!   continuous; `global_rz` hovers around π and may exceed it.
//!
//! The neutral position is [`NEUTRAL_POSITION`] = (0, 0, 400) mm; every motion keeps the hand
//! 350–450 mm from the camera and all 21 keypoints inside an SR300 QVGA view
//! (`sensor_io::Camera::sr300_qvga`: f ≈ 287, 320×240) except `leave_reenter`, which takes the
//! hand fully out of the view and back.
//!
//! # The library
//! See [`MotionLibrary`] for the names, and the table there for durations and speeds. The
//! Handy sub-sequences of thesis §3.5 map onto the library as: TAYL1 (rigid and clenching) →
//! `fist`; SRID1 (finger extension) → `flexion`; SRID2 (finger contact) → `contact`; SRID3
//! (crossing fingers) → `crossing`; SRID4 (pinching) → `pinch`; SHAR1 (fast and complex) →
//! `axis_speed` / `teaser`; SHAR2 (fast rigid) → `rotation_fast`; SHAR3 (rotating fist) →
//! `rotating_fist`; Handy/Teaser → `teaser`.
//!
//! Fig. 3.16 itself is not reproduced in the thesis text (only its caption: three axes of
//! complexity, difficulty growing with the distance to the origin). We read its three axes from
//! the sub-sequences it organizes — **speed** (slow → fast, rigid and articulated),
//! **articulation** (rigid hand → single finger → independent multi-finger motion) and
//! **interaction/self-occlusion** (separate fingers → contact → pinch → crossing → fist) — and
//! provide one motion walking out along each axis with the other two held low: `axis_speed`,
//! `axis_articulation`, `axis_interaction`.

mod analysis;
mod builder;
mod keyposes;
mod library;
mod track;

pub use analysis::{
    hand_in_view, hand_out_of_view, motion_stats, select_calibration_frames, MotionStats,
};
pub use keyposes::{Articulation, KeyPose, DIGITS, NUM_JOINTS};
pub use library::MotionLibrary;

use std::f64::consts::PI;

use hand_model::kinematics::names::{concat_names, DIGIT_DOFS, WRIST_DOFS};
use hand_model::kinematics::{DofKind, Pose, Skeleton};
use hand_model::math::euler_xyz_to_matrix;
use nalgebra::{Matrix3, Vector3};

use crate::error::{DatasetError, Result};
use track::Track;

/// The joint DOFs a motion drives, in the default template's pose-vector order (after the six
/// global DOFs).
pub const JOINT_DOFS: [&str; 22] = concat_names(WRIST_DOFS, DIGIT_DOFS);

/// The six global DOFs, in pose-vector order.
pub const GLOBAL_DOFS: [&str; 6] = hand_model::kinematics::names::GLOBAL_DOFS;

/// The palm center in the model frame (mm): the point that [`Placement::position`] places and
/// about which the global rotations turn.
pub const ANCHOR_MODEL: [f64; 3] = [-5.0, 45.0, 0.0];

/// The neutral camera-frame position of the palm center (mm).
pub const NEUTRAL_POSITION: [f64; 3] = [0.0, 0.0, 400.0];

/// Number of channels: the joints, then position x, y, z, yaw, pitch, roll.
pub(crate) const NUM_CHANNELS: usize = NUM_JOINTS + 6;
pub(crate) const CH_X: usize = NUM_JOINTS;
pub(crate) const CH_Y: usize = NUM_JOINTS + 1;
pub(crate) const CH_Z: usize = NUM_JOINTS + 2;
pub(crate) const CH_YAW: usize = NUM_JOINTS + 3;
pub(crate) const CH_PITCH: usize = NUM_JOINTS + 4;
pub(crate) const CH_ROLL: usize = NUM_JOINTS + 5;

/// Global placement of the hand: where its palm center is and how it is turned relative to the
/// neutral "palm to the camera, fingers up" orientation (see the module docs).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Placement {
    /// Camera-frame position of [`ANCHOR_MODEL`] (mm).
    pub position: Vector3<f64>,
    /// Turn about the camera's vertical axis (rad); ±π/2 = side views, ±π = back of the hand.
    pub yaw: f64,
    /// Tilt about the camera's horizontal axis (rad); + brings the fingertips toward the camera.
    pub pitch: f64,
    /// In-image-plane turn (rad) on top of the neutral `Rz(π)`.
    pub roll: f64,
}

impl Placement {
    /// The neutral placement: palm center at [`NEUTRAL_POSITION`], no turn.
    pub fn neutral() -> Self {
        Placement {
            position: Vector3::from(NEUTRAL_POSITION),
            yaw: 0.0,
            pitch: 0.0,
            roll: 0.0,
        }
    }

    /// The XYZ Euler values `(global_rx, global_ry, global_rz)` = `(pitch, yaw, π + roll)`.
    pub fn euler(&self) -> [f64; 3] {
        [self.pitch, self.yaw, PI + self.roll]
    }

    /// The model → camera rotation `Rx(pitch)·Ry(yaw)·Rz(π + roll)`.
    pub fn rotation(&self) -> Matrix3<f64> {
        let [a, b, c] = self.euler();
        euler_xyz_to_matrix(a, b, c)
    }

    /// The global translation `(global_tx, global_ty, global_tz)` that puts [`ANCHOR_MODEL`] at
    /// `position`.
    pub fn translation(&self) -> Vector3<f64> {
        self.position - self.rotation() * Vector3::from(ANCHOR_MODEL)
    }
}

/// Where one DOF of the target skeleton takes its value from.
#[derive(Copy, Clone, Debug, PartialEq)]
enum Slot {
    /// A joint channel.
    Joint(usize),
    /// A global DOF (0..6 = tx, ty, tz, rx, ry, rz).
    Global(usize),
    /// A DOF the library does not drive (e.g. a finger twist): a constant.
    Fixed(f64),
}

/// A named, seeded hand motion: the pose of a skeleton as a smooth function of time.
///
/// Built by [`MotionLibrary::by_name`] for the default template's skeleton, or re-targeted to
/// another skeleton with the same DOF names by [`Motion::for_skeleton`].
#[derive(Clone, Debug)]
pub struct Motion {
    name: String,
    seed: u64,
    duration: f64,
    tracks: Vec<Track>,
    /// Per joint channel, the clamp limits.
    joint_limits: [[f64; 2]; NUM_JOINTS],
    /// Per target DOF, its source.
    layout: Vec<Slot>,
    dof_names: Vec<String>,
}

impl Motion {
    /// Assemble a motion (tracks in channel order) for the default template's DOF layout.
    pub(crate) fn from_tracks(
        name: &str,
        seed: u64,
        duration: f64,
        tracks: Vec<Track>,
        joint_limits: [[f64; 2]; NUM_JOINTS],
    ) -> Self {
        let layout = (0..6)
            .map(Slot::Global)
            .chain((0..NUM_JOINTS).map(Slot::Joint))
            .collect();
        let dof_names = GLOBAL_DOFS
            .iter()
            .chain(JOINT_DOFS.iter())
            .map(|s| s.to_string())
            .collect();
        Motion {
            name: name.into(),
            seed,
            duration,
            tracks,
            joint_limits,
            layout,
            dof_names,
        }
    }

    /// The same motion for another skeleton: DOFs are matched by name, joint values are clamped
    /// to that skeleton's limits, DOFs the library does not drive (e.g. twists) are held at 0
    /// (clamped into their limits), and the two wrist DOFs are simply dropped when the skeleton
    /// has none (the 26-DOF cylinder model of Ch. 2). Refused: a skeleton lacking one of
    /// [`GLOBAL_DOFS`] or of the 20 digit DOFs of [`JOINT_DOFS`], or whose global DOFs are not
    /// translations/global rotations.
    pub fn for_skeleton(&self, skeleton: &Skeleton) -> Result<Motion> {
        let mut joint_limits = self.joint_limits;
        let mut layout = Vec::with_capacity(skeleton.num_dofs());
        for dof in skeleton.dofs() {
            let slot = if let Some(g) = GLOBAL_DOFS.iter().position(|n| *n == dof.name) {
                let expected = if g < 3 {
                    DofKind::Translation
                } else {
                    DofKind::GlobalRotation
                };
                if dof.kind != expected {
                    return Err(DatasetError::arg(
                        "skeleton",
                        format!("DOF `{}` is not a {expected:?}", dof.name),
                    ));
                }
                Slot::Global(g)
            } else if let Some(j) = JOINT_DOFS.iter().position(|n| *n == dof.name) {
                joint_limits[j] = dof.limits.unwrap_or([f64::NEG_INFINITY, f64::INFINITY]);
                Slot::Joint(j)
            } else {
                let v = dof.limits.map_or(0.0, |[lo, hi]| 0.0f64.clamp(lo, hi));
                Slot::Fixed(v)
            };
            layout.push(slot);
        }
        let optional = |n: &str| n.starts_with("wrist_");
        for name in GLOBAL_DOFS.iter().chain(JOINT_DOFS.iter()) {
            if !optional(name) && skeleton.dof_index(name).is_none() {
                return Err(DatasetError::MissingDof {
                    motion: self.name.clone(),
                    dof: (*name).into(),
                });
            }
        }
        Ok(Motion {
            name: self.name.clone(),
            seed: self.seed,
            duration: self.duration,
            tracks: self.tracks.clone(),
            joint_limits,
            layout,
            dof_names: skeleton.dofs().iter().map(|d| d.name.clone()).collect(),
        })
    }

    /// The library name (`teaser`, `fist`, …).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The seed it was drawn from.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Duration in seconds; [`Motion::pose_at`] holds the end poses outside `[0, duration]`.
    pub fn duration(&self) -> f64 {
        self.duration
    }

    /// The DOF names of the poses it produces, in pose-vector order.
    pub fn dof_names(&self) -> &[String] {
        &self.dof_names
    }

    /// Number of frames at `fps` covering `[0, duration]` (frame `i` at `i / fps`); 0 when `fps`
    /// is not finite and positive.
    pub fn num_frames(&self, fps: f64) -> usize {
        if !(fps.is_finite() && fps > 0.0) {
            return 0;
        }
        (self.duration * fps + 1e-9).floor() as usize + 1
    }

    fn clamp_time(&self, t: f64) -> f64 {
        if t.is_nan() {
            0.0
        } else {
            t.clamp(0.0, self.duration)
        }
    }

    fn channel(&self, ch: usize, t: f64) -> f64 {
        self.tracks[ch].eval(t)
    }

    /// The joint values at time `t` (s), clamped to the limits.
    pub fn articulation_at(&self, t: f64) -> Articulation {
        let t = self.clamp_time(t);
        let mut a = Articulation::zeros();
        for (j, v) in a.0.iter_mut().enumerate() {
            let [lo, hi] = self.joint_limits[j];
            *v = self.channel(j, t).clamp(lo, hi);
        }
        a
    }

    /// The global placement at time `t` (s).
    pub fn placement_at(&self, t: f64) -> Placement {
        let t = self.clamp_time(t);
        Placement {
            position: Vector3::new(
                self.channel(CH_X, t),
                self.channel(CH_Y, t),
                self.channel(CH_Z, t),
            ),
            yaw: self.channel(CH_YAW, t),
            pitch: self.channel(CH_PITCH, t),
            roll: self.channel(CH_ROLL, t),
        }
    }

    /// The pose at time `t` (s) in this motion's DOF layout ([`Motion::dof_names`]). Times
    /// outside `[0, duration]` (and NaN, read as 0) are clamped into it.
    pub fn pose_at(&self, t: f64) -> Pose {
        let mut pose = Pose {
            values: vec![0.0; self.layout.len()],
        };
        self.pose_into(t, &mut pose);
        pose
    }

    /// In-place form of [`Motion::pose_at`]; `pose` is resized to the layout.
    pub fn pose_into(&self, t: f64, pose: &mut Pose) {
        let a = self.articulation_at(t);
        let p = self.placement_at(t);
        let tr = p.translation();
        let eu = p.euler();
        let global = [tr.x, tr.y, tr.z, eu[0], eu[1], eu[2]];
        pose.values.resize(self.layout.len(), 0.0);
        for (v, slot) in pose.values.iter_mut().zip(&self.layout) {
            *v = match *slot {
                Slot::Joint(j) => a.0[j],
                Slot::Global(g) => global[g],
                Slot::Fixed(x) => x,
            };
        }
    }

    /// The poses of frames `0..num_frames(fps)` (frame `i` at `i / fps`), all in memory; empty
    /// when `fps` is not finite and positive.
    pub fn sample(&self, fps: f64) -> Vec<Pose> {
        (0..self.num_frames(fps))
            .map(|i| self.pose_at(i as f64 / fps))
            .collect()
    }
}
