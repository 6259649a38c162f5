//! Issue 2: the Jacobians of a surface correspondence. For a data point p with footpoint q on
//! the posed model, the signed distance d = n·(p − q) changes with the pose and the shape as
//! −n·∂q/∂θ and −n·∂q/∂β (envelope theorem). Both are checked against central finite
//! differences of the model-wide projection itself, for points near random poses and shapes.

use hand_model::kinematics::{DofKind, Pose};
use hand_model::query::SphereMeshGeometry;
use hand_model::shape::Element;
use hand_model::spheremesh::{default_right_hand, PosedSphereMesh, ShapeBasis, SphereMeshTemplate};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn distance(t: &SphereMeshTemplate, pose: &Pose, p: &Vector3<f64>) -> (f64, u32) {
    let posed = PosedSphereMesh::new(t, pose);
    let elements: Vec<Element> = t.elements.iter().map(|e| e.element).collect();
    let g = SphereMeshGeometry::new(&posed.spheres, &elements).expect("geometry");
    let pr = g.project(p).expect("projection");
    (pr.distance, pr.element)
}

fn random_pose(t: &SphereMeshTemplate, rng: &mut ChaCha8Rng) -> Pose {
    let mut pose = Pose::zeros(&t.skeleton);
    for (v, dof) in pose.values.iter_mut().zip(t.skeleton.dofs()) {
        *v = match (dof.kind, dof.limits) {
            (_, Some([lo, hi])) => rng.random_range(lo..=hi) * 0.6,
            (DofKind::Translation, None) => rng.random_range(-50.0..50.0),
            (_, None) => rng.random_range(-1.0..1.0),
        };
    }
    pose
}

#[test]
fn footpoint_jacobians_match_finite_differences_of_the_projection() {
    let t0 = default_right_hand();
    let basis = ShapeBasis::honline(&t0).expect("basis");
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let (mut checked, mut worst_theta, mut worst_beta) = (0, 0.0f64, 0.0f64);
    for _ in 0..4 {
        let beta: Vec<f64> = basis
            .template_values()
            .iter()
            .map(|b| b * rng.random_range(0.92..1.08))
            .collect();
        let t = basis.apply(&t0, &beta).expect("shape");
        let pose = random_pose(&t, &mut rng);
        let posed = PosedSphereMesh::new(&t, &pose);
        let elements: Vec<Element> = t.elements.iter().map(|e| e.element).collect();
        let g = SphereMeshGeometry::new(&posed.spheres, &elements).expect("geometry");
        for _ in 0..40 {
            let s = &posed.spheres[rng.random_range(0..posed.spheres.len())];
            let dir = Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
            .normalize();
            let p = s.center + dir * (s.radius + rng.random_range(2.0..8.0));
            let pr = g.project(&p).expect("projection");
            let n = pr.normal;
            // Pose columns.
            let mut jt = vec![Vector3::zeros(); t.skeleton.num_dofs()];
            posed.for_each_footpoint_column(&t, &pr.spheres, &pr.weights, &mut |d, c| jt[d] += c);
            let h = 1e-6;
            let mut ok = true;
            for (d, col) in jt.iter().enumerate() {
                let mut delta = vec![0.0; t.skeleton.num_dofs()];
                delta[d] = h;
                let (dp, ep) = distance(&t, &pose.retract(&t.skeleton, &delta), &p);
                delta[d] = -h;
                let (dm, em) = distance(&t, &pose.retract(&t.skeleton, &delta), &p);
                if ep != pr.element || em != pr.element {
                    ok = false; // the footpoint changed element: the distance is not smooth here
                    break;
                }
                let fd = (dp - dm) / (2.0 * h);
                let an = -n.dot(col);
                let err = (fd - an).abs() / an.abs().max(1.0);
                worst_theta = worst_theta.max(err);
                assert!(
                    err < 1e-4,
                    "θ column {} ({}): fd {fd} vs analytic {an}",
                    d,
                    t.skeleton.dofs()[d].name
                );
            }
            if !ok {
                continue;
            }
            // Shape columns.
            let mut jb = vec![Vector3::zeros(); basis.len()];
            basis.for_each_footpoint_column(
                &t,
                &posed,
                &pr.spheres,
                &pr.weights,
                &n,
                &mut |j, c| jb[j] += c,
            );
            for (j, col) in jb.iter().enumerate() {
                let eval = |x: f64| {
                    let mut b = beta.clone();
                    b[j] += x;
                    distance(&basis.apply(&t0, &b).expect("shape"), &pose, &p)
                };
                let ((dp, ep), (dm, em)) = (eval(1e-5), eval(-1e-5));
                if ep != pr.element || em != pr.element {
                    continue;
                }
                let fd = (dp - dm) / 2e-5;
                let an = -n.dot(col);
                let err = (fd - an).abs() / an.abs().max(1.0);
                worst_beta = worst_beta.max(err);
                assert!(
                    err < 1e-4,
                    "β column {}: fd {fd} vs analytic {an}",
                    basis.params[j].name
                );
            }
            checked += 1;
        }
    }
    eprintln!("{checked} footpoints checked; worst relative error θ {worst_theta:.1e}, β {worst_beta:.1e}");
    assert!(checked > 80, "too few smooth footpoints ({checked})");
}
