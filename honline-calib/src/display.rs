//! Where on the hand the shape is still uncertain (issue 8 item 4, "a hand rendering colored by
//! certainty"): the marginal standard deviation of the shape parameters carried to the model's
//! elements, so that a rendering can paint each pill or wedge by how well its geometry is known.

use hand_model::kinematics::Pose;
use hand_model::spheremesh::{PosedSphereMesh, ShapeBasis, SphereMeshTemplate};
use hand_model::ModelError;

/// A step that moves a sphere by less than this (mm) does not count as touching it.
const TOUCH_MM: f64 = 1e-6;

/// Per element of `base`, the largest marginal standard deviation `1/√c_i` (mm) over the active
/// shape parameters `i` (indices into `basis`, `marginal[i]` their marginal certainty per mm²,
/// [`crate::OnlineFrame::marginal_certainty`]) that move one of the element's spheres at the rest
/// pose — the weakest parameter governing its geometry. Which parameters move which spheres is
/// found by applying a unit step of each to `beta` (the basis' effects are linear), so any basis
/// works. Parameters with zero certainty give `∞`; elements no active parameter touches give 0.
pub fn element_uncertainty(
    base: &SphereMeshTemplate,
    basis: &ShapeBasis,
    beta: &[f64],
    active: &[usize],
    marginal: &[f64],
) -> Result<Vec<f64>, ModelError> {
    let rest = Pose::zeros(&base.skeleton);
    let at = |b: &[f64]| -> Result<PosedSphereMesh, ModelError> {
        Ok(PosedSphereMesh::new(&basis.apply(base, b)?, &rest))
    };
    let reference = at(beta)?;
    let mut sphere_sigma = vec![0.0f64; base.spheres.len()];
    let mut stepped = beta.to_vec();
    for &i in active {
        let Some(&c) = marginal.get(i) else {
            continue;
        };
        let sigma = if c > 0.0 {
            1.0 / c.sqrt()
        } else {
            f64::INFINITY
        };
        stepped[i] += 1.0;
        let moved = at(&stepped);
        stepped[i] = beta[i];
        for (s, (a, b)) in moved?.spheres.iter().zip(&reference.spheres).enumerate() {
            let shift = (a.center - b.center).norm() + (a.radius - b.radius).abs();
            if shift > TOUCH_MM {
                sphere_sigma[s] = sphere_sigma[s].max(sigma);
            }
        }
    }
    Ok(base
        .elements
        .iter()
        .map(|e| {
            e.element
                .spheres()
                .iter()
                .map(|&s| sphere_sigma.get(s as usize).copied().unwrap_or(0.0))
                .fold(0.0, f64::max)
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use hand_model::spheremesh::default_right_hand;

    /// Only the elements a parameter reaches inherit its uncertainty: a weak middle-phalanx
    /// length of the middle finger leaves the thumb's elements at the others' level.
    #[test]
    fn a_weak_parameter_marks_only_its_elements() {
        let base = default_right_hand();
        let basis = ShapeBasis::honline(&base).unwrap();
        let names: Vec<&str> = basis.names().collect();
        let active: Vec<usize> = (0..basis.len()).collect();
        let weak = names
            .iter()
            .position(|n| *n == "middle_middle_length")
            .unwrap();
        let mut marginal = vec![100.0; basis.len()];
        marginal[weak] = 0.25;
        let beta = basis.template_values();
        let sigma = element_uncertainty(&base, &basis, &beta, &active, &marginal).unwrap();
        let bone = |e: usize| base.skeleton.bones()[base.elements[e].bone].name.clone();
        let weak_elements: Vec<String> = (0..sigma.len())
            .filter(|&e| (sigma[e] - 2.0).abs() < 1e-9)
            .map(bone)
            .collect();
        assert!(!weak_elements.is_empty());
        assert!(
            weak_elements.iter().all(|b| b.starts_with("middle")),
            "{weak_elements:?}"
        );
        assert!(sigma.iter().all(|&s| s == 2.0 || (s - 0.1).abs() < 1e-9));
    }
}
