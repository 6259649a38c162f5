//! The named motions.

use hand_model::kinematics::Skeleton;
use nalgebra::Vector3;

use super::builder::{Builder, MoveOpts};
use super::keyposes::{digit_dofs, Articulation, KeyPose};
use super::{Motion, Placement, CH_PITCH, CH_ROLL, CH_X, CH_Y, CH_YAW, CH_Z, NEUTRAL_POSITION};
use crate::error::{DatasetError, Result};

/// The motion library: named, seeded motions (see the [module docs](super) for conventions).
///
/// | name | what | Handy |
/// |---|---|---|
/// | `teaser` | long mixed sequence: per-finger flexion wave, spread/adduction, pinches, fist clench and rotating fist, crossing, thumb–middle contact, fast rigid bursts, slow turns to side views, point/victory/claw, random poses; small natural wrist motion throughout | Teaser |
/// | `flexion` | each digit flexes and extends in turn, then all together, then rolling waves | SRID1 |
/// | `abduction` | spread ↔ adducted at varying speed, thumb and index abduction alone | — |
/// | `pinch` | thumb–index pinches, then thumb to middle, ring and pinky tips; slight turns | SRID4 |
/// | `fist` | repeated fist clenches at increasing speed under slow rigid motion | TAYL1 |
/// | `crossing` | index/middle crossing and uncrossing | SRID3 |
/// | `contact` | side contact of adducted fingers, thumb–middle and thumb–ring contacts | SRID2 |
/// | `rotation_slow` | open hand turning slowly (yaw ±1.2 rad) with slow articulation | — |
/// | `rotation_fast` | fast rigid turns (≥ 3 rad/s) and sideways shakes of an open hand | SHAR2 |
/// | `rotating_fist` | a fist turning fast about the forearm axis | SHAR3 |
/// | `leave_reenter` | the hand leaves the SR300 view to the right and comes back, leaves left and re-enters from below | — |
/// | `occlusion` | long side views (thumb side, little-finger side) and the back of the hand while the fingers move behind each other | — |
/// | `random` | random key poses and placements from the seed | — |
/// | `axis_speed` | Fig. 3.16 speed axis: one gesture cycle repeated ever faster (×0.5 → ×2.5) | SHAR1 |
/// | `axis_articulation` | Fig. 3.16 articulation axis: rigid hand → one digit → pairs → all → independent digits | — |
/// | `axis_interaction` | Fig. 3.16 interaction axis: apart → side contact → pinch → contact → crossing → fist | — |
///
/// Durations and speeds at seed 0, measured at 60 Hz with the default template by
/// [`super::motion_stats`] (test `motion_table` prints this table; speeds vary by a few percent
/// with the seed):
///
/// | name | duration (s) | max joint speed (rad/s) | max global angular speed (rad/s) | max keypoint speed (mm/s) |
/// |---|---|---|---|---|
/// | `teaser` | 43.6 | 8.8 (`index_pip_flex`) | 5.95 | 1051 |
/// | `flexion` | 19.9 | 6.6 (`index_pip_flex`) | 0.31 | 728 |
/// | `abduction` | 18.7 | 3.9 (`thumb_cmc_abd`) | 0.30 | 462 |
/// | `pinch` | 17.2 | 2.8 (`index_pip_flex`) | 0.68 | 350 |
/// | `fist` | 12.0 | 9.9 (`middle_pip_flex`) | 1.05 | 1286 |
/// | `crossing` | 12.8 | 4.7 (`middle_mcp_flex`) | 0.67 | 650 |
/// | `contact` | 14.5 | 3.1 (`thumb_cmc_abd`) | 0.50 | 412 |
/// | `rotation_slow` | 15.9 | 3.1 (`middle_pip_flex`) | 1.19 | 391 |
/// | `rotation_fast` | 11.4 | 4.5 (`index_pip_flex`) | 6.00 | 1032 |
/// | `rotating_fist` | 10.4 | 4.6 (`index_pip_flex`) | 4.54 | 548 |
/// | `leave_reenter` | 12.2 | 3.9 (`ring_pip_flex`) | 1.01 | 1180 |
/// | `occlusion` | 20.6 | 4.3 (`ring_pip_flex`) | 2.26 | 535 |
/// | `random` | 22.5 | 3.4 (`middle_pip_flex`) | 2.13 | 416 |
/// | `axis_speed` | 29.7 | 9.9 (`middle_pip_flex`) | 2.07 | 1295 |
/// | `axis_articulation` | 27.2 | 4.5 (`index_pip_flex`) | 1.61 | 537 |
/// | `axis_interaction` | 19.0 | 4.4 (`middle_pip_flex`) | 0.33 | 602 |
/// | `calibration` | 17.2 | 3.3 (`index_pip_flex`) | 1.29 | 425 |
pub struct MotionLibrary;

