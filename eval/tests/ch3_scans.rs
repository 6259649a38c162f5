//! Issue 6 "Real scans": the default template calibrated to the six photogrammetry scans of
//! one hand (`../shared/reference/hand-scans-tkach`, complete point clouds in an arbitrary
//! unit), compared with the original authors' fit: rest centers and radii after a similarity
//! alignment, and the d2m residual of both fits on the scans. Skips (and says so) when the
//! reference folder is absent.

use std::path::Path;

use datasets::scans::{
    match_sphere_names, principal_extents, read_obj_points, scale_from_extents,
    sphere_principal_extents, FittedReference,
};
use eval::real_frame::{best_energy, place_pose};
use hand_model::kinematics::Pose;
use hand_model::math::fit_similarity;
use hand_model::query::SphereMeshGeometry;
use hand_model::spheremesh::{default_right_hand, PosedSphereMesh, SphereMeshTemplate};
use hmodel_spheremesh::calibration::{calibrate, CalibrationConfig, CalibrationFrame};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};

const ROOT: &str = "../../shared/reference/hand-scans-tkach";

/// Centroid and principal axes (columns, largest spread first) of a point set.
fn frame_of(points: &[Vector3<f64>]) -> (Vector3<f64>, Matrix3<f64>) {
    let n = points.len() as f64;
    let c = points.iter().sum::<Vector3<f64>>() / n;
    let mut cov = Matrix3::zeros();
    for p in points {
        cov += (p - c) * (p - c).transpose();
    }
    let eig = SymmetricEigen::new(cov);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let axes = Matrix3::from_columns(&order.map(|i| eig.eigenvectors.column(i).into_owned()));
    (c, axes)
}

/// Initial pose of one scan (mm): the template's rest principal frame turned onto the scan's
/// (every axis assignment and sign giving a proper rotation), flat, half-bent or curled fingers;
/// each solved for the pose alone, the
/// one with the lowest energy kept.
fn initial_pose(base: &SphereMeshTemplate, frame: &CalibrationFrame) -> (Pose, f64) {
    let sk = &base.skeleton;
    let rest = PosedSphereMesh::new(base, &Pose::zeros(sk));
    let centers: Vec<Vector3<f64>> = rest.spheres.iter().map(|s| s.center).collect();
    let (_, at) = frame_of(&centers);
    let (cs, as_) = frame_of(&frame.points);
    let config = CalibrationConfig {
        fit_shape: false,
        iterations: 15,
        ..CalibrationConfig::default()
    };
    let mut best: Option<(Pose, f64)> = None;
    for signs in [
        [1.0, 1.0, 1.0],
        [1.0, -1.0, -1.0],
        [-1.0, 1.0, -1.0],
        [-1.0, -1.0, 1.0],
    ] {
        let flip = Matrix3::from_diagonal(&Vector3::from(signs));
        let mut r = as_ * flip * at.transpose();
        if r.determinant() < 0.0 {
            r = -r;
        }
        for bend in [0.0, 0.5] {
            let mut p = Pose::zeros(sk);
            for d in sk.dofs() {
                if d.name.contains("flex") && !d.name.starts_with("global") {
                    p.set(sk, &d.name, bend).unwrap();
                }
            }
            p.clamp_to_limits(sk);
            place_pose(base, &mut p, &r, &cs);
            let fit = calibrate(base, std::slice::from_ref(frame), &[p], &config).unwrap();
            let e = best_energy(&fit);
            if best.as_ref().is_none_or(|(_, b)| e < *b) {
                best = Some((fit.poses[0].clone(), e));
            }
        }
    }
    best.expect("hypotheses")
}

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
        .map(|s| scale_from_extents(&principal_extents(s).unwrap(), &template_extents).unwrap())
        .collect();
    units.sort_by(f64::total_cmp);
    let units_per_mm = units[units.len() / 2];
    let frames: Vec<CalibrationFrame> = scans
        .iter()
        .map(|s| CalibrationFrame::cloud(s.iter().map(|p| p / units_per_mm).collect()))
        .collect();
    // Handedness by fit: the scanned hand is whichever of the default hand and its mirror
    // image explains the scans better at the initialization.
    let left = right.mirrored().unwrap();
    let fit = |t: &SphereMeshTemplate| -> Vec<(Pose, f64)> {
        frames.iter().map(|f| initial_pose(t, f)).collect()
    };
    let total = |v: &[(Pose, f64)]| v.iter().map(|(_, e)| e).sum::<f64>();
    let (fit_right, fit_left) = (fit(&right), fit(&left));
    println!(
        "initialization energy: right hand {:.0}, left hand {:.0}",
        total(&fit_right),
        total(&fit_left)
    );
    let (base, inits) = if total(&fit_left) < total(&fit_right) {
        (left, fit_left)
    } else {
        (right, fit_right)
    };
    let poses: Vec<Pose> = inits.iter().map(|(p, _)| p.clone()).collect();
    let cal = calibrate(&base, &frames, &poses, &CalibrationConfig::default()).unwrap();

    // Our residual on each scan, and the authors' (their per-pose centers with their final
    // radii, in their unit: 0.02806 scan units per mm from their pill lengths).
    let reference = FittedReference::load(root.join("fitted")).unwrap();
    // mm of our scale → scan units → the authors' mm.
    let residual = |t: &SphereMeshTemplate, poses: &[Pose]| -> Vec<f64> {
        frames
            .iter()
            .zip(poses)
            .map(|(frame, pose)| {
                let posed = PosedSphereMesh::new(t, pose);
                let elements: Vec<_> = t.elements.iter().map(|e| e.element).collect();
                let g = SphereMeshGeometry::new(&posed.spheres, &elements).unwrap();
                d2m(&g, &frame.points) * units_per_mm / 0.02806
            })
            .collect()
    };
    let ours = residual(&cal.template, &cal.poses);
    let initial = residual(&base, &poses);
    let theirs: Vec<f64> = reference
        .per_pose_centers
        .iter()
        .zip(&scans)
        .map(|(centers, scan)| {
            let g = reference.geometry(centers, 0.02806).unwrap();
            d2m(&g, scan) / 0.02806
        })
        .collect();

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
        "scans: {units_per_mm:.5} units/mm estimated (authors 0.02806); init energies {:?}; calibration {:.2} s, {} iterations",
        inits.iter().map(|(_, e)| e.round()).collect::<Vec<_>>(),
        cal.seconds,
        cal.iterations.len()
    );
    println!(
        "d2m on the scans (mm): ours {ours:.2?} (initial {initial:.2?}), authors {theirs:.2?}"
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
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    assert!(ours.iter().all(|d| d.is_finite()));
    assert!(
        mean(&ours) < mean(&initial),
        "calibration did not improve the fit"
    );
    let _ = (centers, centers0, radii, mean(&theirs));
}
