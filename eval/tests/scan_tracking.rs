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
//! (`ch3_scans.rs`) — so only the four fingertip keypoints are scored (the tip sphere's far
//! point along the distal bone, as `PosedSphereMesh::keypoints` defines it; the thumb's tip
//! sphere sits differently in the two models); the mean distance of the data points to the
//! tracked sphere-mesh (E_d2m) comes from the data alone. Skips (and says so) when the folder is
//! absent.
//!
//! Measured (90 frames at 30 Hz, means over the last 60; fingertip error mm for the Ch. 2
//! cylinders, the Ch. 3 tracker on the default template and on the hand's own model — the
//! authors' fit carried onto our skeleton — and online calibration from the default template;
//! then E_d2m mm of the last three; every cell re-measured in session 28):
//!
//! | pose | noise-free | ToF | structured light |
//! |---|---|---|---|
//! | 1 (claw) | 10.24 11.19 5.29 8.01 / 2.82 1.62 1.35 | 11.23 12.83 6.66 9.22 / 3.78 3.01 3.27 | 11.84 12.93 9.22 12.19 / 2.82 1.84 1.63 |
//! | 2 (open, spread) | 21.73 17.10 4.79 3.33 / 2.76 1.89 0.99 | 21.65 17.05 5.36 5.62 / 4.00 3.38 3.11 | 21.03 16.49 4.60 3.25 / 2.72 1.89 1.00 |
//! | 3 (two fingers) | 11.16 11.88 11.21 10.88 / 2.52 1.40 0.88 | 10.36 11.75 11.39 9.02 / 3.58 2.78 2.71 | 25.73 35.93 28.79 48.61 / 3.39 1.94 1.75 |
//! | 4 (open) | 9.65 7.57 4.48 3.01 / 2.13 1.17 0.88 | 10.36 8.66 4.38 3.35 / 3.51 2.87 2.99 | 9.44 7.49 4.41 2.91 / 2.14 1.23 0.97 |
//! | 5 (fist) | 69.73 63.09 11.86 50.67 / 2.77 2.23 1.57 | 60.31 63.31 16.69 51.10 / 3.73 3.25 2.97 | 70.93 42.19 60.66 57.10 / 3.26 3.03 2.04 |
//!
//! - Session 28's second look at each placement ([`hand_model::solver::RECHECK_FRAMES`]) moved
//!   two cells of the hand's own model: the fist (noise-free 10.24 → 11.86 mm, ToF 13.71 →
//!   16.69; a start nearer the points at the tenth frame, 3.7 against 4.3 mm, that then
//!   tracked a little worse, E_d2m 2.19 → 2.23 mm) and pose 3 under structured light
//!   (29.79 → 28.79). Every other cell is as the same code without it gives.
//! - The default template's fingers are shorter than this hand's: on the open hands its
//!   fingertips stay 8–17 mm off where online calibration brings them to 3–6 mm.
//! - This test found the depth-only segmentation taking the fingertips for a forearm stump when
//!   the visible forearm is shorter than the fingers (the scans end a few centimetres past the
//!   wrist). Pose 2 noise-free before the fix in `segment_depth_only`: 24.91, 20.50, 6.36 and
//!   17.87 mm.
//! - The fist of pose 5 is placed as an open hand behind it from the default template, by both
//!   trackers; a closed-hand re-initialization hypothesis fixed that (tip sphere centers 48.8 →
//!   18.6 mm noise-free) but moved other starts and library sequences both ways, so it was left
//!   out.
//! - Session 25's edge-on placements (tried by the sphere-mesh trackers' re-initialization only
//!   when the palm-on ones are poor, `hand_model::solver::PLACEMENT_ROLLS`) leave every cell
//!   as it was but the fist under structured light, lost either way (default template 62.77 →
//!   42.22 mm, online 48.23 → 46.49; E_d2m 2.62 → 3.26 and 1.37 → 2.04 mm). Tried as equals they won here, wrongly: on the fist the hand's own model went
//!   10.24 → 65.41 mm, on the claw the default template 11.19 → 43.82. The Ch. 2 cylinders
//!   first kept the palm-on starts: with the sphere-mesh trackers' rule their pose 3 went
//!   11.16 → 29.17 mm (its palm-on placement fails the frame), and 40.98 with the model's area
//!   outside the silhouette added to their score (50.59 with that alone). Since session 26 they
//!   try the backups only when the palm-on placements leave more than 25 % of the silhouette's
//!   area outside the model (`htrack_icp::DEFAULT_PLACEMENT_OUTSIDE`), the score unchanged:
//!   every cell as before (at 20 % the structured-light fist, lost either way, moved 70.93 →
//!   70.99 mm).
//! - Pose 3's folded ring and pinky fingertips are hidden: ≈ 11 mm even with the hand's own
//!   model.
//! - Structured light (session 23; the E_d2m comparison is printed, not asserted, for it): the
//!   open hands track as well as noise-free. Two fixes came from it:
//!   - On pose 3 the shadows across the palm cut its inscribed circles below the forearm's,
//!     and the stump choice flipped to the fingers in some frames. Online calibration, which
//!     this test does not place again, lost the hand for good. The stump is now coherent from
//!     frame to frame in `segment_depth_only`.
//!   - Dropouts inside the silhouette were taken for background by the m2d term. The
//!     distance transform now counts the enclosed zero-depth pixels in
//!     (`sensor_io::preprocess::close_dropouts`).
//!
//!   Online calibration, fingertips before → after the two fixes:
//!
//!   | pose | structured light (mm) |
//!   |---|---|
//!   | 1 | 22.93 → 12.19 |
//!   | 3 | 112.73 → 48.61 |
//!   | 5 | 65.60 → 48.23 |
//!
//!   Noise-free pose 1 went 10.22 → 8.01 mm: the scans have no background wall, and a claw
//!   encloses empty background, which the second fix also counts in. The rest of the
//!   noise-free and ToF cells moved by 0.1 mm or less.
//!
//!   Pose 3 under structured light, other trackers:
//!   - the default template went 17.21 → 35.93 mm;
//!   - the own model went 28.71 → 31.84 mm.
//!
//!   What remains there: grazing dropouts cut the thin strip through which the raised index
//!   finger joins the palm behind the nearer knuckles. The finger is then lost from the hand:
//!   it lies beyond the 150 mm from the palm center within which an occluded part is added
//!   back. On the fist (pose 5) even the hand's own model loses the hand (60.66 mm).

