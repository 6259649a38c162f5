//! Synthetic sensor data for tests and benchmarks: the point cloud `𝒳_s` (thesis §2.3.1) a
//! depth camera would see of a posed cylinder model, made by ray marching.

use hand_model::cylinder::CylinderModel;
use hand_model::kinematics::PosedSkeleton;
use hand_model::render::Intrinsics;
use nalgebra::Vector3;

/// Whether a camera-frame point lies strictly inside some segment of the posed model.
fn inside(model: &CylinderModel, posed: &PosedSkeleton, p: &Vector3<f64>) -> bool {
    model.segments.iter().any(|s| {
        posed.globals.get(s.bone).is_some_and(|g| {
            let local = g.rotation.transpose() * (p - g.translation);
            s.contains_local_point(&local)
        })
    })
}

/// The first visible surface point of the posed model along every `stride`-th pixel ray of
/// `camera` (camera frame, mm): the depth map of the model as a point cloud `𝒳_s`, every point
/// on the front-facing visible surface (§2.3.1).
///
/// Each ray is marched in steps of `step` mm through the depth range of the model's bounding
/// box; the first sample inside a segment is refined by bisection to 1e-9 mm. Parts thinner
/// than `step` along a ray can be missed. Returns no points for a non-finite pose, a
/// non-positive or non-finite `step`, a zero `stride`, or a model not entirely in front of the
/// camera.
pub fn visible_surface_points(
    model: &CylinderModel,
    posed: &PosedSkeleton,
    camera: &Intrinsics,
    stride: u32,
    step: f64,
) -> Vec<Vector3<f64>> {
    let mut out = Vec::new();
    if stride == 0 || !(step.is_finite() && step > 0.0) || camera.validate().is_err() {
        return out;
    }
    // Bounding box of the segments (axis end points padded by the largest radius).
    let mut lo = Vector3::repeat(f64::INFINITY);
    let mut hi = Vector3::repeat(f64::NEG_INFINITY);
    let mut pad = 0.0f64;
    for (i, s) in model.segments.iter().enumerate() {
        pad = pad.max(s.r1.max(s.r2).max(s.r1y).max(s.r2y));
        for p in [model.segment_start(posed, i), model.segment_end(posed, i)] {
            let Some(p) = p.filter(|p| p.iter().all(|v| v.is_finite())) else {
                return out;
            };
            lo = lo.inf(&p);
            hi = hi.sup(&p);
        }
    }
    lo -= Vector3::repeat(pad + step);
    hi += Vector3::repeat(pad + step);
    if !(lo.iter().chain(hi.iter()).all(|v| v.is_finite()) && lo.z > 0.0) {
        return out;
    }
    // Pixel range: project the box corners.
    let (mut umin, mut umax, mut vmin, mut vmax) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for k in 0..8 {
        let c = Vector3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        );
        let [u, v] = camera.project(&c);
        umin = umin.min(u);
        umax = umax.max(u);
        vmin = vmin.min(v);
        vmax = vmax.max(v);
    }
    let clamp = |x: f64, n: u32| x.clamp(0.0, f64::from(n.saturating_sub(1))) as u32;
    let (u0, u1) = (
        clamp(umin.floor(), camera.width),
        clamp(umax.ceil(), camera.width),
    );
    let (v0, v1) = (
        clamp(vmin.floor(), camera.height),
        clamp(vmax.ceil(), camera.height),
    );
    for v in (v0..=v1).step_by(stride as usize) {
        for u in (u0..=u1).step_by(stride as usize) {
            let ray = camera.pixel_ray(f64::from(u), f64::from(v));
            if ray.dir.z <= 0.0 {
                continue;
            }
            let (t0, t1) = (lo.z / ray.dir.z, hi.z / ray.dir.z);
            let mut prev = t0;
            let mut t = t0;
            while t <= t1 {
                if inside(model, posed, &ray.at(t)) {
                    // Bisect (prev outside, t inside) down to the surface.
                    let (mut a, mut b) = (prev, t);
                    while b - a > 1e-9 {
                        let m = 0.5 * (a + b);
                        if inside(model, posed, &ray.at(m)) {
                            b = m;
                        } else {
                            a = m;
                        }
                    }
                    out.push(ray.at(a));
                    break;
                }
                prev = t;
                t += step;
            }
        }
    }
    out
}

/// A 320×240 pinhole camera (fx = fy = 240, centered): the sensor of the tests and benchmarks.
pub fn qvga_camera() -> Intrinsics {
    Intrinsics {
        fx: 240.0,
        fy: 240.0,
        cx: 160.0,
        cy: 120.0,
        width: 320,
        height: 240,
    }
}

/// An upright right hand (fingers toward image −y, palm to the camera) 40 cm from the camera,
/// fingers slightly bent: the reference pose of the tests and benchmarks. DOFs the model lacks
/// are an error.
pub fn upright_pose(model: &CylinderModel) -> hand_model::Result<hand_model::kinematics::Pose> {
    hand_model::kinematics::Pose::from_named(
        &model.skeleton,
        [
            ("global_ty", 40.0),
            ("global_tz", 400.0),
            ("global_rz", std::f64::consts::PI - 0.1),
            ("global_rx", 0.15),
            ("index_mcp_flex", 0.3),
            ("middle_pip_flex", 0.4),
            ("ring_mcp_flex", 0.5),
            ("pinky_mcp_flex", 0.4),
            ("thumb_mcp_flex", 0.3),
        ],
    )
}
