//! Tests of the Ch. 2 cylinder model: geometry queries, kinematics, templates and the htrack
//! `.calib` importer.

use std::path::Path;

use hand_model::cylinder::{
    default_right_hand_cylinders, load_htrack_calib, parse_htrack_calib, CylinderModel,
    CylinderPart, CylinderProjection, Segment, View, CYLINDER_DOF_NAMES, HTRACK_PALM_OFFSET,
    HTRACK_THETA_LAYOUT, NO_SEED,
};
use hand_model::keypoints::Handedness;
use hand_model::kinematics::{DofKind, Pose, PosedSkeleton};
use hand_model::math::{euler_xyz_to_matrix, Rigid3};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const CALIB: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../shared/reference/htrack-default.calib"
);

fn seg(length: f64, r1: f64, r2: f64, r1y: f64, r2y: f64) -> Segment {
    Segment {
        bone: 0,
        length,
        r1,
        r2,
        r1y,
        r2y,
    }
}

fn v3(rng: &mut ChaCha8Rng, lo: [f64; 3], hi: [f64; 3]) -> Vector3<f64> {
    Vector3::new(
        rng.random_range(lo[0]..hi[0]),
        rng.random_range(lo[1]..hi[1]),
        rng.random_range(lo[2]..hi[2]),
    )
}

/// Dense samples of a segment surface (the documented shape) and the sampling resolution: the
/// largest distance from a surface point to its nearest sample is below the returned bound.
fn sample_surface(s: &Segment, nt: usize, nphi: usize, npsi: usize) -> (Vec<Vector3<f64>>, f64) {
    let mut pts = Vec::with_capacity((nt + 1) * nphi + 2 * (npsi + 1) * nphi);
    let tau = std::f64::consts::TAU;
    for i in 0..=nt {
        let t = i as f64 / nt as f64;
        let (r, ry) = s.radii_at(t);
        for j in 0..nphi {
            let phi = tau * j as f64 / nphi as f64;
            pts.push(Vector3::new(r * phi.cos(), t * s.length, ry * phi.sin()));
        }
    }
    for k in 0..=npsi {
        let psi = std::f64::consts::FRAC_PI_2 * k as f64 / npsi as f64;
        for j in 0..nphi {
            let phi = tau * j as f64 / nphi as f64;
            let (sx, sz) = (psi.sin() * phi.cos(), psi.sin() * phi.sin());
            pts.push(Vector3::new(s.r1 * sx, -s.r1y * psi.cos(), s.r1y * sz));
            pts.push(Vector3::new(
                s.r2 * sx,
                s.length + s.r2y * psi.cos(),
                s.r2y * sz,
            ));
        }
    }
    let rmax = s.r1.max(s.r2).max(s.r1y).max(s.r2y);
    let arc = tau * rmax / nphi as f64;
    let axial = (s.length / nt as f64).max(std::f64::consts::FRAC_PI_2 * rmax / npsi as f64)
        + (s.r1 - s.r2).abs().max((s.r1y - s.r2y).abs()) / nt as f64;
    (pts, 0.5 * (arc * arc + axial * axial).sqrt())
}

fn brute_distance(samples: &[Vector3<f64>], p: &Vector3<f64>) -> f64 {
    samples
        .iter()
        .map(|s| (s - p).norm_squared())
        .fold(f64::INFINITY, f64::min)
        .sqrt()
}

fn test_shapes() -> Vec<(String, Segment)> {
    let mut v: Vec<(String, Segment)> = default_right_hand_cylinders()
        .segments
        .iter()
        .enumerate()
        .map(|(i, s)| (format!("default segment {i}"), Segment { bone: 0, ..*s }))
        .collect();
    v.push(("cylinder".into(), seg(25.0, 7.0, 7.0, 7.0, 7.0)));
    v.push(("tapered".into(), seg(20.0, 10.0, 3.0, 10.0, 3.0)));
    v.push(("inverse taper".into(), seg(20.0, 3.0, 10.0, 3.0, 10.0)));
    v.push((
        "elliptic, varying thickness".into(),
        seg(30.0, 12.0, 8.0, 4.0, 6.0),
    ));
    v.push((
        "end sphere swallows start".into(),
        seg(2.0, 1.0, 10.0, 1.0, 10.0),
    ));
    v
}

