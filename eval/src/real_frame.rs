//! A sphere-mesh fit to one real depth frame (issue 7, item 7), scored against marker ground
//! truth through a documented keypoint mapping.
//!
//! The fit uses nothing of the ground truth:
//! 1. preprocessing ([`sensor_io::preprocess`]): median downsampling, depth range, the
//!    depth-only hand segmentation, subsampled points and the silhouette distance transform;
//! 2. initialization: the template's rest centroid placed on the centroid of the segmented cloud
//!    (pushed [`FitConfig::depth_offset`] behind it, since the cloud is the visible surface) in a
//!    fixed upright orientation (fingers toward the image top), palm toward the camera or away
//!    from it, fingers straight or half bent ([`FitConfig::bends`]);
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
use hand_model::spheremesh::{Attachment, PosedSphereMesh, ShapeBasis, SphereMeshTemplate};
use hmodel_spheremesh::calibration::{calibrate, place_pose, CalibrationConfig, CalibrationFrame};
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
    /// Finger flexions (rad, every non-global `flex` DOF, clamped to its limits) of the initial
    /// hypotheses.
    pub bends: Vec<f64>,
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
            bends: vec![0.0, 0.5],
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
    let solve =
        |latent: [f64; 3], init: Option<&Pose>, palm: bool, bend: f64| -> Result<FrameFit> {
            let template = basis
                .apply(base, &basis.from_latent(latent))
                .map_err(|e| EvalError::arg("scales", e.to_string()))?;
            let init = init.cloned().unwrap_or_else(|| {
                let sk = &template.skeleton;
                let mut p = Pose::zeros(sk);
                for d in sk.dofs() {
                    if d.name.contains("flex") && !d.name.starts_with("global") {
                        let _ = p.set(sk, &d.name, bend);
                    }
                }
                p.clamp_to_limits(sk);
                place_pose(&template, &mut p, &upright(palm), &target);
                p
            });
            let fit = calibrate(&template, std::slice::from_ref(&data), &[init], &cal)
                .map_err(|e| EvalError::arg("fit", e.to_string()))?;
            let energy = fit.best_energy();
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
            for &bend in &config.bends {
                let fit = solve([scale; 3], None, palm, bend)?;
                if best.as_ref().is_none_or(|b| fit.energy < b.energy) {
                    best = Some(fit);
                }
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
                let fit = solve(latent, Some(&best.pose), best.palm_toward_camera, 0.0)?;
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

/// How one NYU joint is read off a posed sphere-mesh.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum NyuJointSource {
    /// The point at `fraction` of the arc length of a chain of DESIGN.md keypoints.
    Chain {
        /// Keypoint indices from the base of the chain to its tip.
        chain: [usize; 4],
        /// Fraction of the chain's length from its base.
        fraction: f64,
    },
    /// A named sphere's center moved by `offset` radii along the axes of the bone the sphere
    /// is attached to (honline's palm markers).
    Sphere {
        /// Sphere name (the honline names of the template).
        name: &'static str,
        /// Offset in radii, in the bone frame (x, y toward the fingers, z).
        offset: [f64; 3],
    },
}

/// The mapping of the 14 NYU joints ([`datasets::nyu::NYU_JOINT_NAMES`]) onto the model.
///
/// NYU's 14 joints are 14 of its 36 markers (indices 0, 3, 6, 9, 12, 15, 18, 21, 24, 25, 27,
/// 30, 31, 32). honline's `GroundTruthLoader` reproduces them on the sphere-mesh: per finger 5
/// markers along the chain from the finger base to the tip end, at arc fractions 1, 19/24,
/// 14/24, 9/24, 1/6 (tip first), then the base; the palm markers 30 "palm right", 31 "palm
/// left" (sphere center + radius·(0, −1, 0.5) in the palm frame) and 32 "palm middle" (+
/// radius·(0, 0, 0.5)). Here the finger chains are the DESIGN.md keypoints MCP→PIP→DIP→tip
/// (thumb CMC→MCP→IP→tip; honline starts the finger chains at the membrane's projection on the
/// first phalanx, a few mm distal of the MCP), and the palm markers use the template's spheres of
/// the same names, with honline's offsets read in our model frame (the two model frames differ
/// by the x mirror only, which leaves the offsets unchanged). NYU joint 11 lies on the pinky
/// side and 12 on the thumb side (test frame 1), as `palm_right` (+x) and `palm_left` do on the
/// right-hand template.
pub const NYU_JOINT_SOURCES: [NyuJointSource; NYU_JOINTS] = {
    use NyuJointSource::{Chain, Sphere};
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
        Sphere {
            name: "palm_right",
            offset: [0.0, -1.0, 0.5],
        },
        Sphere {
            name: "palm_left",
            offset: [0.0, -1.0, 0.5],
        },
        Sphere {
            name: "palm_middle",
            offset: [0.0, 0.0, 0.5],
        },
    ]
};

