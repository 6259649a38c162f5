//! A cylinder model fitted to a sphere-mesh template, so that the Ch. 2 tracker can run on (and
//! be scored against) the synthetic sequences of a sphere-mesh subject.
//!
//! The rules are documented on [`CylinderModel::from_sphere_mesh`].

use std::path::Path;

use nalgebra::Vector3;

use super::model::{CylinderKeypoint, CylinderModel, Segment, DIGITS};
use crate::error::{ModelError, Result};
use crate::keypoints::KeypointDef;
use crate::kinematics::{Bone, Dof, Pose, Skeleton};
use crate::math::Rigid3;
use crate::spheremesh::{Attachment, SphereMeshTemplate};

/// Sphere names along a digit, proximal to distal (the honline names).
const DIGIT_SPHERES: [&str; 4] = ["base", "bottom", "middle", "top"];

/// A tip keypoint within this distance (mm) of a distal segment's axial cap point is that
/// segment's [`CylinderKeypoint::Tip`] (rounding of `length + r2`), and the distal segment is only
/// extended toward the tip beyond it.
const TIP_TOLERANCE: f64 = 1e-9;

/// Source name used in error messages.
const SOURCE: &str = "<cylinders fitted to a sphere mesh>";

impl CylinderModel {
    /// The cylinder model of a sphere-mesh template: same bones, the DOFs that move a segment
    /// (26 for the 28-DOF templates, same names), one segment per palm/phalanx bone sized by the
    /// template's spheres, and keypoints that coincide with
    /// [`crate::spheremesh::PosedSphereMesh::keypoints`] at any pose.
    ///
    /// # Rules
    /// - **Skeleton**: the template's bones are kept wholesale (names, tree, rest frames), so every
    ///   joint keypoint is the same bone origin in both models. DOFs that move no segment are
    ///   dropped: for the sphere-mesh templates these are the two wrist DOFs (`wrist_abd`,
    ///   `wrist_flex`), whose bone carries only the forearm spheres. The remaining DOFs keep their
    ///   names, order, axes and limits; for the 28-DOF templates they are exactly
    ///   [`super::CYLINDER_DOF_NAMES`] (6 global + 20 articulations, thesis §2.2). The wrist DOFs
    ///   move no keypoint either (the wrist keypoint is the wrist bone's own rotation center), so a
    ///   sphere-mesh pose mapped by DOF name ([`CylinderModel::pose_by_name`]) gives the same 21
    ///   keypoints.
    /// - **Segments** (htrack's order: palm, then thumb, pinky, ring, middle, index, three each): a
    ///   phalanx segment runs along its bone's +y from the bone origin to the (rest) axial position
    ///   of the next sphere of the digit (`base → bottom → middle → top`, the honline sphere
    ///   names), circular, with the radii of those two spheres; the distal segment is extended when
    ///   needed so that its far cap reaches the tip keypoint (the thumb tip sphere
    ///   `thumb_additional` lies beyond `thumb_top`). The palm is one elliptical segment on the
    ///   palm bone sized by the spheres attached to that bone: thickness `max |z| + r`, cap
    ///   reaching the farthest sphere along +y, width at the start / end the largest `|x| + r` of
    ///   the spheres in the proximal / distal half.
    /// - **Keypoints**: joints are the same bones; a tip is the sphere-mesh tip (tip sphere center
    ///   plus its radius along the bone's +y), expressed in the distal bone's frame — a
    ///   [`CylinderKeypoint::Tip`] of the distal segment when it lies on that segment's axis cap
    ///   (the fingers), a [`CylinderKeypoint::Point`] otherwise (the default thumb tip sphere sits
    ///   1.5 mm off the axis). Keypoints therefore coincide with the template's at every pose, up
    ///   to floating-point rounding.
    ///
    /// Refused: templates without the bones `palm`, `<digit>_1..3` or the spheres
    /// `<digit>_base/bottom/middle/top`, a palm bone without spheres, or a tip keypoint whose
    /// sphere does not ride on the keypoint's bone (the tip would not be rigid on one bone).
    pub fn from_sphere_mesh(template: &SphereMeshTemplate) -> Result<CylinderModel> {
        fit(template, false)
    }

