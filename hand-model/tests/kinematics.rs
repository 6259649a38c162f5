//! Issue 2: the skeleton Jacobian ∂p/∂θ and the shape Jacobian ∂c/∂β against central finite
//! differences, forward kinematics of the rest pose, and the β ↔ (C̄, r̄) round trip.

use hand_model::kinematics::{DofKind, Pose, PosedSkeleton};
use hand_model::spheremesh::{default_right_hand, PosedSphereMesh, ShapeBasis, SphereMeshTemplate};
use hand_model::testing::{central_difference, relative_error};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn random_pose(t: &SphereMeshTemplate, rng: &mut ChaCha8Rng) -> Pose {
    let mut pose = Pose::zeros(&t.skeleton);
    for (v, dof) in pose.values.iter_mut().zip(t.skeleton.dofs()) {
        *v = match (dof.kind, dof.limits) {
            (_, Some([lo, hi])) => rng.random_range(lo..=hi),
            (DofKind::Translation, None) => rng.random_range(-100.0..100.0),
            (_, None) => rng.random_range(-3.0..3.0),
        };
    }
    pose
}

#[test]
fn skeleton_jacobian_matches_central_differences() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let mut worst: f64 = 0.0;
    for _ in 0..20 {
        let pose = random_pose(&t, &mut rng);
        let posed = PosedSkeleton::new(sk, &pose);
        for bone in 0..sk.bones().len() {
            let local = Vector3::new(
                rng.random_range(-15.0..15.0),
                rng.random_range(-5.0..30.0),
                rng.random_range(-15.0..15.0),
            );
            let p = posed.point(bone, &local);
            let mut cols = vec![Vector3::zeros(); sk.num_dofs()];
            posed.point_jacobian(sk, bone, &p, &mut cols);
            for (d, col) in cols.iter().enumerate() {
                let fd = central_difference(1e-6, |h| {
                    let mut delta = vec![0.0; sk.num_dofs()];
                    delta[d] = h;
                    PosedSkeleton::new(sk, &pose.retract(sk, &delta)).point(bone, &local)
                });
                let e = relative_error(col, &fd, 1e-3);
                worst = worst.max(e);
                assert!(
                    e < 1e-5,
                    "bone {} dof {} ({}): analytic {col:?} vs fd {fd:?}",
                    sk.bones()[bone].name,
                    d,
                    sk.dofs()[d].name
                );
            }
        }
    }
    eprintln!("worst relative error of ∂p/∂θ: {worst:.2e}");
}

#[test]
fn sphere_center_jacobian_includes_blends() {
    let t = default_right_hand();
    let sk = &t.skeleton;
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let pose = random_pose(&t, &mut rng);
    let posed = PosedSphereMesh::new(&t, &pose);
    for i in 0..t.spheres.len() {
        let mut cols = vec![Vector3::zeros(); sk.num_dofs()];
        posed.for_each_center_column(&t, i, &mut |d, c| cols[d] += c);
        for (d, col) in cols.iter().enumerate() {
            let fd = central_difference(1e-6, |h| {
                let mut delta = vec![0.0; sk.num_dofs()];
                delta[d] = h;
                PosedSphereMesh::new(&t, &pose.retract(sk, &delta)).spheres[i].center
            });
            assert!(
                relative_error(col, &fd, 1e-3) < 1e-5,
                "sphere {} dof {d}",
                t.spheres[i].name
            );
        }
    }
}

#[test]
fn shape_jacobian_matches_central_differences() {
    let t = default_right_hand();
    let basis = ShapeBasis::honline(&t).expect("default template carries the honline names");
    assert_eq!(basis.len(), 75);
    let beta0 = basis.template_values();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for _ in 0..3 {
        let pose = random_pose(&t, &mut rng);
        let beta: Vec<f64> = beta0
            .iter()
            .map(|b| b * rng.random_range(0.9..1.1))
            .collect();
        let shaped = basis.apply(&t, &beta).expect("valid shape");
        let posed = PosedSphereMesh::new(&shaped, &pose);
        for i in 0..t.spheres.len() {
            let mut dc = vec![Vector3::zeros(); basis.len()];
            let mut dr = vec![0.0; basis.len()];
            basis.for_each_sphere_column(&shaped, &posed, i, &mut |j, c, r| {
                dc[j] += c;
                dr[j] += r;
            });
            for j in 0..basis.len() {
                let eval = |h: f64| {
                    let mut b = beta.clone();
                    b[j] += h;
                    PosedSphereMesh::new(&basis.apply(&t, &b).expect("valid"), &pose).spheres[i]
                };
                let fd = central_difference(1e-5, |h| eval(h).center);
                let fdr = (eval(1e-5).radius - eval(-1e-5).radius) / 2e-5;
                assert!(
                    relative_error(&dc[j], &fd, 1e-3) < 1e-5,
                    "sphere {} β {}: {:?} vs {:?}",
                    t.spheres[i].name,
                    basis.params[j].name,
                    dc[j],
                    fd
                );
                assert!(
                    (dr[j] - fdr).abs() < 1e-6,
                    "radius of sphere {} β {}",
                    t.spheres[i].name,
                    basis.params[j].name
                );
            }
        }
    }
}

