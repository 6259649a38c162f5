//! The cylinder model as data: segments attached to the bones of a 26-DOF skeleton (thesis §2.2).

use std::path::Path;

use nalgebra::{Matrix3, Vector3};

use crate::error::{ModelError, Result};
use crate::keypoints::{Handedness, NUM_KEYPOINTS};
use crate::kinematics::names::{concat_names, DIGIT_DOFS, GLOBAL_DOFS};
use crate::kinematics::{Bone, Dof, DofKind, Pose, PosedSkeleton, Skeleton};
use crate::math::Rigid3;

/// The 26 DOF names of the cylinder model in pose-vector order (thesis §2.2: 6 global + 20
/// articulations). The order of the articulations is htrack's θ order (thumb, index, middle,
/// ring, pinky; abduction first), see [`super::HTRACK_THETA_LAYOUT`].
pub const CYLINDER_DOF_NAMES: [&str; 26] = concat_names(GLOBAL_DOFS, DIGIT_DOFS);

/// One sphere-capped, tapered, elliptical cylinder (thesis §2.2, Fig. 4.10; htrack's `Segment`).
///
/// In the frame of `bone` the axis runs from the origin to `(0, length, 0)`; at axial parameter
/// `t` the cross-section is the ellipse with half-axes `r(t)` (local x, "radius") and `ry(t)`
/// (local z, "thickness"), both interpolated linearly; the ends are half-ellipsoids with
/// half-axes `(r, ry, ry)` centred on the axis end points (see the module documentation of
/// [`crate::cylinder`]).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Segment {
    /// The bone whose frame carries the segment (and whose DOF chain moves it).
    pub bone: usize,
    /// Axis length (mm, ≥ 0).
    pub length: f64,
    /// Radius along local x at the start (mm, ≥ 0).
    pub r1: f64,
    /// Radius along local x at the end (mm, ≥ 0).
    pub r2: f64,
    /// Thickness (half-axis along local z) at the start (mm, ≥ 0).
    pub r1y: f64,
    /// Thickness (half-axis along local z) at the end (mm, ≥ 0).
    pub r2y: f64,
}

impl Segment {
    /// The half-axes `(r(t), ry(t))` of the cross-section at axial parameter `t ∈ [0, 1]`.
    #[inline]
    pub fn radii_at(&self, t: f64) -> (f64, f64) {
        (
            (1.0 - t) * self.r1 + t * self.r2,
            (1.0 - t) * self.r1y + t * self.r2y,
        )
    }

    /// Whether the cross-section is circular everywhere (`r1 = r1y` and `r2 = r2y`).
    pub fn is_circular(&self) -> bool {
        self.r1 == self.r1y && self.r2 == self.r2y
    }

    /// The axis end point `(0, length, 0)` in the bone frame.
    #[inline]
    pub fn end_local(&self) -> Vector3<f64> {
        Vector3::new(0.0, self.length, 0.0)
    }

    /// The far surface point along the axis, `(0, length + r2y, 0)` in the bone frame: the
    /// fingertip keypoint of `DESIGN.md` (the end cap's half-axis along the bone is the
    /// thickness `r2y`, which equals `r2` on every circular segment).
    #[inline]
    pub fn tip_local(&self) -> Vector3<f64> {
        Vector3::new(0.0, self.length + self.r2y, 0.0)
    }

