//! The shape unknowns of the offline calibration (thesis §3.4, Eq. 3.7–3.8) and the exact
//! Jacobians of posed sphere centers and radii with respect to them.
//!
//! Three groups, in this order in the shape vector:
//! - the honline shape vector β ([`ShapeBasis`]: phalanx lengths, finger base positions, palm
//!   and wrist extents, radii; ANCHOR-FACTS §2.5), which moves the rest centers `C̄`, the radii
//!   `r̄` and the joint positions (the translations of `T̄`) together, as anatomy does;
//! - per non-root bone a rest rotation increment `ω_k` (`R̄_k ← R̄_k · exp(ω_k)`: the bone's
//!   frame and its DOF axes turned about its origin — the kinematic calibration of Fig. 3.8;
//!   the thesis parameterizes `T̄` by Euler angles `δ̄`, a multiplicative increment spans the
//!   same and has no gimbal singularity);
//! - optionally, per bone-attached sphere a free center offset `Δō_s` (bone frame) and radius
//!   `Δr̄_s`, for shapes outside the β space (the thesis' unconstrained `C̄`, `r̄`).
//!
//! Free per-sphere centers alone leave sliding directions that no surface observes (a sphere
//! between two pills of equal radius moves along the finger axis without changing the surface
//! of an extended finger; measured: 18 mm drifts of `index_middle` on 8 depth frames), so β is
//! the primary parameterization and the free offsets are regularized toward zero.
//!
//! The root bone's rest transform is not an unknown: it is a gauge freedom against the
//! per-frame global poses `θ_n`.

use hand_model::kinematics::Skeleton;
use hand_model::math::{exp_so3, Rigid3};
use hand_model::spheremesh::{
    Attachment, PosedSphereMesh, ShapeBasis, SphereDef, SphereMeshTemplate,
};
use hand_model::ModelError;
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

/// The shape unknowns of a template and where they live in the shape vector.
#[derive(Clone, Debug)]
pub struct ShapeSpace {
    basis: ShapeBasis,
    /// Per bone the offset of its `ω` (3 unknowns), `None` for the root.
    bone: Vec<Option<usize>>,
    /// Per sphere the offset of its free `[Δō, Δr̄]` (4 unknowns), when enabled.
    sphere: Vec<Option<usize>>,
    len: usize,
}

/// A point of the shape space: β, the accumulated rest rotations and the free offsets.
#[derive(Clone, Debug, PartialEq)]
pub struct ShapeState {
    /// The honline β (absolute values, mm).
    pub beta: Vec<f64>,
    /// Per bone the accumulated rest rotation (identity for the root).
    pub rotation: Vec<Matrix3<f64>>,
    /// The free per-sphere increments (empty when disabled).
    pub free: Vec<f64>,
}

impl ShapeSpace {
    /// The shape space of `base` (the honline β basis must apply to it); `free_spheres` adds
    /// the per-sphere offsets and radii.
    pub fn new(base: &SphereMeshTemplate, free_spheres: bool) -> Result<Self, ModelError> {
        let basis = ShapeBasis::honline(base)?;
        let mut len = basis.len();
        let bone = base
            .skeleton
            .bones()
            .iter()
            .map(|b| {
                b.parent.map(|_| {
                    len += 3;
                    len - 3
                })
            })
            .collect();
        let sphere = base
            .spheres
            .iter()
            .map(|s| match (free_spheres, &s.attachment) {
                (true, Attachment::Bone { .. }) => {
                    len += 4;
                    Some(len - 4)
                }
                _ => None,
            })
            .collect();
        Ok(Self {
            basis,
            bone,
            sphere,
            len,
        })
    }

    /// Number of shape unknowns.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The β basis.
    pub fn basis(&self) -> &ShapeBasis {
        &self.basis
    }

    /// Number of β entries (the first unknowns).
    pub fn num_beta(&self) -> usize {
        self.basis.len()
    }

