//! Forward kinematics and the skeleton Jacobian.

use nalgebra::{Matrix3, Vector3};

use super::{DofKind, Pose, Skeleton};
use crate::math::{axis_angle, euler_xyz_to_matrix, Rigid3};

/// A skeleton evaluated at a pose: global bone frames and, per DOF, its world axis and pivot.
///
/// Reusable: [`PosedSkeleton::update`] re-poses without allocating.
#[derive(Clone, Debug, Default)]
pub struct PosedSkeleton {
    /// Global (model → camera) transform of every bone.
    pub globals: Vec<Rigid3>,
    /// Per DOF: the world direction of its axis (translation direction for translations).
    pub dof_axis: Vec<Vector3<f64>>,
    /// Per DOF: a point on its rotation axis (the bone origin).
    pub dof_pivot: Vec<Vector3<f64>>,
    dof_translation: Vec<bool>,
}

impl PosedSkeleton {
    /// Pose a skeleton.
    pub fn new(skeleton: &Skeleton, pose: &Pose) -> Self {
        let mut p = Self::default();
        p.update(skeleton, pose);
        p
    }

    /// Re-pose in place (forward kinematics). Allocates only on the first call.
    ///
    /// A DOF's world axis is its bone-frame axis rotated by the frame it acts in: the parent's
    /// global frame times the rest frame times the rotations of the bone's earlier DOFs, which
    /// makes the Jacobian exact for multi-DOF joints (the originals used the bone's final frame).
    pub fn update(&mut self, skeleton: &Skeleton, pose: &Pose) {
        let nb = skeleton.bones().len();
        let nd = skeleton.num_dofs();
        assert_eq!(pose.values.len(), nd, "pose does not match the skeleton");
        self.globals.resize(nb, Rigid3::identity());
        self.dof_axis.resize(nd, Vector3::zeros());
        self.dof_pivot.resize(nd, Vector3::zeros());
        self.dof_translation.resize(nd, false);
        let dofs = skeleton.dofs();
        for (b, bone) in skeleton.bones().iter().enumerate() {
            let parent = match bone.parent {
                Some(p) => self.globals[p],
                None => Rigid3::identity(),
            };
            let mut frame = parent.compose(&bone.rest);
            let mut euler = [0.0; 3];
            let mut rot_dofs = [usize::MAX; 3];
            let mut k = 0;
            for &d in &bone.dofs {
                let dof = &dofs[d];
                match dof.kind {
                    DofKind::Translation => {
                        // Validation puts translations first on the root, so `frame` is still
                        // the parent∘rest frame here.
                        self.dof_axis[d] = frame.rotation * dof.axis;
                        self.dof_pivot[d] = frame.translation;
                        self.dof_translation[d] = true;
                        frame.translation += self.dof_axis[d] * pose.values[d];
                    }
                    DofKind::GlobalRotation => {
                        euler[k] = pose.values[d];
                        rot_dofs[k] = d;
                        k += 1;
                    }
                    DofKind::Rotation => {
                        self.dof_axis[d] = frame.rotation * dof.axis;
                        self.dof_pivot[d] = frame.translation;
                        self.dof_translation[d] = false;
                        frame = frame.rotated(&axis_angle(&dof.axis, pose.values[d]));
                    }
                }
            }
            if k == 3 {
                frame = frame.rotated(&euler_xyz_to_matrix(euler[0], euler[1], euler[2]));
                // Tangent-space columns: R ← R·exp(δ) turns about the body axes of the final frame.
                for (i, &d) in rot_dofs.iter().enumerate() {
                    self.dof_axis[d] = frame.rotation.column(i).into_owned();
                    self.dof_pivot[d] = frame.translation;
                    self.dof_translation[d] = false;
                }
            }
            self.globals[b] = frame;
        }
    }

    /// World position of a point given in the frame of `bone`.
    #[inline]
    pub fn point(&self, bone: usize, local: &Vector3<f64>) -> Vector3<f64> {
        self.globals[bone].transform_point(local)
    }

    /// Jacobian column `∂p/∂θ_d` of a world point `p` rigidly attached to a bone moved by DOF `d`.
    #[inline]
    pub fn column(&self, d: usize, p: &Vector3<f64>) -> Vector3<f64> {
        if self.dof_translation[d] {
            self.dof_axis[d]
        } else {
            self.dof_axis[d].cross(&(p - self.dof_pivot[d]))
        }
    }

    /// Visit the non-zero Jacobian columns `(d, ∂p/∂θ_d)` of a world point rigidly attached to
    /// `bone`; allocates nothing.
    #[inline]
    pub fn for_each_column(
        &self,
        skeleton: &Skeleton,
        bone: usize,
        p: &Vector3<f64>,
        mut f: impl FnMut(usize, Vector3<f64>),
    ) {
        for &d in skeleton.chain(bone) {
            f(d, self.column(d, p));
        }
    }

    /// The full 3×n skeleton Jacobian `∂p/∂θ` of a world point rigidly attached to `bone`, written
    /// column by column into `out` (length n; columns of DOFs outside the chain are zero).
    pub fn point_jacobian(
        &self,
        skeleton: &Skeleton,
        bone: usize,
        p: &Vector3<f64>,
        out: &mut [Vector3<f64>],
    ) {
        assert_eq!(
            out.len(),
            skeleton.num_dofs(),
            "output has the wrong number of columns"
        );
        out.iter_mut().for_each(|c| *c = Vector3::zeros());
        self.for_each_column(skeleton, bone, p, |d, c| out[d] = c);
    }

    /// `∂p/∂t̄_b`: how a world point attached to `bone` moves when the rest translation of bone
    /// `b` changes (in b's parent frame); zero when `b` is not on the point's chain.
    pub fn rest_translation_jacobian(
        &self,
        skeleton: &Skeleton,
        b: usize,
        bone: usize,
    ) -> Matrix3<f64> {
        if !skeleton.is_ancestor_or_self(b, bone) {
            return Matrix3::zeros();
        }
        match skeleton.bones()[b].parent {
            Some(p) => self.globals[p].rotation,
            None => Matrix3::identity(),
        }
    }
}