/// Names, in library order.
const NAMES: [&str; 17] = [
    "teaser",
    "flexion",
    "abduction",
    "pinch",
    "fist",
    "crossing",
    "contact",
    "rotation_slow",
    "rotation_fast",
    "rotating_fist",
    "leave_reenter",
    "occlusion",
    "random",
    "axis_speed",
    "axis_articulation",
    "axis_interaction",
    "calibration",
];

impl MotionLibrary {
    /// The motion names.
    pub fn names() -> &'static [&'static str] {
        &NAMES
    }

    /// A one-line description of a motion (`None` for unknown names).
    pub fn describe(name: &str) -> Option<&'static str> {
        Some(match name {
            "teaser" => "long mixed sequence covering every Handy motion type",
            "flexion" => "flexion/extension of each digit, all together, rolling waves",
            "abduction" => "finger spreading and adduction, thumb and index abduction",
            "pinch" => "thumb–index pinches and thumb to the other fingertips",
            "fist" => "fist clenching under slow rigid motion",
            "crossing" => "index/middle crossing",
            "contact" => "finger side contact, thumb–middle and thumb–ring contact",
            "rotation_slow" => "slow global rotation of an open hand",
            "rotation_fast" => "fast rigid rotation (≥ 3 rad/s) of an open hand",
            "rotating_fist" => "a fist rotating fast about the forearm axis",
            "leave_reenter" => "the hand leaves the camera view and re-enters",
            "occlusion" => "long side and back views with self-occluded fingers moving",
            "random" => "random key poses and placements drawn from the seed",
            "axis_speed" => "Fig. 3.16 speed axis: a gesture cycle repeated ever faster",
            "axis_articulation" => "Fig. 3.16 articulation axis: rigid to fully independent digits",
            "axis_interaction" => "Fig. 3.16 interaction axis: apart to contact, crossing, fist",
            "calibration" => "slow, well-separated calibration poses under mild turns",
            _ => return None,
        })
    }

    /// The motion `name` drawn from `seed`, for the default template's skeleton. Unknown names
    /// are an error listing the known ones.
    pub fn by_name(name: &str, seed: u64) -> Result<Motion> {
        let m = match name {
            "teaser" => teaser(seed),
            "flexion" => flexion(seed),
            "abduction" => abduction(seed),
            "pinch" => pinch(seed),
            "fist" => fist(seed),
            "crossing" => crossing(seed),
            "contact" => contact(seed),
            "rotation_slow" => rotation_slow(seed),
            "rotation_fast" => rotation_fast(seed),
            "rotating_fist" => rotating_fist(seed),
            "leave_reenter" => leave_reenter(seed),
            "occlusion" => occlusion(seed),
            "random" => random(seed),
            "axis_speed" => axis_speed(seed),
            "axis_articulation" => axis_articulation(seed),
            "axis_interaction" => axis_interaction(seed),
            "calibration" => calibration(seed),
            _ => {
                return Err(DatasetError::UnknownMotion {
                    name: name.into(),
                    known: NAMES.join(", "),
                })
            }
        };
        Ok(m)
    }

    /// [`MotionLibrary::by_name`] re-targeted to `skeleton` ([`Motion::for_skeleton`]).
    pub fn by_name_for(name: &str, seed: u64, skeleton: &Skeleton) -> Result<Motion> {
        Self::by_name(name, seed)?.for_skeleton(skeleton)
    }
}

