//! Reader of the RealSense hand-pose corpus (`animbank.pose`, IntelRealSense
//! hand_tracking_samples, Apache-2.0) and its retargeting to our 20 digit DOFs.
//!
//! # File format
//! ASCII, one pose per non-empty line: 17 bones × (position x y z, orientation quaternion
//! x y z w) = 119 whitespace-separated numbers. Positions are in metres (camera/world frame),
//! orientations are the **world** orientations of the bones (unit quaternions, Hamilton
//! product, `v_world = q·v_local·q*`). The bone order is that of the samples' rig
//! (`assets/model_hand.json`, its `joints` list `rbi0 → rbi1`):
//!
//! | index | bone | parent |
//! |---|---|---|
//! | 0 | forearm / wrist | – |
//! | 1 | palm | 0 |
//! | 2, 3, 4 | thumb metacarpal, proximal, distal | 1, 2, 3 |
//! | 5, 6, 7 | index proximal, middle, distal | 1, 5, 6 |
//! | 8, 9, 10 | middle finger | 1, 8, 9 |
//! | 11, 12, 13 | ring | 1, 11, 12 |
//! | 14, 15, 16 | pinky | 1, 14, 15 |
//!
//! # Local frames of the rig (worked out from the rig and checked on the data)
//! Every bone frame has **+z along the bone**; the palm frame has +z toward the fingers, **+x
//! toward the thumb/index side** and **−y palmar** (a right hand). Finger joints flex by a
//! positive rotation about the joint's +x (rig limits [−5°, 100°]) and abduct about +y (toward
//! +x = toward the thumb); the thumb's MCP and IP flex by a **negative** rotation about +y (IP
//! limits [−80°, 0°]). The relative rotation of a child is `q_parent⁻¹ q_child`; the data are
//! twist-free (|rotation about the bone| < 0.04 rad at PIP/DIP).
//!
//! # Retargeting (per-joint angles, our conventions: positive flexion toward the palm,
//! positive abduction toward the thumb)
//! - **Finger MCPs and thumb CMC** (two DOFs): the direction of the child bone (finger
//!   proximal phalanx: its +z; thumb metacarpal: the rig's CMC → MCP vector
//!   [`THUMB_METACARPAL_DIR`]) is expressed in the rig palm frame, mapped to our palm frame
//!   (`ours = (−x, z, y)_rig`: our fingers +y, thumb at −x, palmar −z), then in the rest frame
//!   of our bone (from the skeleton), and the flexion/abduction pair of our skeleton that
//!   points our bone's +y there is solved in closed form (`R_x(flex)·R_{±z}(abd)·ŷ = u`). So
//!   the geometry transfers (e.g. the rig's rest splay of the index, 11°, becomes 11° − our
//!   4.6° rest splay).
//! - **PIP / DIP**: the rig's flexion `atan2(−d_y, d_z)` of the child's +z `d` in the parent.
//! - **Thumb MCP / IP**: the rig's flexion `−atan2(d_x, d_z)` (rotation about −y).
//!
//! Validation on the 2336 poses (test `animbank_parses_and_retargets`): the most-flexed poses
//! have finger flexions ≈ 1.5–1.75 rad (a fist), the least flexed ≈ 0 with the fingers spread;
//! 97 % of the retargeted angles lie within our joint limits and the rest by at most 0.23 rad
//! (pinky/ring MCP flexion up to 1.76 > 1.6, thumb MCP hyper-extension to −0.53 < −0.3). The
//! corpus builder ([`crate::prior`]) clamps them to the limits.

use std::path::Path;

use hand_model::kinematics::names::DIGIT_DOFS;
use hand_model::kinematics::Skeleton;
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

use crate::error::{DatasetError, Result};

/// Number of bones per pose.
pub const ANIMBANK_BONES: usize = 17;

/// Numbers per line: 17 × (xyz + quaternion xyzw).
pub const ANIMBANK_VALUES_PER_POSE: usize = ANIMBANK_BONES * 7;

