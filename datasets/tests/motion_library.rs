//! Tests of the motion library: smoothness, limits, determinism, speeds, view, calibration
//! frames.

use datasets::motion::{
    hand_in_view, hand_out_of_view, motion_stats, select_calibration_frames, KeyPose, Motion,
    MotionLibrary, ANCHOR_MODEL, JOINT_DOFS,
};
use datasets::DatasetError;
use hand_model::cylinder::default_right_hand_cylinders;
use hand_model::kinematics::{Bone, Pose, Skeleton};
use hand_model::math::Rigid3;
use hand_model::spheremesh::{default_right_hand, PosedSphereMesh, SphereMeshTemplate};
use nalgebra::Vector3;
use sensor_io::Camera;

const FPS: f64 = 60.0;

fn all_motions(seed: u64) -> Vec<Motion> {
    MotionLibrary::names()
        .iter()
        .map(|n| MotionLibrary::by_name(n, seed).unwrap())
        .collect()
}

fn keypoints(t: &SphereMeshTemplate, pose: &Pose) -> [Vector3<f64>; 21] {
    PosedSphereMesh::new(t, pose).keypoints(t)
}

/// Prints the table of the `MotionLibrary` docs.
#[test]
fn motion_table() {
    println!("| name | duration (s) | max joint speed (rad/s) | max global angular speed (rad/s) | max keypoint speed (mm/s) |");
    println!("|---|---|---|---|---|");
    for m in all_motions(0) {
        let s = motion_stats(&m, FPS).unwrap();
        println!(
            "| `{}` | {:.1} | {:.1} (`{}`) | {:.2} | {:.0} |",
            s.name,
            s.duration,
            s.max_joint_speed,
            s.max_joint_speed_dof,
            s.max_global_angular_speed,
            s.max_keypoint_speed,
        );
        println!(
            "    accel {:.0} rad/s², keypoint accel {:.0} mm/s², not fully in view {}, out of view {}",
            s.max_joint_accel,
            s.max_keypoint_accel,
            s.frames_not_fully_in_view,
            s.frames_out_of_view
        );
    }
}

#[test]
fn every_motion_runs_600_frames_without_nan() {
    let t = default_right_hand();
    for m in all_motions(7) {
        assert!(
            m.num_frames(FPS) >= 600,
            "{} is shorter than 600 frames",
            m.name()
        );
        assert_eq!(m.dof_names().len(), t.skeleton.num_dofs());
        for (i, name) in m.dof_names().iter().enumerate() {
            assert_eq!(name, &t.skeleton.dofs()[i].name);
        }
        for i in 0..600 {
            let pose = m.pose_at(i as f64 / FPS);
            assert_eq!(pose.values.len(), t.skeleton.num_dofs());
            assert!(
                pose.values.iter().all(|v| v.is_finite()),
                "{} frame {i}",
                m.name()
            );
            let k = keypoints(&t, &pose);
            assert!(k.iter().all(|p| p.iter().all(|x| x.is_finite())));
        }
        // Odd times do not panic.
        for t in [f64::NAN, -5.0, f64::INFINITY, f64::NEG_INFINITY, 1e300] {
            assert!(m.pose_at(t).values.iter().all(|v| v.is_finite()));
        }
    }
}

#[test]
fn all_values_within_limits() {
    let t = default_right_hand();
    for m in all_motions(3) {
        for pose in m.sample(FPS) {
            for (v, dof) in pose.values.iter().zip(t.skeleton.dofs()) {
                if let Some([lo, hi]) = dof.limits {
                    assert!(
                        *v >= lo - 1e-12 && *v <= hi + 1e-12,
                        "{}: {} = {v} outside [{lo}, {hi}]",
                        m.name(),
                        dof.name
                    );
                }
            }
        }
    }
}

