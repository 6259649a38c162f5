//! Sensor frames rendered from a posed template, for tests and benchmarks that must not depend
//! on the `datasets` generator: the visible surface ray cast from the sensor camera (§3.3.2),
//! back-projected and subsampled, with the silhouette's distance transform.

use hand_model::kinematics::Pose;
use hand_model::render::render_depth;
use hand_model::spheremesh::{PosedSphereMesh, SphereMeshTemplate};
use sensor_io::dt::DistanceTransform;
use sensor_io::preprocess::PreprocessedFrame;
use sensor_io::{Camera, Mask};

use crate::context::intrinsics;

/// The frame the camera sees of `template` at `pose`: at most `max_points` points spread
/// evenly over the rendered pixels (all of them when fewer), the camera, and the distance
/// transform of the rendered silhouette. An error when the camera is invalid.
pub fn rendered_frame(
    template: &SphereMeshTemplate,
    pose: &Pose,
    camera: &Camera,
    max_points: usize,
) -> hand_model::Result<PreprocessedFrame> {
    let posed = PosedSphereMesh::new(template, pose);
    let elements: Vec<_> = template.elements.iter().map(|e| e.element).collect();
    let r = render_depth(&intrinsics(camera), &posed.spheres, &elements)?;
    let hits: Vec<usize> = (0..r.depth.len()).filter(|&k| r.depth[k] > 0.0).collect();
    let step = hits.len().div_ceil(max_points.max(1)).max(1);
    let w = camera.width as usize;
    let points = hits
        .iter()
        .step_by(step)
        .map(|&k| camera.backproject((k % w) as f64, (k / w) as f64, f64::from(r.depth[k])))
        .collect();
    let mut mask = Mask::zeros(camera.width, camera.height);
    for &k in &hits {
        mask.data[k] = 1;
    }
    let mut dt = DistanceTransform::default();
    dt.compute(&mask);
    Ok(PreprocessedFrame {
        points,
        camera: Some(camera.clone()),
        dt,
        ..PreprocessedFrame::default()
    })
}