use std::path::Path;

#[path = "support/authors.rs"]
mod authors;

use datasets::mesh::{read_obj_mesh, render_mesh_depth, TriangleMesh};
use datasets::noise::{apply_sensor_model, SensorModel};
use datasets::scans::{match_sphere_names, pill_length_scale, FittedReference};
use eval::online::CalibrationMotion;
use hand_model::cylinder::CylinderModel;
use hand_model::keypoints::KeypointDef;
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

/// One scan placed in front of the camera (mm, right hand, where the default template's palm
/// is at the calibration motion's start): the mesh, the truth of every fingertip keypoint of
/// the template (index into the 21, position) and the pivot of the motion.
struct Scene {
    mesh: TriangleMesh,
    tips: Vec<(usize, Vector3<f64>)>,
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
        // A fingertip keypoint is the tip sphere's far surface point along the distal bone
        // (`PosedSphereMesh::keypoints`): the authors' center of the same sphere plus its radius
        // along the distal bone.
        let sphere = |name: &str| reference.sphere_names.iter().position(|n| n == name);
        let tips: Vec<(usize, Vector3<f64>)> = base
            .keypoints
            .iter()
            .enumerate()
            .filter_map(|(k, def)| match *def {
                // The thumb's tip sphere is `thumb_additional` in both models, placed
                // differently relative to `thumb_top` (the models' thumb tips differ by up to
                // 30 mm where their `thumb_top` centers agree within 2–3 mm): fingers only.
                KeypointDef::Tip { sphere: s, .. }
                    if !base.spheres[s].name.starts_with("thumb") =>
                {
                    Some((k, &base.spheres[s].name))
                }
                KeypointDef::Tip { .. } => None,
                KeypointDef::Joint { .. } => None,
            })
            .map(|(k, name)| {
                let top = sphere(name).unwrap();
                let c = place(&fitted[top]);
                // The distal bone's direction: from the nearest other sphere of the digit
                // (`index_middle` for `index_top`, `thumb_top` for `thumb_additional`).
                let digit = name.split('_').next().unwrap_or_default();
                let m = (0..fitted.len())
                    .filter(|&i| i != top && reference.sphere_names[i].starts_with(digit))
                    .map(|i| place(&fitted[i]))
                    .min_by(|a, b| (c - a).norm().total_cmp(&(c - b).norm()))
                    .unwrap();
                (k, c + (c - m).normalize() * reference.final_radii[top])
            })
            .collect();
        assert_eq!(tips.len(), 4);
        Scene {
            mesh: mesh.map(place),
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

/// Per frame: the mean fingertip keypoint error (mm) and, for a sphere-mesh, E_d2m (mm).
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
        keypoints: &[[f64; 3]],
        sphere_mesh: Option<(&PreprocessedFrame, &SphereMeshTemplate, &Pose)>,
    ) {
        let tip = scene
            .tips
            .iter()
            .map(|(k, p)| (Vector3::from(keypoints[*k]) - motion.transform_point(p)).norm())
            .sum::<f64>()
            / scene.tips.len() as f64;
        if !tip.is_finite() {
            eprintln!("NaN tip: {:?} {:?}", scene.tips, keypoints);
        }
        self.tips.push(tip);
        if let Some((frame, t, pose)) = sphere_mesh {
            let posed = PosedSphereMesh::new(t, pose);
            let elements: Vec<_> = t.elements.iter().map(|e| e.element).collect();
            let g = SphereMeshGeometry::new(&posed.spheres, &elements).unwrap();
            let d2m = frame
                .points
                .iter()
                .filter_map(|p| g.phi(p))
                .map(f64::abs)
                .sum::<f64>()
                / frame.points.len().max(1) as f64;
            self.d2m.push(d2m);
        }
    }