#[test]
fn key_poses_are_within_limits_and_named() {
    let t = default_right_hand();
    for k in KeyPose::ALL {
        assert_eq!(KeyPose::by_name(k.name()), Some(k));
        for (name, v) in k.articulation().named() {
            let d = t.skeleton.dof_index(name).unwrap();
            let [lo, hi] = t.skeleton.dofs()[d].limits.unwrap();
            assert!((lo..=hi).contains(&v), "{}: {name} = {v}", k.name());
        }
    }
    assert_eq!(KeyPose::by_name("nope"), None);
}

fn sphere_gap(t: &SphereMeshTemplate, pm: &PosedSphereMesh, a: &str, b: &str) -> f64 {
    let (ia, ib) = (t.sphere_index(a).unwrap(), t.sphere_index(b).unwrap());
    let (sa, sb) = (&pm.spheres[ia], &pm.spheres[ib]);
    (sa.center - sb.center).norm() - sa.radius - sb.radius
}

#[test]
fn contact_key_poses_touch_and_crossing_crosses() {
    let t = default_right_hand();
    for (k, finger) in [
        (KeyPose::PinchIndex, "index"),
        (KeyPose::PinchMiddle, "middle"),
        (KeyPose::PinchRing, "ring"),
        (KeyPose::PinchPinky, "pinky"),
    ] {
        let pose = Pose::from_named(&t.skeleton, k.articulation().named()).unwrap();
        let pm = PosedSphereMesh::new(&t, &pose);
        let gap = sphere_gap(&t, &pm, "thumb_top", &format!("{finger}_top"));
        assert!(gap.abs() < 0.5, "{}: gap {gap} mm", k.name());
    }
    // Crossed: the index tip passes to the little-finger side of the middle tip (model +x),
    // the middle finger passing over the back of the index (larger z = dorsal).
    let pose = Pose::from_named(&t.skeleton, KeyPose::Crossed.articulation().named()).unwrap();
    let k = keypoints(&t, &pose);
    assert!(
        k[8].x > k[12].x + 15.0,
        "index tip {:?} middle tip {:?}",
        k[8],
        k[12]
    );
    assert!(k[12].z > k[8].z, "the middle finger should cross dorsally");
    // Open: fingers do not touch the thumb.
    let pose = Pose::from_named(&t.skeleton, KeyPose::Open.articulation().named()).unwrap();
    let pm = PosedSphereMesh::new(&t, &pose);
    assert!(sphere_gap(&t, &pm, "thumb_top", "index_top") > 30.0);
}

/// Joint angles and the global position/angles sampled at `fps`, as channel vectors.
fn channels(m: &Motion, fps: f64) -> Vec<Vec<f64>> {
    (0..m.num_frames(fps))
        .map(|i| {
            let t = i as f64 / fps;
            let mut v = m.articulation_at(t).0.to_vec();
            let p = m.placement_at(t);
            v.extend([p.position.x, p.position.y, p.position.z]);
            v.extend(p.euler());
            v
        })
        .collect()
}

/// Per motion: (max joint step per 60 Hz frame (rad), max keypoint step per frame (mm)).
fn step_bounds(name: &str) -> (f64, f64) {
    match name {
        "fist" | "axis_speed" | "teaser" => (0.2, 26.0),
        "rotation_fast" | "leave_reenter" => (0.12, 22.0),
        _ => (0.12, 14.0),
    }
}

#[test]
fn no_jumps_between_consecutive_60hz_frames() {
    let t = default_right_hand();
    for m in all_motions(11) {
        let (max_joint, max_kp) = step_bounds(m.name());
        let poses = m.sample(FPS);
        let kps: Vec<_> = poses.iter().map(|p| keypoints(&t, p)).collect();
        let mut worst_joint: f64 = 0.0;
        let mut worst_kp: f64 = 0.0;
        for i in 1..poses.len() {
            for d in 6..t.skeleton.num_dofs() {
                worst_joint = worst_joint.max((poses[i].values[d] - poses[i - 1].values[d]).abs());
            }
            for (a, b) in kps[i].iter().zip(&kps[i - 1]) {
                worst_kp = worst_kp.max((a - b).norm());
            }
        }
        assert!(
            worst_joint <= max_joint,
            "{}: joint step {worst_joint} rad",
            m.name()
        );
        assert!(
            worst_kp <= max_kp,
            "{}: keypoint step {worst_kp} mm",
            m.name()
        );
    }
}