/// A placement offset from the neutral one (mm, rad).
fn pl(dx: f64, dy: f64, dz: f64, yaw: f64, pitch: f64, roll: f64) -> Placement {
    Placement {
        position: Vector3::from(NEUTRAL_POSITION) + Vector3::new(dx, dy, dz),
        yaw,
        pitch,
        roll,
    }
}

/// Digit `d` (0 = thumb) fully flexed on top of `base`.
fn digit_flexed(base: Articulation, d: usize) -> Articulation {
    let [a, b, c, e] = digit_dofs(d);
    let mut out = base;
    if d == 0 {
        out.0[a] = -0.3;
        out.0[b] = 0.85;
        out.0[c] = 0.9;
        out.0[e] = 1.1;
    } else {
        out.0[a] = 0.0;
        out.0[b] = 1.3;
        out.0[c] = 1.6;
        out.0[e] = 0.95;
    }
    out
}

fn open() -> Articulation {
    KeyPose::Open.articulation()
}

/// Each digit flexes and extends in turn (`dur` per half-move).
fn sec_digit_by_digit(b: &mut Builder, dur: f64, hold: f64) {
    for d in 0..5 {
        b.go_art(digit_flexed(open(), d), dur, hold, MoveOpts::default());
        b.go_art(open(), dur, hold, MoveOpts::default());
    }
}

/// A rolling wave: the digits flex one after another and extend one after another.
fn sec_wave(b: &mut Builder, dur: f64, lag: f64) {
    let opts = MoveOpts {
        jitter_amplitude: true,
        wave: lag,
    };
    let mut curled = open();
    for d in 1..5 {
        curled = digit_flexed(curled, d);
    }
    b.go_art(curled, dur, 0.1 + 4.0 * lag, opts);
    b.go_art(open(), dur, 0.1 + 4.0 * lag, opts);
}

fn flexion(seed: u64) -> Motion {
    let mut b = Builder::new("flexion", seed, KeyPose::Open);
    b.wait(0.5);
    sec_digit_by_digit(&mut b, 0.7, 0.25);
    b.go(KeyPose::Fist, 0.8, 0.4);
    b.go(KeyPose::Open, 0.8, 0.4);
    b.go(KeyPose::Flat, 0.6, 0.3);
    b.go(KeyPose::Fist, 0.7, 0.3);
    b.go(KeyPose::Open, 0.7, 0.3);
    sec_wave(&mut b, 0.6, 0.12);
    sec_wave(&mut b, 0.5, 0.09);
    b.wait(0.4);
    b.osc(CH_YAW, 0.2, 0.08, 0.0, b.t_art, 1.0);
    b.finish()
}

fn abduction(seed: u64) -> Motion {
    let mut b = Builder::new("abduction", seed, KeyPose::Open);
    b.wait(0.5);
    for dur in [0.9, 0.7, 0.55, 0.45] {
        b.go(KeyPose::Spread, dur, 0.35);
        b.go(KeyPose::Adducted, dur, 0.35);
    }
    // Thumb abduction alone.
    let base = KeyPose::Adducted.articulation();
    for v in [0.75, -0.4, 0.75] {
        b.go_art(
            base.with("thumb_cmc_abd", v),
            0.7,
            0.25,
            MoveOpts::default(),
        );
    }
    // Index side to side, then middle.
    for (dof, lo, hi) in [
        ("index_mcp_abd", -0.25, 0.32),
        ("middle_mcp_abd", -0.25, 0.35),
    ] {
        b.go_art(base.with(dof, hi), 0.6, 0.2, MoveOpts::default());
        b.go_art(base.with(dof, lo), 0.7, 0.2, MoveOpts::default());
        b.go_art(base, 0.6, 0.2, MoveOpts::default());
    }
    b.go(KeyPose::Spread, 0.8, 0.4);
    b.go(KeyPose::Open, 0.8, 0.4);
    b.osc(CH_PITCH, 0.15, 0.1, 0.0, b.t_art, 1.0);
    b.finish()
}

