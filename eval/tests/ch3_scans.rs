//! Issue 6 "Real scans": the default template calibrated to the six photogrammetry scans of
//! one hand (`../shared/reference/hand-scans-tkach`, complete point clouds in an arbitrary
//! unit), compared with the original authors' fit: rest centers and radii after a similarity
//! alignment, and the d2m residual of both fits on the scans. Skips (and says so) when the
//! reference folder is absent.
//!
//! Measured ([`CalibrationConfig::clouds`], ring and pinky also searched as a pair; the
//! authors' mm): d2m of the hand parts ours [1.19, 1.10, 1.10, 0.81, 1.15, 1.23], the authors'
//! per-pose fits (every center free per pose) [1.36, 1.25, 1.29, 0.94, 1.15] on poses 1–5, the
//! authors' final model pose-fitted by our search (mean 1.84; 1.93 before its joints were held
//! on their spheres by `fit_rest_spheres`) vs ours (mean 1.10). With the
//! plain defaults and the single-digit search ours were [1.59, 1.50, 1.70, 0.98, 1.45, 1.59].
//! Rest centers vs the authors' final model after a similarity: 11.23 mm (plain defaults
//! 10.62 mm, the uncalibrated template 7.81 mm; the two models place their palm and wrist
//! spheres differently), radii 1.88 mm (1.40 mm). Per finger (session 21) the lengths agree
//! but our DIP joints sit 5–8 mm proximal: middle / distal sphere spacing ours 17.9 / 22.7 mm
//! (index), 22.8 / 23.5 (middle), 6.2 / 34.1 (pinky) against the authors' 25.4 / 15.8,
//! 28.7 / 19.6, 23.6 / 15.8; a β prior of 30 per mm² or free-sphere priors of 100 per mm² do
//! not move them back (index 19.1 / 20.9 and 20.7 / 23.9). Without ground truth for the scans
//! this is printed, not asserted.

use std::path::Path;

#[path = "support/authors.rs"]
mod authors;

use datasets::scans::{
    match_sphere_names, principal_extents, read_obj_points, scale_from_extents,
    sphere_principal_extents, FittedReference,
};
use hand_model::kinematics::Pose;
use hand_model::math::fit_similarity;
use hand_model::query::SphereMeshGeometry;
use hand_model::spheremesh::{default_right_hand, PosedSphereMesh, SphereMeshTemplate};
use hmodel_spheremesh::calibration::{
    calibrate, calibrate_clouds, refine_digits, split_forearm, CalibrationConfig, CalibrationFrame,
    CloudSearch,
};
use nalgebra::Vector3;

const ROOT: &str = "../../shared/reference/hand-scans-tkach";

/// Mean unsigned distance (mm) from `points` to the model surface.
fn d2m(geometry: &SphereMeshGeometry, points: &[Vector3<f64>]) -> f64 {
    points
        .iter()
        .filter_map(|p| geometry.phi(p))
        .map(f64::abs)
        .sum::<f64>()
        / points.len() as f64
}

