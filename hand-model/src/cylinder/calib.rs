//! Importer of htrack's `.calib` cylinder-model files (ANCHOR-FACTS §3, "default.calib format").
//!
//! # Format
//! Text. First one line per joint, `name parent m00 m10 m20 m30 m01 … m33`: the joint's initial
//! *local* 4×4 transform, column-major (the root names itself as its parent); then the line
//! `end_of_skeleton`; then one line per segment, `index r1 r2 r1y r2y` (unscaled radii).
//!
//! # What the importer builds (htrack's rules, ANCHOR-FACTS §3)
//! - The joint tree must be htrack's `leftHand2` layout: `root → pose → scale → Hand`, and under
//!   `Hand` the chains `HandThumb1..4`, `HandPinky1..4`, `HandRing1..4`, `HandMiddle1..4`,
//!   `HandIndex1..4` (other joints are read, checked and ignored).
//! - Global transforms are composed down the tree; the `scale` joint's uniform scale is baked
//!   into the positions (and multiplies the radii), the rotations are re-orthonormalized.
//! - Sixteen segments in htrack's joint-id order: `Hand`, then `Thumb1..3`, `Pinky1..3`,
//!   `Ring1..3`, `Middle1..3`, `Index1..3`. A finger segment's length is the distance from its
//!   joint to the next joint; the palm's is the mean distance from `Hand` to the four finger
//!   bases minus [`HTRACK_PALM_OFFSET`] (≈ 11.1222 mm). The `…4` joints are only end points and
//!   get no bone.
//! - DOFs: htrack's 26 effective DOFs (ANCHOR-FACTS §1.1), with our names and signs: htrack
//!   flexes with a negative angle about local X and abducts toward the little finger with a
//!   positive angle about local Z; we use the axes −X and −Z, so flexion is positive toward the
//!   palm and abduction positive toward the thumb ([`HTRACK_THETA_LAYOUT`] gives the mapping).
//!   Limits are htrack's conservative bounds, negated.
//!
//! # Frames and handedness
//! htrack's model frame already has the axes of `DESIGN.md`: +y toward the fingertips and the palm
//! facing −z (a negative rotation about X bends +y toward −z; the thumb base sits at z < 0). Its
//! thumb, however, is at **+x**: the `leftHand` skeleton is geometrically a **left hand**, and the
//! importer reports [`Handedness::Left`] (checked from the geometry by
//! [`CylinderModel::geometric_handedness`]). Nothing of the model needs converting: the frame is
//! kept as is, so positions match htrack's own numbers. Use [`CylinderModel::mirrored`] for the
//! right hand.
//!
//! htrack's *camera* frame differs from ours: it unprojects with `y` up (rows flipped) from
//! horizontally mirrored images. Flipping both x (the mirror) and y (the row flip) is a rotation
//! by π about the optical axis, `p_ours = diag(−1, −1, 1)·p_htrack`, not a reflection: it changes
//! global poses read from htrack outputs (`R ← diag(−1,−1,1)·R`, `t ← diag(−1,−1,1)·t`) but not
//! the handedness of the tracked geometry.

use std::path::Path;

use nalgebra::{Matrix3, Matrix4, Vector3};

use super::model::{build_hand, CylinderModel, DigitSpec, HandSpec, SegmentShape, DIGITS};
use crate::error::{ModelError, Result};
use crate::keypoints::Handedness;
use crate::math::Rigid3;

/// htrack's palm-length offset `315.519/4 − 338.789/5 ≈ 11.1222` mm (global), subtracted from
/// the mean distance between the palm joint and the finger bases (ANCHOR-FACTS §3).
pub const HTRACK_PALM_OFFSET: f64 = 315.519 / 4.0 - 338.789 / 5.0;

/// How htrack's 29-slot θ maps onto our 26 DOFs: `(htrack index, our DOF name, sign)` with
/// `ours = sign · htrack`. Slots 6–8 have no effect in htrack and are dropped. The global slots
/// 0–5 (translation, then XYZ Euler angles `Rx·Ry·Rz`) are in htrack's camera frame (see the
/// module documentation for the conversion to ours).
pub const HTRACK_THETA_LAYOUT: [(usize, &str, f64); 26] = [
    (0, "global_tx", 1.0),
    (1, "global_ty", 1.0),
    (2, "global_tz", 1.0),
    (3, "global_rx", 1.0),
    (4, "global_ry", 1.0),
    (5, "global_rz", 1.0),
    (9, "thumb_cmc_abd", -1.0),
    (10, "thumb_cmc_flex", -1.0),
    (11, "thumb_mcp_flex", -1.0),
    (12, "thumb_ip_flex", -1.0),
    (13, "index_mcp_abd", -1.0),
    (14, "index_mcp_flex", -1.0),
    (15, "index_pip_flex", -1.0),
    (16, "index_dip_flex", -1.0),
    (17, "middle_mcp_abd", -1.0),
    (18, "middle_mcp_flex", -1.0),
    (19, "middle_pip_flex", -1.0),
    (20, "middle_dip_flex", -1.0),
    (21, "ring_mcp_abd", -1.0),
    (22, "ring_mcp_flex", -1.0),
    (23, "ring_pip_flex", -1.0),
    (24, "ring_dip_flex", -1.0),
    (25, "pinky_mcp_abd", -1.0),
    (26, "pinky_mcp_flex", -1.0),
    (27, "pinky_pip_flex", -1.0),
    (28, "pinky_dip_flex", -1.0),
];