    /// The shape directions of an anisotropic scaling at `state` (thesis Eq. 4.14's latent
    /// height, width and thickness β̃; `#shape × 3`): column k moves every β entry that scales
    /// with axis k in proportion to its current value; rest rotations and free offsets stay.
    pub fn latent_map(&self, state: &ShapeState) -> nalgebra::DMatrix<f64> {
        let mut map = nalgebra::DMatrix::zeros(self.len, 3);
        for k in 0..3 {
            let mut axis = [0.0; 3];
            axis[k] = 1.0;
            for (i, v) in self.basis.from_latent(axis).iter().enumerate() {
                if *v != 0.0 {
                    map[(i, k)] = state.beta[i];
                }
            }
        }
        map
    }

    /// Offsets of the rest-rotation unknowns.
    pub fn rotation_offsets(&self) -> impl Iterator<Item = usize> + '_ {
        self.bone.iter().flatten().copied()
    }

    /// `(bone, offset)` of every rest-rotation unknown.
    pub fn rotation_slots(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.bone
            .iter()
            .enumerate()
            .filter_map(|(k, o)| o.map(|o| (k, o)))
    }

    /// Offsets of the free sphere unknowns (`[Δō, Δr̄]` each).
    pub fn sphere_offsets(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.sphere
            .iter()
            .enumerate()
            .filter_map(|(s, o)| o.map(|o| (s, o)))
    }

    /// A name per unknown: `beta:<honline name>`, `rotation:<bone>.<x|y|z>`,
    /// `sphere:<name>.<x|y|z|r>`.
    pub fn names(&self, base: &SphereMeshTemplate) -> Vec<String> {
        let mut out: Vec<String> = self.basis.names().map(|n| format!("beta:{n}")).collect();
        for (k, _) in self.rotation_slots() {
            let bone = &base.skeleton.bones()[k].name;
            out.extend(["x", "y", "z"].map(|a| format!("rotation:{bone}.{a}")));
        }
        for (s, _) in self.sphere_offsets() {
            let name = &base.spheres[s].name;
            out.extend(["x", "y", "z", "r"].map(|a| format!("sphere:{name}.{a}")));
        }
        out
    }

    /// The state of the unchanged template.
    pub fn identity(&self, base: &SphereMeshTemplate) -> ShapeState {
        ShapeState {
            beta: self.basis.template_values(),
            rotation: vec![Matrix3::identity(); base.skeleton.bones().len()],
            free: vec![0.0; self.sphere.iter().flatten().count() * 4],
        }
    }

    /// The template at `state`.
    pub fn template(
        &self,
        base: &SphereMeshTemplate,
        state: &ShapeState,
    ) -> Result<SphereMeshTemplate, ModelError> {
        let mut t = self.basis.apply(base, &state.beta)?;
        for (k, rot) in state.rotation.iter().enumerate() {
            if self.bone[k].is_some() {
                let rest = t.skeleton.bones()[k].rest;
                t.skeleton
                    .set_rest(k, Rigid3::new(rest.rotation * rot, rest.translation));
            }
        }
        let first = self.basis.len() + self.bone.iter().flatten().count() * 3;
        for (s, off) in self.sphere.iter().enumerate() {
            let Some(o) = *off else { continue };
            let x = &state.free[o - first..o - first + 4];
            let def = &mut t.spheres[s];
            if let Attachment::Bone { offset, .. } = &mut def.attachment {
                *offset += Vector3::new(x[0], x[1], x[2]);
            }
            def.radius += x[3];
        }
        Ok(t)
    }

    /// `state` moved by the step `delta` (shape part only): β and free offsets add, rest
    /// rotations compose on the right.
    pub fn step(&self, state: &ShapeState, delta: &[f64]) -> ShapeState {
        let nb = self.basis.len();
        let mut next = state.clone();
        for (b, d) in next.beta.iter_mut().zip(&delta[..nb]) {
            *b += d;
        }
        for (k, off) in self.bone.iter().enumerate() {
            if let Some(o) = *off {
                let w = Vector3::new(delta[o], delta[o + 1], delta[o + 2]);
                next.rotation[k] *= exp_so3(&w);
            }
        }
        let first = nb + self.bone.iter().flatten().count() * 3;
        for (f, d) in next.free.iter_mut().zip(&delta[first.min(delta.len())..]) {
            *f += d;
        }
        next
    }

    /// Visit `(index, ∂c/∂x, ∂r/∂x)` for the posed sphere `s` scaled by `weight` (blends visit
    /// their parts). `template` is the template at the current state, `posed` it at the frame's
    /// pose.
    pub fn for_each_sphere_column(
        &self,
        template: &SphereMeshTemplate,
        posed: &PosedSphereMesh,
        s: usize,
        weight: f64,
        f: &mut impl FnMut(usize, Vector3<f64>, f64),
    ) {
        self.basis
            .for_each_sphere_column(template, posed, s, &mut |j, dc, dr| {
                f(j, dc * weight, dr * weight)
            });
        self.for_each_local_column(template, posed, s, weight, f);
    }

    /// The rest-rotation and free-offset columns of sphere `s` (β excluded).
    fn for_each_local_column(
        &self,
        template: &SphereMeshTemplate,
        posed: &PosedSphereMesh,
        s: usize,
        weight: f64,
        f: &mut impl FnMut(usize, Vector3<f64>, f64),
    ) {
        match &template.spheres[s].attachment {
            Attachment::Blend { parts } => {
                for &(p, w) in parts {
                    self.for_each_local_column(template, posed, p, weight * w, f);
                }
            }
            Attachment::Bone { bone, .. } => {
                let sk = &template.skeleton;
                let c = posed.spheres[s].center;
                if let Some(o) = self.sphere[s] {
                    let r: Matrix3<f64> = posed.skeleton.globals[*bone].rotation;
                    for j in 0..3 {
                        f(o + j, r.column(j) * weight, 0.0);
                    }
                    f(o + 3, Vector3::zeros(), weight);
                }
                let mut k = Some(*bone);
                while let Some(b) = k {
                    if let Some(o) = self.bone[b] {
                        let frame = pre_dof_frame(sk, posed, b);
                        for j in 0..3 {
                            let axis = frame.rotation.column(j).into_owned();
                            f(o + j, axis.cross(&(c - frame.translation)) * weight, 0.0);
                        }
                    }
                    k = sk.bones()[b].parent;
                }
            }
        }
    }
}

