//! A sphere-mesh fit to one real depth frame (issue 7, item 7), scored against marker ground
//! truth through a documented keypoint mapping.
//!
//! The fit uses nothing of the ground truth:
//! 1. preprocessing ([`sensor_io::preprocess`]): median downsampling, depth range, the
//!    depth-only hand segmentation, subsampled points and the silhouette distance transform;
//! 2. initialization: the template's rest centroid placed on the centroid of the segmented cloud
//!    (pushed [`FitConfig::depth_offset`] behind it, since the cloud is the visible surface) in a
//!    fixed upright orientation (fingers toward the image top), palm toward the camera or away
//!    from it;
//! 3. for each uniform latent scale of [`FitConfig::scales`] (Eq. 4.14 with the three factors
//!    equal, [`ShapeBasis::from_latent`]) and each orientation, a pose-only Levenberg–Marquardt
//!    fit of the thesis' d2m + m2d energy ([`calibrate`] with `fit_shape: false`, §3.4 weights);
//!    the hypothesis of lowest final energy is kept;
//! 4. a coordinate search over the three latent scales (height, width, thickness), each moved by
//!    ±[`FitConfig::latent_step`] with the pose refitted from the current best, kept when the
//!    energy drops.
//!
//! One view cannot separate shape from pose (thesis §3.4), hence three latent scales searched on
//! a grid instead of a free β. The energy is a sum over points and pushed pixels, so it favours
//! a model large enough to cover whatever the segmentation kept (e.g. the wrist).

use std::time::Instant;

use datasets::nyu::{NyuJoints, NYU_JOINTS};
use hand_model::kinematics::Pose;
use hand_model::math::matrix_to_euler_xyz;
use hand_model::spheremesh::{PosedSphereMesh, ShapeBasis, SphereMeshTemplate};
use hmodel_spheremesh::calibration::{calibrate, Calibration, CalibrationConfig, CalibrationFrame};
use nalgebra::{Matrix3, Vector3};
use sensor_io::preprocess::{PreprocessConfig, PreprocessedFrame, Preprocessor};
use sensor_io::{Camera, DepthImage, Frame};

use crate::error::{EvalError, Result};

/// Settings of [`fit_depth_frame`].
#[derive(Clone, Debug)]
pub struct FitConfig {
    /// Preprocessing (downsampling, range, segmentation, number of points).
    pub preprocess: PreprocessConfig,
    /// Uniform latent scales tried first (1 = template).
    pub scales: Vec<f64>,
    /// Step of the coordinate search over the three latent scales that follows (0: none).
    pub latent_step: f64,
    /// Bounds of every latent scale.
    pub latent_bounds: [f64; 2],
    /// Rounds of the coordinate search.
    pub latent_rounds: usize,
    /// LM iterations per hypothesis.
    pub iterations: usize,
    /// How far behind the cloud's centroid the model's rest centroid starts (mm).
    pub depth_offset: f64,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            preprocess: PreprocessConfig {
                downsample: 2,
                num_points: 1200,
                ..PreprocessConfig::default()
            },
            scales: vec![0.9, 1.0, 1.1, 1.2, 1.3],
            latent_step: 0.1,
            latent_bounds: [0.7, 1.5],
            latent_rounds: 2,
            iterations: 25,
            depth_offset: 15.0,
        }
    }
}

/// The outcome of [`fit_depth_frame`].
#[derive(Clone, Debug)]
pub struct FrameFit {
    /// The fitted template (the base at the chosen scale).
    pub template: SphereMeshTemplate,
    /// The fitted pose.
    pub pose: Pose,
    /// The chosen latent scales (height, width, thickness; Eq. 4.14).
    pub latent: [f64; 3],
    /// Whether the palm faced the camera at the initialization of the chosen hypothesis.
    pub palm_toward_camera: bool,
    /// Final energy of the chosen hypothesis.
    pub energy: f64,
    /// Energy of the chosen hypothesis at its initialization (for a hypothesis of the latent
    /// search: its warm start from the previous best pose).
    pub initial_energy: f64,
    /// The 21 DESIGN.md keypoints of the fit (camera frame, mm).
    pub keypoints: Vec<[f64; 3]>,
    /// The preprocessed frame that was fitted (processed depth, camera, silhouette, points).
    pub frame: PreprocessedFrame,
    /// Segmented silhouette pixels (at the processed resolution).
    pub silhouette_pixels: usize,
    /// Points fitted.
    pub points: usize,
    /// Wall time (s).
    pub seconds: f64,
}

