//! The project's default right-hand sphere-mesh template, authored from anatomical proportions.
//!
//! Sources of the numbers (rounded to the millimetre, for an adult hand of length ≈ 185 mm from
//! the wrist crease to the middle fingertip):
//! - phalanx and metacarpal lengths: the segment-length to hand-length ratios of Buchholz,
//!   Armstrong & Goldstein, "Anthropometric data for describing the kinematics of the human hand",
//!   Ergonomics 35(3), 1992 — proximal/middle phalanx and distal segment per finger, thumb
//!   metacarpal, proximal and distal segments;
//! - hand breadth at the metacarpals (≈ 80–85 mm) and hand thickness (≈ 30 mm): ANSUR II
//!   (Gordon et al. 2014) male/female averages; finger breadths at the proximal and distal joints
//!   (≈ 20 and ≈ 16 mm, giving radii of ≈ 8.5–10 and ≈ 6–7 mm): the same survey;
//! - topology (which spheres are joined by pills and wedges, the membranes, the passive
//!   `thumb_membrane_middle` blend) and DOF limits: the honline template described in
//!   ANCHOR-FACTS §1.3 and §2, so that the honline shape vector β applies unchanged.
//!
//! Frames (DESIGN.md): origin at the back of the palm near the wrist, +y toward the fingertips,
//! palm facing −z, thumb toward −x (right hand). Each finger bone has local +y along the bone and
//! local +z toward the palm, so a positive rotation about local +x is flexion toward the palm;
//! abduction turns about local −z, which moves every digit toward the thumb side for positive
//! values (the honline convention, mirrored).

use std::path::Path;

use nalgebra::{Matrix3, Vector3};

use super::template::{Attachment, ElementDef, SphereDef, SphereMeshTemplate};
use crate::error::Result;
use crate::keypoints::{Handedness, KeypointDef};
use crate::kinematics::{Bone, Dof, DofKind, Skeleton};
use crate::math::{axis_angle, Rigid3};
use crate::shape::Element;

/// One finger of the default hand (mm, rad).
struct Finger {
    name: &'static str,
    base: [f64; 3],
    splay: f64,
    lengths: [f64; 3],
    radii: [f64; 4],
    abd_limits: [f64; 2],
    membrane: [f64; 3],
    membrane_radius: f64,
}

const FINGERS: [Finger; 4] = [
    Finger {
        name: "index",
        base: [-27.0, 65.0, 3.0],
        splay: 0.08,
        lengths: [40.0, 23.0, 13.5],
        radii: [10.0, 9.0, 7.8, 6.8],
        abd_limits: [-0.30, 0.35],
        membrane: [-2.0, 12.0, 3.0],
        membrane_radius: 3.0,
    },
    Finger {
        name: "middle",
        base: [-8.0, 67.0, 4.0],
        splay: 0.0,
        lengths: [44.0, 26.0, 15.0],
        radii: [10.0, 9.3, 8.0, 7.0],
        abd_limits: [-0.30, 0.40],
        membrane: [1.0, 14.0, 3.0],
        membrane_radius: 3.5,
    },
    Finger {
        name: "ring",
        base: [11.0, 65.0, 3.0],
        splay: -0.06,
        lengths: [41.0, 26.0, 14.5],
        radii: [9.6, 8.8, 7.6, 6.6],
        abd_limits: [-0.20, 0.30],
        membrane: [1.0, 13.0, 3.0],
        membrane_radius: 3.0,
    },
    Finger {
        name: "pinky",
        base: [27.0, 58.0, 1.0],
        splay: -0.15,
        lengths: [32.0, 19.0, 13.0],
        radii: [8.8, 7.8, 6.8, 6.0],
        abd_limits: [-0.35, 0.50],
        membrane: [-1.5, 10.0, 2.5],
        membrane_radius: 2.5,
    },
];

struct Build {
    bones: Vec<Bone>,
    dofs: Vec<Dof>,
    spheres: Vec<SphereDef>,
    /// Rest globals, to turn model-frame centers into bone offsets.
    globals: Vec<Rigid3>,
}

impl Build {
    fn bone(&mut self, name: &str, parent: Option<usize>, rest: Rigid3) -> usize {
        let g = match parent {
            Some(p) => self.globals[p].compose(&rest),
            None => rest,
        };
        self.bones.push(Bone {
            name: name.into(),
            parent,
            rest,
            dofs: vec![],
        });
        self.globals.push(g);
        self.bones.len() - 1
    }

    fn dof(
        &mut self,
        name: &str,
        bone: usize,
        kind: DofKind,
        axis: Vector3<f64>,
        limits: Option<[f64; 2]>,
    ) -> usize {
        self.dofs.push(Dof {
            name: name.into(),
            bone,
            kind,
            axis,
            limits,
        });
        self.dofs.len() - 1
    }

