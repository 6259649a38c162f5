//! The hand geometry of the projection benchmark and the model-level query tests, shared by
//! `benches/projection.rs` and `tests/query_*.rs` (included with `#[path]`): the default
//! right-hand template in a relaxed, slightly flexed pose, 400 mm in front of the camera with the
//! palm toward it (39 spheres, 31 elements).

use hand_model::kinematics::Pose;
use hand_model::shape::{Element, Sphere};
use hand_model::spheremesh::{default_right_hand, PosedSphereMesh};

/// The spheres and elements of the posed default hand (camera frame, mm).
pub fn hand_like_geometry() -> (Vec<Sphere>, Vec<Element>) {
    let t = default_right_hand();
    let mut pose = Pose::zeros(&t.skeleton);
    let named = [
        ("global_tz", 400.0),
        ("global_rz", std::f64::consts::PI),
        ("thumb_cmc_flex", 0.2),
        ("index_mcp_flex", 0.2),
        ("index_pip_flex", 0.3),
        ("middle_mcp_flex", 0.25),
        ("middle_pip_flex", 0.35),
        ("ring_mcp_flex", 0.3),
        ("ring_pip_flex", 0.4),
        ("pinky_mcp_flex", 0.35),
        ("pinky_pip_flex", 0.45),
    ];
    for (name, v) in named {
        pose.set(&t.skeleton, name, v).expect("default DOF");
    }
    let posed = PosedSphereMesh::new(&t, &pose);
    (
        posed.spheres,
        t.elements.iter().map(|e| e.element).collect(),
    )
}
