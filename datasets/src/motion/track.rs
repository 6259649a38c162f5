//! One animated channel: minimum-jerk keyframes plus smoothly faded oscillators.

use std::f64::consts::TAU;

/// The minimum-jerk (quintic) blend `s(u) = 10u³ − 15u⁴ + 6u⁵` on `[0, 1]`: zero velocity and
/// acceleration at both ends, so a chain of such blends is C².
#[inline]
pub(crate) fn min_jerk(u: f64) -> f64 {
    let u = u.clamp(0.0, 1.0);
    u * u * u * (10.0 + u * (-15.0 + 6.0 * u))
}

/// A sinusoid `amp · env(t) · sin(2π·freq·(t − start) + phase)`, where the envelope rises from 0
/// to 1 over `fade` seconds after `start` and falls back to 0 over `fade` seconds before `end`
/// (minimum-jerk ramps, so the product stays C²); zero outside `[start, end]`. With `fade ≤ 0`
/// there is no envelope at all: the oscillator covers the whole motion.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Osc {
    pub amp: f64,
    pub freq: f64,
    pub phase: f64,
    pub start: f64,
    pub end: f64,
    pub fade: f64,
}

impl Osc {
    /// The envelope; `fade ≤ 0` means no envelope at all (an oscillator covering the whole
    /// motion, start and end ignored).
    fn envelope(&self, t: f64) -> f64 {
        if self.fade <= 0.0 {
            return 1.0;
        }
        if t <= self.start || t >= self.end {
            return 0.0;
        }
        let up = min_jerk((t - self.start) / self.fade);
        let down = min_jerk((self.end - t) / self.fade);
        up.min(down)
    }

    fn eval(&self, t: f64) -> f64 {
        let env = self.envelope(t);
        if env == 0.0 {
            return 0.0;
        }
        self.amp * env * (TAU * self.freq * (t - self.start) + self.phase).sin()
    }
}

/// A channel: keyframes `(time, value)` in increasing time, blended by [`min_jerk`] between
/// consecutive keys and held constant outside them, plus a sum of oscillators.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Track {
    pub keys: Vec<(f64, f64)>,
    pub osc: Vec<Osc>,
}

impl Track {
    /// The last key value (0 without keys).
    pub fn last_value(&self) -> f64 {
        self.keys.last().map_or(0.0, |k| k.1)
    }

    /// The last key time (−∞ without keys).
    pub fn last_time(&self) -> f64 {
        self.keys.last().map_or(f64::NEG_INFINITY, |k| k.0)
    }

    /// Append a key at `max(time, last key time + min_gap)`, so key times keep increasing.
    pub fn push(&mut self, time: f64, value: f64, min_gap: f64) {
        let t = time.max(self.last_time() + min_gap);
        self.keys.push((t, value));
    }

    /// The keyframed part at time `t`.
    pub fn keyed(&self, t: f64) -> f64 {
        let keys = &self.keys;
        match keys.len() {
            0 => 0.0,
            1 => keys[0].1,
            n => {
                if t <= keys[0].0 {
                    return keys[0].1;
                }
                if t >= keys[n - 1].0 {
                    return keys[n - 1].1;
                }
                // First key strictly after t.
                let i = keys.partition_point(|k| k.0 <= t);
                let (t0, v0) = keys[i - 1];
                let (t1, v1) = keys[i];
                let span = t1 - t0;
                if span <= 0.0 {
                    return v1;
                }
                v0 + (v1 - v0) * min_jerk((t - t0) / span)
            }
        }
    }

    /// The channel value at time `t`.
    pub fn eval(&self, t: f64) -> f64 {
        self.keyed(t) + self.osc.iter().map(|o| o.eval(t)).sum::<f64>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn min_jerk_is_c2_at_the_ends() {
        assert_eq!(min_jerk(0.0), 0.0);
        assert_eq!(min_jerk(1.0), 1.0);
        let h = 1e-4;
        let v0 = (min_jerk(h) - min_jerk(0.0)) / h;
        let v1 = (min_jerk(1.0) - min_jerk(1.0 - h)) / h;
        assert!(v0.abs() < 1e-6 && v1.abs() < 1e-6);
        let a0 = (min_jerk(2.0 * h) - 2.0 * min_jerk(h) + min_jerk(0.0)) / (h * h);
        assert!(a0.abs() < 1e-2, "{a0}");
    }

    #[test]
    fn keys_hold_outside_and_blend_inside() {
        let mut tr = Track::default();
        tr.push(1.0, 2.0, 0.01);
        tr.push(3.0, 4.0, 0.01);
        tr.push(3.0, 5.0, 0.5); // pushed to 3.5
        assert_eq!(tr.keys[2].0, 3.5);
        assert_eq!(tr.eval(0.0), 2.0);
        assert_eq!(tr.eval(2.0), 3.0);
        assert_eq!(tr.eval(10.0), 5.0);
    }

    #[test]
    fn faded_oscillator_starts_and_ends_at_rest() {
        let o = Osc {
            amp: 1.0,
            freq: 1.0,
            phase: 0.3,
            start: 1.0,
            end: 3.0,
            fade: 0.5,
        };
        assert_eq!(o.eval(0.5), 0.0);
        assert_eq!(o.eval(3.5), 0.0);
        assert!(o.eval(1.001).abs() < 1e-6);
        assert!(o.eval(2.999).abs() < 1e-6);
    }
}