/// Rotation taking the model frame (y toward the fingertips, palm toward −z) to an upright hand
/// in the camera frame (fingers toward −y): palm toward the camera (a half turn about z) or away
/// from it (a half turn about x).
fn upright(palm_toward_camera: bool) -> Matrix3<f64> {
    if palm_toward_camera {
        Matrix3::from_diagonal(&Vector3::new(-1.0, -1.0, 1.0))
    } else {
        Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0))
    }
}

/// Set the six global DOFs of `pose` so that the model is turned by `r` (model → camera) and the
/// centroid of the template's *rest* sphere centers lands on `target` (camera frame, mm); the
/// articulation of `pose` is kept.
pub fn place_pose(
    template: &SphereMeshTemplate,
    pose: &mut Pose,
    r: &Matrix3<f64>,
    target: &Vector3<f64>,
) {
    let sk = &template.skeleton;
    let rest = PosedSphereMesh::new(template, &Pose::zeros(sk));
    let c = rest.spheres.iter().map(|s| s.center).sum::<Vector3<f64>>() / rest.spheres.len() as f64;
    let t = target - r * c;
    let [a, b, g] = matrix_to_euler_xyz(r);
    for (name, v) in [
        ("global_rx", a),
        ("global_ry", b),
        ("global_rz", g),
        ("global_tx", t.x),
        ("global_ty", t.y),
        ("global_tz", t.z),
    ] {
        // Every template has the six global DOFs.
        let _ = pose.set(sk, name, v);
    }
}

/// The lowest energy a calibration reached: its initial energy or that of an accepted step.
pub fn best_energy(calibration: &Calibration) -> f64 {
    calibration
        .iterations
        .iter()
        .filter(|r| r.accepted)
        .map(|r| r.energy)
        .fold(calibration.initial_energy, f64::min)
}

/// Fit `base` to one depth frame (see the module docs). Refused: a frame whose size differs from
/// the camera's, a frame where no hand is segmented (fewer than 50 points), a base template
/// without the honline shape basis.
pub fn fit_depth_frame(
    depth: &DepthImage,
    camera: &Camera,
    base: &SphereMeshTemplate,
    config: &FitConfig,
) -> Result<FrameFit> {
    let start = Instant::now();
    let mut pre = Preprocessor::new(config.preprocess.clone());
    let mut out = PreprocessedFrame::default();
    let frame = Frame {
        index: 0,
        timestamp: 0.0,
        depth: depth.clone(),
        color: None,
    };
    pre.process(&frame, camera, &mut out)
        .map_err(|e| EvalError::arg("depth", e.to_string()))?;
    if out.points.len() < 50 {
        return Err(EvalError::arg(
            "depth",
            format!("no hand segmented ({} points)", out.points.len()),
        ));
    }
    let centroid = out.points.iter().sum::<Vector3<f64>>() / out.points.len() as f64;
    let target = centroid + Vector3::new(0.0, 0.0, config.depth_offset);
    let data = CalibrationFrame::depth(&out);
    let basis = ShapeBasis::honline(base).map_err(|e| EvalError::arg("template", e.to_string()))?;
    let cal = CalibrationConfig {
        fit_shape: false,
        iterations: config.iterations,
        ..CalibrationConfig::default()
    };
    let solve = |latent: [f64; 3], init: Option<&Pose>, palm: bool| -> Result<FrameFit> {
        let template = basis
            .apply(base, &basis.from_latent(latent))
            .map_err(|e| EvalError::arg("scales", e.to_string()))?;
        let init = init.cloned().unwrap_or_else(|| {
            let mut p = Pose::zeros(&template.skeleton);
            place_pose(&template, &mut p, &upright(palm), &target);
            p
        });
        let fit = calibrate(&template, std::slice::from_ref(&data), &[init], &cal)
            .map_err(|e| EvalError::arg("fit", e.to_string()))?;
        let energy = best_energy(&fit);
        let pose = fit.poses[0].clone();
        let keypoints = PosedSphereMesh::new(&template, &pose)
            .keypoints(&template)
            .iter()
            .map(|p| [p.x, p.y, p.z])
            .collect();
        Ok(FrameFit {
            template,
            pose,
            latent,
            palm_toward_camera: palm,
            energy,
            initial_energy: fit.initial_energy,
            keypoints,
            frame: PreprocessedFrame::default(),
            silhouette_pixels: out.hand.count,
            points: out.points.len(),
            seconds: 0.0,
        })
    };
    let mut best: Option<FrameFit> = None;
    for &scale in &config.scales {
        for palm in [true, false] {
            let fit = solve([scale; 3], None, palm)?;
            if best.as_ref().is_none_or(|b| fit.energy < b.energy) {
                best = Some(fit);
            }
        }
    }
    let mut best = best.ok_or_else(|| EvalError::arg("scales", "no scale to try"))?;
    let [lo, hi] = config.latent_bounds;
    for _ in 0..config.latent_rounds {
        let mut improved = false;
        for axis in 0..3 {
            for sign in [-1.0, 1.0] {
                let mut latent = best.latent;
                latent[axis] = (latent[axis] + sign * config.latent_step).clamp(lo, hi);
                if config.latent_step <= 0.0 || latent == best.latent {
                    continue;
                }
                let fit = solve(latent, Some(&best.pose), best.palm_toward_camera)?;
                if fit.energy < best.energy {
                    best = fit;
                    improved = true;
                }
            }
        }
        if !improved {
            break;
        }
    }
    best.frame = out;
    best.seconds = start.elapsed().as_secs_f64();
    Ok(best)
}