/// The bone names, file order (module docs).
pub const ANIMBANK_BONE_NAMES: [&str; ANIMBANK_BONES] = [
    "forearm", "palm", "thumb_1", "thumb_2", "thumb_3", "index_1", "index_2", "index_3",
    "middle_1", "middle_2", "middle_3", "ring_1", "ring_2", "ring_3", "pinky_1", "pinky_2",
    "pinky_3",
];

/// The rig's thumb metacarpal direction in its own frame: the CMC → MCP vector of
/// `model_hand.json` (joint 2, `p0` on body 2), normalized at use.
pub const THUMB_METACARPAL_DIR: [f64; 3] = [0.0350668, -0.0207165, 0.049908];

/// One bone of a recorded pose.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct AnimbankBone {
    /// World position (m).
    pub position: Vector3<f64>,
    /// World orientation.
    pub rotation: UnitQuaternion<f64>,
}

/// One recorded pose: the 17 bones in file order.
#[derive(Clone, Debug, PartialEq)]
pub struct AnimbankPose {
    /// The bones ([`ANIMBANK_BONE_NAMES`] order).
    pub bones: Vec<AnimbankBone>,
}

/// Parse the text of an animbank/`.pose` file; `source` names it in errors. Refused with the
/// line number: a line without exactly 119 numbers, a token that is not a number, a
/// non-finite value, a quaternion of norm outside [0.5, 2] (stored quaternions are unit up to
/// rounding; they are normalized). An empty file is an error too.
pub fn parse_animbank(text: &str, source: &Path) -> Result<Vec<AnimbankPose>> {
    let err = |line: usize, reason: String| DatasetError::Parse {
        file: source.to_path_buf(),
        line: Some(line),
        reason,
    };
    let mut poses = Vec::new();
    let mut vals = Vec::with_capacity(ANIMBANK_VALUES_PER_POSE);
    for (i, line) in text.lines().enumerate() {
        let ln = i + 1;
        vals.clear();
        for tok in line.split_whitespace() {
            if vals.len() == ANIMBANK_VALUES_PER_POSE {
                return Err(err(
                    ln,
                    format!("more than {ANIMBANK_VALUES_PER_POSE} numbers"),
                ));
            }
            let v: f64 = tok
                .parse()
                .map_err(|_| err(ln, format!("`{}` is not a number", truncate(tok))))?;
            if !v.is_finite() {
                return Err(err(ln, format!("value {} is not finite", vals.len())));
            }
            vals.push(v);
        }
        if vals.is_empty() {
            continue;
        }
        if vals.len() != ANIMBANK_VALUES_PER_POSE {
            return Err(err(
                ln,
                format!(
                    "{} numbers, expected {ANIMBANK_VALUES_PER_POSE} (17 bones × xyz + quaternion xyzw)",
                    vals.len()
                ),
            ));
        }
        let mut bones = Vec::with_capacity(ANIMBANK_BONES);
        for (b, c) in vals.chunks_exact(7).enumerate() {
            let q = Quaternion::new(c[6], c[3], c[4], c[5]);
            let n = q.norm();
            if !(0.5..=2.0).contains(&n) {
                return Err(err(
                    ln,
                    format!(
                        "bone {b} ({}): quaternion norm {n:.3} is not ≈ 1",
                        ANIMBANK_BONE_NAMES[b]
                    ),
                ));
            }
            bones.push(AnimbankBone {
                position: Vector3::new(c[0], c[1], c[2]),
                rotation: UnitQuaternion::from_quaternion(q),
            });
        }
        poses.push(AnimbankPose { bones });
    }
    if poses.is_empty() {
        return Err(DatasetError::Parse {
            file: source.to_path_buf(),
            line: None,
            reason: "no poses".into(),
        });
    }
    Ok(poses)
}

fn truncate(s: &str) -> String {
    s.chars().take(24).collect()
}

/// Read and parse an animbank/`.pose` file ([`parse_animbank`]).
pub fn read_animbank(path: &Path) -> Result<Vec<AnimbankPose>> {
    let text = std::fs::read_to_string(path).map_err(|source| DatasetError::Io {
        file: path.to_path_buf(),
        source,
    })?;
    parse_animbank(&text, path)
}

/// The rig palm frame → our palm frame: `ours = (−x, z, y)_rig`.
fn rig_to_ours(v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(-v.x, v.z, v.y)
}