/// htrack digit names in joint-id order (matches [`DIGITS`]).
const HT_DIGITS: [&str; 5] = ["Thumb", "Pinky", "Ring", "Middle", "Index"];

/// One parsed joint line.
struct JointLine {
    name: String,
    parent: Option<usize>,
    line: usize,
    matrix: Matrix4<f64>,
}

/// The expected joints and parents of htrack's `leftHand2` skeleton, in joint-id order.
fn expected_joints() -> Vec<(String, Option<String>)> {
    let mut v: Vec<(String, Option<String>)> = vec![
        ("root".into(), None),
        ("pose".into(), Some("root".into())),
        ("scale".into(), Some("pose".into())),
        ("Hand".into(), Some("scale".into())),
    ];
    for d in HT_DIGITS {
        for k in 1..=4 {
            let parent = if k == 1 {
                "Hand".to_string()
            } else {
                format!("Hand{d}{}", k - 1)
            };
            v.push((format!("Hand{d}{k}"), Some(parent)));
        }
    }
    v
}

fn parse_number(
    tok: &str,
    source: &Path,
    field: &str,
    index: usize,
    what: impl Fn() -> String,
) -> Result<f64> {
    let v: f64 = tok.parse().map_err(|_| {
        ModelError::field(
            source,
            field,
            Some(index),
            format!("{}: `{tok}` is not a number", what()),
        )
    })?;
    if !v.is_finite() {
        return Err(ModelError::field(
            source,
            field,
            Some(index),
            format!("{}: `{tok}` is not finite", what()),
        ));
    }
    Ok(v)
}

/// Read an htrack `.calib` file and build the cylinder model (see [`parse_htrack_calib`]).
pub fn load_htrack_calib(path: &Path) -> Result<CylinderModel> {
    let text = std::fs::read_to_string(path).map_err(|source| ModelError::Io {
        file: path.to_path_buf(),
        source,
    })?;
    parse_htrack_calib(&text, path)
}

