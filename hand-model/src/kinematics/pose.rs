//! The pose vector θ and its manifold update.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::{DofKind, Skeleton};
use crate::error::{ModelError, Result};
use crate::math::{euler_xyz_to_matrix, exp_so3, matrix_to_euler_xyz};

/// The pose vector θ, one value per DOF of a [`Skeleton`] (mm for translations, rad otherwise).
///
/// The three global rotation values are XYZ Euler angles (`R = Rx·Ry·Rz`, as in the originals);
/// solvers never step them additively but through [`Pose::retract`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Pose {
    /// The values, in [`Skeleton::dofs`] order.
    pub values: Vec<f64>,
}

impl Pose {
    /// The rest pose (all zeros).
    pub fn zeros(skeleton: &Skeleton) -> Self {
        Self {
            values: vec![0.0; skeleton.num_dofs()],
        }
    }

    /// A pose from values, checked for length and finiteness.
    pub fn from_values(skeleton: &Skeleton, values: Vec<f64>) -> Result<Self> {
        if values.len() != skeleton.num_dofs() {
            return Err(ModelError::InvalidArgument {
                name: "pose",
                reason: format!("{} values for {} DOFs", values.len(), skeleton.num_dofs()),
            });
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(ModelError::InvalidArgument {
                name: "pose",
                reason: format!("value {i} (`{}`) is not finite", skeleton.dofs()[i].name),
            });
        }
        Ok(Self { values })
    }

    /// Set a DOF by name; unknown names are an error.
    pub fn set(&mut self, skeleton: &Skeleton, name: &str, value: f64) -> Result<()> {
        let i = skeleton
            .dof_index(name)
            .ok_or_else(|| ModelError::InvalidArgument {
                name: "pose",
                reason: format!("unknown DOF `{name}`"),
            })?;
        if !value.is_finite() {
            return Err(ModelError::InvalidArgument {
                name: "pose",
                reason: format!("`{name}` is not finite"),
            });
        }
        self.values[i] = value;
        Ok(())
    }

    /// A pose from `{dof name: value}` pairs (the pose object of DESIGN.md's track and
    /// ground-truth files); DOFs not named stay 0, unknown names and non-finite values are refused.
    pub fn from_named<'a>(
        skeleton: &Skeleton,
        named: impl IntoIterator<Item = (&'a str, f64)>,
    ) -> Result<Self> {
        let mut pose = Pose::zeros(skeleton);
        for (name, value) in named {
            pose.set(skeleton, name, value)?;
        }
        Ok(pose)
    }

    /// `(dof name, value)` pairs in pose-vector order.
    pub fn named<'a>(
        &'a self,
        skeleton: &'a Skeleton,
    ) -> impl Iterator<Item = (&'a str, f64)> + 'a {
        skeleton
            .dofs()
            .iter()
            .map(|d| d.name.as_str())
            .zip(self.values.iter().copied())
    }

    /// Global translation (mm).
    pub fn translation(&self, skeleton: &Skeleton) -> Vector3<f64> {
        let mut t = Vector3::zeros();
        for (d, dof) in skeleton.dofs().iter().enumerate() {
            if dof.kind == DofKind::Translation {
                t += dof.axis * self.values[d];
            }
        }
        t
    }

    /// `θ ⊞ δ`: translations and joint angles add, the global rotation is updated
    /// multiplicatively, `R ← R·exp([δ_r]×)` (DESIGN.md), so no Euler singularity can stall a
    /// solver. `delta` is in the tangent space, with the same layout as θ.
    pub fn retract(&self, skeleton: &Skeleton, delta: &[f64]) -> Pose {
        let mut out = self.clone();
        out.retract_in_place(skeleton, delta);
        out
    }

    /// In-place form of [`Pose::retract`]; allocates nothing.
    pub fn retract_in_place(&mut self, skeleton: &Skeleton, delta: &[f64]) {
        assert_eq!(delta.len(), self.values.len(), "delta has the wrong length");
        let mut rot_dofs = [usize::MAX; 3];
        let mut k = 0;
        for (d, dof) in skeleton.dofs().iter().enumerate() {
            if dof.kind == DofKind::GlobalRotation {
                rot_dofs[k] = d;
                k += 1;
            } else {
                self.values[d] += delta[d];
            }
        }
        if k == 3 {
            let [a, b, c] = rot_dofs.map(|d| self.values[d]);
            let omega = Vector3::new(delta[rot_dofs[0]], delta[rot_dofs[1]], delta[rot_dofs[2]]);
            let r = euler_xyz_to_matrix(a, b, c) * exp_so3(&omega);
            let e = matrix_to_euler_xyz(&r);
            for (i, &d) in rot_dofs.iter().enumerate() {
                self.values[d] = e[i];
            }
        }
    }

    /// Clamp joint DOFs into their limits (global DOFs are unbounded).
    pub fn clamp_to_limits(&mut self, skeleton: &Skeleton) {
        for (v, dof) in self.values.iter_mut().zip(skeleton.dofs()) {
            if let Some([lo, hi]) = dof.limits {
                *v = v.clamp(lo, hi);
            }
        }
    }
}
