//! Per-digit flexion variants of a tracked pose (beyond the thesis), for the second look at a
//! placement and on a frame that fits much worse than the recent ones
//! ([`super::FrameLoop::step`]). A re-initialization places the open mean pose; a digit
//! that is curled in the data but was placed open can stay open, hidden behind a neighbour
//! in the image (the model's silhouette then stays inside the sensor's, so E_m2d does not
//! see it), while its own points are explained by the palm under it. The LM cannot leave
//! such a minimum: the move from open to curled first raises the energy. Solving again from
//! the same pose with that one digit curled (or opened) finds it; so does exchanging two
//! neighbours' flexions, for the commonest case: the wrong one of two fingers curled.
//!
//! Measured (session 33) on 74 cold starts: the library's 16 motions of the default hand
//! (all but `leave_reenter`) from frames 45, 105, 165 and 250, and the `random` motion of 10
//! random subjects from a frame in 45–244, 90 frames each, seed 5, tracked with `hands track`
//! and the default template; mean keypoint error over each cut, summed:
//!
//! | tracker | ToF | noise-free |
//! |---|---|---|
//! | Ch. 3 sphere-mesh | 238.03 → 157.67 mm (12 cuts better, 1 worse; cuts > 10 mm: 5 → 0) | 186.32 → 113.07 mm (10 better, 1 worse; 5 → 0) |
//! | Ch. 2 cylinders | 471.18 → 396.88 mm (16 better, 4 worse; 14 → 8) | 485.70 → 410.80 mm (13 better, 6 worse; 15 → 11) |
//!
//! The five worst sphere-mesh cuts (random subjects, `crossing` from frame 165) all had one
//! pair of neighbours exchanged (the index curled and the middle finger open where the data
//! had the opposite; 15–25 mm mean keypoint error); all were found at the second look (4–8
//! mm over the cut, the first ten frames included). The losses: the noise-free `fist` from
//! frame 250 (2.39 → 5.97 mm: at the second look it was still converging, and a variant fitted
//! that frame better and then held a wrong index finger for 30 frames), for the cylinders
//! `crossing` from frame 105 (11.51 → 20.20 mm) and `fist` from 250 (5.79 → 9.83). A variant
//! wins by the same rule as a placement at the second look, by score and mean distance; the
//! winners' margins were 3–30 % of the score, the loss's 7 %, so no margin separates them. The
//! library's 16 ToF motions from frame 0 are unchanged (the Ch. 3 tracker's sum 22.43 mm).

use crate::kinematics::names::DIGIT_DOFS;
use crate::kinematics::{Pose, Skeleton};

/// The digits, DESIGN.md order (thumb, index, middle, ring, pinky).
pub const DIGITS: usize = 5;

/// The flexion levels a digit is set to, as fractions of each of its three flexion DOFs'
/// upper limits: open, and curled.
pub const DIGIT_FLEXION_LEVELS: [f64; 2] = [0.0, 0.7];

/// A level is not tried when the digit's flexions are already this close to it (rad, mean
/// absolute difference): the solve from there would end where the tracked pose is.
const SAME_FLEXION: f64 = 0.35;

/// The first finger whose flexions may be swapped with the next one's (the thumb's are not:
/// its joints are not a finger's).
const FIRST_SWAPPED: usize = 1;

