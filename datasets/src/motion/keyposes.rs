//! Named key poses of the hand articulation (the 22 joint DOFs, global pose excluded).

use super::JOINT_DOFS;

/// Number of joint (non-global) DOFs a motion drives.
pub const NUM_JOINTS: usize = JOINT_DOFS.len();

/// The five digits in [`JOINT_DOFS`] order.
pub const DIGITS: [&str; 5] = ["thumb", "index", "middle", "ring", "pinky"];

/// The four DOFs of a digit, in [`JOINT_DOFS`] order (`digit` 0 = thumb … 4 = pinky):
/// thumb `cmc_abd, cmc_flex, mcp_flex, ip_flex`, fingers `mcp_abd, mcp_flex, pip_flex, dip_flex`.
pub(crate) fn digit_dofs(digit: usize) -> [usize; 4] {
    let b = 2 + 4 * digit.min(4);
    [b, b + 1, b + 2, b + 3]
}

/// The values of the 22 joint DOFs ([`JOINT_DOFS`] order, radians).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Articulation(pub [f64; NUM_JOINTS]);

impl Articulation {
    /// All joints at 0 (the template's rest pose: flat hand, fingers together as modelled).
    pub const fn zeros() -> Self {
        Articulation([0.0; NUM_JOINTS])
    }

    /// The value of a named joint DOF (`None` for names outside [`JOINT_DOFS`]).
    pub fn get(&self, name: &str) -> Option<f64> {
        JOINT_DOFS
            .iter()
            .position(|d| *d == name)
            .map(|i| self.0[i])
    }

    /// A copy with one named joint DOF changed; unknown names leave the articulation unchanged.
    pub fn with(mut self, name: &str, value: f64) -> Self {
        if let Some(i) = JOINT_DOFS.iter().position(|d| *d == name) {
            self.0[i] = value;
        }
        self
    }

    /// A copy whose digit `digit` (0 = thumb … 4 = pinky) takes its values from `other`.
    pub fn with_digit_of(mut self, digit: usize, other: &Articulation) -> Self {
        for i in digit_dofs(digit) {
            self.0[i] = other.0[i];
        }
        self
    }

    /// `(1 − w)·self + w·other`, joint by joint.
    pub fn lerp(&self, other: &Articulation, w: f64) -> Self {
        let mut out = *self;
        for (o, (a, b)) in out.0.iter_mut().zip(self.0.iter().zip(&other.0)) {
            *o = a + (b - a) * w;
        }
        out
    }

    /// Clamp every joint into `limits` (one `[min, max]` per joint, [`JOINT_DOFS`] order).
    pub fn clamped(mut self, limits: &[[f64; 2]; NUM_JOINTS]) -> Self {
        for (v, [lo, hi]) in self.0.iter_mut().zip(limits) {
            *v = v.clamp(*lo, *hi);
        }
        self
    }

    /// `(dof name, value)` pairs, for [`hand_model::kinematics::Pose::from_named`].
    pub fn named(&self) -> impl Iterator<Item = (&'static str, f64)> + '_ {
        JOINT_DOFS.iter().copied().zip(self.0.iter().copied())
    }
}

/// The named key poses the motions are built from.
///
/// Values are for the default right-hand template (`hand_model::spheremesh::default_right_hand`);
/// the contact poses ([`KeyPose::PinchIndex`] … [`KeyPose::PinchPinky`]) were solved numerically
/// on that template so that the thumb-tip and finger-tip spheres touch (center distance = sum
/// of radii within 0.5 mm); on a reshaped subject they touch approximately (a few mm).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum KeyPose {
    /// Every joint at 0: the template's flat rest hand.
    Flat,
    /// A relaxed open hand (slight natural flexion cascade toward the pinky).
    Open,
    /// Fingers spread (maximal comfortable abduction), thumb abducted and extended.
    Spread,
    /// Fingers pressed side by side (adducted: neighbouring fingers in contact), thumb along the
    /// index.
    Adducted,
    /// A clenched fist, thumb wrapped over the middle phalanges of index and middle. (The thumb
    /// values keep every pair of finger pills of the default template within 1 mm of touching —
    /// an earlier version sank the thumb 16 mm into the fingers, a ground truth no tracker with
    /// a collision term could reach; checked in `eval/tests/ground_truth.rs`.)
    Fist,
    /// Index extended, other fingers curled, thumb over the middle finger.
    Point,
    /// "Victory": index and middle extended and spread, ring and pinky curled under the thumb.
    Victory,
    /// Claw: MCPs extended, PIPs and DIPs flexed.
    Claw,
    /// Thumbs up: fist with the thumb extended.
    ThumbUp,
    /// Precision pinch: thumb tip on the index tip, other fingers relaxed (an "OK" sign).
    PinchIndex,
    /// Thumb tip on the middle fingertip (the thumb–middle contact of the Handy sequences).
    PinchMiddle,
    /// Thumb tip on the ring fingertip.
    PinchRing,
    /// Thumb tip on the pinky tip.
    PinchPinky,
    /// Index and middle crossed (middle over the back of the index), ring and pinky curled.
    Crossed,
}