    /// Attach DOFs to a bone in application order (their pose-vector order is creation order).
    fn apply_order(&mut self, bone: usize, dofs: &[usize]) {
        self.bones[bone].dofs = dofs.to_vec();
    }

    fn sphere_at(&mut self, name: &str, bone: usize, model: [f64; 3], radius: f64) -> usize {
        let offset = self.globals[bone]
            .inverse()
            .transform_point(&Vector3::from(model));
        self.sphere_local(name, bone, offset, radius)
    }

    fn sphere_local(
        &mut self,
        name: &str,
        bone: usize,
        offset: Vector3<f64>,
        radius: f64,
    ) -> usize {
        self.spheres.push(SphereDef {
            name: name.into(),
            attachment: Attachment::Bone { bone, offset },
            radius,
        });
        self.spheres.len() - 1
    }
}

/// Local frame with +y along `dir` and +z toward `palmar` (orthogonalized), x = y × z.
fn frame(dir: Vector3<f64>, palmar: Vector3<f64>) -> Matrix3<f64> {
    let y = dir.normalize();
    let z = (palmar - y * palmar.dot(&y)).normalize();
    let x = y.cross(&z);
    Matrix3::from_columns(&[x, y, z])
}

/// The default right-hand template: 39 spheres, 31 elements (16 pills, 15 wedges), 28 DOFs.
pub fn default_right_hand() -> SphereMeshTemplate {
    build().expect("the embedded default template is valid")
}

