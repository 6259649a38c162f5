//! The sphere-mesh template: rest-pose geometry attached to a kinematic skeleton.

use std::path::Path;

use nalgebra::Vector3;

use crate::error::{ModelError, Result};
use crate::keypoints::{Handedness, KeypointDef};
use crate::kinematics::Skeleton;
use crate::shape::Element;

/// How a sphere follows the skeleton.
#[derive(Clone, Debug, PartialEq)]
pub enum Attachment {
    /// Rigidly attached to a bone at `offset` in the bone's frame: `c = G_bone · offset`.
    Bone {
        /// The bone.
        bone: usize,
        /// Offset in the bone frame (mm).
        offset: Vector3<f64>,
    },
    /// A passive sphere whose center and radius are a fixed blend of other spheres
    /// (honline's `thumb_membrane_middle`); the parts must be earlier, bone-attached spheres.
    Blend {
        /// `(sphere index, weight)` pairs.
        parts: Vec<(usize, f64)>,
    },
}

/// One sphere of the template.
#[derive(Clone, Debug, PartialEq)]
pub struct SphereDef {
    /// Unique name (the honline names: `index_base`, `palm_back`, ...).
    pub name: String,
    /// How it is posed.
    pub attachment: Attachment,
    /// Radius (mm); ignored for blends, whose radius is the blend of the parts' radii.
    pub radius: f64,
}

/// One element with the bone whose DOFs move its correspondences (hmodel's "pose unit").
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ElementDef {
    /// The pill or wedge.
    pub element: Element,
    /// The bone used for the skeleton Jacobian of points on the element.
    pub bone: usize,
}

/// A sphere-mesh hand template (thesis §3.1, Fig. 3.4): the skeleton with its rest frames `T̄`,
/// the spheres (centers `C̄`, radii `r̄`) and the pill/wedge elements.
#[derive(Clone, Debug, PartialEq)]
pub struct SphereMeshTemplate {
    /// Display name.
    pub name: String,
    /// Which hand the geometry is.
    pub handedness: Handedness,
    /// Kinematic tree and DOFs.
    pub skeleton: Skeleton,
    /// Spheres.
    pub spheres: Vec<SphereDef>,
    /// Elements.
    pub elements: Vec<ElementDef>,
    /// The 21 keypoints of DESIGN.md.
    pub keypoints: Vec<KeypointDef>,
}

impl SphereMeshTemplate {
    /// Validate a template; `source` names the file for error messages.
    ///
    /// Refused: negative or non-finite radii, bone/sphere indices out of range, blends of
    /// blends or of later spheres, elements with repeated spheres, a keypoint count other than 21.
    pub fn validate(&self, source: &Path) -> Result<()> {
        let nb = self.skeleton.bones().len();
        let ns = self.spheres.len();
        if ns == 0 {
            return Err(ModelError::field(source, "spheres", None, "no spheres"));
        }
        for (i, s) in self.spheres.iter().enumerate() {
            if self.spheres[..i].iter().any(|o| o.name == s.name) {
                return Err(ModelError::field(
                    source,
                    "spheres.name",
                    Some(i),
                    format!("duplicate name `{}`", s.name),
                ));
            }
            match &s.attachment {
                Attachment::Bone { bone, offset } => {
                    if *bone >= nb {
                        return Err(ModelError::field(
                            source,
                            "spheres.bone",
                            Some(i),
                            format!("bone index {bone} out of range ({nb} bones)"),
                        ));
                    }
                    if !offset.iter().all(|x| x.is_finite()) {
                        return Err(ModelError::field(
                            source,
                            "spheres.center",
                            Some(i),
                            "non-finite center",
                        ));
                    }
                    if !(s.radius.is_finite() && s.radius >= 0.0) {
                        return Err(ModelError::field(
                            source,
                            "spheres.radius",
                            Some(i),
                            format!("radius must be finite and ≥ 0, got {}", s.radius),
                        ));
                    }
                }
                Attachment::Blend { parts } => {
                    if parts.is_empty() {
                        return Err(ModelError::field(
                            source,
                            "spheres.blend",
                            Some(i),
                            "empty blend",
                        ));
                    }
                    for &(p, w) in parts {
                        let ok =
                            p < i && matches!(self.spheres[p].attachment, Attachment::Bone { .. });
                        if !ok || !w.is_finite() || w < 0.0 {
                            return Err(ModelError::field(source, "spheres.blend", Some(i), format!("part {p} must be an earlier bone-attached sphere with a weight ≥ 0")));
                        }
                    }
                }
            }
        }
        for (e, def) in self.elements.iter().enumerate() {
            let idx = def.element.spheres();
            if let Some(&bad) = idx.iter().find(|&&s| s as usize >= ns) {
                return Err(ModelError::field(
                    source,
                    "elements",
                    Some(e),
                    format!("sphere index {bad} out of range ({ns} spheres)"),
                ));
            }
            let distinct = idx
                .iter()
                .enumerate()
                .all(|(a, x)| idx[..a].iter().all(|y| y != x));
            if !distinct {
                return Err(ModelError::field(
                    source,
                    "elements",
                    Some(e),
                    "an element repeats a sphere",
                ));
            }
            if def.bone >= nb {
                return Err(ModelError::field(
                    source,
                    "elements.bone",
                    Some(e),
                    format!("bone index {} out of range", def.bone),
                ));
            }
        }
        crate::keypoints::check_keypoint_count(source, self.keypoints.len())?;
        for (k, kp) in self.keypoints.iter().enumerate() {
            let (bone, sphere) = match kp {
                KeypointDef::Joint { bone } => (*bone, None),
                KeypointDef::Tip { bone, sphere } => (*bone, Some(*sphere)),
            };
            if bone >= nb || sphere.is_some_and(|s| s >= ns) {
                return Err(ModelError::field(
                    source,
                    "keypoints",
                    Some(k),
                    "bone or sphere index out of range",
                ));
            }
        }
        Ok(())
    }