/// Two-DOF (flexion about +x, then abduction about ±z) joint of our skeleton.
#[derive(Copy, Clone, Debug)]
struct SwingJoint {
    /// Rest rotation of our bone relative to the palm.
    rest: Matrix3<f64>,
    /// Sign of the abduction axis (`±z`).
    abd_sign: f64,
}

/// Retargets recorded poses to the 20 digit DOFs ([`DIGIT_DOFS`] order) of a skeleton with
/// the default template's digit layout (module docs).
#[derive(Clone, Debug)]
pub struct Retargeter {
    /// Thumb CMC, then the four finger MCPs.
    joints: [SwingJoint; 5],
    /// Per digit DOF, its `[min, max]` limits in the skeleton.
    limits: [[f64; 2]; 20],
}

impl Retargeter {
    /// Read our rest frames and limits from `skeleton`: it must have the 20 digit DOFs with
    /// limits, bones `thumb_1`, `index_1` … `pinky_1` that are children of `palm` and carry
    /// `[<digit>_…_flex about +x, <digit>_…_abd about ±z]` in that order.
    pub fn new(skeleton: &Skeleton) -> Result<Self> {
        let bad = |reason: String| DatasetError::arg("skeleton", reason);
        let palm = skeleton
            .bone_index("palm")
            .ok_or_else(|| bad("no bone `palm`".into()))?;
        let mut joints = [SwingJoint {
            rest: Matrix3::identity(),
            abd_sign: 1.0,
        }; 5];
        for (j, (bone, flex, abd)) in [
            ("thumb_1", "thumb_cmc_flex", "thumb_cmc_abd"),
            ("index_1", "index_mcp_flex", "index_mcp_abd"),
            ("middle_1", "middle_mcp_flex", "middle_mcp_abd"),
            ("ring_1", "ring_mcp_flex", "ring_mcp_abd"),
            ("pinky_1", "pinky_mcp_flex", "pinky_mcp_abd"),
        ]
        .into_iter()
        .enumerate()
        {
            let b = skeleton
                .bone_index(bone)
                .ok_or_else(|| bad(format!("no bone `{bone}`")))?;
            let bn = &skeleton.bones()[b];
            if bn.parent != Some(palm) {
                return Err(bad(format!("`{bone}` is not a child of `palm`")));
            }
            let dofs: Vec<&str> = bn
                .dofs
                .iter()
                .map(|&d| skeleton.dofs()[d].name.as_str())
                .collect();
            if dofs != [flex, abd] {
                return Err(bad(format!(
                    "`{bone}` carries {dofs:?}, expected [{flex}, {abd}]"
                )));
            }
            let fa = skeleton.dofs()[bn.dofs[0]].axis;
            let aa = skeleton.dofs()[bn.dofs[1]].axis;
            if (fa - Vector3::x()).norm() > 1e-9 || aa.x.abs() + aa.y.abs() > 1e-9 {
                return Err(bad(format!(
                    "`{bone}`: flexion axis {fa:?} / abduction axis {aa:?}, expected +x / ±z"
                )));
            }
            joints[j] = SwingJoint {
                rest: bn.rest.rotation,
                abd_sign: aa.z.signum(),
            };
        }
        let mut limits = [[0.0; 2]; 20];
        for (l, name) in limits.iter_mut().zip(DIGIT_DOFS) {
            let d = skeleton
                .dof_index(name)
                .ok_or_else(|| bad(format!("no DOF `{name}`")))?;
            *l = skeleton.dofs()[d]
                .limits
                .ok_or_else(|| bad(format!("DOF `{name}` has no limits")))?;
        }
        Ok(Self { joints, limits })
    }

    /// The retargeter for the default right-hand template.
    pub fn default_template() -> Self {
        Self::new(&crate::default_template().skeleton)
            .expect("the default template has the digit layout")
    }

    /// The skeleton's `[min, max]` limits of the 20 digit DOFs ([`DIGIT_DOFS`] order).
    pub fn limits(&self) -> &[[f64; 2]; 20] {
        &self.limits
    }

