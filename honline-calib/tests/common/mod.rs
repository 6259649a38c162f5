//! Synthetic subjects and motions shared by the integration tests (issue 8): a subject is the
//! default template with its E_β subset perturbed, a motion bends the fingers with per-finger
//! phases while the hand turns.

#![allow(dead_code)]

use hand_model::kinematics::Pose;
use hand_model::spheremesh::{PosedSphereMesh, ShapeBasis, SphereMeshTemplate};
use honline_calib::error_subset;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use sensor_io::record::HandRecord;

/// A subject: the template's β with the error subset perturbed by ±`sigma` (relative).
pub fn subject(base: &SphereMeshTemplate, sigma: f64, seed: u64) -> (Vec<f64>, SphereMeshTemplate) {
    let basis = ShapeBasis::honline(base).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut beta = basis.template_values();
    for i in error_subset(&basis) {
        beta[i] *= 1.0 + rng.random_range(-sigma..sigma);
    }
    let t = basis.apply(base, &beta).unwrap();
    (beta, t)
}

/// Frame `k` of a sequence facing the camera: the fingers bend and stretch with per-finger
/// phases (`bend`), or stay straight while the hand turns.
pub fn pose(t: &SphereMeshTemplate, k: usize, bend: bool) -> Pose {
    let sk = &t.skeleton;
    let mut p = Pose::zeros(sk);
    let phase = k as f64 * 0.15;
    for d in sk.dofs() {
        let name = d.name.as_str();
        let i = sk.dof_index(name).unwrap();
        p.values[i] = match name {
            "global_tz" => 400.0,
            "global_ty" => 30.0,
            "global_rx" => 0.2 * (phase * 0.7).sin(),
            "global_ry" => 0.3 * (phase * 0.5).sin(),
            n if bend
                && n.contains("flex")
                && !n.starts_with("global")
                && !n.starts_with("wrist") =>
            {
                let digit = ["thumb", "index", "middle", "ring", "pinky"]
                    .iter()
                    .position(|f| n.starts_with(f))
                    .unwrap_or(0) as f64;
                0.5 * (1.0 - (phase + digit * 0.9).cos())
            }
            _ => 0.0,
        };
    }
    p.clamp_to_limits(sk);
    p
}

/// Mean keypoint error (mm) of a record against `pose` of `t`.
pub fn keypoint_error(rec: &HandRecord, t: &SphereMeshTemplate, pose: &Pose) -> f64 {
    let expected = PosedSphereMesh::new(t, pose).keypoints(t);
    rec.keypoints
        .iter()
        .zip(&expected)
        .map(|(k, e)| (Vector3::from(*k) - e).norm())
        .sum::<f64>()
        / expected.len() as f64
}