fn sec_pinches(b: &mut Builder, dur: f64, hold: f64) {
    for k in [
        KeyPose::PinchIndex,
        KeyPose::PinchMiddle,
        KeyPose::PinchRing,
        KeyPose::PinchPinky,
    ] {
        b.go(k, dur, hold);
        b.go(KeyPose::Open, dur, 0.2);
    }
}

fn pinch(seed: u64) -> Motion {
    let mut b = Builder::new("pinch", seed, KeyPose::Open);
    b.wait(0.5);
    for dur in [0.8, 0.6, 0.45] {
        b.go(KeyPose::PinchIndex, dur, 0.5);
        b.go(KeyPose::Open, dur, 0.3);
    }
    sec_pinches(&mut b, 0.7, 0.5);
    b.go(KeyPose::PinchIndex, 0.6, 0.8);
    b.go(KeyPose::Open, 0.6, 0.4);
    let end = b.t_art;
    b.osc(CH_YAW, 0.35, 0.12, 0.0, end, 1.0);
    b.osc(CH_PITCH, 0.2, 0.09, 0.0, end, 1.0);
    b.finish()
}

fn fist(seed: u64) -> Motion {
    let mut b = Builder::new("fist", seed, KeyPose::Open);
    b.wait(0.5);
    for (dur, hold) in [
        (0.9, 0.5),
        (0.7, 0.4),
        (0.55, 0.3),
        (0.45, 0.25),
        (0.35, 0.2),
    ] {
        b.go(KeyPose::Fist, dur, hold);
        b.go(KeyPose::Open, dur, hold);
    }
    b.go(KeyPose::Fist, 0.5, 0.8);
    b.go(KeyPose::Flat, 0.6, 0.4);
    let end = b.t_art;
    b.osc(CH_YAW, 0.5, 0.12, 0.0, end, 1.0);
    b.osc(CH_X, 40.0, 0.08, 0.0, end, 1.0);
    b.osc(CH_ROLL, 0.25, 0.1, 0.0, end, 1.0);
    b.finish()
}

fn crossing(seed: u64) -> Motion {
    let mut b = Builder::new("crossing", seed, KeyPose::Open);
    b.wait(0.5);
    b.go(KeyPose::Adducted, 0.7, 0.3);
    b.go(KeyPose::Crossed, 1.0, 1.0);
    b.go(KeyPose::Adducted, 0.8, 0.3);
    b.go(KeyPose::Open, 0.7, 0.4);
    b.go(KeyPose::Crossed, 0.8, 1.2);
    b.go(KeyPose::Point, 0.7, 0.4);
    b.go(KeyPose::Crossed, 0.6, 0.8);
    b.go(KeyPose::Victory, 0.6, 0.5);
    b.go(KeyPose::Open, 0.7, 0.4);
    let end = b.t_art;
    b.osc(CH_YAW, 0.35, 0.1, 0.0, end, 1.0);
    b.osc(CH_PITCH, 0.15, 0.13, 0.0, end, 1.0);
    b.finish()
}