#[test]
fn rest_pose_reproduces_the_template() {
    let t = default_right_hand();
    let posed = PosedSphereMesh::new(&t, &Pose::zeros(&t.skeleton));
    let rest = t.rest_spheres();
    for (a, b) in posed.spheres.iter().zip(&rest) {
        assert!((a.center - b.center).norm() < 1e-12 && (a.radius - b.radius).abs() < 1e-12);
    }
    // The authored model-frame centers: palm_back at the origin, the index base at its position.
    let i = t.sphere_index("palm_back").expect("palm_back");
    assert!(rest[i].center.norm() < 1e-12);
    let i = t.sphere_index("index_base").expect("index_base");
    assert!((rest[i].center - Vector3::new(-27.0, 65.0, 3.0)).norm() < 1e-9);
    // Right hand: thumb at −x, fingers toward +y.
    let thumb = rest[t.sphere_index("thumb_top").expect("thumb")].center;
    let middle = rest[t.sphere_index("middle_top").expect("middle")].center;
    assert!(
        thumb.x < -40.0 && middle.y > 120.0,
        "thumb {thumb:?} middle {middle:?}"
    );
}

#[test]
fn shape_round_trip_and_latent_scaling() {
    let t = default_right_hand();
    let basis = ShapeBasis::honline(&t).expect("basis");
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let beta: Vec<f64> = basis
        .template_values()
        .iter()
        .map(|b| b * rng.random_range(0.85..1.15))
        .collect();
    let shaped = basis.apply(&t, &beta).expect("apply");
    let (back, resid) = basis.fit(&t, &shaped).expect("fit");
    assert!(resid < 1e-9, "residual {resid}");
    for (a, b) in beta.iter().zip(&back) {
        assert!((a - b).abs() < 1e-8, "{a} vs {b}");
    }
    // Latent height scaling lengthens every phalanx by the same factor.
    let tall = basis.from_latent([1.1, 1.0, 1.0]);
    let j = basis
        .names()
        .position(|n| n == "middle_bottom_length")
        .expect("name");
    assert!((tall[j] / basis.params[j].template_value - 1.1).abs() < 1e-12);
    let k = basis
        .names()
        .position(|n| n == "middle_base_radius")
        .expect("name");
    assert!((tall[k] - basis.params[k].template_value).abs() < 1e-12);
}

#[test]
fn bad_shapes_and_poses_are_refused() {
    let t = default_right_hand();
    let basis = ShapeBasis::honline(&t).expect("basis");
    let mut beta = basis.template_values();
    beta[0] = f64::NAN;
    assert!(basis.apply(&t, &beta).is_err());
    let mut beta = basis.template_values();
    let k = basis
        .names()
        .position(|n| n == "index_top_radius")
        .expect("name");
    beta[k] = -1.0;
    let err = basis.apply(&t, &beta).expect_err("negative radius");
    assert!(err.to_string().contains("index_top"), "{err}");
    assert!(basis.apply(&t, &beta[..10]).is_err());
    assert!(Pose::from_values(&t.skeleton, vec![0.0; 3]).is_err());
    let mut v = vec![0.0; t.skeleton.num_dofs()];
    v[4] = f64::INFINITY;
    assert!(Pose::from_values(&t.skeleton, v).is_err());
}

#[test]
fn multiplicative_rotation_has_no_gimbal_stall() {
    // At gimbal lock of the XYZ Euler angles (ry = π/2) every tangent direction still turns the hand.
    let t = default_right_hand();
    let sk = &t.skeleton;
    let mut pose = Pose::zeros(sk);
    pose.set(sk, "global_ry", std::f64::consts::FRAC_PI_2)
        .expect("dof");
    let p0 = PosedSphereMesh::new(&t, &pose).spheres;
    for k in 3..6 {
        let mut delta = vec![0.0; sk.num_dofs()];
        delta[k] = 0.01;
        let p1 = PosedSphereMesh::new(&t, &pose.retract(sk, &delta)).spheres;
        let moved = p0
            .iter()
            .zip(&p1)
            .map(|(a, b)| (a.center - b.center).norm())
            .fold(0.0, f64::max);
        // 0.01 rad about any axis through the palm moves some sphere ≥ 0.4 mm (hand ≈ 180 mm).
        assert!(
            moved > 0.4,
            "tangent direction {k} barely moves the hand: {moved}"
        );
    }
}