#[test]
fn projections_match_brute_force_sampling() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut worst_elliptic_ratio: f64 = 1.0;
    for (name, s) in test_shapes() {
        let (samples, delta) = sample_surface(&s, 240, 360, 90);
        let circular = s.is_circular();
        let rmax = s.r1.max(s.r2).max(s.r1y).max(s.r2y);
        let m = rmax + 8.0;
        for _ in 0..60 {
            let p = v3(&mut rng, [-m, -m, -m], [m, s.length + m, m]);
            let r = s.project_local_point(&p).expect("finite");
            let d = (p - r.point).norm();
            assert!(
                (d - r.distance.abs()).abs() < 1e-9,
                "{name}: |distance| is ‖p − q‖"
            );
            assert_eq!(
                r.distance < 0.0,
                s.contains_local_point(&p),
                "{name}: sign of the distance at {p:?}"
            );
            let brute = brute_distance(&samples, &p);
            // q lies on the surface, so it can never beat the true minimum.
            assert!(
                d >= brute - delta - 1e-9,
                "{name}: {d} < brute {brute} − {delta} at {p:?}"
            );
            if circular {
                // Exact closest point: at least as close as every sample.
                assert!(d <= brute + 1e-9, "{name}: {d} > brute {brute} at {p:?}");
                if d > 1e-6 {
                    let dir = (p - r.point) / r.distance;
                    assert!(
                        (dir - r.normal).norm() < 1e-7,
                        "{name}: normal ∥ p − q at {p:?}"
                    );
                }
            } else {
                worst_elliptic_ratio = worst_elliptic_ratio.max(d / brute.max(1e-9));
                // htrack's scaling approximation: unscaling x stretches distances by at most
                // max(k, 1/k) for the scaling ratios k of the segment.
                let ks = [s.r1y / s.r1, s.r2y / s.r2];
                let stretch = ks.iter().map(|k| k.max(1.0 / k)).fold(1.0, f64::max);
                assert!(
                    d <= stretch * (brute + delta),
                    "{name}: {d} vs brute {brute} at {p:?}"
                );
            }
            assert!((r.normal.norm() - 1.0).abs() < 1e-12);
        }
    }
    println!("worst elliptic distance / true distance: {worst_elliptic_ratio:.4}");
}

#[test]
fn circular_segments_match_parry_capsule() {
    use parry3d::math::Vector as PV;
    use parry3d::query::PointQuery;
    use parry3d::shape::Capsule;
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for (l, r) in [(30.0, 8.0), (12.99, 5.19), (0.5, 10.0), (40.0, 0.5)] {
        let s = seg(l, r, r, r, r);
        let cap = Capsule::new(
            PV::new(0.0, 0.0, 0.0),
            PV::new(0.0, l as f32, 0.0),
            r as f32,
        );
        let m = r + 10.0;
        for _ in 0..500 {
            let p = v3(&mut rng, [-m, -m, -m], [m, l + m, m]);
            let ours = s.project_local_point(&p).unwrap();
            let theirs =
                cap.project_local_point(PV::new(p.x as f32, p.y as f32, p.z as f32), false);
            let tq = Vector3::new(
                theirs.point.x as f64,
                theirs.point.y as f64,
                theirs.point.z as f64,
            );
            assert!(
                (ours.point - tq).norm() < 1e-3,
                "L={l} r={r} p={p:?}: {:?} vs {tq:?}",
                ours.point
            );
            if ours.distance.abs() > 1e-3 {
                assert_eq!(
                    ours.distance < 0.0,
                    theirs.is_inside,
                    "inside flag at {p:?}"
                );
            }
        }
    }
}

fn random_frame(rng: &mut ChaCha8Rng) -> Rigid3 {
    let e = v3(rng, [-3.0; 3], [3.0; 3]);
    Rigid3::new(
        euler_xyz_to_matrix(e.x, e.y, e.z),
        v3(rng, [-60.0, -60.0, 250.0], [60.0, 60.0, 500.0]),
    )
}

#[test]
fn degenerate_segments_never_give_nan() {
    let shapes = [
        seg(0.0, 5.0, 5.0, 5.0, 5.0),
        seg(0.0, 3.0, 6.0, 3.0, 6.0),
        seg(0.0, 6.0, 3.0, 2.0, 1.0),
        seg(20.0, 0.0, 0.0, 0.0, 0.0),
        seg(20.0, 0.0, 5.0, 0.0, 5.0),
        seg(20.0, 5.0, 0.0, 2.0, 0.0),
        seg(2.0, 1.0, 10.0, 1.0, 10.0),
        seg(2.0, 1.0, 10.0, 0.5, 3.0),
        seg(0.0, 0.0, 0.0, 0.0, 0.0),
    ];
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for s in shapes {
        s.validate(Path::new("<test>"), 0).unwrap();
        let mut queries = vec![
            Vector3::zeros(),
            s.end_local(),
            Vector3::new(0.0, s.length * 0.5, 0.0),
            Vector3::new(0.0, -3.0, 0.0),
            Vector3::new(0.0, s.length + 3.0, 0.0),
            Vector3::new(1e6, -1e6, 1e6),
            Vector3::new(s.r1, 0.0, 0.0),
            Vector3::new(0.0, 0.0, s.r2y),
        ];
        for _ in 0..300 {
            queries.push(v3(&mut rng, [-15.0; 3], [15.0, s.length + 15.0, 15.0]));
        }
        for p in &queries {
            let r = s
                .project_local_point(p)
                .unwrap_or_else(|| panic!("{s:?} {p:?}"));
            assert!(
                r.point.iter().chain(r.normal.iter()).all(|v| v.is_finite())
                    && r.distance.is_finite()
            );
            assert!((r.normal.norm() - 1.0).abs() < 1e-9, "{s:?} {p:?}");
            let frame = random_frame(&mut rng);
            let pw = frame.transform_point(p);
            for view in [View::Orthographic, View::Perspective] {
                let f = s
                    .project_point_front_facing(&frame, &pw, view)
                    .unwrap_or_else(|| panic!("{s:?} {p:?}"));
                assert!(
                    f.point.iter().chain(f.normal.iter()).all(|v| v.is_finite())
                        && f.distance.is_finite()
                );
            }
        }
        // A sphere (zero length, equal radii): the foot point is at the radius.
        if s.length == 0.0 && s.r1 == s.r2 && s.is_circular() && s.r1 > 0.0 {
            for p in &queries {
                let r = s.project_local_point(p).unwrap();
                assert!((r.point.norm() - s.r1).abs() < 1e-9);
            }
        }
    }
    let nan = Vector3::new(f64::NAN, 0.0, 0.0);
    assert!(seg(10.0, 2.0, 2.0, 2.0, 2.0)
        .project_local_point(&nan)
        .is_none());
    let inf = Vector3::new(0.0, f64::INFINITY, 0.0);
    assert!(seg(10.0, 2.0, 2.0, 2.0, 2.0)
        .project_point(&Rigid3::identity(), &inf)
        .is_none());
}

