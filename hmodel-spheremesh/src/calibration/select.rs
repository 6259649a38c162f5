//! Choosing the calibration frames of a tracked sequence (issue 6 "chosen automatically"): the
//! thesis calibrates from a handful of frames "in different poses" (§3.4) — redundancy of poses
//! is what makes the kinematics observable. Frames are picked by farthest-point sampling in pose
//! space, so that the chosen poses are as different from each other as the sequence allows.

use hand_model::kinematics::{DofKind, Pose, Skeleton};

/// Indices of `n` frames (fewer when there are fewer candidates) among `poses`, skipping the
/// frames `usable` rejects: the first is the most articulated frame, each next one the frame
/// farthest from all chosen ones. Distance: the Euclidean distance over joint angles plus the
/// global rotation angles (translations ignored: the place of the hand teaches nothing about
/// its shape).
pub fn select_frames(
    skeleton: &Skeleton,
    poses: &[Pose],
    usable: impl Fn(usize) -> bool,
    n: usize,
) -> Vec<usize> {
    let angular: Vec<usize> = skeleton
        .dofs()
        .iter()
        .enumerate()
        .filter(|(_, d)| d.kind != DofKind::Translation)
        .map(|(i, _)| i)
        .collect();
    let candidates: Vec<usize> = (0..poses.len()).filter(|&i| usable(i)).collect();
    let distance = |a: &Pose, b: &Pose| {
        angular
            .iter()
            .map(|&i| (a.values[i] - b.values[i]).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let articulation = |p: &Pose| {
        angular
            .iter()
            .filter(|&&i| skeleton.dofs()[i].kind == DofKind::Rotation)
            .map(|&i| p.values[i].abs())
            .sum::<f64>()
    };
    let Some(&first) = candidates
        .iter()
        .max_by(|&&a, &&b| articulation(&poses[a]).total_cmp(&articulation(&poses[b])))
    else {
        return Vec::new();
    };
    let mut chosen = vec![first];
    let mut nearest: Vec<f64> = candidates
        .iter()
        .map(|&c| distance(&poses[c], &poses[first]))
        .collect();
    while chosen.len() < n.min(candidates.len()) {
        let (k, _) = nearest
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .expect("candidates remain");
        let pick = candidates[k];
        chosen.push(pick);
        for (d, &c) in nearest.iter_mut().zip(&candidates) {
            *d = d.min(distance(&poses[c], &poses[pick]));
        }
    }
    chosen
}

#[cfg(test)]
mod tests {
    use super::*;
    use hand_model::spheremesh::default_right_hand;

    #[test]
    fn picks_distinct_usable_poses() {
        let t = default_right_hand();
        let sk = &t.skeleton;
        let mut poses = Vec::new();
        for k in 0..30 {
            let mut p = Pose::zeros(sk);
            p.set(sk, "index_pip_flex", f64::from(k % 3) * 0.5).unwrap();
            p.set(sk, "global_tx", f64::from(k)).unwrap();
            poses.push(p);
        }
        let chosen = select_frames(sk, &poses, |i| i != 2, 3);
        assert_eq!(chosen.len(), 3);
        let flex = sk.dof_index("index_pip_flex").unwrap();
        let mut values: Vec<f64> = chosen.iter().map(|&i| poses[i].values[flex]).collect();
        values.sort_by(f64::total_cmp);
        assert_eq!(values, [0.0, 0.5, 1.0]);
        assert!(!chosen.contains(&2));
        assert!(select_frames(sk, &poses, |_| false, 3).is_empty());
    }
}
