//! The honline shape vector β (ANCHOR-FACTS §2.5, thesis §4.3) and its latent anisotropic
//! scaling (Eq. 4.14).
//!
//! Every β entry acts *affinely* on the template: a rest translation, a sphere offset or a
//! radius moves by `(β_j − β̄_j)·dir`. Passive quantities of honline (palm_middle/palm_ring
//! interpolated between palm_index and palm_pinky, membranes sliding with the proximal phalanx,
//! the mirrored wrist spheres, thumb_additional following thumb_top) are extra effects of the same
//! entries, so `∂c/∂β` is exact and constant in the bone frames, and β ↦ (C̄, r̄) can be inverted
//! by linear least squares ([`ShapeBasis::fit`]).

use std::path::Path;

use nalgebra::{DMatrix, DVector, Vector3};
use serde::{Deserialize, Serialize};

use super::posed::PosedSphereMesh;
use super::template::{Attachment, SphereMeshTemplate};
use crate::error::{ModelError, Result};

/// The kind of a β entry (honline `BetaType`).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ShapeKind {
    /// Length of a distal phalanx (offset of the tip sphere).
    TopPhalangeLength,
    /// Length of a phalanx (rest translation of the child bone).
    PhalangeLength,
    /// Finger base position x (rest translation of the first bone, palm frame).
    FingerBaseX,
    /// Finger base position y.
    FingerBaseY,
    /// Finger base position z.
    FingerBaseZ,
    /// Palm sphere offset x (or wrist width).
    PalmCenterX,
    /// Palm sphere offset y (or wrist length).
    PalmCenterY,
    /// A sphere radius.
    Radius,
    /// Offset of thumb_additional along y beyond thumb_top.
    FingerTopY,
    /// Offset of thumb_additional along z beyond thumb_top.
    FingerTopZ,
}

impl ShapeKind {
    /// Default bounds of the honline joint-limit energy on β (ANCHOR-FACTS §2.5), in mm.
    pub fn default_limits(self) -> Option<[f64; 2]> {
        match self {
            ShapeKind::PhalangeLength => Some([10.0, 60.0]),
            ShapeKind::TopPhalangeLength => Some([4.0, 30.0]),
            ShapeKind::Radius => Some([3.0, 25.0]),
            ShapeKind::FingerTopY => Some([3.0, 15.0]),
            ShapeKind::FingerTopZ => Some([1.0, 10.0]),
            _ => None,
        }
    }

    /// The latent axis of Eq. 4.14 that scales this kind: 0 height, 1 width, 2 thickness.
    pub fn latent_axis(self) -> usize {
        match self {
            ShapeKind::TopPhalangeLength
            | ShapeKind::PhalangeLength
            | ShapeKind::FingerBaseY
            | ShapeKind::PalmCenterY
            | ShapeKind::FingerTopY => 0,
            ShapeKind::FingerBaseX | ShapeKind::PalmCenterX => 1,
            ShapeKind::FingerBaseZ | ShapeKind::Radius | ShapeKind::FingerTopZ => 2,
        }
    }
}

/// One way a β entry moves the template.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum ShapeEffect {
    /// The rest translation of `bone` (in its parent's frame) moves by `Δβ·dir`.
    RestTranslation {
        /// The bone.
        bone: usize,
        /// Direction in the parent frame.
        dir: Vector3<f64>,
    },
    /// The offset of a bone-attached sphere (in its bone frame) moves by `Δβ·dir`.
    Offset {
        /// The sphere.
        sphere: usize,
        /// Direction in the bone frame.
        dir: Vector3<f64>,
    },
    /// A radius changes by `Δβ·coef`.
    Radius {
        /// The sphere.
        sphere: usize,
        /// Coefficient.
        coef: f64,
    },
}

/// One entry of β.
#[derive(Clone, Debug, PartialEq)]
pub struct ShapeParam {
    /// Name, e.g. `index_bottom_length`.
    pub name: String,
    /// Kind.
    pub kind: ShapeKind,
    /// Value measured on the template (β̄).
    pub template_value: f64,
    /// Bounds (mm), when the honline limits bound this kind.
    pub limits: Option<[f64; 2]>,
    /// How it moves the template.
    pub effects: Vec<ShapeEffect>,
}

