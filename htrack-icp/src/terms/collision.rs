//! The self-collision term E_collision (thesis Eq. 2.7, linearized in §2.7.4 "Collision",
//! Fig. 2.25).

use hand_model::cylinder::{CylinderModel, Segment};
use hand_model::kinematics::{PosedSkeleton, Skeleton};
use hand_model::query::segment_closest_params;
use hand_model::solver::{EnergyTerm, NormalEquations, PoseContext, TermError, TermStats};
use nalgebra::{Matrix2, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use crate::context::TrackingCtx;

/// Settings of [`Collision`].
///
/// The weight: the thesis fixes ω₆ = 1e8 for its Ch. 2 results (§2.4, with ω₃ = ω₇ = 1e8);
/// htrack's code uses ω = 1e4 with `fraction = 0.1` (the right-hand side scaled by 0.1, an
/// under-relaxation that asks each iteration to remove a tenth of the penetration; hmodel: 1e3
/// and 0.01; ANCHOR-FACTS §5.2, §5.5). We keep htrack's ω = 1e4 (not squared, the convention of
/// every prior term) and no fraction: the fraction would make the linearization inconsistent
/// with the energy (the gradient of `ω Σ pen²` is `2ω Jᵀpen`, not `0.2ω Jᵀpen`), while LM
/// damping already limits the step. 1e8 turns the term into a hard constraint at the scale of
/// our E3D (ω₁ = 1 with IRLS weights); pass it explicitly to reproduce the thesis setting.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CollisionParams {
    /// ω₆ of Eq. 2.7 (per mm² of penetration).
    pub weight: f64,
}

impl Default for CollisionParams {
    fn default() -> Self {
        Self { weight: 1e4 }
    }
}

/// One candidate pair of segments and the overlap it has at the rest pose.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct CollisionPair {
    /// First segment (index into [`CylinderModel::segments`]).
    pub a: usize,
    /// Second segment.
    pub b: usize,
    /// Penetration depth (mm) of the pair at θ = 0 (0 when apart); only deeper penetration
    /// counts.
    pub rest_overlap: f64,
}

/// The collision state of one pair at the current pose.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct PairContact {
    /// Closest point on the axis of segment `a` (camera frame, mm).
    pub point_a: Vector3<f64>,
    /// Closest point on the axis of segment `b`.
    pub point_b: Vector3<f64>,
    /// Axial parameters `(s, t) ∈ [0, 1]²` of the two points.
    pub params: (f64, f64),
    /// `r_a(s) + r_b(t) − ‖point_a − point_b‖` (mm): positive when the segments interpenetrate.
    pub penetration: f64,
}

/// E_collision, thesis Eq. 2.7: `E = ω₆ Σ_{i,j} χ(i,j) (r − d(c_i, c_j))²`, with `d` the distance
/// between the two segment axes, `r` the sum of the radii at the closest points and `χ` one when
/// they interpenetrate (`r > d`).
///
/// **Pairs** (computed once by [`Collision::new`]): every pair of segments except those
/// involving the palm (a segment whose bone is the parent of two or more segment bones) and
/// adjacent ones (one segment's bone the parent of the other's), as in htrack (ANCHOR-FACTS
/// §5.5). The rest pose is taken as collision-free: a pair that already overlaps at θ = 0 (the
/// finger bases of [`CylinderModel::from_sphere_mesh`], which touch through the web) only counts
/// the penetration beyond its rest overlap. The htrack-proportioned default model has no such
/// overlap, so there the term is Eq. 2.7 as written.
///
/// **Residual and row** (§2.7.4, Fig. 2.25): with `x_i`, `x_j` the deepest points of the two
/// surfaces along the closest-point direction `n = (p_i − p_j)/‖p_i − p_j‖` of the axes (`x_i =
/// p_i − n r_i`, `x_j = p_j + n r_j`), the residual is `pen = nᵀ(x_j − x_i) − overlap = r_i(s) +
/// r_j(t) − ‖p_i − p_j‖ − overlap` and the energy `ω₆ pen²`. Its Jacobian row is the thesis'
/// `−nᵀ(J_skel(x_i) − J_skel(x_j))` plus, because the radii are tapered, `r_i' ∂s/∂θ + r_j'
/// ∂t/∂θ` with the derivatives of the closest-point parameters from their optimality conditions
/// (zero for a parameter clamped at an end), so the row is the exact gradient. DOFs shared by
/// both chains (the 6 global ones, and the MCP DOFs for two phalanges of one finger) move both
/// segments rigidly and have exactly zero columns; they are skipped (htrack zeroes the 6 global
/// columns). Radii are the local-x radii `r(t)` (finger segments are circular). Pairs whose axes
/// meet exactly (`‖p_i − p_j‖ < 1e−9` mm, no direction) add no row. As in htrack, a contact at
/// a joint is seen by both segments meeting there (e.g. `middle_2 × index_1` and
/// `middle_2 × index_2` at the index PIP joint), so it counts twice.
///
/// The energy reported is `ω₆ Σ pen²` (mm², times ω₆), one row per colliding pair.
#[derive(Clone, Debug, PartialEq)]
pub struct Collision {
    params: CollisionParams,
    pairs: Vec<CollisionPair>,
    num_segments: usize,
}