    /// As [`CylinderModel::from_sphere_mesh`], plus a **wrist segment** fitted to the spheres of
    /// the template's `wrist` bone (the forearm stub the sphere-mesh models also have: hmodel's
    /// wrist blocks, honline's separately fitted wrist pixels, ANCHOR-FACTS §5.3/§5.6). It rides
    /// on an extra DOF-less bone `forearm`, a child of `wrist` whose +y points down the arm, so
    /// the two wrist DOFs are kept (28 DOFs for the default templates).
    ///
    /// Why: the wristband segmentation keeps the forearm between the band and the wrist
    /// (htrack's cut lies 30 mm above the band). A model without a wrist cannot explain those
    /// points; on our synthetic sequences they are a fifth of the cloud, all on one side, and
    /// even the ℓ1 data term then drags the hand ~20 mm toward the arm. With the wrist segment
    /// they are explained instead of resisted. Templates without wrist spheres get no segment.
    pub fn from_sphere_mesh_with_wrist(template: &SphereMeshTemplate) -> Result<CylinderModel> {
        fit(template, true)
    }
}

/// [`CylinderModel::from_sphere_mesh`] with or without the wrist segment.
fn fit(template: &SphereMeshTemplate, with_wrist: bool) -> Result<CylinderModel> {
    {
        let source = Path::new(SOURCE);
        let sk = &template.skeleton;
        let rest = sk.rest_globals();
        let bone = |name: &str| {
            sk.bone_index(name).ok_or_else(|| {
                ModelError::field(source, "bones", None, format!("no bone `{name}`"))
            })
        };
        // Center in the frame of bone `b` (the attachment offset itself when the sphere rides
        // on `b`, so that no rounding enters) and radius.
        let sphere = |name: &str, b: usize| -> Result<(Vector3<f64>, f64)> {
            let i = template.sphere_index(name).ok_or_else(|| {
                ModelError::field(source, "spheres", None, format!("no sphere `{name}`"))
            })?;
            let (c, r) = match template.spheres[i].attachment {
                Attachment::Bone { bone, offset } if bone == b => {
                    (offset, template.spheres[i].radius)
                }
                _ => {
                    let (c, r) = rest_sphere(template, &rest, i);
                    (rest[b].inverse().transform_point(&c), r)
                }
            };
            Ok((c, r))
        };

        // Segments: palm, then the digits in htrack's order.
        let palm = bone("palm")?;
        let mut segments = vec![palm_segment(template, palm)?];
        let mut distal = Vec::with_capacity(5);
        for digit in DIGITS {
            for k in 0..3 {
                let b = bone(&format!("{digit}_{}", k + 1))?;
                let (_, r1) = sphere(&format!("{digit}_{}", DIGIT_SPHERES[k]), b)?;
                let (far_local, r2) = sphere(&format!("{digit}_{}", DIGIT_SPHERES[k + 1]), b)?;
                segments.push(Segment {
                    bone: b,
                    length: far_local.y.max(0.0),
                    r1,
                    r2,
                    r1y: r1,
                    r2y: r2,
                });
            }
            distal.push(segments.len() - 1);
        }

        // Keypoints; the distal segments grow so that their cap reaches the tip.
        let mut tips: Vec<(usize, Vector3<f64>)> = Vec::with_capacity(5);
        for (k, def) in template.keypoints.iter().enumerate() {
            if let KeypointDef::Tip { bone, sphere } = *def {
                let s = &template.spheres[sphere];
                let offset = match s.attachment {
                    Attachment::Bone { bone: b, offset } if b == bone => offset,
                    _ => {
                        return Err(ModelError::field(
                            source,
                            "keypoints",
                            Some(k),
                            "the tip sphere must be attached to the keypoint's bone",
                        ))
                    }
                };
                let tip = offset + Vector3::y() * s.radius;
                if let Some(&seg) = distal.iter().find(|&&i| segments[i].bone == bone) {
                    let sg = &mut segments[seg];
                    if tip.y - sg.r2y > sg.length + TIP_TOLERANCE {
                        sg.length = tip.y - sg.r2y;
                    }
                }
                tips.push((k, tip));
            }
        }
        let mut keypoints = Vec::with_capacity(template.keypoints.len());
        for (k, def) in template.keypoints.iter().enumerate() {
            keypoints.push(match *def {
                KeypointDef::Joint { bone } => CylinderKeypoint::Joint { bone },
                KeypointDef::Tip { bone, .. } => {
                    let offset = tips
                        .iter()
                        .find(|(i, _)| *i == k)
                        .map(|(_, t)| *t)
                        .unwrap_or_default();
                    match segments.iter().position(|s| {
                        s.bone == bone && (s.tip_local() - offset).norm() <= TIP_TOLERANCE
                    }) {
                        Some(segment) => CylinderKeypoint::Tip { segment },
                        None => CylinderKeypoint::Point { bone, offset },
                    }
                }
            });
        }

        let mut bones = sk.bones().to_vec();
        if with_wrist {
            if let Some(seg) = wrist_segment(template, bones.len()) {
                bones.push(seg.0);
                segments.push(seg.1);
            }
        }
        let full = Skeleton::new(bones, sk.dofs().to_vec(), source)?;
        let skeleton = drop_idle_dofs(&full, &segments, source)?;
        let model = CylinderModel {
            name: format!("{} (fitted cylinders)", template.name),
            handedness: template.handedness,
            skeleton,
            segments,
            keypoints,
        };
        model.validate(source)?;
        Ok(model)
    }
}