/// A random pose within the joint limits, hand placed in front of the camera.
fn random_pose(model: &CylinderModel, rng: &mut ChaCha8Rng) -> Pose {
    let mut values = Vec::new();
    for d in model.skeleton.dofs() {
        values.push(match (d.kind, d.limits) {
            (_, Some([lo, hi])) => rng.random_range(lo..=hi),
            (DofKind::Translation, None) => {
                if d.name == "global_tz" {
                    rng.random_range(300.0..500.0)
                } else {
                    rng.random_range(-80.0..80.0)
                }
            }
            (_, None) => rng.random_range(-3.0..3.0),
        });
    }
    Pose::from_values(&model.skeleton, values).unwrap()
}

/// Query points scattered around the posed model's segments.
fn points_near_model(
    model: &CylinderModel,
    posed: &PosedSkeleton,
    rng: &mut ChaCha8Rng,
    n: usize,
) -> Vec<Vector3<f64>> {
    (0..n)
        .map(|_| {
            let i = rng.random_range(0..model.segments.len());
            let s = &model.segments[i];
            let local = Vector3::new(
                rng.random_range(-1.5..1.5) * (s.r1.max(s.r2) + 4.0),
                rng.random_range(-8.0..s.length + 8.0),
                rng.random_range(-1.5..1.5) * (s.r1y.max(s.r2y) + 4.0),
            );
            posed.point(s.bone, &local)
        })
        .collect()
}

#[test]
fn front_facing_results_are_never_back_facing() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let right = default_right_hand_cylinders();
    let left = right.mirrored().unwrap();
    let mut worst = [0.0f64; 2];
    let mut substituted = 0;
    for model in [&right, &left] {
        for _ in 0..40 {
            let posed = model.posed(&random_pose(model, &mut rng)).unwrap();
            for p in points_near_model(model, &posed, &mut rng, 100) {
                for view in [View::Orthographic, View::Perspective] {
                    let r = model.front_facing_point(&posed, &p, view).unwrap();
                    let v = match view {
                        View::Orthographic => Vector3::z(),
                        View::Perspective => r.point.normalize(),
                    };
                    let nv = r.normal.dot(&v);
                    let k = usize::from(view == View::Perspective);
                    worst[k] = worst[k].max(nv);
                    assert!(
                        nv < 1e-9,
                        "segment {} ({:?}): n·v = {nv}",
                        r.segment,
                        r.part
                    );
                    if r.part == CylinderPart::Silhouette {
                        substituted += 1;
                        assert!(
                            nv.abs() < 1e-9,
                            "silhouette normals are orthogonal to the view: {nv}"
                        );
                    }
                    // Whatever the rule does, the result is a point of that segment's surface.
                    let s = &model.segments[r.segment];
                    let local = posed.globals[s.bone].inverse().transform_point(&r.point);
                    let back = s.project_local_point(&local).unwrap();
                    assert!(
                        back.distance.abs() < 1e-7,
                        "not on the surface: {}",
                        back.distance
                    );
                }
            }
        }
    }
    assert!(
        substituted > 100,
        "the rule was exercised ({substituted} substitutions)"
    );
    println!(
        "worst n·v orthographic {:.2e}, perspective {:.2e}",
        worst[0], worst[1]
    );
}

#[test]
fn front_facing_keeps_front_facing_closest_points() {
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let model = default_right_hand_cylinders();
    for _ in 0..20 {
        let posed = model.posed(&random_pose(&model, &mut rng)).unwrap();
        for p in points_near_model(&model, &posed, &mut rng, 50) {
            for (i, s) in model.segments.iter().enumerate() {
                let frame = posed.globals[s.bone];
                let c = s.project_point(&frame, &p).unwrap();
                let f = s
                    .project_point_front_facing(&frame, &p, View::Orthographic)
                    .unwrap();
                if c.normal.z < 0.0 {
                    assert_eq!(c, f, "segment {i}");
                } else {
                    assert_eq!(f.part, CylinderPart::Silhouette, "segment {i}");
                    if s.is_circular() {
                        // The exact closest point is never farther than a contour point.
                        assert!(f.distance.abs() >= c.distance.abs() - 1e-9, "segment {i}");
                    }
                }
            }
        }
    }
}

