//! A real hand rendered by another renderer: the photogrammetry scans of
//! `../shared/reference/hand-scans-tkach/scans` (triangle meshes of one person's hand, forearm
//! included) as a depth camera sees them, drawn by `datasets::mesh` (a z-buffer rasterizer that
//! shares no code with the sphere-mesh renderer of every other synthetic sequence), moved
//! rigidly in front of the camera, segmented depth-only (no wristband) and tracked by the
//! Ch. 3 tracker and the Ch. 4 online calibrator. No model of this project drew these images,
//! so this is the closest thing to the unseen sequences the trackers are meant for.
//!
//! Ground truth is the original authors' per-pose fit of each scan (`fitted/`, poses 1–5): its
//! sphere centers, carried by the same scale, mirror (the scans are geometrically left hands)
//! and rigid motion as the mesh. It is a fit, not a measurement — the authors' model explains
//! its scan to ≈ 1 mm and places the DIP joints 5–8 mm from where ours would
//! (`ch3_scans.rs`) — so the fingertip spheres, whose placement both fits agree on, are the
//! error reported; the mean distance of the data points to the tracked model (E_d2m) comes from
//! the data alone. Skips (and says so) when the folder is absent.
//!
//! Measured (90 frames at 30 Hz, means over the last 60; fingertip error mm / E_d2m mm, for
//! the default template, the hand's own model — the authors' fit carried onto our skeleton —
//! and online calibration from the default template):
//!
//! | pose | noise-free | ToF |
//! |---|---|---|
//! | 1 (claw) | 9.38 5.15 7.17 / 2.83 1.62 1.38 | 10.29 6.60 9.76 / 3.78 3.02 3.27 |
//! | 2 (open, spread) | 15.17 4.90 2.59 / 2.76 1.89 0.99 | 15.12 5.34 6.55 / 4.00 3.38 3.12 |
//! | 3 | 10.09 8.85 9.49 / 2.52 1.40 0.88 | 9.81 9.02 6.85 / 3.58 2.78 2.71 |
//! | 4 | 7.97 4.42 3.82 / 2.13 1.17 0.88 | 8.75 4.27 3.73 / 3.51 2.87 3.00 |
//! | 5 (fist) | 48.81 10.29 47.60 / 2.77 2.19 1.93 | 50.02 12.29 37.31 / 3.73 3.21 2.97 |
//!
//! This test found that the depth-only segmentation took the fingertips for the forearm stump
//! when the visible forearm is shorter than the fingers (the scans end a few centimetres
//! past the wrist): pose 2 online was 18.05 mm before the fix in `segment_depth_only`. The
//! fist of pose 5 is still placed as an open hand behind it from the default template.

use std::path::Path;

#[path = "support/authors.rs"]
mod authors;

use datasets::mesh::{read_obj_mesh, render_mesh_depth, TriangleMesh};
use datasets::noise::{apply_sensor_model, SensorModel};
use datasets::scans::{match_sphere_names, pill_length_scale, FittedReference};
use eval::online::CalibrationMotion;
use hand_model::kinematics::Pose;
use hand_model::math::{fit_rigid, Rigid3};
use hand_model::query::SphereMeshGeometry;
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::{default_right_hand, PosedSphereMesh, SphereMeshTemplate};
use hmodel_spheremesh::{Tracker, TrackerConfig};
use honline_calib::{OnlineCalibrator, OnlineConfig};
use nalgebra::{Rotation3, Vector3};
use sensor_io::preprocess::{PreprocessConfig, PreprocessedFrame, Preprocessor};
use sensor_io::{Camera, DepthImage, Frame};

const ROOT: &str = "../../shared/reference/hand-scans-tkach";
const FRAMES: usize = 90;
const FPS: f64 = 30.0;
const FINGERTIPS: [&str; 5] = [
    "thumb_top",
    "index_top",
    "middle_top",
    "ring_top",
    "pinky_top",
];

/// One scan placed in front of the camera: the mesh and the authors' fitted centers (mm, right
/// hand, the pose where the default template's palm is at the calibration motion's start), and
/// the pairs (authors' sphere, template sphere) of the fingertips.
struct Scene {
    mesh: TriangleMesh,
    centers: Vec<Vector3<f64>>,
    tips: Vec<(usize, usize)>,
    pivot: Vector3<f64>,
}