impl CylinderModel {
    /// This model's pose for a pose of another skeleton (e.g. the sphere-mesh template it was
    /// fitted to), matched by DOF name: DOFs the other skeleton lacks stay 0, the other's extra
    /// DOFs (the wrist DOFs) are ignored. `pose` must have one value per DOF of `other`.
    pub fn pose_by_name(&self, other: &Skeleton, pose: &Pose) -> Pose {
        let mut out = Pose::zeros(&self.skeleton);
        for (name, v) in pose.named(other) {
            if let Some(i) = self.skeleton.dof_index(name) {
                out.values[i] = v;
            }
        }
        out
    }
}

/// The wrist segment of [`CylinderModel::from_sphere_mesh_with_wrist`]: a DOF-less bone (index
/// `index`) under `wrist`, at the highest wrist sphere and pointing down the arm (rest rotation
/// π about z), carrying an elliptical segment sized like the palm's from the spheres attached to
/// `wrist`: widths `|x| + r` at the top and bottom, thicknesses `|z| + r`.
fn wrist_segment(template: &SphereMeshTemplate, index: usize) -> Option<(Bone, Segment)> {
    let wrist = template.skeleton.bone_index("wrist")?;
    let spheres: Vec<(Vector3<f64>, f64)> = template
        .spheres
        .iter()
        .filter_map(|s| match s.attachment {
            Attachment::Bone { bone, offset } if bone == wrist => Some((offset, s.radius)),
            _ => None,
        })
        .collect();
    let top = spheres
        .iter()
        .map(|(c, _)| c.y)
        .fold(f64::NEG_INFINITY, f64::max);
    let bottom = spheres
        .iter()
        .map(|(c, _)| c.y)
        .fold(f64::INFINITY, f64::min);
    if !(top.is_finite() && bottom.is_finite() && top > bottom) {
        return None;
    }
    let extent = |y: f64| {
        spheres
            .iter()
            .filter(|(c, _)| (c.y - y).abs() < 1e-9)
            .fold((0.0f64, 0.0f64), |(w, t), (c, r)| {
                (w.max(c.x.abs() + r), t.max(c.z.abs() + r))
            })
    };
    let (r1, r1y) = extent(top);
    let (r2, r2y) = extent(bottom);
    let rest = Rigid3::new(
        crate::math::axis_angle(&Vector3::z(), std::f64::consts::PI),
        Vector3::new(0.0, top, 0.0),
    );
    let bone = Bone {
        name: "forearm".into(),
        parent: Some(wrist),
        rest,
        dofs: Vec::new(),
    };
    let segment = Segment {
        bone: index,
        length: top - bottom,
        r1: r1.max(1e-3),
        r2: r2.max(1e-3),
        r1y: r1y.max(1e-3),
        r2y: r2y.max(1e-3),
    };
    Some((bone, segment))
}

/// Rest center (model frame) and radius of sphere `i` (blends blend their parts).
fn rest_sphere(template: &SphereMeshTemplate, rest: &[Rigid3], i: usize) -> (Vector3<f64>, f64) {
    match &template.spheres[i].attachment {
        Attachment::Bone { bone, offset } => (
            rest[*bone].transform_point(offset),
            template.spheres[i].radius,
        ),
        Attachment::Blend { parts } => {
            parts.iter().fold((Vector3::zeros(), 0.0), |acc, &(p, w)| {
                let (c, r) = rest_sphere(template, rest, p);
                (acc.0 + c * w, acc.1 + r * w)
            })
        }
    }
}