#[test]
fn model_queries_pick_the_best_segment_and_batch_matches() {
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let model = default_right_hand_cylinders();
    let posed = model.posed(&random_pose(&model, &mut rng)).unwrap();
    let points = points_near_model(&model, &posed, &mut rng, 300);
    let mut out: Vec<Option<CylinderProjection>> = vec![None; points.len()];
    for view in [None, Some(View::Orthographic), Some(View::Perspective)] {
        let start = std::time::Instant::now();
        let n = model
            .project_points(&posed, &points, view, &mut out)
            .unwrap();
        let us = start.elapsed().as_secs_f64() * 1e6 / points.len() as f64;
        println!("{view:?}: {us:.2} µs per point (16 segments)");
        assert_eq!(n, points.len());
        for (p, o) in points.iter().zip(&out) {
            let single = match view {
                None => model.closest_point(&posed, p),
                Some(v) => model.front_facing_point(&posed, p, v),
            };
            assert_eq!(*o, single);
            let best = o.unwrap();
            assert_eq!(best.bone, model.segments[best.segment].bone);
            for s in &model.segments {
                let frame = posed.globals[s.bone];
                let r = match view {
                    None => s.project_point(&frame, p).unwrap(),
                    Some(v) => s.project_point_front_facing(&frame, p, v).unwrap(),
                };
                assert!(best.distance <= r.distance);
            }
        }
    }
    assert!(model
        .project_points(&posed, &points, None, &mut out[..10])
        .is_err());
    assert!(model
        .closest_point(&posed, &Vector3::new(0.0, f64::NAN, 0.0))
        .is_none());
}

#[test]
fn culled_model_queries_equal_the_brute_force_scan() {
    let mut rng = ChaCha8Rng::seed_from_u64(29);
    let mut elliptic = default_right_hand_cylinders();
    // An elliptical, tapered palm (width and thickness both tapering) and one flattened finger.
    elliptic.segments[0].r1y = elliptic.segments[0].r1 * 0.45;
    elliptic.segments[0].r2y = elliptic.segments[0].r2 * 0.6;
    elliptic.segments[5].r2y = elliptic.segments[5].r2 * 0.7;
    for model in [default_right_hand_cylinders(), elliptic] {
        for _ in 0..4 {
            let posed = model.posed(&random_pose(&model, &mut rng)).unwrap();
            let mut points = points_near_model(&model, &posed, &mut rng, 400);
            // Far points and points around the palm center.
            let c = posed.globals[model.segments[0].bone].translation;
            for _ in 0..100 {
                points.push(c + v3(&mut rng, [-150.0; 3], [150.0; 3]));
            }
            let mut out = vec![None; points.len()];
            for view in [None, Some(View::Orthographic), Some(View::Perspective)] {
                model
                    .project_points(&posed, &points, view, &mut out)
                    .unwrap();
                for (p, o) in points.iter().zip(&out) {
                    let brute = match view {
                        None => model.closest_point_brute_force(&posed, p),
                        Some(v) => model.front_facing_point_brute_force(&posed, p, v),
                    };
                    assert_eq!(*o, brute, "{view:?} at {p:?}");
                }
                // Seeded (temporal coherence): random, stale, absent and out-of-range seeds
                // only reorder the search; then the seeds of the previous result.
                let mut seeds: Vec<u16> = (0..points.len())
                    .map(|i| match i % 4 {
                        0 => rng.random_range(0..model.segments.len() as u16),
                        1 => NO_SEED,
                        2 => 1000,
                        _ => (i % model.segments.len()) as u16,
                    })
                    .collect();
                let mut seeded = vec![None; points.len()];
                for _ in 0..2 {
                    model
                        .project_points_seeded(&posed, &points, view, &mut seeds, &mut seeded)
                        .unwrap();
                    assert_eq!(seeded, out, "{view:?}");
                    for (s, o) in seeds.iter().zip(&out) {
                        assert_eq!(*s, o.map_or(NO_SEED, |o| o.segment as u16));
                    }
                }
            }
        }
    }
}