    /// Index of the sphere called `name`.
    pub fn sphere_index(&self, name: &str) -> Option<usize> {
        self.spheres.iter().position(|s| s.name == name)
    }

    /// Rest-pose centers `C̄` (model frame) and radii `r̄`.
    pub fn rest_spheres(&self) -> Vec<crate::shape::Sphere> {
        let globals = self.skeleton.rest_globals();
        crate::spheremesh::posed::place_spheres(&self.spheres, &globals)
    }

    /// Number of pills and wedges.
    pub fn element_counts(&self) -> (usize, usize) {
        let pills = self
            .elements
            .iter()
            .filter(|e| matches!(e.element, Element::Pill(_)))
            .count();
        (pills, self.elements.len() - pills)
    }

    /// The mirror image of the template (x ↦ −x in the model frame), with the other handedness.
    ///
    /// Rest frames are conjugated by `M = diag(−1, 1, 1)` and joint axes become `−M·a`, so the
    /// same θ gives the mirrored posture (`M·R(a, θ)·M = R(−M·a, θ)`).
    pub fn mirrored(&self) -> Result<SphereMeshTemplate> {
        let m = nalgebra::Matrix3::from_diagonal(&Vector3::new(-1.0, 1.0, 1.0));
        let mut bones = self.skeleton.bones().to_vec();
        for b in &mut bones {
            b.rest.rotation = m * b.rest.rotation * m;
            b.rest.translation = m * b.rest.translation;
        }
        let mut dofs = self.skeleton.dofs().to_vec();
        for d in &mut dofs {
            if d.kind == crate::kinematics::DofKind::Rotation {
                d.axis = -(m * d.axis);
            }
        }
        let skeleton = Skeleton::new(bones, dofs, Path::new("<mirrored>"))?;
        let mut spheres = self.spheres.clone();
        for s in &mut spheres {
            if let Attachment::Bone { offset, .. } = &mut s.attachment {
                *offset = m * *offset;
            }
        }
        let mut elements = self.elements.clone();
        for e in &mut elements {
            // Mirroring flips orientation; keep wedge winding consistent with the new handedness.
            if let Element::Wedge(s) = &mut e.element {
                s.swap(1, 2);
            }
        }
        Ok(SphereMeshTemplate {
            name: format!("{} (mirrored)", self.name),
            handedness: self.handedness.other(),
            skeleton,
            spheres,
            elements,
            keypoints: self.keypoints.clone(),
        })
    }
}