    /// The 20 digit angles of `pose` ([`DIGIT_DOFS`] order, rad), **not** clamped.
    pub fn retarget(&self, pose: &AnimbankPose) -> [f64; 20] {
        let q = |b: usize| pose.bones[b].rotation;
        let rel = |parent: usize, child: usize| q(parent).inverse() * q(child);
        let z = Vector3::z();
        let mut out = [0.0; 20];
        // Swing joints: bone direction in the rig palm frame → ours → our rest frame.
        let swing = |j: usize, dir_palm_rig: Vector3<f64>| -> [f64; 2] {
            let sj = &self.joints[j];
            let u = sj.rest.transpose() * rig_to_ours(&dir_palm_rig);
            let u = u.normalize();
            let flex = u.z.atan2(u.y);
            let abd = (-sj.abd_sign * u.x).clamp(-1.0, 1.0).asin();
            [flex, abd]
        };
        // Thumb: CMC by direction, MCP/IP by the rig's flexion about −y.
        let meta = Vector3::from(THUMB_METACARPAL_DIR).normalize();
        let [f, a] = swing(0, rel(1, 2) * meta);
        out[0] = a;
        out[1] = f;
        for (k, (p, c)) in [(2, 3), (3, 4)].into_iter().enumerate() {
            let d = rel(p, c) * z;
            out[2 + k] = -d.x.atan2(d.z);
        }
        for digit in 0..4 {
            let b = 5 + 3 * digit;
            let o = 4 + 4 * digit;
            let [f, a] = swing(1 + digit, rel(1, b) * z);
            out[o] = a;
            out[o + 1] = f;
            for k in 0..2 {
                let d = rel(b + k, b + k + 1) * z;
                out[o + 2 + k] = (-d.y).atan2(d.z);
            }
        }
        out
    }