/// A shape parameterization over one template topology.
#[derive(Clone, Debug, PartialEq)]
pub struct ShapeBasis {
    /// The β entries in order.
    pub params: Vec<ShapeParam>,
}

const DIGITS: [&str; 5] = ["thumb", "index", "middle", "ring", "pinky"];
/// Membrane fractions of the honline app (index, middle, ring, pinky).
const MEMBRANE_FRACTIONS: [f64; 4] = [0.40, 0.45, 0.51, 0.58];

struct Builder<'a> {
    t: &'a SphereMeshTemplate,
    params: Vec<ShapeParam>,
}

impl Builder<'_> {
    fn bone(&self, name: &str) -> Result<usize> {
        self.t.skeleton.bone_index(name).ok_or_else(|| {
            ModelError::field(
                "<template>",
                "bones",
                None,
                format!("the honline shape vector needs bone `{name}`"),
            )
        })
    }

    fn sphere(&self, name: &str) -> Result<usize> {
        self.t.sphere_index(name).ok_or_else(|| {
            ModelError::field(
                "<template>",
                "spheres",
                None,
                format!("the honline shape vector needs sphere `{name}`"),
            )
        })
    }

    fn offset(&self, sphere: usize) -> Result<Vector3<f64>> {
        match &self.t.spheres[sphere].attachment {
            Attachment::Bone { offset, .. } => Ok(*offset),
            Attachment::Blend { .. } => Err(ModelError::field(
                "<template>",
                "spheres",
                Some(sphere),
                "a shape parameter cannot move a blended sphere directly",
            )),
        }
    }

    fn push(&mut self, name: String, kind: ShapeKind, value: f64, effects: Vec<ShapeEffect>) {
        self.params.push(ShapeParam {
            name,
            kind,
            template_value: value,
            limits: kind.default_limits(),
            effects,
        });
    }

    fn length(
        &mut self,
        name: String,
        child_bone: usize,
        extra: Vec<ShapeEffect>,
    ) -> Result<Vector3<f64>> {
        let t = self.t.skeleton.bones()[child_bone].rest.translation;
        let len = t.norm();
        if len < 1e-9 {
            return Err(ModelError::field(
                "<template>",
                "bones.rest",
                Some(child_bone),
                "zero-length phalanx",
            ));
        }
        let dir = t / len;
        let mut effects = vec![ShapeEffect::RestTranslation {
            bone: child_bone,
            dir,
        }];
        effects.extend(extra.into_iter().map(|e| match e {
            ShapeEffect::Offset { sphere, dir: f } => ShapeEffect::Offset {
                sphere,
                dir: dir * f.x,
            },
            other => other,
        }));
        self.push(name, ShapeKind::PhalangeLength, len, effects);
        Ok(dir)
    }
}