/// Parse the text of an htrack `.calib` file (`source` names it in errors) and build the
/// cylinder model of thesis §2.2 with htrack's rules (module documentation). The result is a
/// left hand in htrack's model frame.
///
/// Errors name the file, the field (`joint.matrix`, `joint.parent`, `joint.name`, `joints`,
/// `end_of_skeleton`, `segment.index`, `segment.radii`) and the joint or segment index, and the
/// reason names the line: truncated files, numbers that do not parse or are not finite,
/// unknown or unexpected parents, missing joints, wrong radius counts, missing segments.
pub fn parse_htrack_calib(text: &str, source: &Path) -> Result<CylinderModel> {
    let mut joints: Vec<JointLine> = Vec::new();
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l));
    let mut ended = false;
    for (n, raw) in lines.by_ref() {
        let toks: Vec<&str> = raw.split_whitespace().collect();
        if toks.is_empty() {
            continue;
        }
        if toks[0] == "end_of_skeleton" {
            ended = true;
            break;
        }
        let j = joints.len();
        let name = toks[0].to_string();
        if toks.len() != 18 {
            let found = toks.len().saturating_sub(2);
            let hint = if found < 16 { " (truncated line?)" } else { "" };
            return Err(ModelError::field(
                source,
                "joint.matrix",
                Some(j),
                format!("line {n}: joint `{name}` has {found} matrix numbers, expected 16{hint}"),
            ));
        }
        if joints.iter().any(|o| o.name == name) {
            return Err(ModelError::field(
                source,
                "joint.name",
                Some(j),
                format!("line {n}: duplicate joint `{name}`"),
            ));
        }
        let parent_name = toks[1];
        let parent = if parent_name == name {
            if j != 0 {
                return Err(ModelError::field(
                    source,
                    "joint.parent",
                    Some(j),
                    format!("line {n}: only the first joint may be its own parent (the root), found `{name}`"),
                ));
            }
            None
        } else {
            match joints.iter().position(|o| o.name == parent_name) {
                Some(p) => Some(p),
                None => {
                    return Err(ModelError::field(
                        source,
                        "joint.parent",
                        Some(j),
                        format!("line {n}: joint `{name}` has unknown parent `{parent_name}` (parents must be listed before their children)"),
                    ))
                }
            }
        };
        if j == 0 && parent.is_some() {
            return Err(ModelError::field(
                source,
                "joint.parent",
                Some(0),
                format!("line {n}: the first joint must be the root (its own parent), found parent `{parent_name}`"),
            ));
        }
        let mut m = Matrix4::zeros();
        for (k, tok) in toks[2..].iter().enumerate() {
            let v = parse_number(tok, source, "joint.matrix", j, || {
                format!("line {n}: joint `{name}`, matrix value {k}")
            })?;
            m[(k % 4, k / 4)] = v;
        }
        joints.push(JointLine {
            name,
            parent,
            line: n,
            matrix: m,
        });
    }
    if !ended {
        return Err(ModelError::field(
            source,
            "end_of_skeleton",
            None,
            format!(
                "truncated file: no `end_of_skeleton` line after {} joints",
                joints.len()
            ),
        ));
    }

    // Segment radii.
    let mut radii: [Option<[f64; 4]>; 16] = [None; 16];
    for (n, raw) in lines {
        let toks: Vec<&str> = raw.split_whitespace().collect();
        if toks.is_empty() {
            continue;
        }
        let idx: usize = toks[0].parse().map_err(|_| {
            ModelError::field(
                source,
                "segment.index",
                None,
                format!("line {n}: segment index `{}` is not an integer", toks[0]),
            )
        })?;
        if idx >= 16 {
            return Err(ModelError::field(
                source,
                "segment.index",
                Some(idx),
                format!("line {n}: segment index out of range (16 segments)"),
            ));
        }
        if toks.len() != 5 {
            return Err(ModelError::field(
                source,
                "segment.radii",
                Some(idx),
                format!(
                    "line {n}: expected 4 radii `r1 r2 r1y r2y`, found {}",
                    toks.len() - 1
                ),
            ));
        }
        if radii[idx].is_some() {
            return Err(ModelError::field(
                source,
                "segment.index",
                Some(idx),
                format!("line {n}: duplicate segment"),
            ));
        }
        let mut r = [0.0; 4];
        for (k, tok) in toks[1..].iter().enumerate() {
            r[k] = parse_number(tok, source, "segment.radii", idx, || {
                format!("line {n}: radius {k}")
            })?;
            if r[k] < 0.0 {
                return Err(ModelError::field(
                    source,
                    "segment.radii",
                    Some(idx),
                    format!("line {n}: radius {k} is negative ({})", r[k]),
                ));
            }
        }
        radii[idx] = Some(r);
    }
    if let Some(i) = radii.iter().position(|r| r.is_none()) {
        return Err(ModelError::field(
            source,
            "segment.radii",
            Some(i),
            "missing radii line for this segment (truncated file?)",
        ));
    }

    // Global transforms (affine: uniformly scaled rotation + translation).
    let mut globals: Vec<Matrix4<f64>> = Vec::with_capacity(joints.len());
    for (j, jl) in joints.iter().enumerate() {
        let m = &jl.matrix;
        let last = [m[(3, 0)], m[(3, 1)], m[(3, 2)], m[(3, 3)]];
        if (last[0].abs() + last[1].abs() + last[2].abs() + (last[3] - 1.0).abs()) > 1e-6 {
            return Err(ModelError::field(
                source,
                "joint.matrix",
                Some(j),
                format!(
                    "line {}: joint `{}` is not an affine transform (last row {last:?})",
                    jl.line, jl.name
                ),
            ));
        }
        let a: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
        if scaled_rotation(&a).is_none() {
            return Err(ModelError::field(
                source,
                "joint.matrix",
                Some(j),
                format!(
                    "line {}: joint `{}`: the linear part is not a uniformly scaled rotation",
                    jl.line, jl.name
                ),
            ));
        }
        let g = match jl.parent {
            Some(p) => globals[p] * m,
            None => *m,
        };
        globals.push(g);
    }

    // The leftHand2 layout.
    let expected = expected_joints();
    let mut id = vec![0usize; expected.len()];
    for (e, (name, parent)) in expected.iter().enumerate() {
        let Some(j) = joints.iter().position(|jl| &jl.name == name) else {
            return Err(ModelError::field(
                source,
                "joints",
                Some(e),
                format!("missing joint `{name}` (htrack leftHand2 layout)"),
            ));
        };
        let found = joints[j].parent.map(|p| joints[p].name.as_str());
        if found != parent.as_deref() {
            return Err(ModelError::field(
                source,
                "joint.parent",
                Some(j),
                format!(
                    "line {}: joint `{name}` must have parent `{}`, found `{}`",
                    joints[j].line,
                    parent.as_deref().unwrap_or(name),
                    found.unwrap_or(name)
                ),
            ));
        }
        id[e] = j;
    }
    let joint = |name: &str| id[expected.iter().position(|(n, _)| n == name).unwrap_or(0)];
    // Rigid frame and uniform scale of a joint's global transform.
    let rigid = |j: usize| -> (Rigid3, f64) {
        let g = &globals[j];
        let a: Matrix3<f64> = g.fixed_view::<3, 3>(0, 0).into_owned();
        let (r, s) = scaled_rotation(&a).unwrap_or((Matrix3::identity(), 1.0));
        (
            Rigid3::new(r, Vector3::new(g[(0, 3)], g[(1, 3)], g[(2, 3)])),
            s,
        )
    };
    let err_rigid = |j: usize| {
        ModelError::field(
            source,
            "joint.matrix",
            Some(j),
            format!(
                "line {}: joint `{}`: the composed transform is degenerate",
                joints[j].line, joints[j].name
            ),
        )
    };
    let hand = joint("Hand");
    let (palm_frame, palm_scale) = rigid(hand);
    let bases = ["Pinky", "Ring", "Middle", "Index"]
        .map(|d| rigid(joint(&format!("Hand{d}1"))).0.translation);
    let mean = bases
        .iter()
        .map(|b| (b - palm_frame.translation).norm())
        .sum::<f64>()
        / 4.0;
    let palm_length = mean - HTRACK_PALM_OFFSET;
    if palm_length.is_nan() || palm_length <= 0.0 {
        return Err(ModelError::field(
            source,
            "joints",
            Some(3),
            format!(
                "the palm length rule gives {palm_length:.3} mm (finger bases too close to `Hand`)"
            ),
        ));
    }
    let shape = |seg: usize, length: f64, s: f64| -> SegmentShape {
        let r = radii[seg].unwrap_or([0.0; 4]);
        [length, r[0] * s, r[1] * s, r[2] * s, r[3] * s]
    };
    let palm = shape(0, palm_length, palm_scale);
    let mut digits: Vec<DigitSpec> = Vec::with_capacity(5);
    for (d, ht) in HT_DIGITS.iter().enumerate() {
        debug_assert_eq!(DIGITS[d].to_lowercase(), ht.to_lowercase());
        let js: [usize; 4] = std::array::from_fn(|k| joint(&format!("Hand{ht}{}", k + 1)));
        let frames = js.map(rigid);
        let mut rests = [Rigid3::identity(); 3];
        let mut shapes = [[0.0; 5]; 3];
        for k in 0..3 {
            let parent = if k == 0 { palm_frame } else { frames[k - 1].0 };
            rests[k] = parent.inverse().compose(&frames[k].0);
            let length = (frames[k + 1].0.translation - frames[k].0.translation).norm();
            shapes[k] = shape(1 + 3 * d + k, length, frames[k].1);
        }
        if !rests.iter().all(Rigid3::is_finite) {
            return Err(err_rigid(js[0]));
        }
        digits.push(DigitSpec { rests, shapes });
    }
    let digits: [DigitSpec; 5] = digits.try_into().map_err(|_| err_rigid(hand))?;
    let spec = HandSpec {
        name: format!("htrack calibration {}", source.display()),
        handedness: Handedness::Left,
        palm_rest: palm_frame,
        palm,
        digits,
        flex_axis: -Vector3::x(),
        abd_axis: -Vector3::z(),
    };
    let mut model = build_hand(spec, source)?;
    model.handedness = model.geometric_handedness();
    Ok(model)
}

/// `A = s·R` with `s > 0` and `R` a rotation (within 1e-3 after dividing by `s`): `(R, s)`,
/// with `R` re-orthonormalized.
fn scaled_rotation(a: &Matrix3<f64>) -> Option<(Matrix3<f64>, f64)> {
    let det = a.determinant();
    if !det.is_finite() || det <= 1e-12 {
        return None;
    }
    let s = det.cbrt();
    let r = a / s;
    if (r.transpose() * r - Matrix3::identity()).norm() > 1e-3 {
        return None;
    }
    Some((Rigid3::from_rotation(r).orthonormalized().rotation, s))
}
