//! The bone tree, its rest frames and its degrees of freedom.

use std::path::Path;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::error::{ModelError, Result};
use crate::math::Rigid3;

/// What a degree of freedom moves.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DofKind {
    /// Global translation along a world axis (root bone only).
    Translation,
    /// Global rotation about a body axis of the root (root bone only). The three of them are
    /// stored as XYZ Euler angles and updated multiplicatively, see [`crate::kinematics::Pose::retract`].
    GlobalRotation,
    /// A joint rotation about an axis of the bone's own frame.
    Rotation,
}

/// One degree of freedom of the pose vector θ.
#[derive(Clone, Debug, PartialEq)]
pub struct Dof {
    /// Self-describing name written in every output file, e.g. `index_mcp_flex`.
    pub name: String,
    /// The bone it moves.
    pub bone: usize,
    /// What it moves.
    pub kind: DofKind,
    /// Unit axis: world axis for translations, body axis for global rotations, bone-frame axis
    /// for joint rotations.
    pub axis: Vector3<f64>,
    /// `[min, max]` joint limits (rad or mm); `None` when unbounded.
    pub limits: Option<[f64; 2]>,
}

/// One bone (a "phalange" in hmodel): a node of the kinematic tree.
#[derive(Clone, Debug, PartialEq)]
pub struct Bone {
    /// Unique name, e.g. `index_1`.
    pub name: String,
    /// Parent bone (`None` for the root); parents precede their children.
    pub parent: Option<usize>,
    /// Rest frame `T̄_k` relative to the parent (Eq. 3.7): the bone's local transform at θ = 0.
    pub rest: Rigid3,
    /// The DOFs of this bone, in the order their rotations post-multiply the rest frame.
    pub dofs: Vec<usize>,
}

/// A kinematic tree with named degrees of freedom.
///
/// The local transform of bone k is `T̄_k · T_k(θ)`, where `T_k` is the product of the bone's DOF
/// transforms in order; the global transform is the product along the chain to the root, so a
/// point `p̄` at rest maps to `p = Π_k T̄_k T_k T̄_k⁻¹ p̄` (Eq. 3.7) once expressed in the model frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Skeleton {
    bones: Vec<Bone>,
    dofs: Vec<Dof>,
    /// Per bone, the DOF indices of the bone and of all its ancestors.
    chains: Vec<Vec<usize>>,
    /// Per bone, whether each other bone is an ancestor-or-self (row-major, bones × bones).
    ancestry: Vec<bool>,
}

impl Skeleton {
    /// Build and validate a skeleton. `source` names the file the data came from (for errors).
    ///
    /// Rules: bone names unique and non-empty, exactly one root (bone 0), parents precede children,
    /// DOFs reference existing bones, axes are finite unit vectors, limits are ordered, global DOFs
    /// sit on the root (three translations then three rotations about x, y, z, or none at all).
    pub fn new(bones: Vec<Bone>, dofs: Vec<Dof>, source: &Path) -> Result<Self> {
        validate(&bones, &dofs, source)?;
        let n = bones.len();
        let mut chains: Vec<Vec<usize>> = Vec::with_capacity(n);
        let mut ancestry = vec![false; n * n];
        for (b, bone) in bones.iter().enumerate() {
            let mut chain = bone.dofs.clone();
            ancestry[b * n + b] = true;
            if let Some(p) = bone.parent {
                chain.extend_from_slice(&chains[p]);
                for a in 0..n {
                    if ancestry[p * n + a] {
                        ancestry[b * n + a] = true;
                    }
                }
            }
            chains.push(chain);
        }
        Ok(Self {
            bones,
            dofs,
            chains,
            ancestry,
        })
    }

    /// The bones, parents first.
    pub fn bones(&self) -> &[Bone] {
        &self.bones
    }

    /// The degrees of freedom, in pose-vector order.
    pub fn dofs(&self) -> &[Dof] {
        &self.dofs
    }

    /// Number of DOFs (length of θ).
    pub fn num_dofs(&self) -> usize {
        self.dofs.len()
    }

    /// The DOFs that move bone `bone` (its own and its ancestors').
    pub fn chain(&self, bone: usize) -> &[usize] {
        &self.chains[bone]
    }

    /// Whether `ancestor` is `bone` or one of its ancestors.
    pub fn is_ancestor_or_self(&self, ancestor: usize, bone: usize) -> bool {
        self.ancestry[bone * self.bones.len() + ancestor]
    }

    /// Index of the bone called `name`.
    pub fn bone_index(&self, name: &str) -> Option<usize> {
        self.bones.iter().position(|b| b.name == name)
    }

    /// Index of the DOF called `name`.
    pub fn dof_index(&self, name: &str) -> Option<usize> {
        self.dofs.iter().position(|d| d.name == name)
    }

