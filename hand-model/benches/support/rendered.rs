//! Realistic input for the model-wide queries, shared by `benches/projection.rs` and
//! `tests/query_seeded.rs` (included with `#[path]`): the default right hand at a few natural
//! poses, 400 mm in front of a QVGA depth camera (fx = fy = 287 px, principal point at the image
//! center, OpenCV frame: x right, y down, looking along +z), rendered with the project's depth
//! renderer and back-projected pixel by pixel, as a tracker sees a frame. Unlike points sampled
//! around the surface, these lie on its visible side, so few plain footpoints are back-facing:
//! only near silhouettes, creases, and behind the surface where sensor noise pushes them.
// Each including target uses a different part.
#![allow(dead_code)]

use hand_model::kinematics::Pose;
use hand_model::render::{render_depth, Intrinsics, NO_ELEMENT};
use hand_model::shape::{Element, Sphere};
use hand_model::spheremesh::{default_right_hand, PosedSphereMesh, SphereMeshTemplate};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The camera of the rendered frames (QVGA, a PrimeSense/RealSense-like focal length).
pub const CAMERA: Intrinsics = Intrinsics {
    fx: 287.0,
    fy: 287.0,
    cx: 160.0,
    cy: 120.0,
    width: 320,
    height: 240,
};

/// Points kept per frame (the thesis' ~2500 sensor points per frame, §3.3.1).
pub const FRAME_POINTS: usize = 2500;

/// One rendered frame of the hand.
pub struct RenderedScene {
    /// Pose label.
    pub name: &'static str,
    /// Spheres of the posed hand (camera frame, mm).
    pub spheres: Vec<Sphere>,
    /// The hand's elements.
    pub elements: Vec<Element>,
    /// The same hand at a slightly different pose (a previous solver iteration): where a
    /// tracker's seeds come from.
    pub previous: Vec<Sphere>,
    /// Back-projected pixels that hit the hand, evenly subsampled to [`FRAME_POINTS`].
    pub points: Vec<Vector3<f64>>,
    /// `points` moved along their camera rays by noise of σ = 1 mm (at most ±3 mm).
    pub noisy: Vec<Vector3<f64>>,
}

/// The poses, as named DOF values on top of "400 mm in front of the camera, fingers up, palm
/// toward the camera" (the model's palm faces −z and its fingers point along +y, so a half turn
/// about z puts the fingers up in the image). Rotations of 30–60° about x and y make fingers
/// occlude each other and the palm.
const POSES: [(&str, &[(&str, f64)]); 4] = [
    ("rest", &[]),
    (
        "fingers_bent",
        &[
            ("global_rx", 0.3),
            ("thumb_cmc_flex", 0.3),
            ("index_mcp_flex", 0.9),
            ("index_pip_flex", 1.1),
            ("middle_mcp_flex", 0.6),
            ("middle_pip_flex", 0.8),
            ("ring_pip_flex", 0.5),
        ],
    ),
    (
        "tilted_x_45",
        &[
            ("global_rx", 0.8),
            ("index_mcp_flex", 0.3),
            ("middle_mcp_flex", 0.4),
            ("middle_pip_flex", 0.5),
            ("ring_mcp_flex", 0.5),
            ("ring_pip_flex", 0.6),
            ("pinky_mcp_flex", 0.6),
            ("pinky_pip_flex", 0.7),
        ],
    ),
    (
        "turned_y_55",
        &[
            ("global_ry", 0.95),
            ("global_rx", 0.2),
            ("thumb_cmc_abd", 0.3),
            ("index_mcp_flex", 0.4),
            ("middle_mcp_flex", 0.5),
            ("middle_pip_flex", 0.4),
            ("ring_mcp_flex", 0.7),
            ("pinky_mcp_flex", 0.8),
        ],
    ),
];

/// The same offsets for every pose: roughly one early solver iteration's change.
const PREVIOUS_OFFSETS: [(&str, f64); 5] = [
    ("global_tx", 1.5),
    ("global_tz", -2.0),
    ("global_rx", 0.03),
    ("index_mcp_flex", -0.05),
    ("middle_pip_flex", 0.05),
];

fn posed(t: &SphereMeshTemplate, named: &[(&str, f64)], offsets: &[(&str, f64)]) -> Vec<Sphere> {
    let mut pose = Pose::zeros(&t.skeleton);
    let base = [("global_tz", 400.0), ("global_rz", std::f64::consts::PI)];
    for &(name, v) in base.iter().chain(named).chain(offsets) {
        let i = t.skeleton.dof_index(name).expect("default DOF");
        pose.values[i] += v;
    }
    PosedSphereMesh::new(t, &pose).spheres
}

/// Every pose of [`POSES`] rendered and back-projected (deterministic).
pub fn rendered_scenes() -> Vec<RenderedScene> {
    let t = default_right_hand();
    let elements: Vec<Element> = t.elements.iter().map(|e| e.element).collect();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    POSES
        .iter()
        .map(|&(name, named)| {
            let spheres = posed(&t, named, &[]);
            let frame = render_depth(&CAMERA, &spheres, &elements).expect("valid hand");
            let hits: Vec<Vector3<f64>> = (0..frame.depth.len())
                .filter(|&k| frame.element[k] != NO_ELEMENT)
                .map(|k| {
                    let (u, v) = ((k % 320) as f64, (k / 320) as f64);
                    let z = f64::from(frame.depth[k]);
                    Vector3::new(
                        (u - CAMERA.cx) / CAMERA.fx * z,
                        (v - CAMERA.cy) / CAMERA.fy * z,
                        z,
                    )
                })
                .collect();
            let n = hits.len().min(FRAME_POINTS);
            let points: Vec<Vector3<f64>> = (0..n).map(|i| hits[i * hits.len() / n]).collect();
            let noisy = points
                .iter()
                .map(|p| {
                    // Irwin–Hall: the sum of three uniforms on [−1, 1] has σ = 1.
                    let noise: f64 = (0..3).map(|_| rng.random_range(-1.0..1.0)).sum();
                    p + p.normalize() * noise
                })
                .collect();
            RenderedScene {
                name,
                previous: posed(&t, named, &PREVIOUS_OFFSETS),
                spheres,
                elements: elements.clone(),
                points,
                noisy,
            }
        })
        .collect()
}