#[test]
fn skeleton_jacobian_matches_finite_differences() {
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let mut models = vec![default_right_hand_cylinders()];
    if Path::new(CALIB).exists() {
        models.push(load_htrack_calib(Path::new(CALIB)).unwrap());
    }
    let h = 1e-6;
    let mut worst: f64 = 0.0;
    for model in &models {
        let sk = &model.skeleton;
        let n = sk.num_dofs();
        for _ in 0..10 {
            let pose = random_pose(model, &mut rng);
            let posed = model.posed(&pose).unwrap();
            let mut cols = vec![Vector3::zeros(); n];
            for s in &model.segments {
                // A surface point of the segment, attached to its bone.
                let probe = Vector3::new(
                    rng.random_range(-20.0..20.0),
                    rng.random_range(-10.0..s.length + 10.0),
                    rng.random_range(-20.0..20.0),
                );
                let local = s.project_local_point(&probe).unwrap().point;
                let q = posed.point(s.bone, &local);
                posed.point_jacobian(sk, s.bone, &q, &mut cols);
                for (d, col) in cols.iter().enumerate() {
                    let mut delta = vec![0.0; n];
                    delta[d] = h;
                    let plus =
                        PosedSkeleton::new(sk, &pose.retract(sk, &delta)).point(s.bone, &local);
                    delta[d] = -h;
                    let minus =
                        PosedSkeleton::new(sk, &pose.retract(sk, &delta)).point(s.bone, &local);
                    let fd = (plus - minus) / (2.0 * h);
                    let rel = (col - fd).norm() / fd.norm().max(1.0);
                    worst = worst.max(rel);
                    assert!(
                        rel < 1e-5,
                        "DOF {} on bone {}: analytic {col:?} vs FD {fd:?}",
                        sk.dofs()[d].name,
                        s.bone
                    );
                }
            }
        }
    }
    println!("worst relative Jacobian error {worst:.2e}");
}

/// Segment numbers of the anchor table, in the htrack segment order (ANCHOR-FACTS §3).
const TABLE_LENGTHS: [f64; 16] = [
    56.27, 32.47, 19.48, 12.99, 24.35, 14.61, 9.74, 30.84, 18.51, 12.34, 32.47, 19.48, 12.99,
    30.84, 18.51, 12.34,
];

fn table_radii(i: usize) -> [f64; 4] {
    match i {
        0 => [29.22, 33.76, 8.77, 8.77],
        1 => [11.04, 6.49, 11.04, 6.49],
        2 => [6.49, 5.84, 6.49, 5.84],
        3 => [5.84, 5.19, 5.84, 5.19],
        _ => match (i - 4) % 3 {
            0 => [6.49, 5.84, 6.49, 5.84],
            1 => [5.84, 5.19, 5.84, 5.19],
            _ => [5.19, 5.19, 5.19, 5.19],
        },
    }
}

fn assert_close3(a: &Vector3<f64>, b: [f64; 3], tol: f64, what: &str) {
    let b = Vector3::from(b);
    assert!((a - b).amax() < tol, "{what}: {a:?} vs {b:?}");
}

#[test]
fn default_template_rest_pose_equals_the_template() {
    let m = default_right_hand_cylinders();
    assert_eq!(m.handedness, Handedness::Right);
    assert_eq!(m.geometric_handedness(), Handedness::Right);
    let names: Vec<&str> = m.skeleton.dofs().iter().map(|d| d.name.as_str()).collect();
    assert_eq!(names, CYLINDER_DOF_NAMES);
    for (i, s) in m.segments.iter().enumerate() {
        let r = table_radii(i);
        let got = [s.length, s.r1, s.r2, s.r1y, s.r2y];
        let want = [TABLE_LENGTHS[i], r[0], r[1], r[2], r[3]];
        for k in 0..5 {
            assert!((got[k] - want[k]).abs() < 1e-9, "segment {i} value {k}");
        }
    }
    let posed = m.posed(&Pose::zeros(&m.skeleton)).unwrap();
    let bone = |n: &str| m.skeleton.bone_index(n).unwrap();
    // The authored positions (the anchor table mirrored to a right hand).
    assert_close3(
        &posed.globals[bone("palm")].translation,
        [0.0; 3],
        1e-12,
        "wrist",
    );
    assert_close3(
        &posed.globals[bone("thumb_1")].translation,
        [-16.23, 8.12, -8.12],
        1e-9,
        "thumb_1",
    );
    assert_close3(
        &posed.globals[bone("index_1")].translation,
        [-24.35, 64.93, 0.0],
        1e-9,
        "index_1",
    );
    assert_close3(
        &posed.globals[bone("middle_1")].translation,
        [-8.12, 64.93, 0.0],
        1e-9,
        "middle_1",
    );
    assert_close3(
        &posed.globals[bone("ring_1")].translation,
        [8.12, 64.93, 0.0],
        1e-9,
        "ring_1",
    );
    assert_close3(
        &posed.globals[bone("pinky_1")].translation,
        [24.35, 64.93, 0.0],
        1e-9,
        "pinky_1",
    );
    // Each phalanx starts where the previous segment ends; rest globals equal FK at θ = 0.
    let rest = m.skeleton.rest_globals();
    for (b, g) in rest.iter().enumerate() {
        assert!((g.rotation - posed.globals[b].rotation).norm() < 1e-12);
        assert!((g.translation - posed.globals[b].translation).norm() < 1e-12);
    }
    for (i, s) in m.segments.iter().enumerate() {
        let bone = &m.skeleton.bones()[s.bone];
        for (c, child) in m.skeleton.bones().iter().enumerate() {
            if child.parent == Some(s.bone) && i > 0 {
                let end = m.segment_end(&posed, i).unwrap();
                assert!(
                    (end - posed.globals[c].translation).norm() < 1e-9,
                    "{} ends at {}",
                    bone.name,
                    child.name
                );
            }
        }
    }
    let kp = m.keypoints(&posed);
    assert_eq!(kp[0], Vector3::zeros());
    for (k, seg_i) in [(4usize, 3usize), (8, 15), (12, 12), (16, 9), (20, 6)] {
        let s = &m.segments[seg_i];
        let dir = posed.globals[s.bone].rotation.column(1).into_owned();
        let want = m.segment_end(&posed, seg_i).unwrap() + dir * s.r2;
        assert!((kp[k] - want).norm() < 1e-12, "tip keypoint {k}");
    }
    // Straight fingers at rest: the middle fingertip is 64.93 + 32.47 + 19.48 + 12.99 + 5.19 up.
    assert_close3(
        &kp[12],
        [-8.12, 64.93 + 32.47 + 19.48 + 12.99 + 5.19, 0.0],
        1e-9,
        "middle tip",
    );
}

