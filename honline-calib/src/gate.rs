//! The window behind the calibrator's gates ([`crate::OnlineConfig::innovation_gate`],
//! [`crate::OnlineConfig::outside_gate`]): a frame statistic over the last accepted frames, and
//! a test of the next frame against its median.

use crate::online::INNOVATION_WINDOW;

/// The last [`INNOVATION_WINDOW`] accepted values of one frame statistic (a ring) and the
/// refusals in a row.
#[derive(Clone, Debug, Default)]
pub(crate) struct Gate {
    values: Vec<f64>,
    next: usize,
    /// A buffer for the median.
    median: Vec<f64>,
    rejected: usize,
}

impl Gate {
    /// Whether `value` is refused: above `factor` times the window's median and above `floor`,
    /// once the window holds a sixth of its frames. After [`INNOVATION_WINDOW`] refusals in a
    /// row the next value is accepted, so that a lasting change of the data is not refused
    /// forever. An accepted value joins the window.
    pub(crate) fn rejects(&mut self, value: f64, factor: f64, floor: f64) -> bool {
        let median = (self.values.len() >= INNOVATION_WINDOW / 6).then(|| {
            self.median.clone_from(&self.values);
            let mid = self.median.len() / 2;
            *self.median.select_nth_unstable_by(mid, f64::total_cmp).1
        });
        let above = median.is_some_and(|m| value > (factor * m).max(floor));
        if above && self.rejected < INNOVATION_WINDOW {
            self.rejected += 1;
            return true;
        }
        self.rejected = 0;
        if self.values.len() < INNOVATION_WINDOW {
            self.values.push(value);
        } else {
            self.values[self.next] = value;
        }
        self.next = (self.next + 1) % INNOVATION_WINDOW;
        false
    }

    /// Forget the window (a new shape to learn).
    pub(crate) fn clear(&mut self) {
        self.values.clear();
        self.next = 0;
        self.rejected = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_value_far_above_the_median_is_refused_until_the_window_gives_way() {
        let mut g = Gate::default();
        for _ in 0..INNOVATION_WINDOW / 6 - 1 {
            assert!(!g.rejects(1.0, 3.0, 0.0));
        }
        // Too few values for a median yet.
        assert!(!g.rejects(100.0, 3.0, 0.0));
        // Median 1: 2.9 passes, 3.1 does not; below the floor nothing is refused.
        assert!(!g.rejects(2.9, 3.0, 0.0));
        assert!(g.rejects(3.1, 3.0, 0.0));
        assert!(!g.rejects(3.1, 3.0, 5.0));
        let refused = (0..2 * INNOVATION_WINDOW)
            .take_while(|_| g.rejects(50.0, 3.0, 0.0))
            .count();
        assert_eq!(refused, INNOVATION_WINDOW);
        g.clear();
        assert!(!g.rejects(50.0, 3.0, 0.0));
    }
}