#[test]
fn accelerations_bounded_at_1khz_so_no_kinks() {
    // A velocity kink of Δv shows as a finite-difference acceleration of Δv·1000; the bounds
    // allow the smooth minimum-jerk peaks only.
    let fps = 1000.0;
    for m in all_motions(5) {
        let c = channels(&m, fps);
        let fast = matches!(m.name(), "fist" | "axis_speed" | "teaser");
        let joint_bound = if fast { 160.0 } else { 80.0 };
        let pos_bound = 6000.0; // mm/s²
        let ang_bound = 60.0; // rad/s² on the Euler channels
        for i in 1..c.len() - 1 {
            let triples = c[i + 1].iter().zip(&c[i]).zip(&c[i - 1]);
            for (ch, ((next, cur), prev)) in triples.enumerate() {
                let a = (next - 2.0 * cur + prev) * fps * fps;
                let bound = if ch < JOINT_DOFS.len() {
                    joint_bound
                } else if ch < JOINT_DOFS.len() + 3 {
                    pos_bound
                } else {
                    ang_bound
                };
                assert!(
                    a.abs() <= bound,
                    "{}: channel {ch} acceleration {a} at t = {}",
                    m.name(),
                    i as f64 / fps
                );
            }
        }
    }
}

#[test]
fn deterministic_per_seed_and_seed_dependent() {
    for name in MotionLibrary::names() {
        let a = MotionLibrary::by_name(name, 42).unwrap();
        let b = MotionLibrary::by_name(name, 42).unwrap();
        let c = MotionLibrary::by_name(name, 43).unwrap();
        assert_eq!(a.seed(), 42);
        let (pa, pb, pc) = (a.sample(FPS), b.sample(FPS), c.sample(FPS));
        assert_eq!(pa, pb, "{name}: same seed, different poses");
        let n = pa.len().min(pc.len());
        let diff = (0..n)
            .flat_map(|i| {
                pa[i]
                    .values
                    .iter()
                    .zip(&pc[i].values)
                    .map(|(x, y)| (x - y).abs())
            })
            .fold(0.0, f64::max);
        assert!(diff > 1e-3, "{name}: seeds 42 and 43 give the same motion");
    }
}

#[test]
fn unknown_names_are_errors() {
    let err = MotionLibrary::by_name("moonwalk", 0).unwrap_err();
    assert!(matches!(err, DatasetError::UnknownMotion { .. }));
    let msg = err.to_string();
    assert!(msg.contains("moonwalk") && msg.contains("teaser") && msg.contains("rotating_fist"));
    assert!(MotionLibrary::describe("moonwalk").is_none());
    for n in MotionLibrary::names() {
        assert!(
            MotionLibrary::describe(n).is_some(),
            "{n} has no description"
        );
    }
}

#[test]
fn speeds_are_realistic() {
    for m in all_motions(0) {
        let s = motion_stats(&m, FPS).unwrap();
        let name = m.name();
        match name {
            "rotation_fast" | "rotating_fist" => {
                assert!(s.max_global_angular_speed >= 3.0, "{name}: {s:?}")
            }
            "rotation_slow" => assert!(s.max_global_angular_speed <= 1.5, "{name}: {s:?}"),
            "teaser" => assert!(s.max_global_angular_speed >= 3.0, "{name}: {s:?}"),
            _ => assert!(s.max_global_angular_speed <= 3.0, "{name}: {s:?}"),
        }
        let joint_bound = match name {
            "fist" | "axis_speed" | "teaser" => 12.0,
            _ => 8.0,
        };
        assert!(s.max_joint_speed <= joint_bound, "{name}: {s:?}");
        assert!(s.max_keypoint_speed <= 1600.0, "{name}: {s:?}");
    }
    assert!(motion_stats(&all_motions(0)[0], 0.0).is_err());
    assert!(motion_stats(&all_motions(0)[0], f64::NAN).is_err());
}