fn contact(seed: u64) -> Motion {
    let mut b = Builder::new("contact", seed, KeyPose::Open);
    b.wait(0.5);
    b.go(KeyPose::Adducted, 0.8, 0.8);
    b.go(KeyPose::Spread, 0.7, 0.3);
    b.go(KeyPose::Adducted, 0.6, 0.6);
    b.go(KeyPose::PinchMiddle, 0.8, 1.0);
    b.go(KeyPose::Open, 0.6, 0.3);
    b.go(KeyPose::PinchMiddle, 0.5, 0.6);
    b.go(KeyPose::PinchRing, 0.6, 0.8);
    b.go(KeyPose::PinchMiddle, 0.5, 0.6);
    b.go(KeyPose::PinchIndex, 0.5, 0.6);
    b.go(KeyPose::Adducted, 0.7, 0.6);
    b.go(KeyPose::Open, 0.7, 0.4);
    let end = b.t_art;
    b.osc(CH_YAW, 0.3, 0.1, 0.0, end, 1.0);
    b.osc(CH_PITCH, 0.2, 0.12, 0.0, end, 1.0);
    b.finish()
}

fn rotation_slow(seed: u64) -> Motion {
    let mut b = Builder::new("rotation_slow", seed, KeyPose::Open);
    for k in [
        KeyPose::Open,
        KeyPose::Spread,
        KeyPose::Open,
        KeyPose::Point,
        KeyPose::Open,
        KeyPose::Spread,
        KeyPose::Open,
    ] {
        b.go(k, 1.2, 1.0);
    }
    let end = b.t_art + 0.5;
    b.swing(CH_YAW, 1.2, 0.1, 0.0, end, 1.5);
    b.osc(CH_PITCH, 0.35, 0.13, 0.0, end, 1.5);
    b.osc(CH_ROLL, 0.4, 0.07, 0.0, end, 1.5);
    b.osc(CH_X, 30.0, 0.06, 0.0, end, 1.5);
    b.t_glob = end;
    b.finish()
}

fn rotation_fast(seed: u64) -> Motion {
    let mut b = Builder::new("rotation_fast", seed, KeyPose::Open);
    b.wait(1.0);
    b.go(KeyPose::Spread, 1.0, 2.0);
    b.go(KeyPose::Open, 1.0, 2.0);
    b.go(KeyPose::Fist, 0.7, 1.5);
    b.go(KeyPose::Open, 0.7, 1.0);
    let end = b.t_art;
    b.swing(CH_YAW, 1.0, 0.85, 0.3, end - 0.3, 0.7);
    b.osc(CH_PITCH, 0.35, 1.1, 0.3, end - 0.3, 0.7);
    b.osc(CH_ROLL, 0.45, 0.7, 0.3, end - 0.3, 0.7);
    b.osc(CH_X, 45.0, 0.6, 0.3, end - 0.3, 0.7);
    b.osc(CH_Y, 25.0, 0.9, 0.3, end - 0.3, 0.7);
    b.t_glob = end;
    b.finish()
}

fn rotating_fist(seed: u64) -> Motion {
    let mut b = Builder::new("rotating_fist", seed, KeyPose::Open);
    b.wait(0.4);
    b.go(KeyPose::Fist, 0.7, 7.5);
    b.go(KeyPose::Open, 0.8, 0.5);
    let (s, e) = (1.2, b.t_art - 1.2);
    b.swing(CH_YAW, 1.3, 0.55, s, e, 0.8);
    b.osc(CH_ROLL, 0.3, 0.4, s, e, 0.8);
    b.osc(CH_PITCH, 0.2, 0.3, s, e, 0.8);
    b.finish()
}

fn leave_reenter(seed: u64) -> Motion {
    let mut b = Builder::new("leave_reenter", seed, KeyPose::Open);
    b.wait_glob(1.0);
    b.place(pl(460.0, -10.0, 0.0, 0.0, 0.0, -0.2), 1.3, 1.0); // out to the right
    b.place(pl(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), 1.3, 1.5); // back
    b.place(pl(-460.0, 20.0, 20.0, 0.3, 0.0, 0.2), 1.0, 0.6); // out to the left
    b.place(pl(-460.0, 380.0, 20.0, 0.0, 0.0, 0.0), 0.6, 0.0); // (unseen) down
    b.place(pl(0.0, 380.0, 0.0, 0.0, 0.0, 0.0), 0.8, 0.4); // (unseen) below the view
    b.place(pl(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), 1.2, 1.2); // re-enter from below
                                                         // Articulation keeps changing, seen or not.
    b.wait(0.6);
    while b.t_art < b.t_glob - 1.5 {
        let k = [
            KeyPose::Fist,
            KeyPose::Open,
            KeyPose::Spread,
            KeyPose::Open,
            KeyPose::Point,
            KeyPose::Open,
        ][b.rng.random_index(6)];
        b.go(k, 0.8, 0.5);
    }
    b.go(KeyPose::Open, 0.7, 0.0);
    b.finish()
}