/// The NYU joints that are finger markers (all but the three palm markers).
pub const FINGER_JOINTS: [usize; 11] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10];

/// The point at `fraction` of the arc length of the polyline `points`.
fn along(points: &[Vector3<f64>], fraction: f64) -> Vector3<f64> {
    let seg: Vec<f64> = points.windows(2).map(|w| (w[1] - w[0]).norm()).collect();
    let mut left = fraction * seg.iter().sum::<f64>();
    for (i, &len) in seg.iter().enumerate() {
        if left <= len && len > 0.0 {
            return points[i] + (points[i + 1] - points[i]) * (left / len);
        }
        left -= len;
    }
    points[points.len() - 1]
}

/// The 14 NYU joints of `template` posed at `pose` ([`NYU_JOINT_SOURCES`]); `None` when the
/// template lacks a named palm sphere or a sphere is not attached to a bone.
pub fn nyu_joints(template: &SphereMeshTemplate, pose: &Pose) -> Option<NyuJoints> {
    let posed = PosedSphereMesh::new(template, pose);
    let kp = posed.keypoints(template);
    let mut out = [[0.0; 3]; NYU_JOINTS];
    for (o, src) in out.iter_mut().zip(NYU_JOINT_SOURCES) {
        let p = match src {
            NyuJointSource::Chain { chain, fraction } => along(&chain.map(|i| kp[i]), fraction),
            NyuJointSource::Sphere { name, offset } => {
                let i = template.spheres.iter().position(|s| s.name == name)?;
                let Attachment::Bone { bone, .. } = template.spheres[i].attachment else {
                    return None;
                };
                let s = &posed.spheres[i];
                let r = posed.skeleton.globals.get(bone)?.rotation;
                s.center + r * Vector3::from(offset) * s.radius
            }
        };
        *o = [p.x, p.y, p.z];
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nyu_mapping_on_the_posed_template() {
        use hand_model::spheremesh::default_right_hand;
        // Arc-length interpolation: segments 10, 10, 20 along x, 0.375 of 40 = 15.
        let line = [0.0, 10.0, 20.0, 40.0].map(|x| Vector3::new(x, 0.0, 0.0));
        assert_eq!(along(&line, 0.375), Vector3::new(15.0, 0.0, 0.0));
        assert_eq!(along(&line, 1.0), line[3]);
        // A translated rest pose: tips are the tip keypoints, the palm markers are the named
        // spheres moved by honline's offsets in the (unrotated) palm frame.
        let t = default_right_hand();
        let sk = &t.skeleton;
        let mut pose = Pose::zeros(sk);
        pose.set(sk, "global_tz", 500.0).unwrap();
        let j = nyu_joints(&t, &pose).unwrap();
        let posed = PosedSphereMesh::new(&t, &pose);
        let kp = posed.keypoints(&t);
        assert_eq!(j[6], [kp[8].x, kp[8].y, kp[8].z]);
        let i = t
            .spheres
            .iter()
            .position(|s| s.name == "palm_right")
            .unwrap();
        let (c, r) = (posed.spheres[i].center, posed.spheres[i].radius);
        let expected = c + Vector3::new(0.0, -r, 0.5 * r);
        assert!((Vector3::from(j[11]) - expected).norm() < 1e-9);
        // The pinky-side marker is on the pinky side (+x on the right hand).
        assert!(j[11][0] > j[12][0]);
        // A template without the palm spheres cannot be mapped.
        let mut bare = t.clone();
        bare.spheres.iter_mut().for_each(|s| s.name.push('_'));
        assert!(nyu_joints(&bare, &pose).is_none());
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