/// How far a calibrated template is from a reference of the same topology: the mean distance
/// of their rest-pose sphere centers after the best rigid alignment (the rest frames are only
/// defined up to the global gauge of the frames' poses; Umeyama/Kabsch,
/// [`hand_model::math::fit_rigid`]) and the mean radius difference, both in mm. `None` when the
/// sphere counts differ or the centers are degenerate.
pub fn rest_sphere_errors(a: &SphereMeshTemplate, b: &SphereMeshTemplate) -> Option<(f64, f64)> {
    let pa = PosedSphereMesh::new(a, &hand_model::kinematics::Pose::zeros(&a.skeleton));
    let pb = PosedSphereMesh::new(b, &hand_model::kinematics::Pose::zeros(&b.skeleton));
    if pa.spheres.len() != pb.spheres.len() {
        return None;
    }
    let ca: Vec<Vector3<f64>> = pa.spheres.iter().map(|s| s.center).collect();
    let cb: Vec<Vector3<f64>> = pb.spheres.iter().map(|s| s.center).collect();
    let fit = hand_model::math::fit_rigid(&ca, &cb).ok()?;
    let n = ca.len() as f64;
    let centers = ca
        .iter()
        .zip(&cb)
        .map(|(x, y)| (fit.transform_point(x) - y).norm())
        .sum::<f64>()
        / n;
    let radii = pa
        .spheres
        .iter()
        .zip(&pb.spheres)
        .map(|(x, y)| (x.radius - y.radius).abs())
        .sum::<f64>()
        / n;
    Some((centers, radii))
}

/// A rest sphere of a reference model that [`fit_rest_spheres`] matches: the template's sphere
/// `sphere` should have this rest center (the template's model frame, mm) and radius (mm).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SphereTarget {
    /// Index of the template sphere.
    pub sphere: usize,
    /// Its target rest center.
    pub center: Vector3<f64>,
    /// Its target radius.
    pub radius: f64,
}

