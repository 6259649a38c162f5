//! Shape-parameter error E_β (thesis §4.4.2, Eq. 4.16): the mean absolute difference between an
//! estimated and the true honline shape vector β (mm) over a selected subset `M` of its entries,
//! `E_β = |M|⁻¹ Σ_{m∈M} |β_[m] − β̄_[m]|`.

use hand_model::spheremesh::{ShapeBasis, ShapeParam};

use crate::error::{EvalError, Result};

/// E_β (Eq. 4.16) over the entries `subset` of `estimate` and `truth` (same layout, e.g. the
/// [`ShapeBasis::honline`] order). Refused: vectors of different lengths, an empty subset, an
/// index out of range, a non-finite selected value.
pub fn beta_error(estimate: &[f64], truth: &[f64], subset: &[usize]) -> Result<f64> {
    if estimate.len() != truth.len() {
        return Err(EvalError::arg(
            "beta",
            format!(
                "estimate has {} entries, truth {}",
                estimate.len(),
                truth.len()
            ),
        ));
    }
    if subset.is_empty() {
        return Err(EvalError::arg("subset", "E_β needs at least one entry"));
    }
    let mut sum = 0.0;
    for &m in subset {
        let (Some(a), Some(b)) = (estimate.get(m), truth.get(m)) else {
            return Err(EvalError::arg(
                "subset",
                format!("index {m} out of range (β has {} entries)", truth.len()),
            ));
        };
        if !(a.is_finite() && b.is_finite()) {
            return Err(EvalError::arg(
                "beta",
                format!("entry {m} is not finite ({a} vs {b})"),
            ));
        }
        sum += (a - b).abs();
    }
    Ok(sum / subset.len() as f64)
}

/// The indices of the β entries of `basis` that `keep` selects (the subset `M` of Eq. 4.16,
/// e.g. the phalanx lengths, or every entry but the radii).
pub fn beta_subset(basis: &ShapeBasis, keep: impl Fn(&ShapeParam) -> bool) -> Vec<usize> {
    basis
        .params
        .iter()
        .enumerate()
        .filter(|(_, p)| keep(p))
        .map(|(i, _)| i)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use hand_model::spheremesh::{default_right_hand, ShapeKind};

    #[test]
    fn beta_error_by_hand_and_on_bad_input() {
        let truth = [10.0, 20.0, 30.0];
        let est = [11.0, 17.0, 30.5];
        assert_eq!(beta_error(&est, &truth, &[0, 1, 2]).unwrap(), 1.5);
        assert_eq!(beta_error(&est, &truth, &[1]).unwrap(), 3.0);
        assert!(beta_error(&est, &truth[..2], &[0]).is_err());
        assert!(beta_error(&est, &truth, &[]).is_err());
        let e = beta_error(&est, &truth, &[3]).unwrap_err();
        assert!(e.to_string().contains("index 3"), "{e}");
        assert!(beta_error(&[f64::NAN, 0.0, 0.0], &truth, &[0]).is_err());
        // An unselected NaN does not matter.
        assert_eq!(
            beta_error(&[f64::NAN, 20.0, 30.0], &truth, &[1, 2]).unwrap(),
            0.0
        );
    }

    #[test]
    fn subsets_of_the_honline_basis() {
        let basis = ShapeBasis::honline(&default_right_hand()).unwrap();
        let all = beta_subset(&basis, |_| true);
        assert_eq!(all.len(), basis.len());
        let lengths = beta_subset(&basis, |p| p.kind == ShapeKind::PhalangeLength);
        assert!(!lengths.is_empty() && lengths.len() < basis.len());
        // Scaling every length by 1.1 gives an error of 10 % of their mean template value.
        let truth = basis.template_values();
        let mut est = truth.clone();
        for &i in &lengths {
            est[i] *= 1.1;
        }
        let mean_len = lengths.iter().map(|&i| truth[i]).sum::<f64>() / lengths.len() as f64;
        let e = beta_error(&est, &truth, &lengths).unwrap();
        assert!((e - 0.1 * mean_len).abs() < 1e-9);
        assert_eq!(
            beta_error(
                &est,
                &truth,
                &beta_subset(&basis, |p| p.kind == ShapeKind::Radius)
            )
            .unwrap(),
            0.0
        );
    }
}