impl Scene {
    /// Scan `fit + 1` with the authors' fit `fit` (`locate_fits` pairs them so).
    fn load(root: &Path, reference: &FittedReference, fit: usize) -> Scene {
        let base = default_right_hand();
        let fitted = &reference.per_pose_centers[fit];
        let units = pill_length_scale(&reference.final_centers, fitted, &reference.blocks)
            .unwrap()
            .scale;
        let corr = match_sphere_names(&reference.sphere_names, &base);
        let start = PosedSphereMesh::new(&base, &start_pose());
        let palm: Vec<(usize, usize)> = corr
            .pairs
            .iter()
            .copied()
            .filter(|&(_, j)| base.spheres[j].name.starts_with("palm"))
            .collect();
        assert!(palm.len() >= 4, "{} palm spheres matched", palm.len());
        let target: Vec<Vector3<f64>> =
            palm.iter().map(|&(_, j)| start.spheres[j].center).collect();
        // Scan units to mm, mirrored or not, whichever palm fits ours better.
        let (to_mm, to_camera) = [1.0, -1.0]
            .into_iter()
            .map(|m| {
                let to_mm = move |p: &Vector3<f64>| Vector3::new(m * p.x, p.y, p.z) / units;
                let ours: Vec<Vector3<f64>> =
                    palm.iter().map(|&(r, _)| to_mm(&fitted[r])).collect();
                let fit = fit_rigid(&ours, &target).unwrap();
                let error: f64 = ours
                    .iter()
                    .zip(&target)
                    .map(|(a, b)| (fit.transform_point(a) - b).norm())
                    .sum();
                (to_mm, fit, error)
            })
            .min_by(|a, b| a.2.total_cmp(&b.2))
            .map(|(f, fit, _)| (f, fit))
            .unwrap();
        let place = |p: &Vector3<f64>| to_camera.transform_point(&to_mm(p));
        let mesh = read_obj_mesh(root.join(format!("scans/pose{}.obj", fit + 1))).unwrap();
        let tips = corr
            .pairs
            .iter()
            .copied()
            .filter(|&(_, j)| FINGERTIPS.contains(&base.spheres[j].name.as_str()))
            .collect::<Vec<_>>();
        assert_eq!(tips.len(), 5);
        Scene {
            mesh: mesh.map(place),
            centers: fitted.iter().map(place).collect(),
            tips,
            pivot: target.iter().sum::<Vector3<f64>>() / target.len() as f64,
        }
    }

    /// The rigid motion of frame time `t` (s): turns of up to 30° and 17° about the palm, a
    /// few centimetres of travel; the identity at `t = 0`.
    fn motion(&self, t: f64) -> Rigid3 {
        let w = std::f64::consts::TAU;
        let r = Rotation3::from_euler_angles(
            0.3 * (w * t / 2.2).sin(),
            0.52 * (w * t / 3.0).sin(),
            0.0,
        );
        let shift = Vector3::new(
            20.0 * (w * t / 3.0).sin(),
            10.0 * (1.0 - (w * t / 2.5).cos()),
            30.0 * (w * t / 3.0).sin(),
        );
        Rigid3::new(*r.matrix(), self.pivot - r * self.pivot + shift)
    }
}

/// Where the default template starts (the calibration motion's first pose).
fn start_pose() -> Pose {
    CalibrationMotion::new(&default_right_hand().skeleton, 0.0, 7).pose_at(0.0)
}

/// The frames of `scene` under `noise`, preprocessed depth-only, with each frame's motion.
fn frames(scene: &Scene, noise: &str) -> Vec<(PreprocessedFrame, Rigid3)> {
    let camera = Camera::sr300_qvga();
    let model = SensorModel::by_name(noise).unwrap();
    let mut pre = Preprocessor::new(PreprocessConfig::default());
    (0..FRAMES)
        .map(|k| {
            let t = k as f64 / FPS;
            let m = scene.motion(t);
            let rendered = render_mesh_depth(&scene.mesh.map(|p| m.transform_point(p)), &camera);
            let thin = vec![false; rendered.depth.len()];
            let mut depth = DepthImage::zeros(camera.width, camera.height);
            apply_sensor_model(
                model,
                &camera,
                &rendered.depth,
                &rendered.normals,
                &thin,
                k as u64,
                &mut depth,
            );
            let frame = Frame {
                index: k as u64,
                timestamp: t,
                depth,
                color: None,
            };
            let mut out = PreprocessedFrame::default();
            pre.process(&frame, &camera, &mut out).unwrap();
            (out, m)
        })
        .collect()
}

/// Per frame: mean fingertip-center error (mm) and E_d2m (mm) of a tracked template and pose.
#[derive(Default)]
struct Scores {
    tips: Vec<f64>,
    d2m: Vec<f64>,
}