impl ShapeBasis {
    /// The 75-entry FULL honline shape vector (ANCHOR-FACTS §2.5) for any template with the
    /// honline sphere names and the bone names of this crate (`thumb_1`, `index_2`, `wrist`, ...).
    pub fn honline(template: &SphereMeshTemplate) -> Result<ShapeBasis> {
        let mut b = Builder {
            t: template,
            params: Vec::with_capacity(75),
        };
        // 0..15: phalanx lengths (bottom, middle, top) per digit.
        for (di, digit) in DIGITS.iter().enumerate() {
            let b1 = b.bone(&format!("{digit}_1"))?;
            let b2 = b.bone(&format!("{digit}_2"))?;
            let b3 = b.bone(&format!("{digit}_3"))?;
            let _ = b1;
            // Membranes slide with the proximal phalanx: Δoffset = fraction·ΔL·dir (encoded
            // here as a placeholder x-coefficient, replaced by the real direction in `length`).
            let extra = if di > 0 {
                let m = b.sphere(&format!("{digit}_membrane"))?;
                vec![ShapeEffect::Offset {
                    sphere: m,
                    dir: Vector3::new(MEMBRANE_FRACTIONS[di - 1], 0.0, 0.0),
                }]
            } else {
                vec![]
            };
            b.length(format!("{digit}_bottom_length"), b2, extra)?;
            b.length(format!("{digit}_middle_length"), b3, vec![])?;
            let top = b.sphere(&format!("{digit}_top"))?;
            let off = b.offset(top)?;
            let len = off.norm();
            let dir = if len > 1e-9 { off / len } else { Vector3::y() };
            let mut effects = vec![ShapeEffect::Offset { sphere: top, dir }];
            if di == 0 {
                let add = b.sphere("thumb_additional")?;
                effects.push(ShapeEffect::Offset {
                    sphere: add,
                    dir: Vector3::new(0.0, dir.y, dir.z),
                });
            }
            b.push(
                format!("{digit}_top_length"),
                ShapeKind::TopPhalangeLength,
                len,
                effects,
            );
        }
        // 15..30: finger base positions (rest translation of the first bone in the palm frame).
        for digit in DIGITS {
            let b1 = b.bone(&format!("{digit}_1"))?;
            let t = template.skeleton.bones()[b1].rest.translation;
            for (axis, kind) in [
                ShapeKind::FingerBaseX,
                ShapeKind::FingerBaseY,
                ShapeKind::FingerBaseZ,
            ]
            .into_iter()
            .enumerate()
            {
                let dir = Vector3::ith(axis, 1.0);
                let name = format!("{digit}_base_{}", ["x", "y", "z"][axis]);
                b.push(
                    name,
                    kind,
                    t[axis],
                    vec![ShapeEffect::RestTranslation { bone: b1, dir }],
                );
            }
        }
        // 30..40: palm centers x/y; palm_middle and palm_ring follow index and pinky.
        let pi = b.sphere("palm_index")?;
        let pp = b.sphere("palm_pinky")?;
        let (oi, op) = (b.offset(pi)?, b.offset(pp)?);
        let span = (oi - op).norm().max(1e-9);
        let mut passive = Vec::new();
        for name in ["palm_middle", "palm_ring"] {
            let s = b.sphere(name)?;
            let rho = (oi - b.offset(s)?).norm() / span;
            passive.push((s, rho));
        }
        for (label, sphere) in [
            ("index", pi),
            ("pinky", pp),
            ("left", b.sphere("palm_left")?),
            ("right", b.sphere("palm_right")?),
            ("thumb", b.sphere("palm_thumb")?),
        ] {
            let off = b.offset(sphere)?;
            for (axis, kind) in [ShapeKind::PalmCenterX, ShapeKind::PalmCenterY]
                .into_iter()
                .enumerate()
            {
                let dir = Vector3::ith(axis, 1.0);
                let mut effects = vec![ShapeEffect::Offset { sphere, dir }];
                for &(s, rho) in &passive {
                    let w = if sphere == pi {
                        1.0 - rho
                    } else if sphere == pp {
                        rho
                    } else {
                        0.0
                    };
                    if w != 0.0 {
                        effects.push(ShapeEffect::Offset {
                            sphere: s,
                            dir: dir * w,
                        });
                    }
                }
                let name = format!("{label}_palm_center_{}", ["x", "y"][axis]);
                b.push(name, kind, off[axis], effects);
            }
        }
        // 40..46: wrist and thumb extras.
        let (wbl, wbr) = (
            b.sphere("wrist_bottom_left")?,
            b.sphere("wrist_bottom_right")?,
        );
        let (wtl, wtr) = (b.sphere("wrist_top_left")?, b.sphere("wrist_top_right")?);
        let obl = b.offset(wbl)?;
        let sx = if obl.x < 0.0 { -1.0 } else { 1.0 };
        let ex = Vector3::x() * sx;
        b.push(
            "wrist_width".into(),
            ShapeKind::PalmCenterX,
            obl.x * sx,
            vec![
                ShapeEffect::Offset {
                    sphere: wbl,
                    dir: ex,
                },
                ShapeEffect::Offset {
                    sphere: wbr,
                    dir: -ex,
                },
                ShapeEffect::Offset {
                    sphere: wtr,
                    dir: -ex,
                },
            ],
        );
        b.push(
            "wrist_length".into(),
            ShapeKind::PalmCenterY,
            -obl.y,
            vec![
                ShapeEffect::Offset {
                    sphere: wbl,
                    dir: -Vector3::y(),
                },
                ShapeEffect::Offset {
                    sphere: wbr,
                    dir: -Vector3::y(),
                },
            ],
        );
        let tml = b.sphere("thumb_membrane_left")?;
        let otml = b.offset(tml)?;
        let ltml = otml.norm();
        let dtml = if ltml > 1e-9 {
            otml / ltml
        } else {
            Vector3::y()
        };
        b.push(
            "thumb_membrane_length".into(),
            ShapeKind::TopPhalangeLength,
            ltml,
            vec![ShapeEffect::Offset {
                sphere: tml,
                dir: dtml,
            }],
        );
        let add = b.sphere("thumb_additional")?;
        let top = b.sphere("thumb_top")?;
        let rel = b.offset(add)? - b.offset(top)?;
        b.push(
            "thumb_additional_y".into(),
            ShapeKind::FingerTopY,
            rel.y,
            vec![ShapeEffect::Offset {
                sphere: add,
                dir: Vector3::y(),
            }],
        );
        b.push(
            "thumb_additional_z".into(),
            ShapeKind::FingerTopZ,
            rel.z,
            vec![ShapeEffect::Offset {
                sphere: add,
                dir: Vector3::z(),
            }],
        );
        b.push(
            "wrist_width_left".into(),
            ShapeKind::PalmCenterX,
            b.offset(wtl)?.x * sx,
            vec![ShapeEffect::Offset {
                sphere: wtl,
                dir: ex,
            }],
        );
        // 46..75: radii.
        for digit in DIGITS {
            for part in ["base", "bottom", "middle", "top"] {
                let s = b.sphere(&format!("{digit}_{part}"))?;
                let mut effects = vec![ShapeEffect::Radius {
                    sphere: s,
                    coef: 1.0,
                }];
                if digit == "thumb" && part == "top" {
                    effects.push(ShapeEffect::Radius {
                        sphere: add,
                        coef: 0.67,
                    });
                }
                b.push(
                    format!("{digit}_{part}_radius"),
                    ShapeKind::Radius,
                    template.spheres[s].radius,
                    effects,
                );
            }
        }
        for name in [
            "palm_index",
            "palm_middle",
            "palm_ring",
            "palm_pinky",
            "palm_left",
            "palm_back",
            "palm_right",
        ] {
            let s = b.sphere(name)?;
            b.push(
                format!("{name}_radius"),
                ShapeKind::Radius,
                template.spheres[s].radius,
                vec![ShapeEffect::Radius {
                    sphere: s,
                    coef: 1.0,
                }],
            );
        }
        for (a, c, name) in [
            (wtl, wtr, "wrist_top_left_radius"),
            (wbl, wbr, "wrist_bottom_left_radius"),
        ] {
            b.push(
                name.into(),
                ShapeKind::Radius,
                template.spheres[a].radius,
                vec![
                    ShapeEffect::Radius {
                        sphere: a,
                        coef: 1.0,
                    },
                    ShapeEffect::Radius {
                        sphere: c,
                        coef: 1.0,
                    },
                ],
            );
        }
        Ok(ShapeBasis { params: b.params })
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.params.len()
    }