/// Most DOFs on the two chains of a pair (the cylinder skeleton has at most 6 + 4 per chain).
const MAX_COLS: usize = 64;

impl Collision {
    /// The term for `model` (the pair list, with each pair's rest overlap, is computed here).
    pub fn new(model: &CylinderModel, params: CollisionParams) -> Self {
        let sk = &model.skeleton;
        let segs = &model.segments;
        let parent = |s: &Segment| sk.bones().get(s.bone).and_then(|b| b.parent);
        let is_palm = |i: usize| {
            segs.iter()
                .filter(|o| parent(o) == Some(segs[i].bone))
                .count()
                >= 2
        };
        let rest = model.rest_posed();
        let mut pairs = Vec::new();
        for a in 0..segs.len() {
            for b in a + 1..segs.len() {
                let adjacent = parent(&segs[a]) == Some(segs[b].bone)
                    || parent(&segs[b]) == Some(segs[a].bone)
                    || segs[a].bone == segs[b].bone;
                if adjacent || is_palm(a) || is_palm(b) {
                    continue;
                }
                let rest_overlap =
                    contact(model, &rest, a, b).map_or(0.0, |c| c.penetration.max(0.0));
                pairs.push(CollisionPair { a, b, rest_overlap });
            }
        }
        Self {
            params,
            pairs,
            num_segments: segs.len(),
        }
    }

    /// The settings.
    pub fn params(&self) -> &CollisionParams {
        &self.params
    }

    /// The candidate pairs.
    pub fn pairs(&self) -> &[CollisionPair] {
        &self.pairs
    }

    /// The pairs that interpenetrate beyond their rest overlap at the context's pose, with
    /// their contact and residual `pen` (for reports and tests; allocates).
    pub fn contacts(&self, ctx: &TrackingCtx<'_>) -> Vec<(CollisionPair, PairContact, f64)> {
        self.pairs
            .iter()
            .filter_map(|p| {
                let c = contact(ctx.model(), ctx.posed(), p.a, p.b)?;
                let pen = c.penetration - p.rest_overlap;
                (pen > 0.0).then_some((*p, c, pen))
            })
            .collect()
    }
}

