//! Self-collision between the finger pills of the sphere-mesh (thesis Eq. 3.3 "collision",
//! the E_collision of Tagliasacchi et al. 2015 Eq. 2.7 on sphere-mesh elements).

use hand_model::kinematics::Pose;
use hand_model::query::segment_closest_params;
use hand_model::shape::Element;
use hand_model::solver::{EnergyTerm, NormalEquations, PoseContext, TermError, TermStats};
use hand_model::spheremesh::{PosedSphereMesh, SphereMeshTemplate};
use nalgebra::{Matrix2, Vector3};
use serde::{Deserialize, Serialize};

use crate::context::TrackingCtx;
use crate::jacobian::{FootpointJacobian, MAX_ELEMENT_DOFS};

/// Settings of [`Collision`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CollisionParams {
    /// τ_collision (thesis §3.6 "Reproducibility": 1e3; hmodel 1e3), per mm² of penetration.
    pub weight: f64,
    /// Penetration tolerated beyond the rest overlap (mm): soft tissue at a contact between
    /// fingers compresses, so the rigid pills of a well-fitted model overlap a little in true
    /// contact poses (a fist); only deeper penetration is penalized.
    pub tolerance: f64,
}

impl Default for CollisionParams {
    fn default() -> Self {
        Self {
            weight: 1e3,
            tolerance: 0.0,
        }
    }
}

/// A candidate pair of pills and the overlap it has at the rest pose.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct PillPair {
    /// First element (a pill).
    pub a: usize,
    /// Second element (a pill).
    pub b: usize,
    /// Penetration (mm) at θ = 0, tolerated (0 when apart).
    pub rest_overlap: f64,
}

/// The contact of two tapered pills `(a0, r_a0)–(a1, r_a1)` and `(b0, r_b0)–(b1, r_b1)`: the
/// closest points of their axes, the penetration `r_a(s) + r_b(t) − ‖A(s) − B(t)‖` and its
/// gradient with respect to the four sphere centers (radii fixed).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct PillContact {
    /// Axial parameters `(s, t) ∈ [0, 1]²`.
    pub params: (f64, f64),
    /// Positive when the pills interpenetrate (mm).
    pub penetration: f64,
    /// `∂pen/∂a0`, `∂pen/∂a1`, `∂pen/∂b0`, `∂pen/∂b1`.
    pub gradient: [Vector3<f64>; 4],
}

/// [`PillContact`] of two pills given as `[center0, center1]` and `[radius0, radius1]`; `None`
/// when the axes meet (no direction) or the input is not finite.
///
/// The gradient: with `n = (A − B)/‖A − B‖`, `∂pen = r_a' ∂s + r_b' ∂t − nᵀ((1−s)∂a0 + s ∂a1 −
/// (1−t)∂b0 − t ∂b1)` (the axis tangents drop out by the optimality of free parameters, and a
/// clamped parameter does not move); `∂s`, `∂t` of the free parameters follow from
/// differentiating their optimality conditions `uᵀ(A − B) = 0`, `vᵀ(A − B) = 0`.
pub fn pill_contact(
    a: [Vector3<f64>; 2],
    ra: [f64; 2],
    b: [Vector3<f64>; 2],
    rb: [f64; 2],
) -> Option<PillContact> {
    let (u, v) = (a[1] - a[0], b[1] - b[0]);
    let (s, t) = segment_closest_params(&a[0], &u, &b[0], &v);
    let diff = (a[0] + u * s) - (b[0] + v * t);
    let d = diff.norm();
    if !(d > 1e-9 && d.is_finite()) {
        return None;
    }
    let n = diff / d;
    let (dra, drb) = (ra[1] - ra[0], rb[1] - rb[0]);
    let penetration = ra[0] + dra * s + rb[0] + drb * t - d;
    // ∂F/∂endpoint for F = (uᵀdiff, −vᵀdiff), per endpoint (a0, a1, b0, b1).
    let df1 = [u * (1.0 - s) - diff, diff + u * s, -u * (1.0 - t), -u * t];
    let df2 = [-v * (1.0 - s), -v * s, diff + v * (1.0 - t), v * t - diff];
    let free_s = s > 0.0 && s < 1.0;
    let free_t = t > 0.0 && t < 1.0;
    let h = Matrix2::new(u.dot(&u), -u.dot(&v), -u.dot(&v), v.dot(&v));
    let h_inv = (free_s && free_t).then(|| h.try_inverse()).flatten();
    let base = [-n * (1.0 - s), -n * s, n * (1.0 - t), n * t];
    let mut gradient = base;
    for k in 0..4 {
        // ∂(s, t)/∂endpoint as two row vectors.
        let (ds, dt) = match h_inv {
            Some(hi) => (
                -(df1[k] * hi[(0, 0)] + df2[k] * hi[(0, 1)]),
                -(df1[k] * hi[(1, 0)] + df2[k] * hi[(1, 1)]),
            ),
            None if free_s && h[(0, 0)] > 0.0 => (-df1[k] / h[(0, 0)], Vector3::zeros()),
            None if free_t && h[(1, 1)] > 0.0 => (Vector3::zeros(), -df2[k] / h[(1, 1)]),
            None => (Vector3::zeros(), Vector3::zeros()),
        };
        gradient[k] += ds * dra + dt * drb;
    }
    penetration.is_finite().then_some(PillContact {
        params: (s, t),
        penetration,
        gradient,
    })
}

