//! Points attached to the kinematic chain (the vertices `k ∈ 𝒦` of thesis Eq. 2.9, Fig. 4.10).

use nalgebra::Vector3;

use crate::cylinder::CylinderModel;
use crate::keypoints::KeypointDef;
use crate::kinematics::{PosedSkeleton, Skeleton};
use crate::spheremesh::{Attachment, SphereMeshTemplate};

/// A point rigidly attached to a bone: `local` in the bone frame.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct KinematicPoint {
    /// The bone.
    pub bone: usize,
    /// Position in the bone frame (mm).
    pub local: Vector3<f64>,
}

impl KinematicPoint {
    /// Its world position under a posed skeleton.
    #[inline]
    pub fn position(&self, posed: &PosedSkeleton) -> Vector3<f64> {
        posed.point(self.bone, &self.local)
    }
}

/// The bone origins of a skeleton: the root and every bone whose rest translation is not zero
/// (a bone sitting on its parent's origin would duplicate it).
fn origins(skeleton: &Skeleton) -> Vec<KinematicPoint> {
    skeleton
        .bones()
        .iter()
        .enumerate()
        .filter(|(i, b)| *i == 0 || b.rest.translation.norm() > 1e-9)
        .map(|(bone, _)| KinematicPoint {
            bone,
            local: Vector3::zeros(),
        })
        .collect()
}

fn leaves(skeleton: &Skeleton) -> impl Iterator<Item = usize> + '_ {
    (0..skeleton.bones().len()).filter(|&b| skeleton.children(b).next().is_none())
}

/// Generic kinematic points: the bone origins plus, for every leaf bone, a tip at
/// `(0, leaf_length, 0)` in its frame (bones point along local +y in both models).
pub fn skeleton_points(skeleton: &Skeleton, leaf_length: f64) -> Vec<KinematicPoint> {
    let mut pts = origins(skeleton);
    pts.extend(leaves(skeleton).map(|bone| KinematicPoint {
        bone,
        local: Vector3::new(0.0, leaf_length, 0.0),
    }));
    pts
}

/// Kinematic points of a sphere-mesh template: the bone origins plus, per leaf bone, its
/// fingertip sphere center (from the template's tip keypoints) or else the bone-attached sphere
/// farthest from the bone origin (e.g. the wrist).
pub fn sphere_mesh_points(template: &SphereMeshTemplate) -> Vec<KinematicPoint> {
    let sk = &template.skeleton;
    let mut pts = origins(sk);
    for leaf in leaves(sk) {
        let tip = template.keypoints.iter().find_map(|k| match *k {
            KeypointDef::Tip { bone, sphere } if bone == leaf => {
                match &template.spheres.get(sphere)?.attachment {
                    Attachment::Bone { bone, offset } if *bone == leaf => Some(*offset),
                    _ => None,
                }
            }
            _ => None,
        });
        let local = tip.or_else(|| {
            template
                .spheres
                .iter()
                .filter_map(|s| match &s.attachment {
                    Attachment::Bone { bone, offset } if *bone == leaf => Some(*offset),
                    _ => None,
                })
                .max_by(|a, b| a.norm().total_cmp(&b.norm()))
        });
        if let Some(local) = local {
            pts.push(KinematicPoint { bone: leaf, local });
        }
    }
    pts
}

/// Kinematic points of a cylinder model (htrack: "every non-structural joint plus its first
/// child", ANCHOR-FACTS §5.5): the bone origins plus the axis end point of every segment on a
/// leaf bone.
pub fn cylinder_points(model: &CylinderModel) -> Vec<KinematicPoint> {
    let sk = &model.skeleton;
    let mut pts = origins(sk);
    for leaf in leaves(sk) {
        if let Some(s) = model.segments.iter().find(|s| s.bone == leaf) {
            pts.push(KinematicPoint {
                bone: leaf,
                local: s.end_local(),
            });
        }
    }
    pts
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cylinder::default_right_hand_cylinders;
    use crate::spheremesh::default_right_hand;

    #[test]
    fn default_models_have_tips_on_every_leaf() {
        let t = default_right_hand();
        let pts = sphere_mesh_points(&t);
        let n_leaves = leaves(&t.skeleton).count();
        assert_eq!(n_leaves, 6, "5 digit tips + wrist");
        assert_eq!(
            pts.iter().filter(|p| p.local.norm() > 0.0).count(),
            n_leaves
        );
        let c = default_right_hand_cylinders();
        let pts = cylinder_points(&c);
        assert_eq!(
            pts.iter().filter(|p| p.local.norm() > 0.0).count(),
            leaves(&c.skeleton).count()
        );
        assert!(pts.len() >= 16 + 5);
    }
}