#[test]
fn dof_signs_follow_the_project_convention() {
    let m = default_right_hand_cylinders();
    let rest = m.keypoints(&m.rest_posed());
    let moved = |name: &str, v: f64| {
        let mut pose = Pose::zeros(&m.skeleton);
        pose.set(&m.skeleton, name, v).unwrap();
        m.keypoints(&m.posed(&pose).unwrap())
    };
    // Flexion toward the palm (−z), abduction toward the thumb (−x for a right hand).
    assert!(moved("index_mcp_flex", 0.5)[8].z < rest[8].z - 10.0);
    assert!(moved("index_mcp_abd", 0.3)[8].x < rest[8].x - 10.0);
    assert!(moved("pinky_mcp_abd", 0.3)[20].x < rest[20].x - 5.0);
    // The thumb flexes across the palm (+x, −z) and abducts radially (−x).
    let t = moved("thumb_cmc_flex", 0.8)[4];
    assert!(t.x > rest[4].x && t.z < rest[4].z);
    assert!(moved("thumb_cmc_abd", 0.3)[4].x < rest[4].x);
    for (idx, name, sign) in HTRACK_THETA_LAYOUT {
        assert!(CYLINDER_DOF_NAMES.contains(&name), "{idx} {name}");
        assert_eq!(sign, if idx < 6 { 1.0 } else { -1.0 });
    }
}

#[test]
fn invalid_models_are_rejected() {
    let mut m = default_right_hand_cylinders();
    m.segments[3].r2 = f64::NAN;
    let e = m.validate(Path::new("model.json")).unwrap_err().to_string();
    assert!(
        e.contains("model.json") && e.contains("segments.r2") && e.contains("[3]"),
        "{e}"
    );
    let mut m = default_right_hand_cylinders();
    m.segments[5].r1y = 0.0;
    assert!(m.validate(Path::new("x")).is_err());
    let m = default_right_hand_cylinders();
    let mut pose = Pose::zeros(&m.skeleton);
    pose.values[7] = f64::NAN;
    assert!(m.posed(&pose).is_err());
    pose.values.pop();
    assert!(m.posed(&pose).is_err());
}

// ---------------------------------------------------------------------------------------------
// htrack `.calib` importer.