/// E_collision on the sphere-mesh: `τ Σ_pairs max(0, pen − pen_rest)²` over pairs of finger
/// pills (Eq. 2.7 with the closest points of the pill axes and the radii interpolated there,
/// as hmodel's Collision.cpp, ANCHOR-FACTS §5.5).
///
/// **Pairs** ([`Collision::new`]): every two pills that share no sphere and whose "pose unit"
/// bones ([`hand_model::spheremesh::ElementDef::bone`]) are neither equal nor parent and child
/// — pills of different digits, or of the same digit two phalanges apart. Wedges (palm,
/// membranes, wrist) take no part, as the palm in htrack/hmodel. The rest pose is taken as
/// collision-free: a pair already overlapping at θ = 0 counts only the penetration beyond it.
///
/// **Row**: one per colliding pair, residual `pen − pen_rest`, Jacobian `Σ_k (∂pen/∂c_k)ᵀ
/// ∂c_k/∂θ` over the four sphere centers ([`pill_contact`] gives the exact gradient, the
/// center Jacobians are [`FootpointJacobian`]'s). hmodel's under-relaxation `fraction` is not
/// applied (see htrack-icp's `CollisionParams` for why).
#[derive(Clone, Debug, PartialEq)]
pub struct Collision {
    params: CollisionParams,
    pairs: Vec<PillPair>,
}

/// Most DOFs of the hand skeletons (34 for honline's).
const MAX_DOFS: usize = 64;

impl Collision {
    /// The term for `template` (the pair list with rest overlaps is computed here).
    pub fn new(template: &SphereMeshTemplate, params: CollisionParams) -> Self {
        let sk = &template.skeleton;
        let rest = PosedSphereMesh::new(template, &Pose::zeros(sk));
        let parent = |b: usize| sk.bones().get(b).and_then(|x| x.parent);
        let pills: Vec<(usize, [u32; 2], usize)> = template
            .elements
            .iter()
            .enumerate()
            .filter_map(|(e, d)| match d.element {
                Element::Pill(s) => Some((e, s, d.bone)),
                Element::Wedge(_) => None,
            })
            .collect();
        let mut pairs = Vec::new();
        for (i, &(ea, sa, ba)) in pills.iter().enumerate() {
            for &(eb, sb, bb) in &pills[i + 1..] {
                let shares = sa.iter().any(|s| sb.contains(s));
                let adjacent = ba == bb || parent(ba) == Some(bb) || parent(bb) == Some(ba);
                if shares || adjacent {
                    continue;
                }
                let rest_overlap =
                    contact_of(&rest, sa, sb).map_or(0.0, |c| c.penetration.max(0.0));
                pairs.push(PillPair {
                    a: ea,
                    b: eb,
                    rest_overlap,
                });
            }
        }
        Self { params, pairs }
    }

    /// The candidate pairs.
    pub fn pairs(&self) -> &[PillPair] {
        &self.pairs
    }
}

fn pill_spheres(template: &SphereMeshTemplate, e: usize) -> Option<[u32; 2]> {
    match template.elements.get(e)?.element {
        Element::Pill(s) => Some(s),
        Element::Wedge(_) => None,
    }
}

fn contact_of(posed: &PosedSphereMesh, a: [u32; 2], b: [u32; 2]) -> Option<PillContact> {
    let sp = |i: u32| posed.spheres.get(i as usize);
    let (a0, a1, b0, b1) = (sp(a[0])?, sp(a[1])?, sp(b[0])?, sp(b[1])?);
    pill_contact(
        [a0.center, a1.center],
        [a0.radius, a1.radius],
        [b0.center, b1.center],
        [b0.radius, b1.radius],
    )
}