    /// Children of a bone.
    pub fn children(&self, bone: usize) -> impl Iterator<Item = usize> + '_ {
        self.bones
            .iter()
            .enumerate()
            .filter(move |(_, b)| b.parent == Some(bone))
            .map(|(i, _)| i)
    }

    /// Replace the rest frame of a bone (used by calibration and shape parameters).
    pub fn set_rest(&mut self, bone: usize, rest: Rigid3) {
        self.bones[bone].rest = rest;
    }

    /// The global transforms of all bones at θ = 0 (the rest pose in the model frame).
    pub fn rest_globals(&self) -> Vec<Rigid3> {
        let mut g: Vec<Rigid3> = Vec::with_capacity(self.bones.len());
        for bone in &self.bones {
            let t = match bone.parent {
                Some(p) => g[p].compose(&bone.rest),
                None => bone.rest,
            };
            g.push(t);
        }
        g
    }
}

fn validate(bones: &[Bone], dofs: &[Dof], src: &Path) -> Result<()> {
    if bones.is_empty() {
        return Err(ModelError::field(src, "bones", None, "no bones"));
    }
    for (i, b) in bones.iter().enumerate() {
        if b.name.is_empty() {
            return Err(ModelError::field(src, "bones.name", Some(i), "empty name"));
        }
        if bones[..i].iter().any(|o| o.name == b.name) {
            return Err(ModelError::field(
                src,
                "bones.name",
                Some(i),
                format!("duplicate bone name `{}`", b.name),
            ));
        }
        match b.parent {
            None if i != 0 => {
                return Err(ModelError::field(
                    src,
                    "bones.parent",
                    Some(i),
                    "only bone 0 may be the root",
                ))
            }
            Some(_) if i == 0 => {
                return Err(ModelError::field(
                    src,
                    "bones.parent",
                    Some(0),
                    "bone 0 must be the root",
                ))
            }
            Some(p) if p >= i => {
                return Err(ModelError::field(
                    src,
                    "bones.parent",
                    Some(i),
                    format!("parent {p} must precede the bone (missing or out-of-order bone)"),
                ))
            }
            _ => {}
        }
        if !b.rest.is_finite() {
            return Err(ModelError::field(
                src,
                "bones.rest",
                Some(i),
                "non-finite rest frame",
            ));
        }
        let r = &b.rest.rotation;
        if (r.transpose() * r - nalgebra::Matrix3::identity()).norm() > 1e-4
            || r.determinant() < 0.0
        {
            return Err(ModelError::field(
                src,
                "bones.rest",
                Some(i),
                "rest rotation is not a rotation",
            ));
        }
        for &d in &b.dofs {
            if dofs.get(d).map(|dof| dof.bone) != Some(i) {
                return Err(ModelError::field(
                    src,
                    "bones.dofs",
                    Some(i),
                    format!("DOF {d} does not exist or belongs to another bone"),
                ));
            }
        }
    }
    let mut globals = Vec::new();
    for (i, d) in dofs.iter().enumerate() {
        if d.name.is_empty() || dofs[..i].iter().any(|o| o.name == d.name) {
            return Err(ModelError::field(
                src,
                "dofs.name",
                Some(i),
                format!("empty or duplicate name `{}`", d.name),
            ));
        }
        if d.bone >= bones.len() {
            return Err(ModelError::field(
                src,
                "dofs.bone",
                Some(i),
                format!("bone index {} out of range", d.bone),
            ));
        }
        if !bones[d.bone].dofs.contains(&i) {
            return Err(ModelError::field(
                src,
                "dofs.bone",
                Some(i),
                "DOF is not listed by its bone",
            ));
        }
        if !d.axis.iter().all(|x| x.is_finite()) || (d.axis.norm() - 1.0).abs() > 1e-6 {
            return Err(ModelError::field(
                src,
                "dofs.axis",
                Some(i),
                "axis must be a finite unit vector",
            ));
        }
        if let Some([lo, hi]) = d.limits {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                return Err(ModelError::field(
                    src,
                    "dofs.limits",
                    Some(i),
                    format!("invalid limits [{lo}, {hi}]"),
                ));
            }
        }
        if d.kind != DofKind::Rotation {
            if d.bone != 0 {
                return Err(ModelError::field(
                    src,
                    "dofs.kind",
                    Some(i),
                    "global DOFs must sit on the root bone",
                ));
            }
            globals.push((d.kind, d.axis));
        }
    }
    let expected = [
        (DofKind::Translation, Vector3::x()),
        (DofKind::Translation, Vector3::y()),
        (DofKind::Translation, Vector3::z()),
        (DofKind::GlobalRotation, Vector3::x()),
        (DofKind::GlobalRotation, Vector3::y()),
        (DofKind::GlobalRotation, Vector3::z()),
    ];
    let root_dofs: Vec<_> = bones[0]
        .dofs
        .iter()
        .map(|&d| (dofs[d].kind, dofs[d].axis))
        .collect();
    if !globals.is_empty() && root_dofs.as_slice() != expected.as_slice() {
        return Err(ModelError::field(
            src,
            "bones.dofs",
            Some(0),
            "the root must carry tx, ty, tz, rx, ry, rz (in that order) and nothing else",
        ));
    }
    Ok(())
}
