//! Speed statistics of a motion and the automatic choice of calibration frames.

use hand_model::keypoints::NUM_KEYPOINTS;
use hand_model::kinematics::Pose;
use hand_model::spheremesh::{PosedSphereMesh, SphereMeshTemplate};
use nalgebra::{Matrix3, Vector3};
use sensor_io::Camera;

use super::{Motion, GLOBAL_DOFS, JOINT_DOFS};
use crate::default_template;
use crate::error::{DatasetError, Result};

/// Whether every keypoint is in front of `camera` and projects inside its image.
pub fn hand_in_view(camera: &Camera, keypoints: &[Vector3<f64>]) -> bool {
    keypoints.iter().all(|p| {
        if !(p.z > 0.0 && p.iter().all(|x| x.is_finite())) {
            return false;
        }
        let uv = camera.project(p);
        camera.contains(uv.x, uv.y)
    })
}

/// Whether no keypoint is visible: each is behind `camera` or projects outside its image.
pub fn hand_out_of_view(camera: &Camera, keypoints: &[Vector3<f64>]) -> bool {
    keypoints.iter().all(|p| {
        if p.z.is_nan() || p.z <= 0.0 {
            return true;
        }
        let uv = camera.project(p);
        !camera.contains(uv.x, uv.y)
    })
}

/// Poses a motion on the default template whatever skeleton it was re-targeted to.
struct DefaultPoser {
    /// Per default-template DOF, its index in `GLOBAL_DOFS ++ JOINT_DOFS` (None: held at 0).
    map: Vec<Option<usize>>,
    posed: PosedSphereMesh,
    pose: Pose,
}

impl DefaultPoser {
    fn new(template: &SphereMeshTemplate) -> Self {
        let names: Vec<&str> = GLOBAL_DOFS
            .iter()
            .chain(JOINT_DOFS.iter())
            .copied()
            .collect();
        let map = template
            .skeleton
            .dofs()
            .iter()
            .map(|d| names.iter().position(|n| *n == d.name))
            .collect();
        DefaultPoser {
            map,
            posed: PosedSphereMesh::default(),
            pose: Pose::zeros(&template.skeleton),
        }
    }

    /// Keypoints and the palm frame rotation/translation at time `t`.
    fn keypoints(
        &mut self,
        template: &SphereMeshTemplate,
        motion: &Motion,
        t: f64,
    ) -> [Vector3<f64>; NUM_KEYPOINTS] {
        let a = motion.articulation_at(t);
        let p = motion.placement_at(t);
        let tr = p.translation();
        let eu = p.euler();
        let global = [tr.x, tr.y, tr.z, eu[0], eu[1], eu[2]];
        for (v, m) in self.pose.values.iter_mut().zip(&self.map) {
            *v = match *m {
                Some(i) if i < 6 => global[i],
                Some(i) => a.0[i - 6],
                None => 0.0,
            };
        }
        self.posed.update(template, &self.pose);
        self.posed.keypoints(template)
    }
}

/// Joint values, global rotation and keypoints of one sampled frame.
type FrameSample = (
    [f64; JOINT_DOFS.len()],
    Matrix3<f64>,
    [Vector3<f64>; NUM_KEYPOINTS],
);

/// Speed statistics of a motion sampled at a frame rate (keypoints on the default template).
#[derive(Clone, Debug, PartialEq)]
pub struct MotionStats {
    /// Motion name.
    pub name: String,
    /// Duration (s).
    pub duration: f64,
    /// Number of frames sampled.
    pub frames: usize,
    /// Largest joint angular speed between consecutive frames (rad/s), global DOFs excluded.
    pub max_joint_speed: f64,
    /// The joint DOF reaching it.
    pub max_joint_speed_dof: String,
    /// Largest finite-difference joint acceleration (rad/s²).
    pub max_joint_accel: f64,
    /// Largest angular speed of the global rotation (rad/s), from `R_iᵀ R_{i+1}`.
    pub max_global_angular_speed: f64,
    /// Largest keypoint speed (mm/s) between consecutive frames.
    pub max_keypoint_speed: f64,
    /// Largest finite-difference keypoint acceleration (mm/s²).
    pub max_keypoint_accel: f64,
    /// Frames with at least one keypoint outside the SR300 QVGA view.
    pub frames_not_fully_in_view: usize,
    /// Frames with every keypoint outside the SR300 QVGA view.
    pub frames_out_of_view: usize,
}

