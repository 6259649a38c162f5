//! Sensor frames rendered from a posed template, for tests and benchmarks that must not depend
//! on the `datasets` generator: the visible surface ray cast from the sensor camera (§3.3.2),
//! back-projected and subsampled, with the silhouette's distance transform.

use hand_model::kinematics::Pose;
use hand_model::render::render_depth;
use hand_model::spheremesh::{PosedSphereMesh, SphereMeshTemplate};
use sensor_io::dt::DistanceTransform;
use sensor_io::preprocess::{HandSegment, PreprocessedFrame};
use sensor_io::{Camera, DepthImage, Mask};

use crate::context::intrinsics;

/// A complete point cloud of `template` at `pose` (a noise-free multi-view scan, thesis §3.4):
/// per element, random points on the spheres interpolated between its spheres (centers and radii
/// blended by random weights) in random directions, kept when they lie on the model's outer
/// surface (`|φ| ≤ 0.01 mm`: the surface is the envelope of those spheres, every other point
/// of them is inside). About `n` points, spread over the elements by their surface area.
pub fn surface_cloud(
    template: &SphereMeshTemplate,
    pose: &Pose,
    n: usize,
    seed: u64,
) -> Result<Vec<nalgebra::Vector3<f64>>, hand_model::query::GeometryError> {
    use rand::{Rng, SeedableRng};
    let posed = PosedSphereMesh::new(template, pose);
    let elements: Vec<_> = template.elements.iter().map(|e| e.element).collect();
    let geometry = hand_model::query::SphereMeshGeometry::new(&posed.spheres, &elements)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(n);
    // Rejection rate is high where elements overlap; a bounded number of tries keeps it finite.
    for _ in 0..40 * n {
        if out.len() >= n {
            break;
        }
        let e = elements[rng.random_range(0..elements.len())].spheres();
        let mut w: Vec<f64> = e.iter().map(|_| rng.random_range(0.0..1.0)).collect();
        let total: f64 = w.iter().sum::<f64>().max(1e-12);
        w.iter_mut().for_each(|x| *x /= total);
        let (mut c, mut r) = (nalgebra::Vector3::zeros(), 0.0);
        for (&k, wk) in e.iter().zip(&w) {
            c += posed.spheres[k as usize].center * *wk;
            r += posed.spheres[k as usize].radius * *wk;
        }
        let u = nalgebra::Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        let Some(u) = u.try_normalize(1e-6) else {
            continue;
        };
        let p = c + u * r;
        if geometry.phi(&p).is_some_and(|phi| phi.abs() <= 0.01) {
            out.push(p);
        }
    }
    Ok(out)
}

/// The frame the camera sees of `template` at `pose`: at most `max_points` points spread
/// evenly over the rendered pixels (all of them when fewer) with their pixel indices, the camera,
/// the depth image (mm, rounded), the silhouette as the hand's segment and its distance
/// transform. An error when the camera is invalid.
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
    let pixels = hits.iter().step_by(step).map(|&k| k as u32).collect();
    let mut mask = Mask::zeros(camera.width, camera.height);
    for &k in &hits {
        mask.data[k] = 1;
    }
    let mut dt = DistanceTransform::default();
    dt.compute(&mask);
    let depth = DepthImage {
        width: camera.width,
        height: camera.height,
        data: r
            .depth
            .iter()
            .map(|&z| z.round().clamp(0.0, 65535.0) as u16)
            .collect(),
    };
    Ok(PreprocessedFrame {
        points,
        pixels,
        camera: Some(camera.clone()),
        dt,
        depth,
        hand: HandSegment {
            count: hits.len(),
            mask,
            ..HandSegment::default()
        },
        ..PreprocessedFrame::default()
    })
}