/// The template of `base`'s topology and shape space (β, rest rotations, free sphere offsets and
/// radii) whose rest spheres come nearest to `targets`: a reference model that stores spheres
/// but not this crate's kinematics (the original authors' fitted sphere-mesh, say) carried
/// onto this skeleton, so that it can be posed by the same pose search as a calibration and
/// their residuals compared on equal terms. β moves the joints with the spheres, as anatomy
/// does; free offsets take up what β cannot.
///
/// Minimizes `Σ |c_s − c*_s|² + (r_s − r*_s)²` over the targets plus priors toward `base` on the
/// rest rotations (10 per rad²), the free center offsets of the spheres on a joint (10 per mm²:
/// the joints stay on their spheres, as in both models, and the rest rotations and lengths
/// place them) and the other free offsets (10⁻² per mm², which only holds the spheres without a
/// target), `iterations` Levenberg–Marquardt steps. Measured on the authors' final model of
/// `hand-scans-tkach`: rest centers within 0.19 mm of theirs; with the joint spheres as free as
/// the rest (10⁻²), within 0.03 mm but the joints 1–3.3 mm off their spheres. Returns the
/// template with the mean center distance and mean absolute radius difference (mm) left at the
/// targets. Errors: no target, a target index out of range or not finite, a `base` without the
/// honline β basis.
pub fn fit_rest_spheres(
    base: &SphereMeshTemplate,
    targets: &[SphereTarget],
    iterations: usize,
) -> Result<(SphereMeshTemplate, f64, f64), ModelError> {
    let bad = targets.iter().find(|t| {
        t.sphere >= base.spheres.len()
            || !t.center.iter().all(|v| v.is_finite())
            || !t.radius.is_finite()
    });
    if targets.is_empty() || bad.is_some() {
        return Err(ModelError::InvalidArgument {
            name: "targets",
            reason: format!(
                "{} targets for {} spheres; each needs a sphere index in range and finite values",
                targets.len(),
                base.spheres.len()
            ),
        });
    }
    let space = ShapeSpace::new(base, true)?;
    let n = space.len();
    let first_free = space.num_beta() + space.rotation_offsets().count() * 3;
    let zeros = hand_model::kinematics::Pose::zeros(&base.skeleton);
    // Cost, gradient (Jᵀr) and Gauss–Newton matrix (JᵀJ) at a state.
    let linearize = |state: &ShapeState| -> Result<(f64, DVector<f64>, DMatrix<f64>), ModelError> {
        let t = space.template(base, state)?;
        let posed = PosedSphereMesh::new(&t, &zeros);
        let mut g = DVector::zeros(n);
        let mut h = DMatrix::zeros(n, n);
        let mut cost = 0.0;
        let mut add = |cols: &[(usize, f64)], r: f64, w: f64| {
            cost += w * r * r;
            for &(i, a) in cols {
                g[i] += w * a * r;
                for &(j, b) in cols {
                    h[(i, j)] += w * a * b;
                }
            }
        };
        for target in targets {
            let sphere = &posed.spheres[target.sphere];
            let mut cols: Vec<(usize, Vector3<f64>, f64)> = Vec::new();
            space.for_each_sphere_column(&t, &posed, target.sphere, 1.0, &mut |i, dc, dr| {
                cols.push((i, dc, dr))
            });
            let res = sphere.center - target.center;
            for axis in 0..3 {
                let row: Vec<(usize, f64)> = cols.iter().map(|c| (c.0, c.1[axis])).collect();
                add(&row, res[axis], 1.0);
            }
            let row: Vec<(usize, f64)> = cols.iter().map(|c| (c.0, c.2)).collect();
            add(&row, sphere.radius - target.radius, 1.0);
        }
        for (k, o) in space.rotation_slots() {
            let w = nalgebra::Rotation3::from_matrix(&state.rotation[k]).scaled_axis();
            for j in 0..3 {
                add(&[(o + j, 1.0)], w[j], 10.0);
            }
        }
        for (s, o) in space.sphere_offsets() {
            for j in 0..4 {
                let w = if j < 3 && on_joint(&base.spheres[s]) {
                    10.0
                } else {
                    1e-2
                };
                add(&[(o + j, 1.0)], state.free[o - first_free + j], w);
            }
        }
        Ok((cost, g, h))
    };
    let mut state = space.identity(base);
    let (mut cost, mut g, mut h) = linearize(&state)?;
    let mut lambda = 1e-4;
    for _ in 0..iterations {
        let mut a = h.clone();
        for i in 0..n {
            a[(i, i)] += lambda * a[(i, i)] + 1e-9;
        }
        let Some(delta) = a.cholesky().map(|c| c.solve(&(-&g))) else {
            lambda *= 10.0;
            continue;
        };
        let next = space.step(&state, delta.as_slice());
        match linearize(&next) {
            Ok((c, ng, nh)) if c < cost => {
                let done = cost - c < 1e-10 * cost.max(1e-300);
                (state, cost, g, h) = (next, c, ng, nh);
                lambda = (lambda / 3.0).max(1e-12);
                if done {
                    break;
                }
            }
            _ => lambda *= 10.0,
        }
    }
    let t = space.template(base, &state)?;
    let posed = PosedSphereMesh::new(&t, &zeros);
    let k = targets.len() as f64;
    let centers = targets
        .iter()
        .map(|x| (posed.spheres[x.sphere].center - x.center).norm())
        .sum::<f64>()
        / k;
    let radii = targets
        .iter()
        .map(|x| (posed.spheres[x.sphere].radius - x.radius).abs())
        .sum::<f64>()
        / k;
    Ok((t, centers, radii))
}