fn rotation_angle(r: &Matrix3<f64>) -> f64 {
    ((r.trace() - 1.0) * 0.5).clamp(-1.0, 1.0).acos()
}

/// Sample `motion` at `fps` over its whole duration and measure its speeds. Refused: `fps` not
/// finite and positive.
pub fn motion_stats(motion: &Motion, fps: f64) -> Result<MotionStats> {
    if !(fps.is_finite() && fps > 0.0) {
        return Err(DatasetError::arg(
            "fps",
            format!("must be positive, got {fps}"),
        ));
    }
    let template = default_template();
    let camera = Camera::sr300_qvga();
    let mut poser = DefaultPoser::new(template);
    let n = motion.num_frames(fps);
    let mut s = MotionStats {
        name: motion.name().into(),
        duration: motion.duration(),
        frames: n,
        max_joint_speed: 0.0,
        max_joint_speed_dof: String::new(),
        max_joint_accel: 0.0,
        max_global_angular_speed: 0.0,
        max_keypoint_speed: 0.0,
        max_keypoint_accel: 0.0,
        frames_not_fully_in_view: 0,
        frames_out_of_view: 0,
    };
    let mut prev: Option<FrameSample> = None;
    let mut prev_vel: Option<([f64; JOINT_DOFS.len()], [Vector3<f64>; NUM_KEYPOINTS])> = None;
    for i in 0..n {
        let t = i as f64 / fps;
        let a = motion.articulation_at(t).0;
        let r = motion.placement_at(t).rotation();
        let k = poser.keypoints(template, motion, t);
        if !hand_in_view(&camera, &k) {
            s.frames_not_fully_in_view += 1;
        }
        if hand_out_of_view(&camera, &k) {
            s.frames_out_of_view += 1;
        }
        if let Some((pa, pr, pk)) = prev {
            let mut va = [0.0; JOINT_DOFS.len()];
            for j in 0..a.len() {
                va[j] = (a[j] - pa[j]) * fps;
                if va[j].abs() > s.max_joint_speed {
                    s.max_joint_speed = va[j].abs();
                    s.max_joint_speed_dof = JOINT_DOFS[j].into();
                }
            }
            let w = rotation_angle(&(pr.transpose() * r)) * fps;
            s.max_global_angular_speed = s.max_global_angular_speed.max(w);
            let mut vk = [Vector3::zeros(); NUM_KEYPOINTS];
            for q in 0..NUM_KEYPOINTS {
                vk[q] = (k[q] - pk[q]) * fps;
                s.max_keypoint_speed = s.max_keypoint_speed.max(vk[q].norm());
            }
            if let Some((pva, pvk)) = prev_vel {
                for j in 0..a.len() {
                    s.max_joint_accel = s.max_joint_accel.max(((va[j] - pva[j]) * fps).abs());
                }
                for q in 0..NUM_KEYPOINTS {
                    s.max_keypoint_accel =
                        s.max_keypoint_accel.max(((vk[q] - pvk[q]) * fps).norm());
                }
            }
            prev_vel = Some((va, vk));
        }
        prev = Some((a, r, k));
    }
    Ok(s)
}

/// Weight of the viewing direction in the calibration feature (mm per unit direction).
const VIEW_WEIGHT: f64 = 60.0;