/// A synthetic calibration in the htrack format (our own numbers: identity rotations, a 0.9
/// scale, a small thumb rotation about z), optionally without some joint.
fn synthetic_calib(skip_joint: Option<&str>) -> String {
    let mut out = String::new();
    let mut joint = |name: &str, parent: &str, cols: [[f64; 4]; 4]| {
        if Some(name) == skip_joint {
            return;
        }
        out.push_str(&format!("{name} {parent}"));
        for c in cols {
            for v in c {
                out.push_str(&format!(" {v}"));
            }
        }
        out.push('\n');
    };
    let id = |t: [f64; 3]| {
        [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [t[0], t[1], t[2], 1.0],
        ]
    };
    joint("root", "root", id([0.0; 3]));
    joint("pose", "root", id([0.0; 3]));
    joint(
        "scale",
        "pose",
        [
            [0.9, 0.0, 0.0, 0.0],
            [0.0, 0.9, 0.0, 0.0],
            [0.0, 0.0, 0.9, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ],
    );
    joint("Hand", "scale", id([0.0; 3]));
    let (c, s) = (0.8f64, 0.6f64);
    for (d, base, lens) in [
        ("Thumb", [25.0, 12.0, -9.0], [35.0, 25.0, 18.0]),
        ("Pinky", [-28.0, 75.0, 0.0], [28.0, 20.0, 14.0]),
        ("Ring", [-9.0, 78.0, 0.0], [36.0, 24.0, 16.0]),
        ("Middle", [9.0, 80.0, 0.0], [40.0, 26.0, 17.0]),
        ("Index", [27.0, 77.0, 0.0], [36.0, 24.0, 16.0]),
    ] {
        let first = if d == "Thumb" {
            [
                [c, s, 0.0, 0.0],
                [-s, c, 0.0, 0.0],
                [0.0, 0.0, 1.0, 0.0],
                [base[0], base[1], base[2], 1.0],
            ]
        } else {
            id(base)
        };
        joint(&format!("Hand{d}1"), "Hand", first);
        for k in 2..=4 {
            joint(
                &format!("Hand{d}{k}"),
                &format!("Hand{d}{}", k - 1),
                id([0.0, lens[k - 2], 0.0]),
            );
        }
    }
    out.push_str("end_of_skeleton\n");
    for i in 0..16 {
        let r = if i == 0 {
            "30 40 10 10".to_string()
        } else {
            format!("{} {} {} {}", 9 - i % 3, 8 - i % 3, 9 - i % 3, 8 - i % 3)
        };
        out.push_str(&format!("{i} {r}\n"));
    }
    out
}

#[test]
fn synthetic_calib_imports_with_htrack_rules() {
    let text = synthetic_calib(None);
    let m = parse_htrack_calib(&text, Path::new("synthetic.calib")).unwrap();
    assert_eq!(m.handedness, Handedness::Left);
    assert_eq!(m.segments.len(), 16);
    let s = 0.9;
    let mean = [(-28.0f64, 75.0f64), (-9.0, 78.0), (9.0, 80.0), (27.0, 77.0)]
        .iter()
        .map(|(x, y)| x.hypot(*y) * s)
        .sum::<f64>()
        / 4.0;
    assert!((m.segments[0].length - (mean - HTRACK_PALM_OFFSET)).abs() < 1e-9);
    assert!((HTRACK_PALM_OFFSET - 11.1222).abs() < 1e-3);
    assert!((m.segments[0].r1 - 27.0).abs() < 1e-9 && (m.segments[0].r2y - 9.0).abs() < 1e-9);
    // Thumb segments (1..3): lengths 35, 25, 18 scaled.
    for (k, l) in [35.0, 25.0, 18.0].iter().enumerate() {
        assert!((m.segments[1 + k].length - l * s).abs() < 1e-9);
    }
    let posed = m.rest_posed();
    let kp = m.keypoints(&posed);
    assert!(
        (kp[1] - Vector3::new(25.0, 12.0, -9.0) * s).norm() < 1e-9,
        "thumb base {:?}",
        kp[1]
    );
    // The thumb is rotated by atan2(0.6, 0.8) about z: its second joint lies along (−0.6, 0.8).
    assert!((kp[2] - kp[1] - Vector3::new(-0.6, 0.8, 0.0) * 35.0 * s).norm() < 1e-9);
    let mirrored = m.mirrored().unwrap();
    assert_eq!(mirrored.handedness, Handedness::Right);
    assert_eq!(mirrored.geometric_handedness(), Handedness::Right);
}

fn import_error(text: &str) -> String {
    match parse_htrack_calib(text, Path::new("bad.calib")) {
        Ok(_) => panic!("accepted a corrupt file:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn corrupt_calib_files_give_clear_errors() {
    let good = synthetic_calib(None);
    let lines: Vec<&str> = good.lines().collect();
    // Truncated at every line and in the middle of lines: always an error naming the file.
    for k in 0..lines.len() {
        let cut = lines[..k].join("\n");
        let e = import_error(&cut);
        assert!(e.starts_with("bad.calib: field `"), "{e}");
        let half = format!("{}\n{}", cut, &lines[k][..lines[k].len() / 2]);
        let e = import_error(&half);
        assert!(e.starts_with("bad.calib: field `"), "{e}");
    }
    let e = import_error(&lines[..20].join("\n"));
    assert!(
        e.contains("end_of_skeleton") && e.contains("truncated"),
        "{e}"
    );
    let e = import_error(&format!("{}\n{}", lines[..5].join("\n"), &lines[5][..40]));
    assert!(
        e.contains("`joint.matrix`[5]") && e.contains("line 6") && e.contains("truncated"),
        "{e}"
    );
    let e = import_error(&lines[..lines.len() - 1].join("\n"));
    assert!(
        e.contains("`segment.radii`[15]") && e.contains("missing"),
        "{e}"
    );

    // Bad numbers.
    let nan = good.replacen("HandRing2 HandRing1 1 ", "HandRing2 HandRing1 nan ", 1);
    let e = import_error(&nan);
    assert!(
        e.contains("`joint.matrix`[13]") && e.contains("not finite") && e.contains("HandRing2"),
        "{e}"
    );
    let abc = good.replacen(
        "HandRing2 HandRing1 1 0 0",
        "HandRing2 HandRing1 1 0 abc",
        1,
    );
    let e = import_error(&abc);
    assert!(
        e.contains("`abc` is not a number") && e.contains("matrix value 2"),
        "{e}"
    );
    let bad_radius = good.replacen("\n7 8 7 8 7\n", "\n7 NaN 7 8 7\n", 1);
    assert_ne!(bad_radius, good);
    let e = import_error(&bad_radius);
    assert!(
        e.contains("`segment.radii`[7]") && e.contains("not finite"),
        "{e}"
    );

    // Missing bones: an intermediate one (its child's parent is unknown), a last one.
    let e = import_error(&synthetic_calib(Some("HandIndex2")));
    assert!(
        e.contains("`joint.parent`") && e.contains("unknown parent `HandIndex2`"),
        "{e}"
    );
    let e = import_error(&synthetic_calib(Some("HandIndex4")));
    assert!(
        e.contains("`joints`[23]") && e.contains("missing joint `HandIndex4`"),
        "{e}"
    );
    let e = import_error(&synthetic_calib(Some("scale")));
    assert!(e.contains("unknown parent `scale`"), "{e}");

    // Wrong radius count, wrong parent, bad matrices.
    let e = import_error(&good.replacen("\n3 ", "\n3 7 ", 1));
    assert!(
        e.contains("`segment.radii`[3]") && e.contains("found 5"),
        "{e}"
    );
    let short = good.replacen("\n3 9 8 9 8\n", "\n3 9 8 9\n", 1);
    assert_ne!(short, good);
    let e = import_error(&short);
    assert!(
        e.contains("`segment.radii`[3]") && e.contains("found 3"),
        "{e}"
    );
    let e = import_error(&good.replacen("HandThumb3 HandThumb2", "HandThumb3 HandThumb1", 1));
    assert!(e.contains("must have parent `HandThumb2`"), "{e}");
    let e = import_error(&good.replacen("scale pose 0.9 0 0", "scale pose 0.9 0 0.5", 1));
    assert!(
        e.contains("uniformly scaled rotation") && e.contains("`scale`"),
        "{e}"
    );
    let e = import_error(&good.replacen("\n12 ", "\n17 ", 1));
    assert!(e.contains("`segment.index`[17]"), "{e}");
}

#[test]
fn real_htrack_default_calib_reproduces_the_anchor_table() {
    let path = Path::new(CALIB);
    if !path.exists() {
        println!("skipped: {} absent", path.display());
        return;
    }
    let m = load_htrack_calib(path).unwrap();
    // htrack's leftHand skeleton is geometrically a left hand (thumb at +x, palm facing −z).
    assert_eq!(m.handedness, Handedness::Left);
    for (i, s) in m.segments.iter().enumerate() {
        let r = table_radii(i);
        let got = [s.length, s.r1, s.r2, s.r1y, s.r2y];
        let want = [TABLE_LENGTHS[i], r[0], r[1], r[2], r[3]];
        for k in 0..5 {
            assert!(
                (got[k] - want[k]).abs() < 0.01,
                "segment {i} value {k}: {} vs {}",
                got[k],
                want[k]
            );
        }
        println!(
            "segment {i:2}: length {:6.3} r1 {:6.3} r2 {:6.3} r1y {:6.3} r2y {:6.3}",
            s.length, s.r1, s.r2, s.r1y, s.r2y
        );
    }
    // Joint global origins at θ = 0 (htrack's model frame is kept, so no conversion).
    let posed = m.rest_posed();
    let origin = |n: &str| posed.globals[m.skeleton.bone_index(n).unwrap()].translation;
    for (bone, want) in [
        ("thumb_1", [16.23, 8.12, -8.12]),
        ("pinky_1", [-24.35, 64.93, 0.0]),
        ("ring_1", [-8.12, 64.93, 0.0]),
        ("middle_1", [8.12, 64.93, 0.0]),
        ("index_1", [24.35, 64.93, 0.0]),
    ] {
        println!("{bone}: {:?}", origin(bone));
        assert_close3(&origin(bone), want, 0.01, bone);
    }
    // Middle4 (the fingertip end point) is the end of segment 12 (Middle3).
    let middle4 = m.segment_end(&posed, 12).unwrap();
    println!("Middle4: {middle4:?}");
    assert_close3(&middle4, [6.47, 129.25, -7.87], 0.01, "Middle4");
    // Our signs: flexion toward the palm (−z), abduction toward the thumb (+x on this left hand).
    let rest = m.keypoints(&posed);
    let moved = |name: &str, v: f64| {
        let mut pose = Pose::zeros(&m.skeleton);
        pose.set(&m.skeleton, name, v).unwrap();
        m.keypoints(&m.posed(&pose).unwrap())
    };
    assert!(moved("index_mcp_flex", 0.5)[8].z < rest[8].z - 10.0);
    assert!(moved("index_mcp_abd", 0.3)[8].x > rest[8].x + 5.0);
    assert!(moved("thumb_cmc_abd", 0.3)[4].x > rest[4].x);
    assert!(moved("thumb_cmc_flex", 0.8)[4].z < rest[4].z);
    // Mirroring gives the right hand in our frames.
    let right = m.mirrored().unwrap();
    assert_eq!(right.geometric_handedness(), Handedness::Right);
    assert!(right.keypoints(&right.rest_posed())[1].x < 0.0);
}
