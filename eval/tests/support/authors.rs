//! The original authors' final model of the real hand scans (`hand-scans-tkach/fitted`)
//! carried onto this project's skeleton — shared by the tests that compare with it
//! (`ch3_scans`) and that track it as another person's hand (`real_hand`).

use datasets::scans::{match_sphere_names, FittedReference};
use hand_model::kinematics::Pose;
use hand_model::math::fit_rigid;
use hand_model::spheremesh::{PosedSphereMesh, SphereMeshTemplate};
use hmodel_spheremesh::calibration::{fit_rest_spheres, SphereTarget};
use nalgebra::Vector3;

/// The authors' final model carried onto `base`'s skeleton ([`fit_rest_spheres`]): their rest
/// centers, rigidly aligned to the template's rest centers of the same names (mirrored first
/// when that aligns better: their files are geometrically left hands), as targets; aligned
/// again to the fitted template and refitted once, since the first alignment also sees the
/// differences of shape. Returns the template, the mean center and radius differences left,
/// and the number of matched spheres.
pub fn authors_on_skeleton(
    reference: &FittedReference,
    base: &SphereMeshTemplate,
) -> (SphereMeshTemplate, f64, f64, usize) {
    let corr = match_sphere_names(&reference.sphere_names, base);
    let theirs = |mirror: bool| -> Vec<Vector3<f64>> {
        corr.pairs
            .iter()
            .map(|&(r, _)| {
                let c = reference.final_centers[r];
                if mirror {
                    Vector3::new(-c.x, c.y, c.z)
                } else {
                    c
                }
            })
            .collect()
    };
    let rest_of = |t: &SphereMeshTemplate| -> Vec<Vector3<f64>> {
        let rest = PosedSphereMesh::new(t, &Pose::zeros(&t.skeleton));
        corr.pairs
            .iter()
            .map(|&(_, i)| rest.spheres[i].center)
            .collect()
    };
    let aligned = |from: &[Vector3<f64>], to: &[Vector3<f64>]| {
        let fit = fit_rigid(from, to).unwrap();
        let moved: Vec<Vector3<f64>> = from.iter().map(|p| fit.transform_point(p)).collect();
        let error = moved
            .iter()
            .zip(to)
            .map(|(a, b)| (a - b).norm())
            .sum::<f64>();
        (moved, error)
    };
    let target = rest_of(base);
    let (straight, mirrored) = (
        aligned(&theirs(false), &target),
        aligned(&theirs(true), &target),
    );
    let mirror = mirrored.1 < straight.1;
    let source = theirs(mirror);
    let mut centers = if mirror { mirrored.0 } else { straight.0 };
    let mut out = None;
    for _ in 0..2 {
        let targets: Vec<SphereTarget> = corr
            .pairs
            .iter()
            .zip(&centers)
            .map(|(&(r, i), c)| SphereTarget {
                sphere: i,
                center: *c,
                radius: reference.final_radii[r],
            })
            .collect();
        let (t, dc, dr) = fit_rest_spheres(base, &targets, 50).unwrap();
        centers = aligned(&source, &rest_of(&t)).0;
        out = Some((t, dc, dr, targets.len()));
    }
    out.unwrap()
}