fn occlusion(seed: u64) -> Motion {
    let mut b = Builder::new("occlusion", seed, KeyPose::Open);
    b.wait_glob(0.6);
    b.place(pl(0.0, 0.0, 0.0, 1.5, 0.1, 0.0), 1.5, 3.6); // thumb side to the camera
    b.place(pl(0.0, 0.0, 10.0, 2.9, 0.15, 0.0), 1.4, 3.2); // back of the hand
    b.place(pl(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), 2.4, 0.6); // front
    b.place(pl(0.0, 0.0, 0.0, -1.5, 0.1, 0.1), 1.4, 3.2); // little-finger side
    b.place(pl(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), 1.4, 0.6); // front
    let end = b.t_glob;
    b.wait(1.5);
    let seq = [
        KeyPose::Fist,
        KeyPose::Open,
        KeyPose::Point,
        KeyPose::Open,
        KeyPose::Spread,
        KeyPose::PinchIndex,
        KeyPose::Open,
        KeyPose::Claw,
        KeyPose::Open,
    ];
    let mut i = 0;
    while b.t_art < end - 1.8 {
        b.go(seq[i % seq.len()], 0.8, 0.4);
        i += 1;
    }
    b.go(KeyPose::Open, 0.8, 0.0);
    b.finish()
}

/// Random placements in the "natural" range around the neutral one.
fn random_placement(b: &mut Builder) -> Placement {
    let yaw = b.uniform(-1.0, 1.0);
    let pitch = b.uniform(-0.4, 0.4);
    let roll = b.uniform(-0.5, 0.5);
    let (dx, dy, dz) = (
        b.uniform(-40.0, 40.0),
        b.uniform(-30.0, 30.0),
        b.uniform(-35.0, 35.0),
    );
    pl(dx, dy, dz, yaw, pitch, roll)
}

fn random(seed: u64) -> Motion {
    let mut b = Builder::new("random", seed, KeyPose::Open);
    while b.t_art < 20.0 {
        let a = b.random_articulation();
        let (dur, hold) = (b.uniform(0.6, 1.3), b.uniform(0.0, 0.4));
        b.go_art(a, dur, hold, MoveOpts::default());
    }
    while b.t_glob < b.t_art - 2.0 {
        let p = random_placement(&mut b);
        let (dur, hold) = (b.uniform(1.2, 2.5), b.uniform(0.0, 0.6));
        b.place(p, dur, hold);
    }
    b.place(Placement::neutral(), 1.5, 0.0);
    b.finish()
}

fn axis_speed(seed: u64) -> Motion {
    let mut b = Builder::new("axis_speed", seed, KeyPose::Open);
    b.wait(0.5);
    b.sync();
    for speed in [0.5, 0.75, 1.0, 1.5, 2.0, 2.5] {
        let d = 0.9 / speed;
        let h = 0.25 / speed;
        b.place(pl(25.0, 0.0, 0.0, 0.5, 0.15, 0.1), 2.0 * (d + h), 0.0);
        b.place(pl(-25.0, 0.0, 0.0, -0.5, -0.15, -0.1), 2.0 * (d + h), 0.0);
        b.go(KeyPose::Fist, d, h);
        b.go(KeyPose::Open, d, h);
        b.go(KeyPose::Spread, d, h);
        b.go(KeyPose::Adducted, d, h);
        b.sync();
    }
    b.place(Placement::neutral(), 0.8, 0.3);
    b.go(KeyPose::Open, 0.6, 0.3);
    b.finish()
}