/// Whether `sphere` is centered on its bone's origin, the joint (every phalanx's first sphere):
/// β moves that joint with it, and a free center offset would part the two, which the
/// keypoints (the joints) then miss.
pub(crate) fn on_joint(sphere: &SphereDef) -> bool {
    matches!(&sphere.attachment, Attachment::Bone { offset, .. } if offset.norm() < 1e-9)
}

/// The frame of bone `k` before its own DOFs act (`G_parent ∘ T̄_k`).
fn pre_dof_frame(skeleton: &Skeleton, posed: &PosedSphereMesh, k: usize) -> Rigid3 {
    let bone = &skeleton.bones()[k];
    match bone.parent {
        Some(p) => posed.skeleton.globals[p].compose(&bone.rest),
        None => bone.rest,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hand_model::kinematics::Pose;
    use hand_model::spheremesh::default_right_hand;
    use hand_model::testing::relative_error;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Center and radius columns against central differences of `step` + `template`, at a
    /// random state and pose, for every sphere (blends included) and every unknown.
    #[test]
    fn columns_match_finite_differences() {
        let base = default_right_hand();
        let space = ShapeSpace::new(&base, true).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let shift: Vec<f64> = (0..space.len())
            .map(|i| {
                if i < space.num_beta() {
                    rng.random_range(-1.0..1.0)
                } else {
                    rng.random_range(-0.05..0.05)
                }
            })
            .collect();
        let state = space.step(&space.identity(&base), &shift);
        let mut pose = Pose::zeros(&base.skeleton);
        for v in pose.values.iter_mut() {
            *v = rng.random_range(-0.4..0.4);
        }
        let t = space.template(&base, &state).unwrap();
        let posed = PosedSphereMesh::new(&t, &pose);
        let h = 1e-6;
        let mut worst: f64 = 0.0;
        for s in 0..base.spheres.len() {
            let mut cols = vec![Vector3::zeros(); space.len()];
            let mut rcols = vec![0.0; space.len()];
            space.for_each_sphere_column(&t, &posed, s, 1.0, &mut |i, c, r| {
                cols[i] += c;
                rcols[i] += r;
            });
            for i in 0..space.len() {
                let eval = |d: f64| {
                    let mut x = vec![0.0; space.len()];
                    x[i] = d;
                    let tt = space.template(&base, &space.step(&state, &x)).unwrap();
                    let p = PosedSphereMesh::new(&tt, &pose);
                    (p.spheres[s].center, p.spheres[s].radius)
                };
                let (cp, rp) = eval(h);
                let (cm, rm) = eval(-h);
                let fd = (cp - cm) / (2.0 * h);
                worst = worst.max(relative_error(&fd, &cols[i], 1.0));
                worst = worst.max(((rp - rm) / (2.0 * h) - rcols[i]).abs());
            }
        }
        assert!(worst < 1e-6, "worst relative error {worst}");
    }
}