/// The elliptical palm segment on bone `palm`, sized by the spheres attached to it (their
/// centers in the palm frame): thickness `ry = max |z| + r`; length such that the end cap
/// (half-axis `ry` along +y) reaches `max y + r`; width `r1` / `r2` the largest `|x| + r` of the
/// spheres in the proximal / distal half of the axis (the other half's when one is empty).
fn palm_segment(template: &SphereMeshTemplate, palm: usize) -> Result<Segment> {
    let spheres: Vec<(Vector3<f64>, f64)> = template
        .spheres
        .iter()
        .filter_map(|s| match s.attachment {
            Attachment::Bone { bone, offset } if bone == palm => Some((offset, s.radius)),
            _ => None,
        })
        .collect();
    if spheres.is_empty() {
        return Err(ModelError::field(
            Path::new(SOURCE),
            "spheres",
            None,
            "no sphere is attached to the palm bone",
        ));
    }
    let ry = spheres
        .iter()
        .fold(0.0f64, |m, (c, r)| m.max(c.z.abs() + r))
        .max(1e-3);
    let reach = spheres.iter().fold(0.0f64, |m, (c, r)| m.max(c.y + r));
    let length = (reach - ry).max(0.0);
    let (mut near, mut far) = (0.0f64, 0.0f64);
    for (c, r) in &spheres {
        let w = c.x.abs() + r;
        if c.y < 0.5 * length {
            near = near.max(w);
        } else {
            far = far.max(w);
        }
    }
    if near == 0.0 {
        near = far;
    }
    if far == 0.0 {
        far = near;
    }
    Ok(Segment {
        bone: palm,
        length,
        r1: near.max(1e-3),
        r2: far.max(1e-3),
        r1y: ry,
        r2y: ry,
    })
}