fn axis_articulation(seed: u64) -> Motion {
    let mut b = Builder::new("axis_articulation", seed, KeyPose::Open);
    // 1. Rigid hand.
    b.wait_glob(0.4);
    b.place(pl(40.0, -10.0, 0.0, 0.5, 0.2, 0.1), 1.2, 0.2);
    b.place(pl(-40.0, 10.0, 20.0, -0.5, -0.2, -0.1), 1.4, 0.2);
    b.place(Placement::neutral(), 1.2, 0.2);
    b.t_art = b.t_glob;
    // 2. One digit at a time.
    for d in [1, 0] {
        b.go_art(digit_flexed(open(), d), 0.8, 0.3, MoveOpts::default());
        b.go_art(open(), 0.8, 0.3, MoveOpts::default());
    }
    // 3. Pairs.
    let pair = |x: usize, y: usize| digit_flexed(digit_flexed(open(), x), y);
    for (x, y) in [(1, 2), (3, 4), (0, 1)] {
        b.go_art(pair(x, y), 0.8, 0.3, MoveOpts::default());
        b.go_art(open(), 0.8, 0.3, MoveOpts::default());
    }
    // 4. All together.
    b.go(KeyPose::Fist, 0.8, 0.3);
    b.go(KeyPose::Open, 0.8, 0.3);
    // 5. Independent digits.
    for _ in 0..8 {
        let a = b.random_articulation();
        b.go_art(a, 0.8, 0.2, MoveOpts::default());
    }
    b.go(KeyPose::Open, 0.8, 0.3);
    b.finish()
}

fn axis_interaction(seed: u64) -> Motion {
    let mut b = Builder::new("axis_interaction", seed, KeyPose::Open);
    b.wait(0.5);
    for k in [
        KeyPose::Spread,
        KeyPose::Adducted,
        KeyPose::PinchIndex,
        KeyPose::PinchMiddle,
        KeyPose::Crossed,
        KeyPose::Victory,
        KeyPose::Crossed,
        KeyPose::Fist,
        KeyPose::ThumbUp,
        KeyPose::Fist,
    ] {
        b.go(k, 0.8, 0.9);
    }
    b.go(KeyPose::Open, 0.8, 0.5);
    let end = b.t_art;
    b.osc(CH_YAW, 0.25, 0.08, 0.0, end, 1.0);
    b.finish()
}

/// Slow, well separated poses under mild turns: a motion meant for multi-frame calibration.
fn calibration(seed: u64) -> Motion {
    let mut b = Builder::new("calibration", seed, KeyPose::Open);
    b.wait(0.5);
    for k in [
        KeyPose::Spread,
        KeyPose::Fist,
        KeyPose::Open,
        KeyPose::Claw,
        KeyPose::PinchIndex,
        KeyPose::Point,
        KeyPose::Victory,
        KeyPose::ThumbUp,
        KeyPose::Open,
    ] {
        b.go(k, 1.0, 0.8);
    }
    let end = b.t_art;
    b.swing(CH_YAW, 0.7, 0.07, 0.0, end, 1.0);
    b.osc(CH_PITCH, 0.3, 0.09, 0.0, end, 1.0);
    b.finish()
}