impl Scores {
    fn add(
        &mut self,
        scene: &Scene,
        motion: &Rigid3,
        frame: &PreprocessedFrame,
        t: &SphereMeshTemplate,
        pose: &Pose,
    ) {
        let posed = PosedSphereMesh::new(t, pose);
        let tip = scene
            .tips
            .iter()
            .map(|&(r, j)| {
                (posed.spheres[j].center - motion.transform_point(&scene.centers[r])).norm()
            })
            .sum::<f64>()
            / scene.tips.len() as f64;
        let elements: Vec<_> = t.elements.iter().map(|e| e.element).collect();
        let g = SphereMeshGeometry::new(&posed.spheres, &elements).unwrap();
        let d2m = frame
            .points
            .iter()
            .filter_map(|p| g.phi(p))
            .map(f64::abs)
            .sum::<f64>()
            / frame.points.len().max(1) as f64;
        self.tips.push(tip);
        self.d2m.push(d2m);
    }

    /// Means over the last two thirds (the first frames place the hand).
    fn summary(&self) -> (f64, f64) {
        let tail = |v: &[f64]| {
            let s = &v[v.len() / 3..];
            s.iter().sum::<f64>() / s.len() as f64
        };
        (tail(&self.tips), tail(&self.d2m))
    }
}

/// The Ch. 3 tracker on `template`, placed by its own hypotheses.
fn track_fixed(
    scene: &Scene,
    frames: &[(PreprocessedFrame, Rigid3)],
    template: &SphereMeshTemplate,
) -> Scores {
    let prior = PcaPrior::project_default();
    let mut tracker = Tracker::new(template, TrackerConfig::default(), Some(&prior)).unwrap();
    let mut scores = Scores::default();
    for (k, (f, m)) in frames.iter().enumerate() {
        let rec = tracker.track(f, k as u64, k as f64 / FPS);
        assert!(rec.is_finite());
        scores.add(scene, m, f, template, tracker.pose());
    }
    scores
}

/// Online calibration from the default template, placed by the Ch. 3 tracker's first frame.
fn track_online(scene: &Scene, frames: &[(PreprocessedFrame, Rigid3)]) -> Scores {
    let base = default_right_hand();
    let prior = PcaPrior::project_default();
    let mut seed = Tracker::new(&base, TrackerConfig::default(), Some(&prior)).unwrap();
    seed.track(&frames[0].0, 0, 0.0);
    let mut calib = OnlineCalibrator::new(&base, OnlineConfig::default(), Some(&prior)).unwrap();
    calib.set_pose(seed.pose()).unwrap();
    let mut scores = Scores::default();
    for (k, (f, m)) in frames.iter().enumerate() {
        let out = calib.track(f, k as u64, k as f64 / FPS);
        assert!(out.record.is_finite());
        scores.add(scene, m, f, calib.template(), calib.pose());
    }
    scores
}

#[test]
fn tracks_the_real_scans_rendered_by_another_renderer() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join(ROOT);
    if !root.join("scans/pose1.obj").exists() {
        println!("skipped: {} absent", root.display());
        return;
    }
    let reference = FittedReference::load(root.join("fitted")).unwrap();
    let (own, dc, _, _) = authors::authors_on_skeleton(&reference, &default_right_hand());
    println!("the authors' hand on our skeleton: rest centers within {dc:.2} mm of theirs");
    let default = default_right_hand();
    for noise in ["none", "tof"] {
        println!("{noise}: pose | fingertips mm (default, own model, online) | E_d2m mm (same)");
        for fit in 0..reference.per_pose_centers.len() {
            let scene = Scene::load(&root, &reference, fit);
            let frames = frames(&scene, noise);
            let [(tip_d, d2m_d), (tip_o, d2m_o), (tip_c, d2m_c)] = [
                track_fixed(&scene, &frames, &default).summary(),
                track_fixed(&scene, &frames, &own).summary(),
                track_online(&scene, &frames).summary(),
            ];
            let pose = fit + 1;
            println!(
                "  pose{pose} | {tip_d:.2} {tip_o:.2} {tip_c:.2} | {d2m_d:.2} {d2m_o:.2} {d2m_c:.2}"
            );
            // The data explain the hand's own model and the calibrated one better than the
            // default template, on every pose.
            assert!(d2m_o < d2m_d && d2m_c < d2m_d, "pose{pose} {noise}: E_d2m");
            // The open hands (poses 2 and 4; the segmentation once cut their fingertips as a
            // forearm stump: online 18.1 and 10.0 mm noise-free) end with the fingertips
            // found. Pose 5, a fist, is placed as an open hand behind it by both Ch. 3 runs
            // from the default template (printed, not asserted).
            if pose == 2 || pose == 4 {
                let bound = if noise == "none" { 6.0 } else { 9.0 };
                assert!(
                    tip_o < bound && tip_c < bound,
                    "pose{pose} {noise}: fingertips"
                );
            }
        }
    }
}