fn build() -> Result<SphereMeshTemplate> {
    let mut b = Build {
        bones: vec![],
        dofs: vec![],
        spheres: vec![],
        globals: vec![],
    };
    let root = b.bone("root", None, Rigid3::identity());
    let mut root_dofs = vec![];
    for (name, axis) in [
        ("global_tx", Vector3::x()),
        ("global_ty", Vector3::y()),
        ("global_tz", Vector3::z()),
    ] {
        root_dofs.push(b.dof(name, root, DofKind::Translation, axis, None));
    }
    for (name, axis) in [
        ("global_rx", Vector3::x()),
        ("global_ry", Vector3::y()),
        ("global_rz", Vector3::z()),
    ] {
        root_dofs.push(b.dof(name, root, DofKind::GlobalRotation, axis, None));
    }
    b.apply_order(root, &root_dofs);
    let palm = b.bone("palm", Some(root), Rigid3::identity());
    let finger_frame = Matrix3::from_columns(&[-Vector3::x(), Vector3::y(), -Vector3::z()]);
    let wrist = b.bone(
        "wrist",
        Some(palm),
        Rigid3::new(finger_frame, Vector3::new(0.0, -10.0, 0.0)),
    );
    let w_abd = b.dof(
        "wrist_abd",
        wrist,
        DofKind::Rotation,
        -Vector3::z(),
        Some([-1.0, 0.2]),
    );
    let w_flex = b.dof(
        "wrist_flex",
        wrist,
        DofKind::Rotation,
        Vector3::x(),
        Some([-1.0, 1.6]),
    );
    b.apply_order(wrist, &[w_flex, w_abd]);

    // Thumb: CMC on the radial side near the wrist, metacarpal pointing out, up and palmward.
    let t_dir = Vector3::new(-0.55, 0.75, -0.37).normalize();
    let t_rot = frame(t_dir, Vector3::new(0.7, 0.0, -0.7));
    let mut t_abd_axis = t_rot.column(2).into_owned();
    // Positive thumb abduction spreads the thumb radially (toward −x).
    if t_abd_axis.cross(&t_dir).x > 0.0 {
        t_abd_axis = -t_abd_axis;
    }
    let t_abd_local = t_rot.transpose() * t_abd_axis;
    let thumb_cmc = Vector3::new(-25.0, 12.0, -6.0);
    let (t1_len, t2_len, t_top) = (42.0, 31.0, 16.0);
    let t1 = b.bone("thumb_1", Some(palm), Rigid3::new(t_rot, thumb_cmc));
    let t2 = b.bone(
        "thumb_2",
        Some(t1),
        Rigid3::from_translation(Vector3::new(0.0, t1_len, 0.0)),
    );
    let t3 = b.bone(
        "thumb_3",
        Some(t2),
        Rigid3::from_translation(Vector3::new(0.0, t2_len, 0.0)),
    );
    let d_abd = b.dof(
        "thumb_cmc_abd",
        t1,
        DofKind::Rotation,
        t_abd_local,
        Some([-0.5, 0.8]),
    );
    let d_f1 = b.dof(
        "thumb_cmc_flex",
        t1,
        DofKind::Rotation,
        Vector3::x(),
        Some([-0.6, 1.0]),
    );
    let d_f2 = b.dof(
        "thumb_mcp_flex",
        t2,
        DofKind::Rotation,
        Vector3::x(),
        Some([-0.3, 1.0]),
    );
    let d_f3 = b.dof(
        "thumb_ip_flex",
        t3,
        DofKind::Rotation,
        Vector3::x(),
        Some([-0.3, 1.4]),
    );
    b.apply_order(t1, &[d_f1, d_abd]);
    b.apply_order(t2, &[d_f2]);
    b.apply_order(t3, &[d_f3]);

    let mut digit_bones = vec![(t1, t2, t3)];
    for f in &FINGERS {
        let rot = axis_angle(&Vector3::z(), f.splay) * finger_frame;
        let b1 = b.bone(
            &format!("{}_1", f.name),
            Some(palm),
            Rigid3::new(rot, Vector3::from(f.base)),
        );
        let b2 = b.bone(
            &format!("{}_2", f.name),
            Some(b1),
            Rigid3::from_translation(Vector3::new(0.0, f.lengths[0], 0.0)),
        );
        let b3 = b.bone(
            &format!("{}_3", f.name),
            Some(b2),
            Rigid3::from_translation(Vector3::new(0.0, f.lengths[1], 0.0)),
        );
        let abd = b.dof(
            &format!("{}_mcp_abd", f.name),
            b1,
            DofKind::Rotation,
            -Vector3::z(),
            Some(f.abd_limits),
        );
        let f1 = b.dof(
            &format!("{}_mcp_flex", f.name),
            b1,
            DofKind::Rotation,
            Vector3::x(),
            Some([-0.5, 1.6]),
        );
        let f2 = b.dof(
            &format!("{}_pip_flex", f.name),
            b2,
            DofKind::Rotation,
            Vector3::x(),
            Some([-0.1, 1.9]),
        );
        let f3 = b.dof(
            &format!("{}_dip_flex", f.name),
            b3,
            DofKind::Rotation,
            Vector3::x(),
            Some([-0.2, 1.5]),
        );
        b.apply_order(b1, &[f1, abd]);
        b.apply_order(b2, &[f2]);
        b.apply_order(b3, &[f3]);
        digit_bones.push((b1, b2, b3));
    }

    // Spheres in the honline order (ANCHOR-FACTS §2.6): pinky, ring, middle, index (top, middle,
    // bottom, base), thumb, palm, membranes, thumb extras, wrist.
    let mut tips = [0usize; 5];
    for (fi, f) in FINGERS.iter().enumerate().rev() {
        let (b1, b2, b3) = digit_bones[fi + 1];
        tips[fi + 1] = b.sphere_local(
            &format!("{}_top", f.name),
            b3,
            Vector3::new(0.0, f.lengths[2], 0.0),
            f.radii[3],
        );
        b.sphere_local(
            &format!("{}_middle", f.name),
            b3,
            Vector3::zeros(),
            f.radii[2],
        );
        b.sphere_local(
            &format!("{}_bottom", f.name),
            b2,
            Vector3::zeros(),
            f.radii[1],
        );
        b.sphere_local(
            &format!("{}_base", f.name),
            b1,
            Vector3::zeros(),
            f.radii[0],
        );
    }
    let thumb_top = b.sphere_local("thumb_top", t3, Vector3::new(0.0, t_top, 0.0), 8.0);
    b.sphere_local("thumb_middle", t3, Vector3::zeros(), 9.0);
    b.sphere_local("thumb_bottom", t2, Vector3::zeros(), 11.0);
    let thumb_base = b.sphere_local("thumb_base", t1, Vector3::zeros(), 14.0);
    b.sphere_at("palm_pinky", palm, [27.0, 49.0, 2.0], 11.5);
    b.sphere_at("palm_ring", palm, [9.0, 55.0, 3.0], 12.5);
    b.sphere_at("palm_middle", palm, [-9.0, 56.0, 3.0], 12.5);
    b.sphere_at("palm_index", palm, [-28.0, 54.0, 2.0], 12.5);
    let palm_thumb = b.sphere_at("palm_thumb", palm, [-36.0, 44.0, -2.0], 5.0);
    b.sphere_at("palm_back", palm, [0.0, 0.0, 0.0], 15.0);
    b.sphere_at("palm_right", palm, [22.0, 10.0, 1.0], 15.0);
    b.sphere_at("palm_left", palm, [-20.0, 10.0, 0.0], 15.5);
    for (fi, f) in FINGERS.iter().enumerate().rev() {
        let b1 = digit_bones[fi + 1].0;
        b.sphere_local(
            &format!("{}_membrane", f.name),
            b1,
            Vector3::from(f.membrane),
            f.membrane_radius,
        );
    }
    let thumb_additional = b.sphere_local(
        "thumb_additional",
        t3,
        Vector3::new(0.0, t_top + 6.0, 1.5),
        5.0,
    );
    let tml = b.sphere_local("thumb_membrane_left", t2, Vector3::new(0.0, 12.0, 0.0), 4.0);
    b.sphere_at("wrist_top_left", wrist, [-12.0, -4.0, 0.0], 15.5);
    b.sphere_at("wrist_top_right", wrist, [12.0, -4.0, 0.0], 15.5);
    b.sphere_at("wrist_bottom_left", wrist, [-12.0, -50.0, 0.0], 17.5);
    b.sphere_at("wrist_bottom_right", wrist, [12.0, -50.0, 0.0], 17.5);
    b.spheres.push(SphereDef {
        name: "thumb_membrane_middle".into(),
        attachment: Attachment::Blend {
            parts: vec![(palm_thumb, 0.4), (tml, 0.3), (thumb_base, 0.3)],
        },
        radius: 0.0,
    });
    tips[0] = thumb_additional;
    let _ = thumb_top;

    let skeleton = Skeleton::new(b.bones, b.dofs, Path::new("<default template>"))?;
    let spheres = b.spheres;
    let idx = |name: &str| {
        spheres
            .iter()
            .position(|s| s.name == name)
            .map(|i| i as u32)
            .expect("named sphere")
    };
    let bone = |name: &str| skeleton.bone_index(name).expect("named bone");
    let mut elements = Vec::new();
    for (digit, bones) in [
        ("pinky", "pinky"),
        ("ring", "ring"),
        ("middle", "middle"),
        ("index", "index"),
        ("thumb", "thumb"),
    ] {
        for (a, c, k) in [
            ("middle", "top", 3),
            ("bottom", "middle", 2),
            ("base", "bottom", 1),
        ] {
            elements.push(ElementDef {
                element: Element::Pill([
                    idx(&format!("{digit}_{a}")),
                    idx(&format!("{digit}_{c}")),
                ]),
                bone: bone(&format!("{bones}_{k}")),
            });
        }
    }
    let wedge = |a: &str, c: &str, d: &str| Element::Wedge([idx(a), idx(c), idx(d)]);
    let palm_wedges = [
        wedge("palm_right", "palm_ring", "palm_pinky"),
        wedge("palm_back", "palm_right", "palm_ring"),
        wedge("palm_back", "palm_middle", "palm_ring"),
        wedge("palm_back", "palm_left", "palm_middle"),
        wedge("palm_left", "palm_middle", "palm_index"),
        wedge("palm_pinky", "ring_membrane", "pinky_membrane"),
        wedge("palm_ring", "palm_pinky", "ring_membrane"),
        wedge("palm_ring", "middle_membrane", "ring_membrane"),
        wedge("palm_middle", "palm_ring", "middle_membrane"),
        wedge("palm_middle", "palm_index", "middle_membrane"),
        wedge("palm_index", "middle_membrane", "index_membrane"),
        wedge("thumb_base", "thumb_membrane_middle", "palm_thumb"),
    ];
    elements.extend(palm_wedges.into_iter().map(|element| ElementDef {
        element,
        bone: palm,
    }));
    elements.push(ElementDef {
        element: Element::Pill([idx("thumb_top"), idx("thumb_additional")]),
        bone: t3,
    });
    elements.push(ElementDef {
        element: wedge("wrist_bottom_left", "wrist_top_left", "wrist_top_right"),
        bone: wrist,
    });
    elements.push(ElementDef {
        element: wedge("wrist_bottom_right", "wrist_bottom_left", "wrist_top_right"),
        bone: wrist,
    });
    elements.push(ElementDef {
        element: wedge("thumb_base", "thumb_membrane_middle", "thumb_membrane_left"),
        bone: palm,
    });

    let mut keypoints = vec![KeypointDef::Joint { bone: wrist }];
    for (d, &(b1, b2, b3)) in digit_bones.iter().enumerate() {
        keypoints.extend([
            KeypointDef::Joint { bone: b1 },
            KeypointDef::Joint { bone: b2 },
            KeypointDef::Joint { bone: b3 },
            KeypointDef::Tip {
                bone: b3,
                sphere: tips[d],
            },
        ]);
    }
    let template = SphereMeshTemplate {
        name: "hands default right hand".into(),
        handedness: Handedness::Right,
        skeleton,
        spheres,
        elements,
        keypoints,
    };
    template.validate(Path::new("<default template>"))?;
    Ok(template)
}