    /// Check the numbers: everything finite and ≥ 0; at each end the radius and the thickness
    /// are both zero or both positive, with a ratio in `[0.01, 100]` (the elliptical-to-circular
    /// scaling of the closest-point query divides by them).
    pub fn validate(&self, source: &Path, index: usize) -> Result<()> {
        let vals = [
            ("segments.length", self.length),
            ("segments.r1", self.r1),
            ("segments.r2", self.r2),
            ("segments.r1y", self.r1y),
            ("segments.r2y", self.r2y),
        ];
        for (field, v) in vals {
            if !(v.is_finite() && v >= 0.0) {
                return Err(ModelError::field(
                    source,
                    field,
                    Some(index),
                    format!("must be finite and ≥ 0, got {v}"),
                ));
            }
        }
        for (field, r, ry) in [
            ("segments.r1y", self.r1, self.r1y),
            ("segments.r2y", self.r2, self.r2y),
        ] {
            let ok = (r == 0.0 && ry == 0.0)
                || (r > 0.0 && ry > 0.0 && ry / r >= 0.01 && ry / r <= 100.0);
            if !ok {
                return Err(ModelError::field(
                    source,
                    field,
                    Some(index),
                    format!(
                        "radius {r} and thickness {ry} must both be zero or both positive with a ratio in [0.01, 100]"
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// How one of the 21 keypoints of `DESIGN.md` is read off a posed cylinder model.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum CylinderKeypoint {
    /// A joint: the origin (rotation center) of a bone.
    Joint {
        /// The bone.
        bone: usize,
    },
    /// A fingertip: the far surface point of a segment along its axis ([`Segment::tip_local`]).
    Tip {
        /// The distal segment.
        segment: usize,
    },
    /// A point rigidly attached to a bone, given in the bone frame: a fingertip off its
    /// segment's axis (the thumb tip of [`CylinderModel::from_sphere_mesh`], whose tip sphere
    /// does not sit on the axis).
    Point {
        /// The bone.
        bone: usize,
        /// Position in the bone frame (mm).
        offset: Vector3<f64>,
    },
}

/// The cylinder hand model of thesis Ch. 2 (§2.2 "Tracking model"): a 26-DOF skeleton and one
/// [`Segment`] per palm/phalanx bone.
#[derive(Clone, Debug, PartialEq)]
pub struct CylinderModel {
    /// Display name.
    pub name: String,
    /// Which hand the geometry is (thumb at −x: right, at +x: left, palm facing −z).
    pub handedness: Handedness,
    /// Kinematic tree and DOFs.
    pub skeleton: Skeleton,
    /// The segments; their index is the `segment` of a [`CylinderProjection`](super::CylinderProjection).
    pub segments: Vec<Segment>,
    /// The 21 keypoints of `DESIGN.md`.
    pub keypoints: Vec<CylinderKeypoint>,
}

impl CylinderModel {
    /// Validate the model; `source` names the file (or template) for error messages.
    ///
    /// Refused: no segments, segments on missing bones or with invalid numbers (see
    /// [`Segment::validate`]), a keypoint count other than 21, keypoints on missing bones or
    /// segments.
    pub fn validate(&self, source: &Path) -> Result<()> {
        let nb = self.skeleton.bones().len();
        if self.segments.is_empty() {
            return Err(ModelError::field(source, "segments", None, "no segments"));
        }
        for (i, s) in self.segments.iter().enumerate() {
            if s.bone >= nb {
                return Err(ModelError::field(
                    source,
                    "segments.bone",
                    Some(i),
                    format!("bone index {} out of range ({nb} bones)", s.bone),
                ));
            }
            s.validate(source, i)?;
        }
        crate::keypoints::check_keypoint_count(source, self.keypoints.len())?;
        for (k, kp) in self.keypoints.iter().enumerate() {
            let ok = match *kp {
                CylinderKeypoint::Joint { bone } => bone < nb,
                CylinderKeypoint::Tip { segment } => segment < self.segments.len(),
                CylinderKeypoint::Point { bone, offset } => {
                    bone < nb && offset.iter().all(|v| v.is_finite())
                }
            };
            if !ok {
                return Err(ModelError::field(
                    source,
                    "keypoints",
                    Some(k),
                    "bone or segment index out of range",
                ));
            }
        }
        Ok(())
    }

    /// Forward kinematics (thesis Eq. 3.7 applied to the Ch. 2 skeleton): the posed skeleton,
    /// whose `globals[bone]` are the segment frames. The pose must have one finite value per DOF.
    pub fn posed(&self, pose: &Pose) -> Result<PosedSkeleton> {
        let checked = Pose::from_values(&self.skeleton, pose.values.clone())?;
        Ok(PosedSkeleton::new(&self.skeleton, &checked))
    }

    /// The posed skeleton at θ = 0 (the template in the model frame).
    pub fn rest_posed(&self) -> PosedSkeleton {
        PosedSkeleton::new(&self.skeleton, &Pose::zeros(&self.skeleton))
    }

    /// World position of the start (bone origin) of segment `i`; `None` when out of range.
    pub fn segment_start(&self, posed: &PosedSkeleton, i: usize) -> Option<Vector3<f64>> {
        let s = self.segments.get(i)?;
        Some(posed.globals.get(s.bone)?.translation)
    }

    /// World position of the axis end point of segment `i`; `None` when out of range.
    pub fn segment_end(&self, posed: &PosedSkeleton, i: usize) -> Option<Vector3<f64>> {
        let s = self.segments.get(i)?;
        Some(posed.globals.get(s.bone)?.transform_point(&s.end_local()))
    }

    /// The 21 keypoints of `DESIGN.md` in the frame of `posed` (camera frame for a tracked
    /// pose): joints are bone origins, tips the far axial surface point of the distal segment.
    /// Entries whose bone or segment is missing from `posed` are left at zero.
    pub fn keypoints(&self, posed: &PosedSkeleton) -> [Vector3<f64>; NUM_KEYPOINTS] {
        let mut out = [Vector3::zeros(); NUM_KEYPOINTS];
        for (k, def) in self.keypoints.iter().enumerate().take(NUM_KEYPOINTS) {
            let p = match *def {
                CylinderKeypoint::Joint { bone } => posed.globals.get(bone).map(|g| g.translation),
                CylinderKeypoint::Tip { segment } => self.segments.get(segment).and_then(|s| {
                    posed
                        .globals
                        .get(s.bone)
                        .map(|g| g.transform_point(&s.tip_local()))
                }),
                CylinderKeypoint::Point { bone, offset } => {
                    posed.globals.get(bone).map(|g| g.transform_point(&offset))
                }
            };
            if let Some(p) = p {
                out[k] = p;
            }
        }
        out
    }

    /// Keypoint `k` as a point rigidly attached to a bone: `(bone, position in the bone frame)`,
    /// so that its skeleton Jacobian is [`PosedSkeleton::for_each_column`] on that bone (e.g.
    /// the wrist keypoint `k₀` of thesis Eq. 2.4). `None` when `k`, its bone or its segment is
    /// out of range.
    pub fn keypoint_on_bone(&self, k: usize) -> Option<(usize, Vector3<f64>)> {
        let (bone, local) = match *self.keypoints.get(k)? {
            CylinderKeypoint::Joint { bone } => (bone, Vector3::zeros()),
            CylinderKeypoint::Tip { segment } => {
                let s = self.segments.get(segment)?;
                (s.bone, s.tip_local())
            }
            CylinderKeypoint::Point { bone, offset } => (bone, offset),
        };
        (bone < self.skeleton.bones().len()).then_some((bone, local))
    }

    /// Which hand the rest geometry shows, whatever [`CylinderModel::handedness`] says.
    ///
    /// With `s` the vector from the little-finger base to the index base, `y` the middle
    /// finger's direction and `p` the direction toward which it flexes (palmar), a right hand
    /// has `(s × y)·p > 0` (thumb side −x, fingers +y, palm −z gives `(−x × y)·(−z) = 1`).
    /// Falls back to the stored handedness when the bones `index_1`, `pinky_1`, `middle_1` or
    /// the DOF `middle_mcp_flex` are missing.
    pub fn geometric_handedness(&self) -> Handedness {
        let sk = &self.skeleton;
        let (Some(i), Some(p), Some(m), Some(f)) = (
            sk.bone_index("index_1"),
            sk.bone_index("pinky_1"),
            sk.bone_index("middle_1"),
            sk.dof_index("middle_mcp_flex"),
        ) else {
            return self.handedness;
        };
        let g = sk.rest_globals();
        let s = g[i].translation - g[p].translation;
        let y = g[m].rotation * Vector3::y();
        let palmar = g[m].rotation * sk.dofs()[f].axis.cross(&Vector3::y());
        if s.cross(&y).dot(&palmar) > 0.0 {
            Handedness::Right
        } else {
            Handedness::Left
        }
    }

    /// The mirror image of the model (x ↦ −x in the model frame), with the other handedness.
    ///
    /// Rest frames are conjugated by `M = diag(−1, 1, 1)` and joint axes become `−M·a`, so the
    /// same θ gives the mirrored posture; segments are symmetric in their local x and keep their
    /// numbers; off-axis keypoint offsets are mirrored with their frames.
    pub fn mirrored(&self) -> Result<CylinderModel> {
        let m = Matrix3::from_diagonal(&Vector3::new(-1.0, 1.0, 1.0));
        let mut bones = self.skeleton.bones().to_vec();
        for b in &mut bones {
            b.rest.rotation = m * b.rest.rotation * m;
            b.rest.translation = m * b.rest.translation;
        }
        let mut dofs = self.skeleton.dofs().to_vec();
        for d in &mut dofs {
            if d.kind == DofKind::Rotation {
                d.axis = -(m * d.axis);
            }
        }
        let skeleton = Skeleton::new(bones, dofs, Path::new("<mirrored>"))?;
        Ok(CylinderModel {
            name: format!("{} (mirrored)", self.name),
            handedness: self.handedness.other(),
            skeleton,
            segments: self.segments.clone(),
            keypoints: self
                .keypoints
                .iter()
                .map(|k| match *k {
                    CylinderKeypoint::Point { bone, offset } => CylinderKeypoint::Point {
                        bone,
                        offset: m * offset,
                    },
                    other => other,
                })
                .collect(),
        })
    }
}

/// Shape numbers of one segment: `[length, r1, r2, r1y, r2y]` (mm).
pub(crate) type SegmentShape = [f64; 5];

/// One digit of the shared hand layout.
pub(crate) struct DigitSpec {
    /// Rest frames of the three bones, each relative to its parent (palm, then the previous bone).
    pub rests: [Rigid3; 3],
    /// The three segments.
    pub shapes: [SegmentShape; 3],
}

/// Everything that differs between the cylinder templates; the topology, DOF names, orders and
/// limits are shared (htrack's `leftHand2` layout, ANCHOR-FACTS §1.1, with our signs).
pub(crate) struct HandSpec {
    pub name: String,
    pub handedness: Handedness,
    /// Palm rest frame relative to the root.
    pub palm_rest: Rigid3,
    pub palm: SegmentShape,
    /// Thumb, pinky, ring, middle, index (htrack's joint-id order).
    pub digits: [DigitSpec; 5],
    /// Bone-frame axis about which a positive angle flexes toward the palm.
    pub flex_axis: Vector3<f64>,
    /// Bone-frame axis about which a positive angle abducts toward the thumb side.
    pub abd_axis: Vector3<f64>,
}

/// Digit names in htrack's joint-id order (the bone and segment order of every cylinder model).
pub(crate) const DIGITS: [&str; 5] = ["thumb", "pinky", "ring", "middle", "index"];

/// Our joint limits `(abduction, [flexion × 3])`: htrack's conservative bounds (ANCHOR-FACTS
/// §1.1) with the signs flipped, so flexion is positive toward the palm and abduction toward
/// the thumb.
fn limits(digit: &str) -> ([f64; 2], [f64; 2]) {
    let flex = [-0.1, 1.5];
    let abd = match digit {
        "thumb" | "middle" | "ring" => [-0.3, 0.3],
        "index" => [-0.4, 0.5],
        _ => [-0.3, 0.5],
    };
    (abd, flex)
}

/// Build a cylinder model with the shared layout: bones `root, palm, thumb_1..3, pinky_1..3,
/// ring_1..3, middle_1..3, index_1..3`, segments in the same order (htrack's segment order),
/// DOFs in [`CYLINDER_DOF_NAMES`] order.
pub(crate) fn build_hand(spec: HandSpec, source: &Path) -> Result<CylinderModel> {
    let mut bones: Vec<Bone> = Vec::with_capacity(17);
    let mut dofs: Vec<Dof> = Vec::with_capacity(26);
    let mut segments = Vec::with_capacity(16);
    fn push_dof(
        dofs: &mut Vec<Dof>,
        name: &str,
        bone: usize,
        kind: DofKind,
        axis: Vector3<f64>,
        lim: Option<[f64; 2]>,
    ) -> usize {
        dofs.push(Dof {
            name: name.into(),
            bone,
            kind,
            axis,
            limits: lim,
        });
        dofs.len() - 1
    }
    bones.push(Bone {
        name: "root".into(),
        parent: None,
        rest: Rigid3::identity(),
        dofs: vec![],
    });
    let mut root_dofs = Vec::new();
    for (i, axis) in [Vector3::x(), Vector3::y(), Vector3::z()]
        .into_iter()
        .enumerate()
    {
        root_dofs.push(push_dof(
            &mut dofs,
            CYLINDER_DOF_NAMES[i],
            0,
            DofKind::Translation,
            axis,
            None,
        ));
    }
    for (i, axis) in [Vector3::x(), Vector3::y(), Vector3::z()]
        .into_iter()
        .enumerate()
    {
        root_dofs.push(push_dof(
            &mut dofs,
            CYLINDER_DOF_NAMES[3 + i],
            0,
            DofKind::GlobalRotation,
            axis,
            None,
        ));
    }
    bones[0].dofs = root_dofs;
    bones.push(Bone {
        name: "palm".into(),
        parent: Some(0),
        rest: spec.palm_rest,
        dofs: vec![],
    });
    let seg = |bone: usize, s: &SegmentShape| Segment {
        bone,
        length: s[0],
        r1: s[1],
        r2: s[2],
        r1y: s[3],
        r2y: s[4],
    };
    segments.push(seg(1, &spec.palm));

    // Bones in htrack's order; DOFs created afterwards in θ order.
    let mut digit_bones = [[0usize; 3]; 5];
    for (d, digit) in spec.digits.iter().enumerate() {
        let mut parent = 1;
        for (k, slot) in digit_bones[d].iter_mut().enumerate() {
            bones.push(Bone {
                name: format!("{}_{}", DIGITS[d], k + 1),
                parent: Some(parent),
                rest: digit.rests[k],
                dofs: vec![],
            });
            let b = bones.len() - 1;
            *slot = b;
            segments.push(seg(b, &digit.shapes[k]));
            parent = b;
        }
    }
    // θ order: thumb, index, middle, ring, pinky.
    for name in ["thumb", "index", "middle", "ring", "pinky"] {
        let d = DIGITS.iter().position(|&n| n == name).unwrap_or(0);
        let [b1, b2, b3] = digit_bones[d];
        let (abd_lim, flex_lim) = limits(name);
        let (n_abd, n_f1, n_f2, n_f3) = if name == "thumb" {
            (
                "thumb_cmc_abd",
                "thumb_cmc_flex",
                "thumb_mcp_flex",
                "thumb_ip_flex",
            )
        } else {
            ("mcp_abd", "mcp_flex", "pip_flex", "dip_flex")
        };
        let full = |n: &str| {
            if name == "thumb" {
                n.to_string()
            } else {
                format!("{name}_{n}")
            }
        };
        let abd = push_dof(
            &mut dofs,
            &full(n_abd),
            b1,
            DofKind::Rotation,
            spec.abd_axis,
            Some(abd_lim),
        );
        let f1 = push_dof(
            &mut dofs,
            &full(n_f1),
            b1,
            DofKind::Rotation,
            spec.flex_axis,
            Some(flex_lim),
        );
        let f2 = push_dof(
            &mut dofs,
            &full(n_f2),
            b2,
            DofKind::Rotation,
            spec.flex_axis,
            Some(flex_lim),
        );
        let f3 = push_dof(
            &mut dofs,
            &full(n_f3),
            b3,
            DofKind::Rotation,
            spec.flex_axis,
            Some(flex_lim),
        );
        // htrack applies all flexions (local X) before the abductions (local Z):
        // local = rest · R(flex) · R(abd) (ANCHOR-FACTS §1.1 "Posing").
        bones[b1].dofs = vec![f1, abd];
        bones[b2].dofs = vec![f2];
        bones[b3].dofs = vec![f3];
    }
    debug_assert!(dofs
        .iter()
        .zip(CYLINDER_DOF_NAMES)
        .all(|(d, n)| d.name == n));
    let skeleton = Skeleton::new(bones, dofs, source)?;

    let mut keypoints = vec![CylinderKeypoint::Joint { bone: 1 }];
    for name in ["thumb", "index", "middle", "ring", "pinky"] {
        let d = DIGITS.iter().position(|&n| n == name).unwrap_or(0);
        let [b1, b2, b3] = digit_bones[d];
        keypoints.extend([
            CylinderKeypoint::Joint { bone: b1 },
            CylinderKeypoint::Joint { bone: b2 },
            CylinderKeypoint::Joint { bone: b3 },
            CylinderKeypoint::Tip {
                segment: 1 + 3 * d + 2,
            },
        ]);
    }
    let model = CylinderModel {
        name: spec.name,
        handedness: spec.handedness,
        skeleton,
        segments,
        keypoints,
    };
    model.validate(source)?;
    Ok(model)
}
