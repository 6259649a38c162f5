//! Skeleton Jacobians of sphere-mesh surface points (thesis Eq. 3.7 chained with Eq. 3.1).
//!
//! A correspondence on an element is `q = Σ w_i c_i + (Σ w_i r_i)·n` over the element's spheres
//! ([`hand_model::query::Projection`]); the trackers hold `w` and `n` fixed, so
//! `∂q/∂θ_d = Σ w_i ∂c_i/∂θ_d`. A sphere attached to bone `b` moves rigidly with `b`'s chain, and
//! a blended sphere is a fixed mix of such spheres. Because a DOF's column is affine in the
//! point (`a × (p − o)` for rotations, `a` for translations), the weighted sum collapses to one
//! cross product per DOF: `Σ_i w_i a × (c_i − o) = a × (P − W o)` with `W = Σ w_i`, `P = Σ w_i
//! c_i` over the spheres whose chain contains the DOF. [`FootpointJacobian`] precomputes, per
//! element, the union of its spheres' chains and for each sphere the mask of those DOFs, so one
//! footpoint costs one accumulation pass and one cross product per DOF — no allocation, no
//! dynamic dispatch (the hmodel GPU kernel used the element's "pose unit" bone alone, an
//! approximation on membranes and the thumb web; this is exact).

use hand_model::spheremesh::{Attachment, PosedSphereMesh, SphereMeshTemplate};
use hand_model::ModelError;
use nalgebra::Vector3;

/// Most DOFs that move one element (the union of its spheres' chains; the hand has 34 at most).
pub const MAX_ELEMENT_DOFS: usize = 32;

/// One bone-attached sphere contributing to a template sphere, with its share and the DOFs of
/// the element that move it.
#[derive(Copy, Clone, Debug, PartialEq)]
struct Part {
    base: u32,
    weight: f64,
    mask: u32,
}

#[derive(Clone, Debug, PartialEq)]
struct ElementJacobian {
    /// Sorted union of the chains of the element's spheres.
    dofs: Vec<usize>,
    /// The element's template spheres, in element order.
    spheres: Vec<u32>,
    /// Per element sphere, its bone-attached parts.
    parts: Vec<Vec<Part>>,
    /// Every sphere rides on a bone whose chain is all of `dofs` (a rigid element: one bone,
    /// or spheres on bones with the same chain): then `∂q/∂θ_d` is the column of the skeleton
    /// point `s = Σ w_i c_i` itself.
    rigid: bool,
}

/// Per element, what moves its surface points (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct FootpointJacobian {
    elements: Vec<ElementJacobian>,
}

impl FootpointJacobian {
    /// Precompute the DOF sets of every element of `template`. An error when an element is moved
    /// by more than [`MAX_ELEMENT_DOFS`] DOFs or refers to a sphere or bone out of range.
    pub fn new(template: &SphereMeshTemplate) -> Result<Self, ModelError> {
        let sk = &template.skeleton;
        let invalid = |reason: String| ModelError::InvalidArgument {
            name: "template",
            reason,
        };
        let bases = |s: usize| -> Result<Vec<(usize, f64)>, ModelError> {
            let def = template
                .spheres
                .get(s)
                .ok_or_else(|| invalid(format!("sphere {s} out of range")))?;
            Ok(match &def.attachment {
                Attachment::Bone { .. } => vec![(s, 1.0)],
                Attachment::Blend { parts } => parts.clone(),
            })
        };
        let bone_of = |s: usize| -> Result<usize, ModelError> {
            match template.spheres.get(s).map(|d| &d.attachment) {
                Some(Attachment::Bone { bone, .. }) if *bone < sk.bones().len() => Ok(*bone),
                _ => Err(invalid(format!(
                    "sphere {s} is not attached to a valid bone"
                ))),
            }
        };
        let mut elements = Vec::with_capacity(template.elements.len());
        for (e, def) in template.elements.iter().enumerate() {
            let spheres: Vec<u32> = def.element.spheres().to_vec();
            let mut dofs: Vec<usize> = Vec::new();
            for &s in &spheres {
                for (b, _) in bases(s as usize)? {
                    dofs.extend_from_slice(sk.chain(bone_of(b)?));
                }
            }
            dofs.sort_unstable();
            dofs.dedup();
            if dofs.len() > MAX_ELEMENT_DOFS {
                return Err(invalid(format!(
                    "element {e} is moved by {} DOFs (at most {MAX_ELEMENT_DOFS})",
                    dofs.len()
                )));
            }
            let mut parts = Vec::with_capacity(spheres.len());
            for &s in &spheres {
                let mut list = Vec::new();
                for (b, weight) in bases(s as usize)? {
                    let chain = sk.chain(bone_of(b)?);
                    let mask = dofs
                        .iter()
                        .enumerate()
                        .filter(|(_, d)| chain.contains(d))
                        .fold(0u32, |m, (k, _)| m | (1 << k));
                    list.push(Part {
                        base: b as u32,
                        weight,
                        mask,
                    });
                }
                parts.push(list);
            }
            let full = if dofs.len() == 32 {
                u32::MAX
            } else {
                (1u32 << dofs.len()) - 1
            };
            let rigid = parts.iter().flatten().all(|p| p.mask == full);
            elements.push(ElementJacobian {
                dofs,
                spheres,
                parts,
                rigid,
            });
        }
        Ok(Self { elements })
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.elements.len()
    }