/// How one NYU joint is read off the 21 DESIGN.md keypoints.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum NyuJointSource {
    /// The point at `fraction` of the arc length of a keypoint chain (first to last).
    Chain {
        /// Keypoint indices from the base of the chain to its tip.
        chain: [usize; 4],
        /// Fraction of the chain's length from its base.
        fraction: f64,
    },
    /// `a + f·(b − c)`: a keypoint offset along the difference of two others.
    Offset {
        /// Base keypoint.
        a: usize,
        /// Difference `b − c`.
        b: usize,
        /// Difference `b − c`.
        c: usize,
        /// Factor.
        f: f64,
    },
    /// The midpoint of two keypoints.
    Mid(usize, usize),
}

/// The keypoint mapping of the 14 NYU joints ([`datasets::nyu::NYU_JOINT_NAMES`]).
///
/// NYU's 14 joints are 14 of its 36 markers; honline's `GroundTruthLoader` reproduces the
/// finger markers as 5 points along the chain from the finger base to the tip end, at arc
/// fractions 1, 19/24, 14/24, 9/24, 1/6 (tip first). The 14-joint set keeps markers 0 and 3 of
/// each finger (fractions 1 and 0.375 along MCP→PIP→DIP→tip), markers 0, 1, 3 of the thumb
/// (1, 0.79, 0.375 along CMC→MCP→IP→tip) and three palm markers: the two wrist-side palm points
/// (NYU joint 11 on the pinky side, 12 on the thumb side, read off the image of test frame 1)
/// modeled as the wrist keypoint moved by half the index-to-pinky MCP spread toward either side,
/// and the palm center modeled as the midpoint of the wrist and the middle MCP. The palm
/// markers are approximations; [`FINGER_JOINTS`] selects the 11 finger joints that follow the
/// marker definition exactly up to the model's joint placement.
pub const NYU_FROM_KEYPOINTS: [NyuJointSource; NYU_JOINTS] = {
    use NyuJointSource::{Chain, Mid, Offset};
    const PINKY: [usize; 4] = [17, 18, 19, 20];
    const RING: [usize; 4] = [13, 14, 15, 16];
    const MIDDLE: [usize; 4] = [9, 10, 11, 12];
    const INDEX: [usize; 4] = [5, 6, 7, 8];
    const THUMB: [usize; 4] = [1, 2, 3, 4];
    const MID: f64 = 9.0 / 24.0;
    [
        Chain {
            chain: PINKY,
            fraction: 1.0,
        },
        Chain {
            chain: PINKY,
            fraction: MID,
        },
        Chain {
            chain: RING,
            fraction: 1.0,
        },
        Chain {
            chain: RING,
            fraction: MID,
        },
        Chain {
            chain: MIDDLE,
            fraction: 1.0,
        },
        Chain {
            chain: MIDDLE,
            fraction: MID,
        },
        Chain {
            chain: INDEX,
            fraction: 1.0,
        },
        Chain {
            chain: INDEX,
            fraction: MID,
        },
        Chain {
            chain: THUMB,
            fraction: 1.0,
        },
        Chain {
            chain: THUMB,
            fraction: 19.0 / 24.0,
        },
        Chain {
            chain: THUMB,
            fraction: MID,
        },
        Offset {
            a: 0,
            b: 17,
            c: 5,
            f: 0.5,
        },
        Offset {
            a: 0,
            b: 5,
            c: 17,
            f: 0.5,
        },
        Mid(0, 9),
    ]
};