impl KeyPose {
    /// Every key pose.
    pub const ALL: [KeyPose; 14] = [
        KeyPose::Flat,
        KeyPose::Open,
        KeyPose::Spread,
        KeyPose::Adducted,
        KeyPose::Fist,
        KeyPose::Point,
        KeyPose::Victory,
        KeyPose::Claw,
        KeyPose::ThumbUp,
        KeyPose::PinchIndex,
        KeyPose::PinchMiddle,
        KeyPose::PinchRing,
        KeyPose::PinchPinky,
        KeyPose::Crossed,
    ];

    /// A snake_case name (`open`, `fist`, `pinch_index`, ...).
    pub fn name(self) -> &'static str {
        match self {
            KeyPose::Flat => "flat",
            KeyPose::Open => "open",
            KeyPose::Spread => "spread",
            KeyPose::Adducted => "adducted",
            KeyPose::Fist => "fist",
            KeyPose::Point => "point",
            KeyPose::Victory => "victory",
            KeyPose::Claw => "claw",
            KeyPose::ThumbUp => "thumb_up",
            KeyPose::PinchIndex => "pinch_index",
            KeyPose::PinchMiddle => "pinch_middle",
            KeyPose::PinchRing => "pinch_ring",
            KeyPose::PinchPinky => "pinch_pinky",
            KeyPose::Crossed => "crossed",
        }
    }

    /// The key pose called `name` (see [`KeyPose::name`]).
    pub fn by_name(name: &str) -> Option<KeyPose> {
        KeyPose::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Whether the pose is defined by a contact (its amplitude must not be jittered).
    pub fn is_contact(self) -> bool {
        matches!(
            self,
            KeyPose::PinchIndex
                | KeyPose::PinchMiddle
                | KeyPose::PinchRing
                | KeyPose::PinchPinky
                | KeyPose::Crossed
        )
    }

    /// The joint values (all within the default template's limits).
    pub fn articulation(self) -> Articulation {
        let open = open();
        let fist = fist();
        match self {
            KeyPose::Flat => Articulation::zeros(),
            KeyPose::Open => open,
            KeyPose::Spread => set(
                Articulation::zeros(),
                &[
                    ("thumb_cmc_abd", 0.6),
                    ("thumb_cmc_flex", -0.3),
                    ("thumb_mcp_flex", 0.0),
                    ("thumb_ip_flex", 0.05),
                    ("index_mcp_abd", 0.3),
                    ("middle_mcp_abd", 0.05),
                    ("ring_mcp_abd", -0.15),
                    ("pinky_mcp_abd", -0.3),
                    ("index_mcp_flex", 0.0),
                    ("middle_mcp_flex", 0.02),
                    ("ring_mcp_flex", 0.05),
                    ("pinky_mcp_flex", 0.08),
                    ("index_pip_flex", 0.05),
                    ("middle_pip_flex", 0.05),
                    ("ring_pip_flex", 0.08),
                    ("pinky_pip_flex", 0.1),
                ],
            ),
            KeyPose::Adducted => set(
                Articulation::zeros(),
                &[
                    ("thumb_cmc_abd", -0.3),
                    ("thumb_cmc_flex", 0.1),
                    ("thumb_mcp_flex", 0.1),
                    ("thumb_ip_flex", 0.05),
                    ("index_mcp_abd", -0.08),
                    ("middle_mcp_abd", 0.0),
                    ("ring_mcp_abd", 0.06),
                    ("pinky_mcp_abd", 0.15),
                    ("index_mcp_flex", 0.05),
                    ("middle_mcp_flex", 0.05),
                    ("ring_mcp_flex", 0.08),
                    ("pinky_mcp_flex", 0.1),
                    ("index_pip_flex", 0.05),
                    ("middle_pip_flex", 0.05),
                    ("ring_pip_flex", 0.05),
                    ("pinky_pip_flex", 0.08),
                ],
            ),
            KeyPose::Fist => fist,
            KeyPose::Point => set(
                fist,
                &[
                    ("index_mcp_abd", 0.05),
                    ("index_mcp_flex", 0.05),
                    ("index_pip_flex", 0.05),
                    ("index_dip_flex", 0.02),
                    ("thumb_cmc_abd", -0.05),
                    ("thumb_cmc_flex", 0.5),
                ],
            ),
            KeyPose::Victory => set(
                fist,
                &[
                    ("index_mcp_abd", 0.25),
                    ("index_mcp_flex", 0.05),
                    ("index_pip_flex", 0.05),
                    ("index_dip_flex", 0.02),
                    ("middle_mcp_abd", -0.2),
                    ("middle_mcp_flex", 0.05),
                    ("middle_pip_flex", 0.05),
                    ("middle_dip_flex", 0.02),
                    ("thumb_cmc_abd", -0.2),
                    ("thumb_cmc_flex", 0.8),
                    ("thumb_mcp_flex", 0.6),
                ],
            ),
            KeyPose::Claw => set(
                Articulation::zeros(),
                &[
                    ("thumb_cmc_abd", 0.3),
                    ("thumb_cmc_flex", 0.2),
                    ("thumb_mcp_flex", 0.5),
                    ("thumb_ip_flex", 0.8),
                    ("index_mcp_abd", 0.15),
                    ("ring_mcp_abd", -0.08),
                    ("pinky_mcp_abd", -0.15),
                    ("index_mcp_flex", 0.1),
                    ("middle_mcp_flex", 0.1),
                    ("ring_mcp_flex", 0.15),
                    ("pinky_mcp_flex", 0.2),
                    ("index_pip_flex", 1.3),
                    ("middle_pip_flex", 1.35),
                    ("ring_pip_flex", 1.35),
                    ("pinky_pip_flex", 1.3),
                    ("index_dip_flex", 0.9),
                    ("middle_dip_flex", 0.9),
                    ("ring_dip_flex", 0.9),
                    ("pinky_dip_flex", 0.85),
                ],
            ),
            KeyPose::ThumbUp => set(
                fist,
                &[
                    ("thumb_cmc_abd", 0.2),
                    ("thumb_cmc_flex", -0.2),
                    ("thumb_mcp_flex", 0.0),
                    ("thumb_ip_flex", -0.1),
                ],
            ),
            KeyPose::PinchIndex => set(
                open,
                &[
                    ("thumb_cmc_abd", -0.126),
                    ("thumb_cmc_flex", 0.364),
                    ("thumb_mcp_flex", 0.275),
                    ("thumb_ip_flex", 0.194),
                    ("index_mcp_abd", 0.0),
                    ("index_mcp_flex", 0.694),
                    ("index_pip_flex", 0.800),
                    ("index_dip_flex", 0.390),
                ],
            ),
            KeyPose::PinchMiddle => set(
                open,
                &[
                    ("thumb_cmc_abd", -0.168),
                    ("thumb_cmc_flex", 0.503),
                    ("thumb_mcp_flex", 0.324),
                    ("thumb_ip_flex", 0.203),
                    ("middle_mcp_abd", 0.0),
                    ("middle_mcp_flex", 0.809),
                    ("middle_pip_flex", 0.863),
                    ("middle_dip_flex", 0.415),
                ],
            ),
            KeyPose::PinchRing => set(
                open,
                &[
                    ("thumb_cmc_abd", -0.245),
                    ("thumb_cmc_flex", 0.648),
                    ("thumb_mcp_flex", 0.391),
                    ("thumb_ip_flex", 0.225),
                    ("ring_mcp_abd", 0.0),
                    ("ring_mcp_flex", 0.876),
                    ("ring_pip_flex", 0.875),
                    ("ring_dip_flex", 0.420),
                ],
            ),
            KeyPose::PinchPinky => set(
                open,
                &[
                    ("thumb_cmc_abd", -0.375),
                    ("thumb_cmc_flex", 0.773),
                    ("thumb_mcp_flex", 0.468),
                    ("thumb_ip_flex", 0.256),
                    ("pinky_mcp_abd", 0.0),
                    ("pinky_mcp_flex", 0.873),
                    ("pinky_pip_flex", 0.801),
                    ("pinky_dip_flex", 0.391),
                ],
            ),
            KeyPose::Crossed => set(
                fist,
                &[
                    ("index_mcp_abd", -0.25),
                    ("index_mcp_flex", 0.5),
                    ("index_pip_flex", 0.4),
                    ("index_dip_flex", 0.24),
                    ("middle_mcp_abd", 0.4),
                    ("middle_mcp_flex", -0.1),
                    ("middle_pip_flex", 0.1),
                    ("middle_dip_flex", 0.06),
                    ("thumb_cmc_abd", -0.3),
                    ("thumb_cmc_flex", 0.75),
                    ("thumb_mcp_flex", 0.55),
                    ("thumb_ip_flex", 0.3),
                ],
            ),
        }
    }
}