/// Closest points of two segments' axes and their penetration; `None` for segment indices out
/// of range or a non-finite pose.
pub fn contact(
    model: &CylinderModel,
    posed: &PosedSkeleton,
    a: usize,
    b: usize,
) -> Option<PairContact> {
    let (sa, sb) = (model.segments.get(a)?, model.segments.get(b)?);
    let (ga, gb) = (posed.globals.get(sa.bone)?, posed.globals.get(sb.bone)?);
    let p0 = ga.translation;
    let u = ga.transform_point(&sa.end_local()) - p0;
    let q0 = gb.translation;
    let v = gb.transform_point(&sb.end_local()) - q0;
    let (s, t) = segment_closest_params(&p0, &u, &q0, &v);
    let point_a = p0 + u * s;
    let point_b = q0 + v * t;
    let d = (point_a - point_b).norm();
    let penetration = sa.radii_at(s).0 + sb.radii_at(t).0 - d;
    penetration.is_finite().then_some(PairContact {
        point_a,
        point_b,
        params: (s, t),
        penetration,
    })
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
        let model = ctx.model();
        if model.segments.len() != self.num_segments {
            return Err(TermError::ShapeMismatch {
                expected: self.num_segments,
                found: model.segments.len(),
            });
        }
        let sk = ctx.skeleton();
        let posed = ctx.posed();
        let omega = self.params.weight;
        let mut cols = [(0usize, 0.0f64); MAX_COLS];
        let mut stats = TermStats::ZERO;
        for pair in &self.pairs {
            let Some(c) = contact(model, posed, pair.a, pair.b) else {
                continue;
            };
            let pen = c.penetration - pair.rest_overlap;
            if pen <= 0.0 {
                continue;
            }
            let n = match (c.point_a - c.point_b).try_normalize(1e-9) {
                Some(n) => n,
                None => continue,
            };
            let k = pair_row(sk, posed, model, pair, &c, &n, &mut cols)?;
            stats += ne.add_row(&cols[..k], pen, omega)?;
        }
        Ok(stats)
    }
}

/// The Jacobian row of `pen` for one pair (see [`Collision`]) into `cols`; returns its length.
fn pair_row(
    sk: &Skeleton,
    posed: &PosedSkeleton,
    model: &CylinderModel,
    pair: &CollisionPair,
    c: &PairContact,
    n: &Vector3<f64>,
    cols: &mut [(usize, f64); MAX_COLS],
) -> Result<usize, TermError> {
    let (sa, sb) = (&model.segments[pair.a], &model.segments[pair.b]);
    let bones = sk.bones().len();
    for bone in [sa.bone, sb.bone] {
        if bone >= bones {
            return Err(TermError::BoneOutOfRange { bone, bones });
        }
    }
    let (s, t) = c.params;
    let u = posed.globals[sa.bone].transform_vector(&sa.end_local());
    let v = posed.globals[sb.bone].transform_vector(&sb.end_local());
    let diff = c.point_a - c.point_b;
    // Optimality conditions F = (uᵀdiff, −vᵀdiff) = 0 of the free parameters.
    let free_s = s > 0.0 && s < 1.0;
    let free_t = t > 0.0 && t < 1.0;
    let h = Matrix2::new(u.dot(&u), -u.dot(&v), -u.dot(&v), v.dot(&v));
    let h_inv = if free_s && free_t {
        h.try_inverse()
    } else {
        None
    };
    let (dra, drb) = (sa.r2 - sa.r1, sb.r2 - sb.r1);
    let mut k = 0;
    for (chain, other, on_a) in [
        (sk.chain(sa.bone), sk.chain(sb.bone), true),
        (sk.chain(sb.bone), sk.chain(sa.bone), false),
    ] {
        for &d in chain {
            if other.contains(&d) {
                continue;
            }
            if k == MAX_COLS {
                return Err(TermError::Failed(
                    "collision pair touches more than 64 DOFs",
                ));
            }
            // ∂(p_a − p_b)/∂θ_d and ∂u/∂θ_d (or ∂v) at fixed (s, t).
            let (dp, du, dv) = if on_a {
                let dp = posed.column(d, &c.point_a);
                let du = posed.column(d, &(c.point_a + u)) - dp;
                (dp, du, Vector3::zeros())
            } else {
                let dq = posed.column(d, &c.point_b);
                let dv = posed.column(d, &(c.point_b + v)) - dq;
                (-dq, Vector3::zeros(), dv)
            };
            let df = Vector2::new(du.dot(&diff) + u.dot(&dp), -dv.dot(&diff) - v.dot(&dp));
            let (ds, dt) = match h_inv {
                Some(hi) => {
                    let x = -(hi * df);
                    (x.x, x.y)
                }
                None if free_s && h[(0, 0)] > 0.0 => (-df.x / h[(0, 0)], 0.0),
                None if free_t && h[(1, 1)] > 0.0 => (0.0, -df.y / h[(1, 1)]),
                None => (0.0, 0.0),
            };
            cols[k] = (d, dra * ds + drb * dt - n.dot(&dp));
            k += 1;
        }
    }
    Ok(k)
}