/// The skeleton without the DOFs that move no segment (DOFs on bones none of whose descendants,
/// nor themselves, carry a segment), indices remapped.
fn drop_idle_dofs(sk: &Skeleton, segments: &[Segment], source: &Path) -> Result<Skeleton> {
    let moves_segment = |b: usize| segments.iter().any(|s| sk.is_ancestor_or_self(b, s.bone));
    let mut map = vec![None; sk.num_dofs()];
    let mut dofs: Vec<Dof> = Vec::with_capacity(sk.num_dofs());
    for (i, d) in sk.dofs().iter().enumerate() {
        if moves_segment(d.bone) {
            map[i] = Some(dofs.len());
            dofs.push(d.clone());
        }
    }
    let bones: Vec<Bone> = sk
        .bones()
        .iter()
        .map(|b| Bone {
            dofs: b.dofs.iter().filter_map(|&d| map[d]).collect(),
            ..b.clone()
        })
        .collect();
    Skeleton::new(bones, dofs, source)
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::cylinder::CYLINDER_DOF_NAMES;
    use crate::kinematics::{DofKind, PosedSkeleton};
    use crate::spheremesh::{default_right_hand, PosedSphereMesh};

    /// A random pose of `sk`: joint angles uniform within their limits, global translation
    /// within ±200 mm, global rotation within ±π.
    fn random_pose(sk: &Skeleton, rng: &mut ChaCha8Rng) -> Pose {
        let values = sk
            .dofs()
            .iter()
            .map(|d| match (d.kind, d.limits) {
                (DofKind::Translation, _) => rng.random_range(-200.0..200.0),
                (DofKind::GlobalRotation, _) => rng.random_range(-3.1..3.1),
                (DofKind::Rotation, Some([lo, hi])) => rng.random_range(lo..=hi),
                (DofKind::Rotation, None) => rng.random_range(-1.0..1.0),
            })
            .collect();
        Pose { values }
    }

    /// Max keypoint distance (mm) between the template and its fitted model over the rest pose
    /// and `n` random poses.
    fn max_keypoint_gap(template: &SphereMeshTemplate, n: usize) -> f64 {
        let model = CylinderModel::from_sphere_mesh(template).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(42);
        let mut worst = 0.0f64;
        for i in 0..=n {
            let pose = if i == 0 {
                Pose::zeros(&template.skeleton)
            } else {
                random_pose(&template.skeleton, &mut rng)
            };
            let expected = PosedSphereMesh::new(template, &pose).keypoints(template);
            let cyl_pose = model.pose_by_name(&template.skeleton, &pose);
            let got = model.keypoints(&model.posed(&cyl_pose).unwrap());
            for (a, b) in expected.iter().zip(&got) {
                worst = worst.max((a - b).norm());
            }
        }
        worst
    }

    #[test]
    fn fitted_model_has_the_cylinder_dofs_and_layout() {
        let template = default_right_hand();
        let model = CylinderModel::from_sphere_mesh(&template).unwrap();
        let names: Vec<&str> = model
            .skeleton
            .dofs()
            .iter()
            .map(|d| d.name.as_str())
            .collect();
        assert_eq!(names, CYLINDER_DOF_NAMES);
        assert_eq!(
            model.skeleton.bones().len(),
            template.skeleton.bones().len()
        );
        assert_eq!(model.segments.len(), 16);
        assert_eq!(model.handedness, template.handedness);
        assert_eq!(model.geometric_handedness(), template.handedness);
        // Palm first, elliptical; the phalanges circular with the sphere radii.
        let palm = &model.segments[0];
        assert_eq!(model.skeleton.bones()[palm.bone].name, "palm");
        assert!(!palm.is_circular() && palm.r1y < palm.r1);
        let idx = |n: &str| template.sphere_index(n).unwrap();
        let index_1 = model
            .segments
            .iter()
            .find(|s| model.skeleton.bones()[s.bone].name == "index_1")
            .unwrap();
        assert_eq!(index_1.r1, template.spheres[idx("index_base")].radius);
        assert_eq!(index_1.r2, template.spheres[idx("index_bottom")].radius);
        assert!((index_1.length - 40.0).abs() < 1e-9);
        eprintln!(
            "palm segment: length {:.2}, r {:.2}→{:.2}, thickness {:.2}",
            palm.length, palm.r1, palm.r2, palm.r1y
        );
        // Fingertips are on the axis caps; the default thumb tip is not (tip sphere off-axis).
        let tips: Vec<_> = [4, 8, 12, 16, 20].map(|k| model.keypoints[k]).into();
        assert!(matches!(tips[0], CylinderKeypoint::Point { .. }));
        assert!(tips[1..]
            .iter()
            .all(|t| matches!(t, CylinderKeypoint::Tip { .. })));
    }

    #[test]
    fn keypoints_coincide_with_the_sphere_mesh_at_any_pose() {
        let template = default_right_hand();
        let gap = max_keypoint_gap(&template, 200);
        eprintln!("max keypoint gap over rest + 200 random poses: {gap:.2e} mm");
        assert!(gap < 1e-9, "{gap}");
        // The mirrored (left) template too: the off-axis thumb tip is mirrored with its frame.
        let left = template.mirrored().unwrap();
        let gap = max_keypoint_gap(&left, 50);
        assert!(gap < 1e-9, "{gap}");
        let model = CylinderModel::from_sphere_mesh(&template).unwrap();
        let mirrored = model.mirrored().unwrap();
        let direct = CylinderModel::from_sphere_mesh(&left).unwrap();
        let kp = |m: &CylinderModel| m.keypoints(&m.rest_posed());
        for (a, b) in kp(&mirrored).iter().zip(&kp(&direct)) {
            assert!((a - b).norm() < 1e-9);
        }
    }

    /// Fraction of the template's sphere centers (forearm spheres of the wrist bone excluded:
    /// the cylinder model has no forearm) inside some segment, at rest and at random poses.
    #[test]
    fn segments_cover_the_sphere_centers() {
        let template = default_right_hand();
        let model = CylinderModel::from_sphere_mesh(&template).unwrap();
        let wrist = template.skeleton.bone_index("wrist").unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (mut inside, mut total) = (0usize, 0usize);
        let mut outside = std::collections::BTreeSet::new();
        for i in 0..=20 {
            let pose = if i == 0 {
                Pose::zeros(&template.skeleton)
            } else {
                random_pose(&template.skeleton, &mut rng)
            };
            let mesh = PosedSphereMesh::new(&template, &pose);
            let posed: PosedSkeleton = model
                .posed(&model.pose_by_name(&template.skeleton, &pose))
                .unwrap();
            for (s, def) in mesh.spheres.iter().zip(&template.spheres) {
                if matches!(def.attachment, Attachment::Bone { bone, .. } if bone == wrist) {
                    continue;
                }
                total += 1;
                let hit = model.segments.iter().any(|seg| {
                    let local = posed.globals[seg.bone].inverse().transform_point(&s.center);
                    seg.contains_local_point(&local)
                });
                if hit {
                    inside += 1;
                } else {
                    outside.insert(def.name.clone());
                }
            }
        }
        let frac = inside as f64 / total as f64;
        eprintln!(
            "sphere centers inside a segment: {frac:.3} ({inside}/{total}); outside: {outside:?}"
        );
        assert!(frac > 0.95, "{frac}; outside: {outside:?}");
    }

    #[test]
    fn templates_without_the_named_parts_are_refused() {
        let mut t = default_right_hand();
        let i = t.sphere_index("ring_middle").unwrap();
        t.spheres[i].name = "ring_mid".into();
        assert!(CylinderModel::from_sphere_mesh(&t).is_err());
    }
}
