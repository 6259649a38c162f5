//! The seeded keyframe builder behind every library motion.

use std::f64::consts::TAU;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::keyposes::{digit_dofs, Articulation, KeyPose, NUM_JOINTS};
use super::track::{Osc, Track};
use super::{
    Motion, Placement, CH_PITCH, CH_ROLL, CH_X, CH_Y, CH_YAW, CH_Z, JOINT_DOFS, NUM_CHANNELS,
};
use crate::default_template;

/// Relative timing jitter of every move.
const TIME_JITTER: f64 = 0.12;
/// Relative amplitude jitter of non-contact key poses (about the relaxed hand).
const AMP_JITTER: f64 = 0.08;
/// Per-digit stagger of the start (fraction of the move duration).
const START_STAGGER: f64 = 0.08;
/// Per-digit spread of the end (fraction of the move duration).
const END_STAGGER: f64 = 0.10;
/// Smallest gap between two keys of a channel (fraction of the move duration).
const MIN_GAP: f64 = 0.35;

/// Options of an articulation move.
#[derive(Copy, Clone, Debug)]
pub(crate) struct MoveOpts {
    /// Jitter the amplitude about the relaxed hand (off for contact poses).
    pub jitter_amplitude: bool,
    /// Extra start delay per digit (s): digit d (0 = thumb) starts `d·wave` later (a finger wave).
    pub wave: f64,
}

impl Default for MoveOpts {
    fn default() -> Self {
        MoveOpts {
            jitter_amplitude: true,
            wave: 0.0,
        }
    }
}

/// The joint limits of the default template, [`JOINT_DOFS`] order.
pub(crate) fn default_joint_limits() -> [[f64; 2]; NUM_JOINTS] {
    let sk = &default_template().skeleton;
    let mut out = [[f64::NEG_INFINITY, f64::INFINITY]; NUM_JOINTS];
    for (j, name) in JOINT_DOFS.iter().enumerate() {
        if let Some(lim) = sk.dof_index(name).and_then(|d| sk.dofs()[d].limits) {
            out[j] = lim;
        }
    }
    out
}

/// Builds the tracks of one motion: an articulation cursor and a placement cursor that advance
/// independently, so rigid motion can overlay finger motion.
pub(crate) struct Builder {
    pub rng: ChaCha8Rng,
    name: &'static str,
    seed: u64,
    tracks: Vec<Track>,
    /// Time at which the next articulation move starts.
    pub t_art: f64,
    /// Time at which the next placement move starts.
    pub t_glob: f64,
    pub limits: [[f64; 2]; NUM_JOINTS],
    relaxed: Articulation,
}

impl Builder {
    /// A builder starting from `start` at the neutral placement.
    pub fn new(name: &'static str, seed: u64, start: KeyPose) -> Self {
        let limits = default_joint_limits();
        let mut tracks = vec![Track::default(); NUM_CHANNELS];
        let a = start.articulation().clamped(&limits);
        for (j, v) in a.0.iter().enumerate() {
            tracks[j].push(0.0, *v, 0.0);
        }
        let p = Placement::neutral();
        for (ch, v) in placement_channels(&p) {
            tracks[ch].push(0.0, v, 0.0);
        }
        Builder {
            rng: ChaCha8Rng::seed_from_u64(seed),
            name,
            seed,
            tracks,
            t_art: 0.0,
            t_glob: 0.0,
            limits,
            relaxed: KeyPose::Open.articulation(),
        }
    }

    /// `x·(1 + U(−rel, rel))`.
    pub fn jitter(&mut self, x: f64, rel: f64) -> f64 {
        x * (1.0 + self.rng.random_range(-rel..=rel))
    }