#[cfg(test)]
mod tests {
    use hand_model::cylinder::{default_right_hand_cylinders, CylinderModel, View};
    use hand_model::kinematics::Pose;
    use hand_model::solver::check::check_gradient;
    use hand_model::solver::terms::{DampingParams, JointLimits, JointLimitsParams};
    use hand_model::solver::{EnergyTerm, LmOptions, NormalEquations};
    use hand_model::spheremesh::default_right_hand;

    use super::*;
    use crate::IrlsParams;

    /// Index and middle abducted into each other (a little flexed, so the axes are skew and the
    /// closest points interior), the hand somewhere in front of the camera.
    fn crossed_pose(model: &CylinderModel) -> Pose {
        Pose::from_named(
            &model.skeleton,
            [
                ("global_tz", 400.0),
                ("global_rx", 0.3),
                ("global_ry", -0.2),
                ("index_mcp_abd", -0.38),
                ("index_mcp_flex", 0.25),
                ("index_pip_flex", 0.3),
                ("middle_mcp_abd", 0.28),
                ("middle_mcp_flex", 0.05),
                ("middle_pip_flex", 0.2),
            ],
        )
        .unwrap()
    }

    fn ctx_at<'m>(model: &'m CylinderModel, pose: &Pose) -> TrackingCtx<'m> {
        let mut ctx = TrackingCtx::new(model, View::Orthographic, IrlsParams::default());
        ctx.update(pose, false).unwrap();
        ctx
    }

    fn name(model: &CylinderModel, s: usize) -> &str {
        &model.skeleton.bones()[model.segments[s].bone].name
    }

    #[test]
    fn pairs_exclude_the_palm_and_adjacent_segments() {
        let model = default_right_hand_cylinders();
        let term = Collision::new(&model, CollisionParams::default());
        // 15 digit segments: C(15, 2) = 105 pairs, minus 2 adjacent pairs per digit.
        assert_eq!(term.pairs().len(), 105 - 10);
        assert!(term.pairs().iter().all(|p| p.a != 0 && p.b != 0));
        // The htrack-proportioned default does not overlap at rest.
        assert!(term.pairs().iter().all(|p| p.rest_overlap == 0.0));
        // Nothing collides at rest: no rows.
        let ctx = ctx_at(&model, &Pose::zeros(&model.skeleton));
        let mut ne = NormalEquations::new(model.skeleton.num_dofs());
        let stats = term.accumulate(&ctx, &mut ne).unwrap();
        assert_eq!(stats, TermStats::ZERO);
        assert!(ne.rhs().iter().all(|&v| v == 0.0));
    }

    #[test]
    fn fitted_sphere_mesh_model_touching_finger_bases_are_tolerated() {
        let model = CylinderModel::from_sphere_mesh(&default_right_hand()).unwrap();
        let term = Collision::new(&model, CollisionParams::default());
        let overlapping: Vec<_> = term
            .pairs()
            .iter()
            .filter(|p| p.rest_overlap > 0.0)
            .map(|p| (name(&model, p.a), name(&model, p.b), p.rest_overlap))
            .collect();
        eprintln!("rest overlaps of the fitted model: {overlapping:?}");
        assert!(!overlapping.is_empty());
        let ctx = ctx_at(&model, &Pose::zeros(&model.skeleton));
        assert!(term.contacts(&ctx).is_empty());
        let mut ne = NormalEquations::new(model.skeleton.num_dofs());
        assert_eq!(term.accumulate(&ctx, &mut ne).unwrap().rows, 0);
        // Abducted into each other, index and middle do collide.
        let ctx = ctx_at(&model, &crossed_pose(&model));
        assert!(!term.contacts(&ctx).is_empty());
    }

    #[test]
    fn collision_gradient_matches_finite_differences() {
        let model = default_right_hand_cylinders();
        let sk = &model.skeleton;
        let pose = crossed_pose(&model);
        let term = Collision::new(&model, CollisionParams { weight: 1.0 });
        let mut ctx = ctx_at(&model, &pose);
        let contacts = term.contacts(&ctx);
        for (p, c, pen) in &contacts {
            eprintln!(
                "{} × {}: (s, t) = ({:.3}, {:.3}), penetration {pen:.3} mm",
                name(&model, p.a),
                name(&model, p.b),
                c.params.0,
                c.params.1
            );
        }
        assert!(contacts.len() >= 2, "{contacts:?}");
        // At least one contact with both closest points interior (the ∂s/∂θ, ∂t/∂θ terms).
        assert!(contacts.iter().any(|(_, c, _)| {
            let (s, t) = c.params;
            s > 0.0 && s < 1.0 && t > 0.0 && t < 1.0
        }));
        let mut update = |p: &Pose, c: &mut TrackingCtx<'_>| c.update(p, false).unwrap();
        let cmp =
            check_gradient(sk, &pose, sk.num_dofs(), &term, &mut ctx, &mut update, 1e-6).unwrap();
        let rel = cmp.relative_error(1e-9);
        eprintln!("collision gradient: relative error {rel:.2e}");
        assert!(rel < 1e-6, "relative error {rel:e}\n{cmp:?}");
        // The 6 global columns are zero (htrack zeroes them; here they are exactly zero).
        let (ne, energy) = hand_model::solver::check::linearize(
            &pose,
            sk.num_dofs(),
            &term,
            &mut ctx,
            &mut update,
        )
        .unwrap();
        assert!(energy > 0.0);
        for g in 0..6 {
            assert_eq!(ne.rhs()[g], 0.0);
            assert_eq!(ne.lhs()[(g, g)], 0.0);
        }
    }

    #[test]
    fn lm_separates_interpenetrating_fingers() {
        let model = default_right_hand_cylinders();
        let sk = &model.skeleton;
        let start = crossed_pose(&model);
        let term = Collision::new(&model, CollisionParams::default());
        let limits = JointLimits::new(sk, &JointLimitsParams::default());
        let options = LmOptions {
            iterations: 10,
            rigid_iterations: 0,
            damping: DampingParams::uniform(1.0),
            ..LmOptions::default()
        };
        let mut ctx = ctx_at(&model, &start);
        let before: f64 = term.contacts(&ctx).iter().map(|c| c.2).fold(0.0, f64::max);
        let terms: [&dyn EnergyTerm<TrackingCtx<'_>>; 2] = [&term, &limits];
        let (pose, report) = crate::tests::solve_terms(&mut ctx, &terms, options, &start);
        ctx.update(&pose, false).unwrap();
        let after: f64 = term.contacts(&ctx).iter().map(|c| c.2).fold(0.0, f64::max);
        let moved = (0..sk.num_dofs())
            .map(|d| (pose.values[d] - start.values[d]).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "max penetration {before:.3} mm -> {after:.2e} mm; energy {:.3e} -> {:.3e}; \
             largest joint change {moved:.3} rad; {:?}",
            report.energy_before, report.energy_after, report.termination
        );
        assert!(report.termination.was_successful());
        assert!(before > 2.0);
        assert!(after < 1e-3, "{after}");
        // The global pose does not move (zero columns).
        for g in 0..6 {
            assert_eq!(pose.values[g], start.values[g]);
        }
    }
}