/// Add `gᵀ ∂c/∂θ` of sphere `sphere` (on element `element`) to the dense row.
fn add_center_row(
    jac: &FootpointJacobian,
    posed: &PosedSphereMesh,
    element: usize,
    sphere: u32,
    g: &Vector3<f64>,
    row: &mut [f64; MAX_DOFS],
) {
    let mut cols = [Vector3::zeros(); MAX_ELEMENT_DOFS];
    let dofs = jac.columns(posed, element, &[sphere; 3], &[1.0, 0.0, 0.0], &mut cols);
    for (&d, c) in dofs.iter().zip(&cols) {
        if let Some(x) = row.get_mut(d) {
            *x += g.dot(c);
        }
    }
}

impl EnergyTerm<TrackingCtx<'_>> for Collision {
    fn name(&self) -> &'static str {
        "collision"
    }

    fn accumulate(
        &self,
        ctx: &TrackingCtx<'_>,
        ne: &mut NormalEquations,
    ) -> Result<TermStats, TermError> {
        let template = ctx.template();
        let nd = ctx.skeleton().num_dofs();
        if nd > MAX_DOFS {
            return Err(TermError::Failed("more than 64 DOFs"));
        }
        let posed = ctx.posed_mesh();
        let jac = ctx.jacobian();
        let mut stats = TermStats::ZERO;
        let mut pairs = [(0usize, 0.0f64); MAX_DOFS];
        for pair in &self.pairs {
            let (Some(sa), Some(sb)) = (
                pill_spheres(template, pair.a),
                pill_spheres(template, pair.b),
            ) else {
                return Err(TermError::Failed(
                    "collision pair is not a pill of this template",
                ));
            };
            let Some(c) = contact_of(posed, sa, sb) else {
                continue;
            };
            let pen = c.penetration - pair.rest_overlap - self.params.tolerance.max(0.0);
            if pen <= 0.0 {
                continue;
            }
            let mut row = [0.0f64; MAX_DOFS];
            for (k, (e, s)) in [
                (pair.a, sa[0]),
                (pair.a, sa[1]),
                (pair.b, sb[0]),
                (pair.b, sb[1]),
            ]
            .into_iter()
            .enumerate()
            {
                add_center_row(jac, posed, e, s, &c.gradient[k], &mut row);
            }
            let mut k = 0;
            for (d, &v) in row[..nd].iter().enumerate() {
                if v != 0.0 {
                    pairs[k] = (d, v);
                    k += 1;
                }
            }
            stats += ne.add_row(&pairs[..k], pen, self.params.weight)?;
        }
        Ok(stats)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hand_model::testing::relative_error;

    /// The contact gradient against central differences, for free and clamped parameters.
    #[test]
    fn pill_contact_gradient_matches_finite_differences() {
        let cases = [
            // crossing axes (both free)
            (
                [Vector3::new(-10.0, 0.0, 0.0), Vector3::new(12.0, 1.0, 0.5)],
                [Vector3::new(0.5, -9.0, 6.0), Vector3::new(-1.0, 11.0, 7.0)],
            ),
            // end of one against the middle of the other (one clamped)
            (
                [Vector3::new(0.0, 0.0, 0.0), Vector3::new(0.0, 20.0, 0.0)],
                [Vector3::new(-8.0, 26.0, 3.0), Vector3::new(9.0, 27.0, 4.0)],
            ),
        ];
        for (a, b) in cases {
            let (ra, rb) = ([8.0, 6.0], [7.5, 5.0]);
            let c = pill_contact(a, ra, b, rb).unwrap();
            for k in 0..4 {
                let fd = Vector3::from_fn(|i, _| {
                    let f = |h: f64| {
                        let (mut a, mut b) = (a, b);
                        let p = if k < 2 { &mut a[k] } else { &mut b[k - 2] };
                        p[i] += h;
                        pill_contact(a, ra, b, rb).unwrap().penetration
                    };
                    (f(1e-6) - f(-1e-6)) / 2e-6
                });
                let err = relative_error(&fd, &c.gradient[k], 1e-3);
                assert!(err < 1e-6, "endpoint {k}: fd {fd:?} vs {:?}", c.gradient[k]);
            }
        }
    }
}