    /// Whether the template has no elements.
    pub fn is_empty(&self) -> bool {
        self.elements.is_empty()
    }

    /// The DOFs that move element `element` (sorted), empty when out of range.
    pub fn dofs(&self, element: usize) -> &[usize] {
        self.elements.get(element).map_or(&[], |e| &e.dofs)
    }

    /// The columns `∂q/∂θ_d` for `d` in [`dofs`](Self::dofs)`(element)` of the point
    /// `q = Σ w_i c_i + r·n` with `spheres`/`weights` as in a
    /// [`Projection`](hand_model::query::Projection) on that element (sphere ids that are not
    /// the element's contribute nothing), written to `out[..k]`; returns the DOF list (length
    /// `k`). `posed` must be the template posed at the current θ.
    pub fn columns<'a>(
        &'a self,
        posed: &PosedSphereMesh,
        element: usize,
        spheres: &[u32; 3],
        weights: &[f64; 3],
        out: &mut [Vector3<f64>; MAX_ELEMENT_DOFS],
    ) -> &'a [usize] {
        let Some(ej) = self.elements.get(element) else {
            return &[];
        };
        let k = ej.dofs.len();
        let sk = &posed.skeleton;
        if ej.rigid {
            // Weights sum to 1 over the element's own spheres (blends included).
            let mut p = Vector3::zeros();
            let mut wsum = 0.0;
            for (&s, &w) in spheres.iter().zip(weights) {
                if w != 0.0 && ej.spheres.contains(&s) {
                    p += posed.spheres[s as usize].center * w;
                    wsum += w;
                }
            }
            for (o, &d) in out.iter_mut().zip(&ej.dofs) {
                *o = if wsum == 0.0 {
                    Vector3::zeros()
                } else {
                    sk.column(d, &(p / wsum)) * wsum
                };
            }
            return &ej.dofs[..k];
        }
        let mut wsum = [0.0f64; MAX_ELEMENT_DOFS];
        let mut psum = [Vector3::zeros(); MAX_ELEMENT_DOFS];
        for (&s, &w) in spheres.iter().zip(weights) {
            if w == 0.0 {
                continue;
            }
            let Some(slot) = ej.spheres.iter().position(|&x| x == s) else {
                continue;
            };
            for part in &ej.parts[slot] {
                let ww = w * part.weight;
                let c = posed.spheres[part.base as usize].center * ww;
                let mut mask = part.mask;
                while mask != 0 {
                    let j = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    wsum[j] += ww;
                    psum[j] += c;
                }
            }
        }
        for (j, &d) in ej.dofs.iter().enumerate() {
            out[j] = if wsum[j] == 0.0 {
                Vector3::zeros()
            } else {
                // column(d, P/W)·W = a × (P − W o) (or W a for a translation).
                sk.column(d, &(psum[j] / wsum[j])) * wsum[j]
            };
        }
        &ej.dofs[..k]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hand_model::kinematics::Pose;
    use hand_model::query::SphereMeshGeometry;
    use hand_model::spheremesh::default_right_hand;
    use hand_model::testing::{central_difference, relative_error};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Columns against central differences of the re-evaluated footpoint, on every element of
    /// the default hand (blended spheres and multi-bone elements included).
    #[test]
    fn columns_match_finite_differences() {
        let t = default_right_hand();
        let sk = &t.skeleton;
        let jac = FootpointJacobian::new(&t).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut pose = Pose::zeros(sk);
        for v in pose.values.iter_mut() {
            *v = rng.random_range(-0.3..0.3);
        }
        pose.set(sk, "global_tz", 400.0).unwrap();
        let posed = PosedSphereMesh::new(&t, &pose);
        let elements: Vec<_> = t.elements.iter().map(|e| e.element).collect();
        let geo = SphereMeshGeometry::new(&posed.spheres, &elements).unwrap();
        let mut out = [Vector3::zeros(); MAX_ELEMENT_DOFS];
        let mut worst = 0.0f64;
        for (e, el) in elements.iter().enumerate() {
            let c = posed.spheres[el.spheres()[0] as usize].center;
            let p = c + Vector3::new(3.0, -20.0, 25.0);
            let pr = geo.project_on_element(e, &p).unwrap();
            let dofs = jac.columns(&posed, e, &pr.spheres, &pr.weights, &mut out);
            for d in 0..sk.num_dofs() {
                let f = |x: f64| {
                    let mut q = pose.clone();
                    q.retract_in_place(sk, &unit(sk.num_dofs(), d, x));
                    let ps = PosedSphereMesh::new(&t, &q);
                    // q with w and n held fixed.
                    let s: Vector3<f64> = (0..3)
                        .map(|i| ps.spheres[pr.spheres[i] as usize].center * pr.weights[i])
                        .sum();
                    s
                };
                let fd = central_difference(1e-6, f);
                let got = dofs
                    .iter()
                    .position(|&x| x == d)
                    .map_or(Vector3::zeros(), |k| out[k]);
                worst = worst.max(relative_error(&fd, &got, 1.0));
            }
        }
        assert!(worst < 1e-6, "worst relative error {worst}");
    }

    fn unit(n: usize, d: usize, x: f64) -> Vec<f64> {
        let mut v = vec![0.0; n];
        v[d] = x;
        v
    }
}