#[test]
fn hand_stays_in_view_at_a_natural_distance() {
    let t = default_right_hand();
    let cam = Camera::sr300_qvga();
    for m in all_motions(9) {
        if m.name() == "leave_reenter" {
            continue;
        }
        for (i, pose) in m.sample(FPS).iter().enumerate() {
            let k = keypoints(&t, pose);
            assert!(
                hand_in_view(&cam, &k),
                "{} frame {i} leaves the view",
                m.name()
            );
            let z = m.placement_at(i as f64 / FPS).position.z;
            assert!(
                (350.0..=450.0).contains(&z),
                "{} frame {i}: z = {z}",
                m.name()
            );
        }
    }
}

#[test]
fn leave_reenter_leaves_twice_and_comes_back() {
    let t = default_right_hand();
    let cam = Camera::sr300_qvga();
    let m = MotionLibrary::by_name("leave_reenter", 1).unwrap();
    let poses = m.sample(FPS);
    let out: Vec<bool> = poses
        .iter()
        .map(|p| hand_out_of_view(&cam, &keypoints(&t, p)))
        .collect();
    let inside: Vec<bool> = poses
        .iter()
        .map(|p| hand_in_view(&cam, &keypoints(&t, p)))
        .collect();
    assert!(inside[0] && *inside.last().unwrap());
    let episodes = out.windows(2).filter(|w| !w[0] && w[1]).count();
    assert_eq!(episodes, 2, "expected two exits");
    let longest = out.split(|o| !o).map(|run| run.len()).max().unwrap_or(0);
    assert!(
        longest as f64 / FPS >= 0.5,
        "out of view for {longest} frames only"
    );
}

#[test]
fn teaser_is_interesting_throughout_its_first_600_frames() {
    let m = MotionLibrary::by_name("teaser", 0).unwrap();
    let c = channels(&m, FPS);
    for w in 0..10 {
        let frames = &c[w * 60..(w + 1) * 60];
        let range = |ch: usize| {
            let (lo, hi) = frames.iter().fold((f64::MAX, f64::MIN), |(l, h), f| {
                (l.min(f[ch]), h.max(f[ch]))
            });
            hi - lo
        };
        let joint = (0..JOINT_DOFS.len()).map(range).fold(0.0, f64::max);
        let rot = (JOINT_DOFS.len() + 3..JOINT_DOFS.len() + 6)
            .map(range)
            .fold(0.0, f64::max);
        assert!(
            joint >= 0.3 || rot >= 0.3,
            "second {w}: joint range {joint}, rotation range {rot}"
        );
    }
}

#[test]
fn placement_puts_the_palm_center_at_its_position_upright() {
    let t = default_right_hand();
    let m = MotionLibrary::by_name("flexion", 0).unwrap();
    for time in [0.0, 3.3, 7.0] {
        let pose = m.pose_at(time);
        let pm = PosedSphereMesh::new(&t, &pose);
        let palm = t.skeleton.bone_index("palm").unwrap();
        let c = pm.skeleton.globals[palm].transform_point(&Vector3::from(ANCHOR_MODEL));
        let p = m.placement_at(time).position;
        assert!((c - p).norm() < 1e-9);
        // Upright: the middle fingertip is above (smaller y than) the wrist; thumb on the
        // image's right (larger x) of the little finger; the palm faces the camera.
        let k = pm.keypoints(&t);
        assert!(k[12].y < k[0].y - 100.0);
        assert!(k[4].x > k[20].x);
        let normal = pm.skeleton.globals[palm].rotation * -Vector3::z();
        assert!(normal.z < -0.8, "palm normal {normal:?}");
    }
}

