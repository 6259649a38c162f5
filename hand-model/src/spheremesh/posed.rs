//! Posing a sphere-mesh template (Eq. 3.7) and the Jacobians of its spheres.

use nalgebra::Vector3;

use super::template::{Attachment, SphereDef, SphereMeshTemplate};
use crate::keypoints::{KeypointDef, NUM_KEYPOINTS};
use crate::kinematics::{Pose, PosedSkeleton};
use crate::math::Rigid3;
use crate::shape::Sphere;

/// A posed sphere-mesh: bone frames plus sphere centers and radii in the camera frame.
#[derive(Clone, Debug, Default)]
pub struct PosedSphereMesh {
    /// Posed skeleton (bone frames, DOF axes).
    pub skeleton: PosedSkeleton,
    /// Posed spheres, in template order.
    pub spheres: Vec<Sphere>,
}

pub(crate) fn place_spheres(defs: &[SphereDef], globals: &[Rigid3]) -> Vec<Sphere> {
    let mut out = Vec::with_capacity(defs.len());
    place_spheres_into(defs, globals, &mut out);
    out
}

fn place_spheres_into(defs: &[SphereDef], globals: &[Rigid3], out: &mut Vec<Sphere>) {
    out.clear();
    for d in defs {
        let s = match &d.attachment {
            Attachment::Bone { bone, offset } => {
                Sphere::new(globals[*bone].transform_point(offset), d.radius)
            }
            Attachment::Blend { parts } => {
                let mut c = Vector3::zeros();
                let mut r = 0.0;
                for &(p, w) in parts {
                    c += out[p].center * w;
                    r += out[p].radius * w;
                }
                Sphere::new(c, r)
            }
        };
        out.push(s);
    }
}

impl PosedSphereMesh {
    /// Pose a template.
    pub fn new(template: &SphereMeshTemplate, pose: &Pose) -> Self {
        let mut p = Self::default();
        p.update(template, pose);
        p
    }

    /// Re-pose in place; allocates only on the first call.
    pub fn update(&mut self, template: &SphereMeshTemplate, pose: &Pose) {
        self.skeleton.update(&template.skeleton, pose);
        place_spheres_into(&template.spheres, &self.skeleton.globals, &mut self.spheres);
    }

    /// Visit `(d, ∂c_i/∂θ_d)` for the center of sphere `i` (blends sum their parts' columns).
    pub fn for_each_center_column(
        &self,
        template: &SphereMeshTemplate,
        i: usize,
        f: &mut dyn FnMut(usize, Vector3<f64>),
    ) {
        match &template.spheres[i].attachment {
            Attachment::Bone { bone, .. } => {
                let c = self.spheres[i].center;
                self.skeleton
                    .for_each_column(&template.skeleton, *bone, &c, &mut *f);
            }
            Attachment::Blend { parts } => {
                for &(p, w) in parts {
                    self.for_each_center_column(template, p, &mut |d, col| f(d, col * w));
                }
            }
        }
    }

    /// Visit `(d, ∂q/∂θ_d)` for a footpoint `q = Σ w_i c_i + (Σ w_i r_i)·n` given by its spheres
    /// and barycentric weights (a [`crate::query::Projection`]): the weighted sum of the sphere
    /// centers' columns, with `n` held fixed. The residual `n·(p − q)` of the d2m term (Eq. 3.4)
    /// then has the exact derivative `−n·∂q/∂θ` (the change of `n` is orthogonal to `p − q`), also
    /// for elements whose spheres ride on different bones (membranes, the thumb web).
    pub fn for_each_footpoint_column(
        &self,
        template: &SphereMeshTemplate,
        spheres: &[u32; 3],
        weights: &[f64; 3],
        f: &mut dyn FnMut(usize, Vector3<f64>),
    ) {
        for (&s, &w) in spheres.iter().zip(weights) {
            if w != 0.0 {
                self.for_each_center_column(template, s as usize, &mut |d, col| f(d, col * w));
            }
        }
    }

    /// The 21 keypoints of DESIGN.md in the camera frame: joints are bone origins (rotation
    /// centers); a tip is the tip sphere's center plus its radius along the bone's +y axis.
    pub fn keypoints(&self, template: &SphereMeshTemplate) -> [Vector3<f64>; NUM_KEYPOINTS] {
        let mut out = [Vector3::zeros(); NUM_KEYPOINTS];
        for (k, def) in template.keypoints.iter().enumerate().take(NUM_KEYPOINTS) {
            out[k] = match *def {
                KeypointDef::Joint { bone } => self.skeleton.globals[bone].translation,
                KeypointDef::Tip { bone, sphere } => {
                    let dir = self.skeleton.globals[bone].rotation.column(1).into_owned();
                    let s = &self.spheres[sphere];
                    s.center + dir * s.radius
                }
            };
        }
        out
    }
}
