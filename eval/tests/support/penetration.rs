//! How deep the finger pills of a template interpenetrate at a pose: the physical validity of
//! a ground truth (a real hand's fingers do not pass through each other).

use std::collections::BTreeMap;

use hand_model::kinematics::Pose;
use hand_model::shape::Element;
use hand_model::spheremesh::{PosedSphereMesh, SphereMeshTemplate};
use hmodel_spheremesh::terms::{pill_contact, Collision, CollisionParams};

/// The deepest interpenetration (mm) beyond the rest overlap over the collision pairs of the
/// sphere-mesh tracker's collision term, at the pose given by DOF name (missing DOFs 0).
pub fn max_penetration(t: &SphereMeshTemplate, pose: &BTreeMap<String, f64>) -> f64 {
    let values = t
        .skeleton
        .dofs()
        .iter()
        .map(|d| pose.get(&d.name).copied().unwrap_or(0.0))
        .collect();
    let posed = PosedSphereMesh::new(t, &Pose { values });
    let pill = |e: usize| match t.elements[e].element {
        Element::Pill(s) => Some(s.map(|i| posed.spheres[i as usize])),
        Element::Wedge(_) => None,
    };
    Collision::new(t, CollisionParams::default())
        .pairs()
        .iter()
        .filter_map(|p| {
            let (a, b) = (pill(p.a)?, pill(p.b)?);
            let c = pill_contact(
                [a[0].center, a[1].center],
                [a[0].radius, a[1].radius],
                [b[0].center, b[1].center],
                [b[0].radius, b[1].radius],
            )?;
            Some(c.penetration - p.rest_overlap)
        })
        .fold(0.0, f64::max)
}