#[test]
fn retargeting_by_dof_name() {
    let t = default_right_hand();
    let m = MotionLibrary::by_name("pinch", 2).unwrap();
    let same = m.for_skeleton(&t.skeleton).unwrap();
    for i in 0..100 {
        let time = i as f64 * 0.1;
        assert_eq!(m.pose_at(time), same.pose_at(time));
    }
    // The 26-DOF cylinder model: no wrist DOFs, same digits.
    let cyl = default_right_hand_cylinders();
    let c = MotionLibrary::by_name_for("pinch", 2, &cyl.skeleton).unwrap();
    assert_eq!(c.dof_names().len(), 26);
    let pose = c.pose_at(2.0);
    let full = m.pose_at(2.0);
    for (name, v) in pose.named(&cyl.skeleton) {
        let d = t.skeleton.dof_index(name).unwrap();
        let lim = cyl.skeleton.dofs()[cyl.skeleton.dof_index(name).unwrap()].limits;
        let expect = match lim {
            Some([lo, hi]) => full.values[d].clamp(lo, hi),
            None => full.values[d],
        };
        assert!((v - expect).abs() < 1e-12, "{name}");
    }
    // A skeleton without global DOFs is refused.
    let bare = Skeleton::new(
        vec![Bone {
            name: "root".into(),
            parent: None,
            rest: Rigid3::identity(),
            dofs: vec![],
        }],
        vec![],
        std::path::Path::new("<test>"),
    )
    .unwrap();
    let err = m.for_skeleton(&bare).unwrap_err();
    assert!(matches!(err, DatasetError::MissingDof { .. }), "{err}");
}

/// Palm-frame keypoints of a pose (the articulation part of the calibration feature).
fn palm_features(t: &SphereMeshTemplate, pose: &Pose) -> Vec<f64> {
    let pm = PosedSphereMesh::new(t, pose);
    let palm = t.skeleton.bone_index("palm").unwrap();
    let g = pm.skeleton.globals[palm];
    pm.keypoints(t)
        .iter()
        .flat_map(|p| {
            (g.rotation.transpose() * (p - g.translation))
                .iter()
                .copied()
                .collect::<Vec<_>>()
        })
        .collect()
}

fn min_pairwise(feats: &[Vec<f64>]) -> f64 {
    let mut best = f64::MAX;
    for i in 0..feats.len() {
        for j in i + 1..feats.len() {
            let d: f64 = feats[i]
                .iter()
                .zip(&feats[j])
                .map(|(a, b)| (a - b).powi(2))
                .sum();
            best = best.min(d.sqrt());
        }
    }
    best
}

#[test]
fn calibration_frames_are_diverse_deterministic_and_in_view() {
    let t = default_right_hand();
    let cam = Camera::sr300_qvga();
    for name in ["teaser", "calibration", "random", "leave_reenter"] {
        let m = MotionLibrary::by_name(name, 0).unwrap();
        let sel = select_calibration_frames(&m, 8, FPS, 600);
        assert_eq!(sel.len(), 8, "{name}");
        assert_eq!(sel, select_calibration_frames(&m, 8, FPS, 600));
        assert!(sel.windows(2).all(|w| w[0] < w[1]) && *sel.last().unwrap() < 600);
        let poses: Vec<Pose> = sel.iter().map(|&i| m.pose_at(i as f64 / FPS)).collect();
        for p in &poses {
            assert!(hand_in_view(&cam, &keypoints(&t, p)), "{name}");
        }
        // More diverse in articulation than evenly spaced frames.
        let chosen: Vec<_> = poses.iter().map(|p| palm_features(&t, p)).collect();
        let even: Vec<_> = (0..8)
            .map(|i| palm_features(&t, &m.pose_at((i * 75) as f64 / FPS)))
            .collect();
        println!(
            "{name}: {sel:?}, min pairwise palm-frame distance {:.0} mm (evenly spaced {:.0})",
            min_pairwise(&chosen),
            min_pairwise(&even)
        );
        assert!(min_pairwise(&chosen) >= min_pairwise(&even), "{name}");
    }
    let m = MotionLibrary::by_name("fist", 0).unwrap();
    assert!(select_calibration_frames(&m, 0, FPS, 600).is_empty());
    assert!(select_calibration_frames(&m, 8, f64::NAN, 600).is_empty());
    assert!(select_calibration_frames(&m, 8, FPS, 0).is_empty());
    assert_eq!(select_calibration_frames(&m, 50, FPS, 10).len(), 10);
}