    /// Whether the basis is empty.
    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }

    /// β̄: the values measured on the template.
    pub fn template_values(&self) -> Vec<f64> {
        self.params.iter().map(|p| p.template_value).collect()
    }

    /// Names in order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.params.iter().map(|p| p.name.as_str())
    }

    /// β ↦ (C̄, r̄): the template reshaped to `beta`. Refused: wrong length, non-finite values,
    /// or a shape with a negative radius or a zero-length phalanx.
    pub fn apply(&self, template: &SphereMeshTemplate, beta: &[f64]) -> Result<SphereMeshTemplate> {
        if beta.len() != self.len() {
            return Err(ModelError::InvalidArgument {
                name: "beta",
                reason: format!("{} values for {} parameters", beta.len(), self.len()),
            });
        }
        if let Some(i) = beta.iter().position(|v| !v.is_finite()) {
            return Err(ModelError::InvalidArgument {
                name: "beta",
                reason: format!("`{}` is not finite", self.params[i].name),
            });
        }
        let mut out = template.clone();
        let mut rests: Vec<_> = template.skeleton.bones().iter().map(|b| b.rest).collect();
        for (p, &v) in self.params.iter().zip(beta) {
            let delta = v - p.template_value;
            for e in &p.effects {
                match *e {
                    ShapeEffect::RestTranslation { bone, dir } => {
                        rests[bone].translation += dir * delta
                    }
                    ShapeEffect::Offset { sphere, dir } => {
                        if let Attachment::Bone { offset, .. } = &mut out.spheres[sphere].attachment
                        {
                            *offset += dir * delta;
                        }
                    }
                    ShapeEffect::Radius { sphere, coef } => {
                        out.spheres[sphere].radius += coef * delta
                    }
                }
            }
        }
        for (b, rest) in rests.into_iter().enumerate() {
            out.skeleton.set_rest(b, rest);
        }
        for (i, s) in out.spheres.iter().enumerate() {
            if matches!(s.attachment, Attachment::Bone { .. }) && s.radius < 0.0 {
                return Err(ModelError::InvalidArgument {
                    name: "beta",
                    reason: format!("sphere `{}` (index {i}) gets a negative radius", s.name),
                });
            }
        }
        out.validate(Path::new("<shape>"))?;
        Ok(out)
    }

    /// (C̄, r̄) ↦ β: the β whose shape is closest (least squares over rest translations, sphere
    /// offsets and radii) to `target`, a template of the same topology as `template`. Returns β
    /// and the RMS of what β cannot express (mm).
    pub fn fit(
        &self,
        template: &SphereMeshTemplate,
        target: &SphereMeshTemplate,
    ) -> Result<(Vec<f64>, f64)> {
        let nb = template.skeleton.bones().len();
        let ns = template.spheres.len();
        if target.skeleton.bones().len() != nb || target.spheres.len() != ns {
            return Err(ModelError::InvalidArgument {
                name: "target",
                reason: "the target template has another topology".into(),
            });
        }
        let rows = 3 * nb + 4 * ns;
        let mut a = DMatrix::<f64>::zeros(rows, self.len());
        for (j, p) in self.params.iter().enumerate() {
            for e in &p.effects {
                match *e {
                    ShapeEffect::RestTranslation { bone, dir } => {
                        for k in 0..3 {
                            a[(3 * bone + k, j)] += dir[k];
                        }
                    }
                    ShapeEffect::Offset { sphere, dir } => {
                        for k in 0..3 {
                            a[(3 * nb + 3 * sphere + k, j)] += dir[k];
                        }
                    }
                    ShapeEffect::Radius { sphere, coef } => {
                        a[(3 * nb + 3 * ns + sphere, j)] += coef
                    }
                }
            }
        }
        let mut dq = DVector::<f64>::zeros(rows);
        for b in 0..nb {
            let d = target.skeleton.bones()[b].rest.translation
                - template.skeleton.bones()[b].rest.translation;
            dq.fixed_rows_mut::<3>(3 * b).copy_from(&d);
        }
        for s in 0..ns {
            if let (Attachment::Bone { offset: o1, .. }, Attachment::Bone { offset: o2, .. }) = (
                &template.spheres[s].attachment,
                &target.spheres[s].attachment,
            ) {
                dq.fixed_rows_mut::<3>(3 * nb + 3 * s).copy_from(&(o2 - o1));
                dq[3 * nb + 3 * ns + s] = target.spheres[s].radius - template.spheres[s].radius;
            }
        }
        let ata = a.transpose() * &a;
        let atb = a.transpose() * &dq;
        let x =
            ata.cholesky()
                .map(|c| c.solve(&atb))
                .ok_or_else(|| ModelError::InvalidArgument {
                    name: "target",
                    reason: "shape basis is rank deficient on this template".into(),
                })?;
        let resid = (&a * &x - &dq).norm() / (rows as f64).sqrt();
        let beta = self
            .params
            .iter()
            .zip(x.iter())
            .map(|(p, d)| p.template_value + d)
            .collect();
        Ok((beta, resid))
    }

    /// Visit `(j, ∂c_i/∂β_j, ∂r_i/∂β_j)` for sphere `i` of a posed template (the β Jacobian of
    /// thesis §4.3; blends sum their parts). Entries with no effect on sphere `i` are skipped.
    pub fn for_each_sphere_column(
        &self,
        template: &SphereMeshTemplate,
        posed: &PosedSphereMesh,
        i: usize,
        f: &mut dyn FnMut(usize, Vector3<f64>, f64),
    ) {
        match &template.spheres[i].attachment {
            Attachment::Blend { parts } => {
                for &(p, w) in parts {
                    self.for_each_sphere_column(template, posed, p, &mut |j, dc, dr| {
                        f(j, dc * w, dr * w)
                    });
                }
            }
            Attachment::Bone { bone, .. } => {
                let bone = *bone;
                for (j, p) in self.params.iter().enumerate() {
                    let mut dc = Vector3::zeros();
                    let mut dr = 0.0;
                    let mut hit = false;
                    for e in &p.effects {
                        match *e {
                            ShapeEffect::RestTranslation { bone: b, dir }
                                if template.skeleton.is_ancestor_or_self(b, bone) =>
                            {
                                dc += posed.skeleton.rest_translation_jacobian(
                                    &template.skeleton,
                                    b,
                                    bone,
                                ) * dir;
                                hit = true;
                            }
                            ShapeEffect::Offset { sphere, dir } if sphere == i => {
                                dc += posed.skeleton.globals[bone].rotation * dir;
                                hit = true;
                            }
                            ShapeEffect::Radius { sphere, coef } if sphere == i => {
                                dr += coef;
                                hit = true;
                            }
                            _ => {}
                        }
                    }
                    if hit {
                        f(j, dc, dr);
                    }
                }
            }
        }
    }

    /// Visit `(j, ∂q/∂β_j)` for a footpoint `q = Σ w_i c_i + (Σ w_i r_i)·n` (a
    /// [`crate::query::Projection`]'s spheres, weights and normal): `Σ w_i (∂c_i/∂β_j + n·∂r_i/∂β_j)`.
    /// This is the β column of the data terms of thesis §4.3 (ANCHOR-FACTS §2.5 "β Jacobian
    /// rules"), exact for the residual `n·(p − q)`.
    pub fn for_each_footpoint_column(
        &self,
        template: &SphereMeshTemplate,
        posed: &PosedSphereMesh,
        spheres: &[u32; 3],
        weights: &[f64; 3],
        normal: &Vector3<f64>,
        f: &mut dyn FnMut(usize, Vector3<f64>),
    ) {
        for (&s, &w) in spheres.iter().zip(weights) {
            if w != 0.0 {
                self.for_each_sphere_column(template, posed, s as usize, &mut |j, dc, dr| {
                    f(j, (dc + normal * dr) * w)
                });
            }
        }
    }

    /// Eq. 4.14: β = β̄ ∘ I·β̃ for the latent scale factors β̃ = (height, width, thickness)
    /// (1 = template). ∂β_i/∂β̃_k = β̄_i when entry i scales with axis k ([`ShapeKind::latent_axis`]).
    pub fn from_latent(&self, latent: [f64; 3]) -> Vec<f64> {
        self.params
            .iter()
            .map(|p| p.template_value * latent[p.kind.latent_axis()])
            .collect()
    }
}