/// The pose feature of one frame: the 21 keypoints expressed in the palm frame (articulation,
/// independent of the global pose) and the direction toward the camera in the palm frame,
/// scaled by [`VIEW_WEIGHT`] mm (a 90° change of view ≈ 85 mm of feature distance).
fn feature(template: &SphereMeshTemplate, posed: &PosedSphereMesh, palm: usize) -> Vec<f64> {
    let k = posed.keypoints(template);
    let g = posed.skeleton.globals[palm];
    let rt = g.rotation.transpose();
    let mut f = Vec::with_capacity(3 * NUM_KEYPOINTS + 3);
    for p in &k {
        f.extend((rt * (p - g.translation)).iter());
    }
    let to_cam = rt * (-g.translation);
    let n = to_cam.norm();
    let dir = if n > 1e-9 {
        to_cam / n
    } else {
        Vector3::zeros()
    };
    f.extend((dir * VIEW_WEIGHT).iter());
    f
}

fn dist2(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// Choose `n` frames of a motion for multi-frame calibration (issue 6), deterministically.
///
/// Frames `0..frames` at `fps` (capped at the motion's length) are described by a pose feature
/// — the 21 keypoints of the default template in the palm frame plus the viewing direction in
/// the palm frame (60 mm per unit) — and chosen by farthest-point sampling: first the frame
/// farthest from the mean feature, then repeatedly the frame farthest from all chosen ones (ties
/// go to the earliest frame). Only frames whose keypoints all lie inside the SR300 QVGA view are
/// candidates (all frames when none is). Returns at most `n` frame indices, sorted; empty when
/// `n` or `frames` is 0 or `fps` is not finite and positive.
pub fn select_calibration_frames(motion: &Motion, n: usize, fps: f64, frames: usize) -> Vec<usize> {
    if n == 0 || frames == 0 || !(fps.is_finite() && fps > 0.0) {
        return Vec::new();
    }
    let template = default_template();
    let camera = Camera::sr300_qvga();
    let palm = template.skeleton.bone_index("palm").unwrap_or(0);
    let mut poser = DefaultPoser::new(template);
    let count = frames.min(motion.num_frames(fps));
    let mut feats = Vec::with_capacity(count);
    let mut in_view = Vec::with_capacity(count);
    for i in 0..count {
        let k = poser.keypoints(template, motion, i as f64 / fps);
        in_view.push(hand_in_view(&camera, &k));
        feats.push(feature(template, &poser.posed, palm));
    }
    let mut candidates: Vec<usize> = (0..count).filter(|&i| in_view[i]).collect();
    if candidates.is_empty() {
        candidates = (0..count).collect();
    }
    let dim = feats.first().map_or(0, |f| f.len());
    let mut mean = vec![0.0; dim];
    for &i in &candidates {
        for (m, x) in mean.iter_mut().zip(&feats[i]) {
            *m += x;
        }
    }
    for m in &mut mean {
        *m /= candidates.len() as f64;
    }
    let mut chosen = Vec::with_capacity(n.min(candidates.len()));
    let mut min_d: Vec<f64> = candidates
        .iter()
        .map(|&i| dist2(&feats[i], &mean))
        .collect();
    let mut taken = vec![false; candidates.len()];
    while chosen.len() < n.min(candidates.len()) {
        let mut best: Option<usize> = None;
        for (c, &d) in min_d.iter().enumerate() {
            if taken[c] {
                continue;
            }
            if best.is_none_or(|b| d > min_d[b]) {
                best = Some(c);
            }
        }
        let Some(b) = best else { break };
        taken[b] = true;
        let fb = candidates[b];
        chosen.push(fb);
        // After the first pick, distances are to the chosen set only.
        let first = chosen.len() == 1;
        for (c, &i) in candidates.iter().enumerate() {
            if taken[c] {
                continue;
            }
            let d = dist2(&feats[i], &feats[fb]);
            min_d[c] = if first { d } else { min_d[c].min(d) };
        }
    }
    chosen.sort_unstable();
    chosen
}