    /// `U(lo, hi)` (lo when the range is empty).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        if hi > lo {
            self.rng.random_range(lo..hi)
        } else {
            lo
        }
    }

    /// Move the hand to a key pose in about `dur` seconds, then hold about `hold` seconds.
    pub fn go(&mut self, k: KeyPose, dur: f64, hold: f64) {
        let opts = MoveOpts {
            jitter_amplitude: !k.is_contact(),
            ..MoveOpts::default()
        };
        self.go_art(k.articulation(), dur, hold, opts);
    }

    /// Move the articulation to `target` (see [`MoveOpts`]).
    pub fn go_art(&mut self, target: Articulation, dur: f64, hold: f64, opts: MoveOpts) {
        let dur = self.jitter(dur.max(0.05), TIME_JITTER);
        let hold = self.jitter(hold.max(0.0), TIME_JITTER);
        let t0 = self.t_art;
        let mut target = target;
        if opts.jitter_amplitude {
            for d in 0..5 {
                let f = 1.0 + self.rng.random_range(-AMP_JITTER..=AMP_JITTER);
                for i in digit_dofs(d) {
                    target.0[i] = self.relaxed.0[i] + (target.0[i] - self.relaxed.0[i]) * f;
                }
            }
        }
        let target = target.clamped(&self.limits);
        // Groups: the wrist, then the five digits.
        let mut groups: Vec<(Vec<usize>, f64)> = vec![(vec![0, 1], 0.0)];
        for d in 0..5 {
            groups.push((digit_dofs(d).to_vec(), opts.wave * d as f64));
        }
        for (chans, delay) in groups {
            let s = self.uniform(0.0, START_STAGGER) * dur + delay;
            let e = self.uniform(-END_STAGGER, END_STAGGER) * dur + delay;
            for ch in chans {
                let tr = &mut self.tracks[ch];
                let start = t0 + s;
                if tr.last_time() < start - 1e-9 {
                    let v = tr.last_value();
                    tr.push(start, v, 0.0);
                }
                tr.push(t0 + dur + e, target.0[ch], MIN_GAP * dur);
            }
        }
        self.t_art = t0 + dur + hold;
    }

    /// Keep the current articulation for about `dur` seconds.
    pub fn wait(&mut self, dur: f64) {
        let d = self.jitter(dur.max(0.0), TIME_JITTER);
        self.t_art += d;
    }

    /// Move the placement to `p` in about `dur` seconds, then hold about `hold` seconds.
    pub fn place(&mut self, p: Placement, dur: f64, hold: f64) {
        let dur = self.jitter(dur.max(0.05), TIME_JITTER);
        let hold = self.jitter(hold.max(0.0), TIME_JITTER);
        let t0 = self.t_glob;
        for (ch, v) in placement_channels(&p) {
            let tr = &mut self.tracks[ch];
            if tr.last_time() < t0 - 1e-9 {
                let last = tr.last_value();
                tr.push(t0, last, 0.0);
            }
            tr.push(t0 + dur, v, MIN_GAP * dur);
        }
        self.t_glob = t0 + dur + hold;
    }

    /// Keep the placement for about `dur` seconds.
    pub fn wait_glob(&mut self, dur: f64) {
        let d = self.jitter(dur.max(0.0), TIME_JITTER);
        self.t_glob += d;
    }

    /// Bring both cursors to the later of the two.
    pub fn sync(&mut self) {
        let t = self.t_art.max(self.t_glob);
        self.t_art = t;
        self.t_glob = t;
    }

    /// Add an oscillator `amp·env·sin(2π f (t − start) + φ)` on a channel, with the frequency
    /// jittered by ±10 % and a random phase; `fade` ≤ 0 covers the whole motion.
    pub fn osc(&mut self, ch: usize, amp: f64, freq: f64, start: f64, end: f64, fade: f64) {
        let freq = self.jitter(freq, 0.10);
        let phase = self.uniform(0.0, TAU);
        self.tracks[ch].osc.push(Osc {
            amp,
            freq,
            phase,
            start,
            end,
            fade,
        });
    }

    /// Like [`Builder::osc`] but starting in phase 0 (a smooth swing starting from the keyed
    /// value) — the envelope already makes it start at rest.
    pub fn swing(&mut self, ch: usize, amp: f64, freq: f64, start: f64, end: f64, fade: f64) {
        let freq = self.jitter(freq, 0.10);
        self.tracks[ch].osc.push(Osc {
            amp,
            freq,
            phase: 0.0,
            start,
            end,
            fade,
        });
    }

    /// A random articulation within the limits: per finger a curl level driving MCP, PIP and
    /// DIP with the natural DIP ≈ 0.65·PIP coupling, abduction shrinking with the curl, a random
    /// thumb; the wrist stays at 0 (its motion comes from the natural oscillators).
    pub fn random_articulation(&mut self) -> Articulation {
        let mut a = Articulation::zeros();
        // Thumb: anywhere in 80 % of its range.
        for i in digit_dofs(0) {
            let [lo, hi] = self.limits[i];
            let m = 0.1 * (hi - lo);
            a.0[i] = self.uniform(lo + m, hi - m);
        }
        for d in 1..5 {
            let [abd, mcp, pip, dip] = digit_dofs(d);
            let curl: f64 = self.uniform(0.0, 1.0);
            let curl = curl * curl.sqrt(); // bias toward open hands
            a.0[mcp] = self.uniform(-0.1, 0.2) + 1.25 * curl * self.uniform(0.8, 1.1);
            a.0[pip] = self.uniform(0.0, 0.15) + 1.55 * curl * self.uniform(0.8, 1.1);
            a.0[dip] = 0.65 * a.0[pip] + self.uniform(-0.05, 0.1);
            let [lo, hi] = self.limits[abd];
            a.0[abd] = self.uniform(0.6 * lo, 0.6 * hi) * (1.0 - 0.8 * curl);
        }
        a.clamped(&self.limits)
    }

    /// Finish: add the natural wrist motion and global sway (seeded phases) and assemble the
    /// motion; the duration is the end of the last key or cursor.
    pub fn finish(mut self) -> Motion {
        let mut duration = self.t_art.max(self.t_glob);
        for tr in &self.tracks {
            duration = duration.max(tr.last_time());
        }
        // Small natural wrist motion and global sway (wrist_abd = channel 0, wrist_flex = 1).
        let (w_abd, w_flex) = (0, 1);
        for (ch, amp, freq) in [
            (w_flex, 0.06, 0.23),
            (w_flex, 0.025, 0.53),
            (w_abd, 0.035, 0.19),
            (w_abd, 0.015, 0.41),
            (CH_X, 4.0, 0.11),
            (CH_Y, 4.0, 0.14),
            (CH_Z, 6.0, 0.08),
            (CH_YAW, 0.04, 0.12),
            (CH_PITCH, 0.035, 0.16),
            (CH_ROLL, 0.035, 0.10),
        ] {
            self.osc(ch, amp, freq, 0.0, duration, 0.0);
        }
        Motion::from_tracks(self.name, self.seed, duration, self.tracks, self.limits)
    }
}

/// The channel values of a placement.
fn placement_channels(p: &Placement) -> [(usize, f64); 6] {
    [
        (CH_X, p.position.x),
        (CH_Y, p.position.y),
        (CH_Z, p.position.z),
        (CH_YAW, p.yaw),
        (CH_PITCH, p.pitch),
        (CH_ROLL, p.roll),
    ]
}