/// The NYU joints that are finger markers (all but the two wrist-side palm points and the palm
/// center).
pub const FINGER_JOINTS: [usize; 11] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10];

/// The 14 NYU joints of a fit's 21 keypoints ([`NYU_FROM_KEYPOINTS`]); `None` unless there are 21
/// keypoints.
pub fn nyu_joints_from_keypoints(keypoints: &[[f64; 3]]) -> Option<NyuJoints> {
    if keypoints.len() != hand_model::keypoints::NUM_KEYPOINTS {
        return None;
    }
    let k = |i: usize| Vector3::from(keypoints[i]);
    Some(NYU_FROM_KEYPOINTS.map(|src| {
        let p = match src {
            NyuJointSource::Chain { chain, fraction } => {
                let seg: Vec<f64> = chain
                    .windows(2)
                    .map(|w| (k(w[1]) - k(w[0])).norm())
                    .collect();
                let mut left = fraction * seg.iter().sum::<f64>();
                let mut p = k(chain[3]);
                for (i, &len) in seg.iter().enumerate() {
                    if left <= len && len > 0.0 {
                        p = k(chain[i]) + (k(chain[i + 1]) - k(chain[i])) * (left / len);
                        break;
                    }
                    left -= len;
                }
                p
            }
            NyuJointSource::Offset { a, b, c, f } => k(a) + (k(b) - k(c)) * f,
            NyuJointSource::Mid(a, b) => (k(a) + k(b)) * 0.5,
        };
        [p.x, p.y, p.z]
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keypoint_mapping_by_hand() {
        // A straight finger chain of segments 10, 10, 20 along x: fraction 0.375 of 40 = 15.
        let mut kp = vec![[0.0; 3]; 21];
        for (i, x) in [(5, 0.0), (6, 10.0), (7, 20.0), (8, 40.0)] {
            kp[i] = [x, 0.0, 0.0];
        }
        kp[17] = [0.0, 8.0, 0.0];
        kp[9] = [0.0, 0.0, 6.0];
        let j = nyu_joints_from_keypoints(&kp).unwrap();
        assert_eq!(j[6], [40.0, 0.0, 0.0]);
        assert!((j[7][0] - 15.0).abs() < 1e-12);
        // Wrist-side points: wrist (origin) ± half the index→pinky MCP spread.
        assert_eq!(j[11], [0.0, 4.0, 0.0]);
        assert_eq!(j[12], [0.0, -4.0, 0.0]);
        assert_eq!(j[13], [0.0, 0.0, 3.0]);
        assert!(nyu_joints_from_keypoints(&kp[..20]).is_none());
    }

    #[test]
    fn upright_orientations_are_rotations_with_fingers_up() {
        for palm in [true, false] {
            let r = upright(palm);
            assert!((r.determinant() - 1.0).abs() < 1e-12);
            assert_eq!(r * Vector3::y(), -Vector3::y());
            // The palm normal (−z in the model) faces the camera (−z in the camera) or not.
            assert_eq!((r * -Vector3::z()).z < 0.0, palm);
        }
    }
}