/// `exact` (a [`rendered_frame`]) with Gaussian depth noise of `sigma` mm on every pixel of
/// its depth image, its points moved along their rays to the noisy depths, so that the
/// trackers measure σ̂ ≈ `sigma`; deterministic for a given `seed`. A frame without a camera
/// is returned as it is.
pub fn noisy_frame(exact: &PreprocessedFrame, sigma: f64, seed: u64) -> PreprocessedFrame {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let Some(camera) = exact.camera.clone() else {
        return exact.clone();
    };
    let mut frame = exact.clone();
    for d in frame.depth.data.iter_mut().filter(|d| **d != 0) {
        let (u1, u2): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random());
        let n = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos() * sigma;
        *d = (f64::from(*d) + n).round().max(1.0) as u16;
    }
    let w = camera.width;
    for (p, &k) in frame.points.iter_mut().zip(&frame.pixels) {
        if let Some(&z) = frame.depth.data.get(k as usize) {
            *p = camera.backproject(f64::from(k % w), f64::from(k / w), f64::from(z));
        }
    }
    frame
}

/// A synthetic calibration problem (issue 6): a subject whose honline β is the default
/// template's perturbed by up to ±`perturbation` (relative), `n` depth frames of it in random
/// poses (even frames nearly straight, odd ones bent: the bends make the phalanx lengths
/// observable), and initial poses 3 mm off the truth (as if tracked with a wrong template).
pub struct CalibrationScene {
    /// The subject's true template.
    pub truth: SphereMeshTemplate,
    /// The true pose of every frame.
    pub poses: Vec<Pose>,
    /// The frames, as the sensor sees them.
    pub frames: Vec<crate::calibration::CalibrationFrame>,
    /// The initial poses handed to the calibration.
    pub initial: Vec<Pose>,
}

impl CalibrationScene {
    /// Build the scene from `seed` with frames of at most `points` points seen by `camera`.
    /// Errors come from the template (an invalid perturbed shape) or the camera.
    pub fn new(
        base: &SphereMeshTemplate,
        seed: u64,
        n: usize,
        points: usize,
        perturbation: f64,
        camera: &Camera,
    ) -> hand_model::Result<Self> {
        use rand::{Rng, SeedableRng};
        let basis = hand_model::spheremesh::ShapeBasis::honline(base)?;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let beta: Vec<f64> = basis
            .template_values()
            .iter()
            .map(|v| v * (1.0 + rng.random_range(-perturbation..perturbation)))
            .collect();
        let truth = basis.apply(base, &beta)?;
        Self::with_rng(truth, &mut rng, n, points, camera)
    }

    /// The scene of a given subject `truth` (frames and poses drawn from `seed`).
    pub fn from_truth(
        truth: SphereMeshTemplate,
        seed: u64,
        n: usize,
        points: usize,
        camera: &Camera,
    ) -> hand_model::Result<Self> {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        Self::with_rng(truth, &mut rng, n, points, camera)
    }

    fn with_rng(
        truth: SphereMeshTemplate,
        rng: &mut rand_chacha::ChaCha8Rng,
        n: usize,
        points: usize,
        camera: &Camera,
    ) -> hand_model::Result<Self> {
        use rand::Rng;
        let sk = &truth.skeleton;
        let poses: Vec<Pose> = (0..n)
            .map(|k| {
                let mut p = Pose::zeros(sk);
                let mut set = |name: &str, v: f64| {
                    if let Some(i) = sk.dof_index(name) {
                        p.values[i] = v;
                    }
                };
                set("global_tz", 400.0);
                set("global_ty", 30.0);
                set("global_rx", rng.random_range(-0.5..0.5));
                set("global_ry", rng.random_range(-0.7..0.7));
                for d in sk.dofs() {
                    if d.name.contains("flex") && !d.name.starts_with("global") {
                        let v = if k % 2 == 0 {
                            rng.random_range(0.0..0.3)
                        } else {
                            rng.random_range(0.2..1.1)
                        };
                        set(&d.name, v);
                    }
                }
                p.clamp_to_limits(sk);
                p
            })
            .collect();
        let frames = poses
            .iter()
            .map(|p| {
                rendered_frame(&truth, p, camera, points)
                    .map(|f| crate::calibration::CalibrationFrame::depth(&f))
            })
            .collect::<hand_model::Result<Vec<_>>>()?;
        let initial = poses
            .iter()
            .map(|p| {
                let mut q = p.clone();
                q.values[0] += 3.0;
                q
            })
            .collect();
        Ok(Self {
            truth,
            poses,
            frames,
            initial,
        })
    }
}