    /// Means over the last two thirds (the first frames place the hand); E_d2m NaN for the
    /// cylinders.
    fn summary(&self) -> (f64, f64) {
        let tail = |v: &[f64]| {
            let s = &v[v.len().min(v.len() / 3)..];
            s.iter().sum::<f64>() / s.len() as f64
        };
        (tail(&self.tips), tail(&self.d2m))
    }
}

/// The Ch. 2 tracker on the cylinders fitted to the default template (the `cylinders`
/// method), placed by its own hypotheses.
fn track_cylinders(scene: &Scene, frames: &[(PreprocessedFrame, Rigid3)]) -> Scores {
    let model = CylinderModel::from_sphere_mesh_with_wrist(&default_right_hand()).unwrap();
    let prior = PcaPrior::project_default();
    let mut tracker =
        htrack_icp::Tracker::new(&model, htrack_icp::TrackerConfig::default(), Some(&prior))
            .unwrap();
    let mut scores = Scores::default();
    for (k, (f, m)) in frames.iter().enumerate() {
        let rec = tracker.track(f, k as u64, k as f64 / FPS);
        assert!(rec.is_finite());
        scores.add(scene, m, &rec.keypoints, None);
    }
    scores
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
        scores.add(
            scene,
            m,
            &rec.keypoints,
            Some((f, template, tracker.pose())),
        );
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
        let model = (f, calib.template(), calib.pose());
        scores.add(scene, m, &out.record.keypoints, Some(model));
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
    for noise in ["none", "tof", "structured"] {
        println!(
            "{noise}: pose | fingertips mm (cylinders, default, own model, online) | E_d2m mm (the sphere-meshes)"
        );
        for fit in 0..reference.per_pose_centers.len() {
            let scene = Scene::load(&root, &reference, fit);
            let frames = frames(&scene, noise);
            let (tip_y, _) = track_cylinders(&scene, &frames).summary();
            let [(tip_d, d2m_d), (tip_o, d2m_o), (tip_c, d2m_c)] = [
                track_fixed(&scene, &frames, &default).summary(),
                track_fixed(&scene, &frames, &own).summary(),
                track_online(&scene, &frames).summary(),
            ];
            let pose = fit + 1;
            println!(
                "  pose{pose} | {tip_y:.2} {tip_d:.2} {tip_o:.2} {tip_c:.2} | {d2m_d:.2} {d2m_o:.2} {d2m_c:.2}"
            );
            // The data explain the hand's own model and the calibrated one better than the
            // default template, on every pose (under structured light: printed, module docs).
            if noise != "structured" {
                assert!(d2m_o < d2m_d && d2m_c < d2m_d, "pose{pose} {noise}: E_d2m");
            }
            // The open hands (poses 2 and 4; the segmentation once cut their fingertips as a
            // forearm stump) end with the fingertips found by the hand's own model and by
            // online calibration. The rest is printed, not asserted (module docs).
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
