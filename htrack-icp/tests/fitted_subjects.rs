//! The cylinder model fitted to the synthetic subjects of `datasets` (non-default β): its
//! keypoints coincide with the sphere-mesh ground truth, its segments cover the sphere-mesh, and
//! the collision term is silent at rest — what scoring the Ch. 2 tracker on synthetic sequences
//! relies on. (A test here rather than in `hand-model`, which must not depend on `datasets`.)

use datasets::synth::{SceneConfig, Synthesizer};
use datasets::Subject;
use hand_model::cylinder::{CylinderModel, View};
use hand_model::kinematics::{DofKind, Pose, Skeleton};
use hand_model::spheremesh::{Attachment, PosedSphereMesh, SphereMeshTemplate};
use htrack_icp::terms::{Collision, CollisionParams};
use htrack_icp::{IrlsParams, TrackingCtx};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn random_pose(sk: &Skeleton, rng: &mut ChaCha8Rng) -> Pose {
    let values = sk
        .dofs()
        .iter()
        .map(|d| match (d.kind, d.limits) {
            (DofKind::Translation, _) => rng.random_range(-100.0..100.0),
            (DofKind::GlobalRotation, _) => rng.random_range(-1.5..1.5),
            (DofKind::Rotation, Some([lo, hi])) => rng.random_range(lo..=hi),
            (DofKind::Rotation, None) => 0.0,
        })
        .collect();
    Pose { values }
}

fn subjects() -> Vec<(String, SphereMeshTemplate)> {
    let mut out: Vec<_> = Subject::names()
        .iter()
        .map(|n| Subject::named(n).unwrap())
        .collect();
    out.extend((1..=3).map(|seed| Subject::random(seed, 0.1).unwrap()));
    out.into_iter()
        .map(|s| (s.name.clone(), s.template().unwrap()))
        .collect()
}

#[test]
fn fitted_subjects_share_keypoints_and_cover_the_sphere_mesh() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for (name, template) in subjects() {
        let model = CylinderModel::from_sphere_mesh(&template).unwrap();
        assert_eq!(model.skeleton.num_dofs(), 26, "{name}");
        let wrist = template.skeleton.bone_index("wrist").unwrap();
        let (mut gap, mut inside, mut total) = (0.0f64, 0, 0);
        for i in 0..=30 {
            let pose = if i == 0 {
                Pose::zeros(&template.skeleton)
            } else {
                random_pose(&template.skeleton, &mut rng)
            };
            let mesh = PosedSphereMesh::new(&template, &pose);
            let posed = model
                .posed(&model.pose_by_name(&template.skeleton, &pose))
                .unwrap();
            for (a, b) in mesh
                .keypoints(&template)
                .iter()
                .zip(&model.keypoints(&posed))
            {
                gap = gap.max((a - b).norm());
            }
            for (s, def) in mesh.spheres.iter().zip(&template.spheres) {
                if matches!(def.attachment, Attachment::Bone { bone, .. } if bone == wrist) {
                    continue;
                }
                total += 1;
                if model.segments.iter().any(|seg| {
                    let local = posed.globals[seg.bone].inverse().transform_point(&s.center);
                    seg.contains_local_point(&local)
                }) {
                    inside += 1;
                }
            }
        }
        let frac = f64::from(inside) / f64::from(total);
        let palm = &model.segments[0];
        eprintln!(
            "{name}: keypoint gap {gap:.1e} mm, sphere centers inside {frac:.3}, palm {:.1} × \
             {:.1}→{:.1} × {:.1} mm",
            palm.length, palm.r1, palm.r2, palm.r1y
        );
        assert!(gap < 1e-9, "{name}: {gap}");
        assert!(frac > 0.95, "{name}: {frac}");
        // Collision: silent at rest (rest overlaps are tolerated).
        let term = Collision::new(&model, CollisionParams::default());
        let mut ctx = TrackingCtx::new(&model, View::Orthographic, IrlsParams::default());
        ctx.update(&Pose::zeros(&model.skeleton), false).unwrap();
        assert!(term.contacts(&ctx).is_empty(), "{name}");
    }
}

#[test]
fn synthesizer_ground_truth_matches_the_fitted_model() {
    let subject = Subject::named("long_fingers").unwrap();
    let base = hand_model::spheremesh::default_right_hand();
    let mut synth = Synthesizer::new(&base, &subject.beta, SceneConfig::default()).unwrap();
    let model = CylinderModel::from_sphere_mesh(synth.template()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let sk = synth.template().skeleton.clone();
    let mut gap = 0.0f64;
    for i in 0..3 {
        let mut pose = random_pose(&sk, &mut rng);
        pose.set(&sk, "global_tz", 450.0).unwrap();
        let frame = synth.render(i, i as f64 / 30.0, &pose).unwrap();
        // The tracker's side: the ground-truth pose by DOF name.
        let named = frame.truth.pose.iter().map(|(k, v)| (k.as_str(), *v));
        let cyl = Pose::from_named(
            &model.skeleton,
            named.filter(|(k, _)| model.skeleton.dof_index(k).is_some()),
        )
        .unwrap();
        let kp = model.keypoints(&model.posed(&cyl).unwrap());
        assert_eq!(frame.truth.keypoints.len(), kp.len());
        for (t, k) in frame.truth.keypoints.iter().zip(&kp) {
            gap = gap.max((nalgebra::Vector3::from(*t) - k).norm());
        }
    }
    eprintln!("synthesizer ground truth vs fitted model keypoints: max {gap:.1e} mm");
    assert!(gap < 1e-6, "{gap}");
}