#[test]
fn calibrates_to_the_real_scans_like_the_authors() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join(ROOT);
    if !root.join("scans/pose1.obj").exists() {
        println!("skipped: {} absent", root.display());
        return;
    }
    let right = default_right_hand();
    let scans: Vec<Vec<Vector3<f64>>> = (1..=6)
        .map(|k| read_obj_points(root.join(format!("scans/pose{k}.obj"))).unwrap())
        .collect();
    // One unit for all scans: the median of the per-scan extent estimates.
    let rest = PosedSphereMesh::new(&right, &Pose::zeros(&right.skeleton));
    let template_extents = sphere_principal_extents(&rest.spheres).unwrap();
    let mut units: Vec<f64> = scans
        .iter()
        .map(|s| {
            let hand = split_forearm(s).unwrap().hand;
            scale_from_extents(&principal_extents(&hand).unwrap(), &template_extents).unwrap()
        })
        .collect();
    units.sort_by(f64::total_cmp);
    let units_per_mm = units[units.len() / 2];
    let mm: Vec<Vec<Vector3<f64>>> = scans
        .iter()
        .map(|s| s.iter().map(|p| p / units_per_mm).collect())
        .collect();
    let search = CloudSearch::default();
    let run = calibrate_clouds(&right, &mm, &search, &CalibrationConfig::clouds()).unwrap();
    let (init, cal) = (&run.init, &run.calibration);
    println!(
        "initialization: {} hand (hypothesis energy {:.0} vs {:.0}); points kept after the forearm cut {:?} of {:?}; data energy per round (kept) {:?}",
        if init.mirrored { "left" } else { "right" },
        init.energies[0],
        init.energies[1],
        init.frames.iter().map(|f| f.points.len()).collect::<Vec<_>>(),
        scans.iter().map(Vec::len).collect::<Vec<_>>(),
        run.rounds.iter().map(|(e, k)| (e.round(), *k)).collect::<Vec<_>>()
    );
    let (base, frames) = (init.template.clone(), init.frames.clone());
    let poses: Vec<Pose> = init.poses.iter().map(|p| p.pose.clone()).collect();
    // Our residual on each scan, and the authors' (their per-pose centers with their final
    // radii, in their unit: 0.02806 scan units per mm from their pill lengths).
    let reference = FittedReference::load(root.join("fitted")).unwrap();
    // Distances in the authors' mm: ours are in our mm (scan units / units_per_mm), theirs in
    // scan units (their per-pose centers, their radii × 0.02806).
    let ours_on = |t: &SphereMeshTemplate, poses: &[Pose], clouds: &[Vec<Vector3<f64>>]| {
        clouds
            .iter()
            .zip(poses)
            .map(|(cloud, pose)| {
                let posed = PosedSphereMesh::new(t, pose);
                let elements: Vec<_> = t.elements.iter().map(|e| e.element).collect();
                let g = SphereMeshGeometry::new(&posed.spheres, &elements).unwrap();
                d2m(&g, cloud) * units_per_mm / 0.02806
            })
            .collect::<Vec<f64>>()
    };
    let theirs_on = |clouds: &[Vec<Vector3<f64>>]| {
        reference
            .per_pose_centers
            .iter()
            .zip(clouds)
            .map(|(centers, cloud)| {
                let g = reference.geometry(centers, 0.02806).unwrap();
                d2m(&g, cloud) / 0.02806
            })
            .collect::<Vec<f64>>()
    };
    let hand: Vec<Vec<Vector3<f64>>> = frames.iter().map(|f| f.points.clone()).collect();
    let hand_units: Vec<Vec<Vector3<f64>>> = hand
        .iter()
        .map(|c| c.iter().map(|p| p * units_per_mm).collect())
        .collect();
    let ours = ours_on(&cal.template, &cal.poses, &hand);
    let initial = ours_on(&base, &poses, &hand);
    let theirs = theirs_on(&hand_units);
    let ours_full = ours_on(&cal.template, &cal.poses, &mm);
    let theirs_full = theirs_on(&scans);

    // Rest centers and radii vs the authors' final model (mm), similarity-aligned over the
    // spheres both models name.
    let corr = match_sphere_names(&reference.sphere_names, &cal.template);
    let rest = PosedSphereMesh::new(&cal.template, &Pose::zeros(&cal.template.skeleton));
    let a: Vec<Vector3<f64>> = corr
        .pairs
        .iter()
        .map(|&(_, t)| rest.spheres[t].center)
        .collect();
    let b: Vec<Vector3<f64>> = corr
        .pairs
        .iter()
        .map(|&(r, _)| reference.final_centers[r])
        .collect();
    let sim = fit_similarity(&a, &b).unwrap();
    let n = corr.pairs.len() as f64;
    let centers = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (sim.transform_point(x) - y).norm())
        .sum::<f64>()
        / n;
    let radii = corr
        .pairs
        .iter()
        .map(|&(r, t)| (rest.spheres[t].radius * sim.scale - reference.final_radii[r]).abs())
        .sum::<f64>()
        / n;
    let default_rest = PosedSphereMesh::new(&base, &Pose::zeros(&base.skeleton));
    let a0: Vec<Vector3<f64>> = corr
        .pairs
        .iter()
        .map(|&(_, t)| default_rest.spheres[t].center)
        .collect();
    let sim0 = fit_similarity(&a0, &b).unwrap();
    let centers0 = a0
        .iter()
        .zip(&b)
        .map(|(x, y)| (sim0.transform_point(x) - y).norm())
        .sum::<f64>()
        / n;
    println!(
        "scans: {units_per_mm:.5} units/mm estimated (authors 0.02806); hypothesis energies {:?}; calibration {:.2} s, {} iterations",
        init.poses.iter().map(|p| p.energy.round()).collect::<Vec<_>>(),
        cal.seconds,
        cal.iterations.len()
    );
    println!(
        "d2m on the scans without forearm (mm): ours {ours:.2?} (initial {initial:.2?}), authors {theirs:.2?}"
    );
    println!(
        "d2m on the whole scans, forearm included (mm): ours {ours_full:.2?}, authors {theirs_full:.2?}"
    );
    // Posed centers per scan vs the authors' per-pose centers (each in its scan's frame and
    // units): a similarity per pose, distances converted to the authors' mm.
    let per_pose: Vec<f64> = reference
        .per_pose_centers
        .iter()
        .enumerate()
        .map(|(k, centers)| {
            let posed = PosedSphereMesh::new(&cal.template, &cal.poses[k]);
            let pa: Vec<Vector3<f64>> = corr
                .pairs
                .iter()
                .map(|&(_, t)| posed.spheres[t].center)
                .collect();
            let pb: Vec<Vector3<f64>> = corr.pairs.iter().map(|&(r, _)| centers[r]).collect();
            let sim = fit_similarity(&pa, &pb).unwrap();
            pa.iter()
                .zip(&pb)
                .map(|(x, y)| (sim.transform_point(x) - y).norm())
                .sum::<f64>()
                / pa.len() as f64
                / 0.02806
        })
        .collect();
    println!("posed centers vs the authors' per-pose fits (mm, per pose): {per_pose:.2?}");
    println!(
        "vs the authors' final model ({} spheres, similarity scale {:.3}): centers {centers:.2} mm (default template {centers0:.2} mm), radii {radii:.2} mm",
        corr.pairs.len(),
        sim.scale
    );
    // Where the two fits put each finger's joints: the spacing of its four spheres, ours
    // scaled by the similarity, theirs in their mm.
    for finger in ["thumb", "index", "middle", "ring", "pinky"] {
        let at = |part: &str| {
            let name = format!("{finger}_{part}");
            corr.pairs
                .iter()
                .position(|&(r, _)| reference.sphere_names[r] == name)
        };
        let ks: Vec<usize> = ["base", "bottom", "middle", "top"]
            .iter()
            .filter_map(|p| at(p))
            .collect();
        let spacing = |pts: &[Vector3<f64>], scale: f64| -> Vec<f64> {
            ks.windows(2)
                .map(|w| (pts[w[1]] - pts[w[0]]).norm() * scale)
                .collect()
        };
        println!(
            "{finger}: sphere spacing base→bottom→middle→top ours {:.1?}, the authors' {:.1?} mm",
            spacing(&a, sim.scale),
            spacing(&b, 1.0)
        );
    }
    // The authors' final model on our skeleton (shape fixed), posed on each scan by the same
    // pose search as ours: the like-for-like comparison (their per-pose fits above free every
    // center per pose; ours is one kinematic model).
    let transplant = authors::authors_on_skeleton(&reference, &base);
    println!(
        "authors' final model on our skeleton: rest centers within {:.2} mm, radii {:.2} mm of theirs ({} spheres)",
        transplant.1, transplant.2, transplant.3
    );
    let to_authors_mm = 1.0 / 0.02806;
    let hand_authors_mm: Vec<Vec<Vector3<f64>>> = hand_units
        .iter()
        .map(|c| c.iter().map(|p| p * to_authors_mm).collect())
        .collect();
    // Each scan's pose: the per-digit search from our calibrated pose (its translation brought
    // to the authors' mm; the whole-hand hypothesis search is left out for time, the per-digit
    // one still offers every digit its alternatives), then the calibration's own energy with
    // the shape held.
    let to_theirs = units_per_mm / 0.02806;
    let authors_posed: Vec<f64> = hand_authors_mm
        .iter()
        .zip(&cal.poses)
        .map(|(hand, ours)| {
            let mut start = ours.clone();
            for name in ["global_tx", "global_ty", "global_tz"] {
                if let Some(i) = base.skeleton.dof_index(name) {
                    start.values[i] *= to_theirs;
                }
            }
            let refined = refine_digits(&transplant.0, hand, &start, &search).unwrap();
            let config = CalibrationConfig {
                fit_shape: false,
                ..CalibrationConfig::clouds()
            };
            let frame = CalibrationFrame::cloud(hand.clone());
            let fit = calibrate(&transplant.0, &[frame], &[refined.pose], &config).unwrap();
            let posed = PosedSphereMesh::new(&transplant.0, &fit.poses[0]);
            let elements: Vec<_> = transplant.0.elements.iter().map(|e| e.element).collect();
            d2m(
                &SphereMeshGeometry::new(&posed.spheres, &elements).unwrap(),
                hand,
            )
        })
        .collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    println!(
        "d2m without forearm (mm), same skeleton and pose search: ours {ours:.2?} (mean {:.2}), the authors' final model pose-fitted {authors_posed:.2?} (mean {:.2})",
        mean(&ours),
        mean(&authors_posed)
    );
    assert!(ours.iter().all(|d| d.is_finite()));
    assert!(
        transplant.1 < 3.0,
        "the authors' model did not carry onto our skeleton ({:.2} mm)",
        transplant.1
    );
    // Ours is fitted to these scans, theirs only posed: ours must not be worse on average by
    // more than 0.25 mm (a shape calibrated on the scans that explains them worse than a fixed
    // shape fitted elsewhere would be a failed calibration).
    assert!(
        mean(&ours) <= mean(&authors_posed) + 0.25,
        "ours {:.2} mm vs the authors' final model pose-fitted {:.2} mm",
        mean(&ours),
        mean(&authors_posed)
    );
    assert!(
        mean(&ours) < mean(&initial),
        "calibration did not improve the fit"
    );
    // Issue 6: ours not worse than the authors' per-pose fits on any scan they fitted.
    for (k, (o, t)) in ours.iter().zip(&theirs).enumerate() {
        assert!(
            o <= t,
            "pose {}: ours {o:.3} mm vs the authors' {t:.3} mm",
            k + 1
        );
    }
    // The shape stays near the authors' (measured 11.58 mm; the uncalibrated template 7.81).
    assert!(
        centers < 12.5,
        "rest centers {centers:.2} mm from the authors'"
    );
    let _ = (centers0, radii);
}