/// `pose` with digit `digit`'s three flexions set to each level of [`DIGIT_FLEXION_LEVELS`]
/// (clamped to their limits), then, for a finger but the last, with its flexions and the next
/// finger's exchanged: a hand placed open with one finger curled in the data often curls the
/// wrong one of two neighbours and extends the other into the curled one's place, which no
/// single digit's level undoes. Variants the digit is already near are left out. Empty for a
/// digit out of range or a skeleton without that digit's flexions (found by their DESIGN.md
/// names, [`DIGIT_DOFS`]) or without upper limits on them.
pub fn digit_variants(skeleton: &Skeleton, pose: &Pose, digit: usize) -> Vec<Pose> {
    let Some(dofs) = flexions(skeleton, digit).filter(|_| pose.values.len() == skeleton.num_dofs())
    else {
        return Vec::new();
    };
    let levels = DIGIT_FLEXION_LEVELS.iter().map(|&level| {
        dofs.iter()
            .map(|&(i, [lo, hi])| (i, (level * hi).clamp(lo, hi)))
            .collect::<Vec<_>>()
    });
    let swap = (digit >= FIRST_SWAPPED)
        .then(|| flexions(skeleton, digit + 1))
        .flatten()
        .map(|next| {
            dofs.iter()
                .zip(&next)
                .flat_map(|(&(a, la), &(b, lb))| {
                    let clamp = |v: f64, [lo, hi]: [f64; 2]| v.clamp(lo, hi);
                    [
                        (a, clamp(pose.values[b], la)),
                        (b, clamp(pose.values[a], lb)),
                    ]
                })
                .collect::<Vec<_>>()
        });
    levels
        .chain(swap)
        .filter(|targets| {
            let moved = targets
                .iter()
                .map(|&(i, t)| (pose.values[i] - t).abs())
                .sum::<f64>();
            moved / dofs.len() as f64 > SAME_FLEXION
        })
        .map(|targets| {
            let mut out = pose.clone();
            for (i, t) in targets {
                out.values[i] = t;
            }
            out
        })
        .collect()
}

/// Digit `digit`'s three flexion DOFs with their limits (DESIGN.md names), or `None`.
fn flexions(skeleton: &Skeleton, digit: usize) -> Option<Vec<(usize, [f64; 2])>> {
    DIGIT_DOFS
        .get(4 * digit + 1..4 * digit + 4)?
        .iter()
        .map(|n| {
            let i = skeleton.dof_index(n)?;
            Some((i, skeleton.dofs()[i].limits?))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spheremesh::default_right_hand;

    #[test]
    fn variants_move_one_digit_to_the_levels_it_is_not_near() {
        let t = default_right_hand();
        let sk = &t.skeleton;
        let pose =
            Pose::from_named(sk, [("middle_pip_flex", 0.1), ("index_pip_flex", 1.2)]).unwrap();
        // Middle finger open: only the curled level differs from it.
        let v = digit_variants(sk, &pose, 2);
        assert_eq!(v.len(), 1);
        let changed: Vec<&str> = (0..sk.num_dofs())
            .filter(|&i| v[0].values[i] != pose.values[i])
            .map(|i| sk.dofs()[i].name.as_str())
            .collect();
        assert_eq!(
            changed,
            ["middle_mcp_flex", "middle_pip_flex", "middle_dip_flex"]
        );
        let pip = sk.dof_index("middle_pip_flex").unwrap();
        assert!((v[0].values[pip] - 0.7 * sk.dofs()[pip].limits.unwrap()[1]).abs() < 1e-12);
        // Index finger half bent, the middle open: both levels, then the two exchanged.
        let v = digit_variants(sk, &pose, 1);
        assert_eq!(v.len(), 3);
        let at = |p: &Pose, name: &str| p.values[sk.dof_index(name).unwrap()];
        assert_eq!(at(&v[2], "index_pip_flex"), 0.1);
        assert_eq!(at(&v[2], "middle_pip_flex"), 1.2);
        // The pinky has no next finger, the thumb is not exchanged.
        assert_eq!(digit_variants(sk, &pose, 4).len(), 1);
        assert_eq!(digit_variants(sk, &pose, 0).len(), 1);
        // Out of range or the wrong pose length: nothing.
        assert!(digit_variants(sk, &pose, DIGITS).is_empty());
        let short = Pose {
            values: vec![0.0; 3],
        };
        assert!(digit_variants(sk, &short, 1).is_empty());
    }
}