    /// [`Retargeter::retarget`] clamped into the skeleton's limits.
    pub fn retarget_clamped(&self, pose: &AnimbankPose) -> [f64; 20] {
        let mut v = self.retarget(pose);
        for (x, [lo, hi]) in v.iter_mut().zip(&self.limits) {
            *x = x.clamp(*lo, *hi);
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ANIMBANK: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/reference/pose-corpus-realsense/animbank.pose"
    );

    fn line(values: &[f64]) -> String {
        values
            .iter()
            .map(|v| v.to_string())
            .collect::<Vec<_>>()
            .join(" ")
    }

    /// A synthetic pose: every bone at the origin with the identity orientation.
    fn rest_values() -> Vec<f64> {
        (0..ANIMBANK_BONES)
            .flat_map(|_| [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
            .collect()
    }

    #[test]
    fn parses_synthetic_lines_and_refuses_corrupt_ones() {
        let src = Path::new("<memory>");
        let v = rest_values();
        let text = format!("{}\n\n{}\n", line(&v), line(&v));
        let poses = parse_animbank(&text, src).unwrap();
        assert_eq!(poses.len(), 2);
        assert_eq!(poses[0].bones.len(), 17);
        // Truncated at every possible point: a clear error, never a panic.
        let one = line(&v);
        for cut in 0..one.len() {
            let r = parse_animbank(&one[..cut], src);
            if cut < one.len() - 1 {
                assert!(r.is_err(), "cut at {cut} accepted");
            }
        }
        let short = parse_animbank(&line(&v[..118]), src)
            .unwrap_err()
            .to_string();
        assert!(
            short.contains("line 1") && short.contains("118 numbers"),
            "{short}"
        );
        let long = format!("{} 1", line(&v));
        assert!(parse_animbank(&long, src).is_err());
        let mut nan = v.clone();
        nan[5] = f64::NAN;
        assert!(parse_animbank(&line(&nan), src).is_err());
        let word = format!("{} x", line(&v[..118]));
        let e = parse_animbank(&word, src).unwrap_err().to_string();
        assert!(e.contains("not a number"), "{e}");
        let mut zero_q = v.clone();
        zero_q[6] = 0.0;
        assert!(parse_animbank(&line(&zero_q), src).is_err());
        assert!(parse_animbank("", src).is_err());
        assert!(parse_animbank("\u{0}\u{1}garbage", src).is_err());
    }

    #[test]
    fn identity_rig_retargets_to_the_rig_rest_geometry() {
        let v = rest_values();
        let pose = &parse_animbank(&line(&v), Path::new("<memory>")).unwrap()[0];
        let r = Retargeter::default_template();
        let a = r.retarget(pose);
        // PIP/DIP and thumb MCP/IP: exactly 0 at the rig's rest.
        for i in [2, 3, 6, 7, 10, 11, 14, 15, 18, 19] {
            assert!(a[i].abs() < 1e-12, "{} = {}", DIGIT_DOFS[i], a[i]);
        }
        // Fingers parallel to the rig palm's z: abduction = minus our rest splay, no flexion.
        assert!((a[4] + 0.08).abs() < 1e-9, "index abd {}", a[4]);
        assert!((a[16] - 0.15).abs() < 1e-9, "pinky abd {}", a[16]);
        assert!(a[5].abs() < 1e-9);
        // The rig's thumb metacarpal at rest is close to our thumb's rest direction.
        assert!(
            a[0].abs() < 0.1 && a[1].abs() < 0.1,
            "thumb cmc {:?}",
            &a[..2]
        );
        // Flexing the rig's index PIP by +0.7 about +x gives +0.7 in our convention.
        let mut pose = pose.clone();
        let flex = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.7);
        for b in 6..8 {
            pose.bones[b].rotation = flex;
        }
        let a = r.retarget(&pose);
        assert!(
            (a[6] - 0.7).abs() < 1e-9 && a[7].abs() < 1e-9,
            "{:?}",
            &a[4..8]
        );
    }

    #[test]
    fn animbank_parses_and_retargets() {
        let path = Path::new(ANIMBANK);
        if !path.exists() {
            eprintln!("skipped: {ANIMBANK} absent");
            return;
        }
        let poses = read_animbank(path).unwrap();
        assert_eq!(poses.len(), 2336);
        let r = Retargeter::default_template();
        let all: Vec<[f64; 20]> = poses.iter().map(|p| r.retarget(p)).collect();
        let flex_sum = |a: &[f64; 20]| -> f64 {
            (0..4)
                .map(|d| a[5 + 4 * d] + a[6 + 4 * d] + a[7 + 4 * d])
                .sum()
        };
        let mut order: Vec<usize> = (0..all.len()).collect();
        order.sort_by(|&a, &b| flex_sum(&all[a]).total_cmp(&flex_sum(&all[b])));
        let (open, fist) = (&all[order[0]], &all[*order.last().unwrap()]);
        eprintln!("open-most pose {}: {open:.2?}", order[0]);
        eprintln!("fist-most pose {}: {fist:.2?}", order.last().unwrap());
        for d in 0..4 {
            let o = 4 + 4 * d;
            // Fist: MCP and PIP strongly flexed, DIP flexed.
            assert!(fist[o + 1] > 1.4 && fist[o + 2] > 1.4 && fist[o + 3] > 0.6);
            // Open hand: every finger flexion near zero.
            for k in 1..4 {
                assert!(open[o + k].abs() < 0.3, "{}", DIGIT_DOFS[o + k]);
            }
        }
        // Open hand is spread: index toward the thumb, pinky away from it.
        assert!(open[4] > 0.1 && open[16] < -0.2);
        // Joint limits.
        let lim = r.limits();
        let mut values_in = 0usize;
        let mut poses_in = 0usize;
        let mut worst = 0.0f64;
        for a in &all {
            let mut ok = true;
            for (v, [lo, hi]) in a.iter().zip(lim) {
                let excess = (lo - v).max(v - hi).max(0.0);
                worst = worst.max(excess);
                if excess > 0.0 {
                    ok = false;
                } else {
                    values_in += 1;
                }
            }
            poses_in += ok as usize;
        }
        let fv = values_in as f64 / (all.len() * 20) as f64;
        let fp = poses_in as f64 / all.len() as f64;
        eprintln!(
            "within limits: {:.1} % of angles, {:.1} % of poses entirely; worst excess {worst:.3} rad",
            100.0 * fv,
            100.0 * fp
        );
        assert!(fv > 0.95, "{fv}");
        assert!(worst < 0.3, "{worst}");
    }
}
