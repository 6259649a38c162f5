use eval::synthetic::{SyntheticSequence, SyntheticSpec};
use hand_model::cylinder::{CylinderModel, View};
use hand_model::kinematics::Pose;
use htrack_icp::{IrlsParams, TrackingCtx};

#[test]
fn distances_at_truth() {
    let mut seq = SyntheticSequence::new(SyntheticSpec { frames: 12, ..Default::default() }).unwrap();
    let model = CylinderModel::from_sphere_mesh(seq.template()).unwrap();
    let sk = &model.skeleton;
    let mut ctx = TrackingCtx::new(&model, View::Orthographic, IrlsParams::default());
    seq.run(
        |f, t| {
            let mut pose = Pose::zeros(sk);
            for (i, d) in sk.dofs().iter().enumerate() {
                pose.values[i] = t.pose[&d.name];
            }
            ctx.set_frame(f);
            ctx.update(&pose, false).unwrap();
            let mut d: Vec<(f64, f64)> = ctx
                .correspondences()
                .iter()
                .zip(ctx.points())
                .map(|(c, x)| {
                    let c = c.as_ref().unwrap();
                    let local = model.posed(&pose).unwrap().globals[0].rotation.transpose() * (x - model.posed(&pose).unwrap().globals[0].translation);
                    ((c.point - x).norm(), local.y)
                })
                .collect();
            d.sort_by(|a, b| a.0.total_cmp(&b.0));
            let n = d.len();
            let far: Vec<f64> = d.iter().filter(|x| x.0 > 5.0).map(|x| x.1).collect();
            println!(
                "n {n} median {:.2} p90 {:.2} p99 {:.2} >5mm {} (local y of those: mean {:.1})",
                d[n / 2].0, d[n * 9 / 10].0, d[n * 99 / 100].0, far.len(),
                far.iter().sum::<f64>() / far.len().max(1) as f64
            );
            t.clone()
        },
        |_| {},
    )
    .unwrap();
}