fn set(mut a: Articulation, values: &[(&str, f64)]) -> Articulation {
    for &(n, v) in values {
        a = a.with(n, v);
    }
    a
}

fn open() -> Articulation {
    set(
        Articulation::zeros(),
        &[
            ("thumb_cmc_abd", 0.15),
            ("thumb_cmc_flex", 0.05),
            ("thumb_mcp_flex", 0.1),
            ("thumb_ip_flex", 0.1),
            ("index_mcp_abd", 0.06),
            ("ring_mcp_abd", -0.04),
            ("pinky_mcp_abd", -0.08),
            ("index_mcp_flex", 0.08),
            ("middle_mcp_flex", 0.1),
            ("ring_mcp_flex", 0.14),
            ("pinky_mcp_flex", 0.18),
            ("index_pip_flex", 0.12),
            ("middle_pip_flex", 0.15),
            ("ring_pip_flex", 0.2),
            ("pinky_pip_flex", 0.25),
            ("index_dip_flex", 0.06),
            ("middle_dip_flex", 0.08),
            ("ring_dip_flex", 0.1),
            ("pinky_dip_flex", 0.12),
        ],
    )
}

fn fist() -> Articulation {
    set(
        Articulation::zeros(),
        &[
            ("thumb_cmc_abd", 0.15),
            ("thumb_cmc_flex", 1.0),
            ("thumb_mcp_flex", 0.7),
            ("thumb_ip_flex", 0.4),
            ("index_mcp_abd", -0.02),
            ("ring_mcp_abd", 0.03),
            ("pinky_mcp_abd", 0.08),
            ("index_mcp_flex", 1.4),
            ("middle_mcp_flex", 1.45),
            ("ring_mcp_flex", 1.5),
            ("pinky_mcp_flex", 1.5),
            ("index_pip_flex", 1.6),
            ("middle_pip_flex", 1.65),
            ("ring_pip_flex", 1.65),
            ("pinky_pip_flex", 1.6),
            ("index_dip_flex", 1.0),
            ("middle_dip_flex", 1.0),
            ("ring_dip_flex", 1.0),
            ("pinky_dip_flex", 0.95),
        ],
    )
}