fn teaser(seed: u64) -> Motion {
    let mut b = Builder::new("teaser", seed, KeyPose::Open);
    b.wait(0.3);
    // Flexion and extension of each digit in turn.
    sec_digit_by_digit(&mut b, 0.4, 0.05);
    // Spread and adduction.
    b.go(KeyPose::Spread, 0.45, 0.25);
    b.go(KeyPose::Adducted, 0.45, 0.2);
    b.go(KeyPose::Spread, 0.4, 0.2);
    b.go(KeyPose::Open, 0.4, 0.1);
    // Pinches.
    b.go(KeyPose::PinchIndex, 0.5, 0.35);
    b.go(KeyPose::Open, 0.4, 0.1);
    b.go(KeyPose::PinchMiddle, 0.5, 0.3);
    b.go(KeyPose::Open, 0.4, 0.1);
    // Fist clench, then the rotating fist.
    b.go(KeyPose::Fist, 0.45, 0.2);
    b.go(KeyPose::Open, 0.4, 0.1);
    b.go(KeyPose::Fist, 0.4, 2.6);
    let fist_turn = (b.t_art - 2.6, b.t_art);
    b.go(KeyPose::Open, 0.5, 0.1);
    // Crossing.
    b.go(KeyPose::Crossed, 0.6, 0.6);
    b.go(KeyPose::Open, 0.5, 0.1);
    // Finger contact.
    b.go(KeyPose::Adducted, 0.4, 0.3);
    b.go(KeyPose::PinchRing, 0.5, 0.4);
    b.go(KeyPose::PinchMiddle, 0.4, 0.4);
    b.go(KeyPose::Open, 0.4, 0.2);
    // Fast rigid burst with an open hand.
    let fast = (b.t_art, b.t_art + 3.0);
    b.go(KeyPose::Spread, 0.6, 1.2);
    b.go(KeyPose::Open, 0.6, 0.6);
    // Slow turn to the side views with moving fingers.
    let side = b.t_art;
    for k in [
        KeyPose::Point,
        KeyPose::Victory,
        KeyPose::Fist,
        KeyPose::Open,
        KeyPose::Claw,
        KeyPose::Open,
        KeyPose::ThumbUp,
        KeyPose::Open,
    ] {
        b.go(k, 0.6, 0.35);
    }
    // Rolling waves and random poses.
    sec_wave(&mut b, 0.45, 0.08);
    for _ in 0..6 {
        let a = b.random_articulation();
        b.go_art(a, 0.6, 0.15, MoveOpts::default());
    }
    sec_pinches(&mut b, 0.45, 0.3);
    b.go(KeyPose::Fist, 0.5, 0.3);
    b.go(KeyPose::Open, 0.5, 0.4);
    let end = b.t_art;

    // Placement: slow drift throughout, bursts on top.
    b.osc(CH_YAW, 0.35, 0.09, 0.0, end, 1.0);
    b.osc(CH_PITCH, 0.2, 0.13, 0.0, end, 1.0);
    b.osc(CH_ROLL, 0.25, 0.07, 0.0, end, 1.0);
    b.osc(CH_X, 25.0, 0.05, 0.0, end, 1.0);
    b.osc(CH_Z, 25.0, 0.07, 0.0, end, 1.0);
    b.swing(CH_YAW, 1.0, 0.7, fist_turn.0, fist_turn.1, 0.5);
    b.osc(CH_ROLL, 0.25, 0.5, fist_turn.0, fist_turn.1, 0.5);
    b.swing(CH_YAW, 0.9, 0.9, fast.0, fast.1, 0.5);
    b.osc(CH_PITCH, 0.35, 1.2, fast.0, fast.1, 0.5);
    b.osc(CH_X, 40.0, 0.8, fast.0, fast.1, 0.5);
    b.t_glob = side;
    b.place(pl(0.0, 0.0, 0.0, 1.35, 0.1, 0.0), 1.6, 1.8);
    b.place(pl(0.0, 0.0, 0.0, -0.3, 0.0, 0.0), 1.6, 0.2);
    b.place(pl(0.0, 0.0, 0.0, -1.35, 0.15, 0.0), 1.8, 1.5);
    b.place(Placement::neutral(), 1.6, 0.0);
    b.finish()
}

// A little `random_index` helper on the rng, so the motions read naturally.
trait RandomIndex {
    fn random_index(&mut self, n: usize) -> usize;
}

impl RandomIndex for rand_chacha::ChaCha8Rng {
    fn random_index(&mut self, n: usize) -> usize {
        use rand::Rng;
        self.random_range(0..n.max(1))
    }
}
