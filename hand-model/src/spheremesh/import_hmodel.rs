//! Import and export of the original hmodel / honline sphere-mesh files (`C.txt`, `R.txt`,
//! `B.txt`, `I.txt`; ANCHOR-FACTS §2.1–2.6). The conventions are documented on
//! [`import_hmodel_dir`].

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Matrix4, Vector3};

use super::json::write_atomic;
use super::template::{Attachment, ElementDef, SphereDef, SphereMeshTemplate};
use crate::error::{ModelError, Result};
use crate::keypoints::{Handedness, KeypointDef};
use crate::kinematics::{Bone, Dof, DofKind, Pose, Skeleton};
use crate::math::Rigid3;
use crate::shape::Element;

/// The third block index that marks a pill in `B.txt` (MSVC's `RAND_MAX`, hard-coded because
/// glibc's differs).
pub const PILL_SENTINEL: i64 = 32767;

/// Which original model a folder holds.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum HmodelVariant {
    /// hmodel (SIGGRAPH Asia'16): 38 spheres, 30 blocks, 19 transforms.
    Hmodel,
    /// honline (TOG'17): 39 spheres, 31 blocks, 18 transforms.
    Honline,
}

impl HmodelVariant {
    /// Number of spheres in `C.txt` / `R.txt`.
    pub fn num_spheres(self) -> usize {
        match self {
            HmodelVariant::Hmodel => 38,
            HmodelVariant::Honline => 39,
        }
    }

    /// Number of blocks in the original `B.txt`.
    pub fn num_blocks(self) -> usize {
        match self {
            HmodelVariant::Hmodel => 30,
            HmodelVariant::Honline => 31,
        }
    }

    /// Number of transforms the original writes to `I.txt`.
    pub fn num_transforms(self) -> usize {
        match self {
            HmodelVariant::Hmodel => 19,
            HmodelVariant::Honline => 18,
        }
    }

    /// Lower-case label (`hmodel` / `honline`).
    pub fn label(self) -> &'static str {
        match self {
            HmodelVariant::Hmodel => "hmodel",
            HmodelVariant::Honline => "honline",
        }
    }

    fn from_sphere_count(n: usize) -> Option<Self> {
        match n {
            38 => Some(HmodelVariant::Hmodel),
            39 => Some(HmodelVariant::Honline),
            _ => None,
        }
    }
}

/// The honline pose vector θ (34 slots; hmodel uses the first 29) → this crate's DOF names.
/// Slot 6 is unused in the originals (`None`).
pub const HONLINE_THETA_DOFS: [Option<&str>; 34] = [
    Some("global_tx"),
    Some("global_ty"),
    Some("global_tz"),
    Some("global_rx"),
    Some("global_ry"),
    Some("global_rz"),
    None,
    Some("wrist_abd"),
    Some("wrist_flex"),
    Some("thumb_cmc_abd"),
    Some("thumb_cmc_flex"),
    Some("thumb_mcp_flex"),
    Some("thumb_ip_flex"),
    Some("index_mcp_abd"),
    Some("index_mcp_flex"),
    Some("index_pip_flex"),
    Some("index_dip_flex"),
    Some("middle_mcp_abd"),
    Some("middle_mcp_flex"),
    Some("middle_pip_flex"),
    Some("middle_dip_flex"),
    Some("ring_mcp_abd"),
    Some("ring_mcp_flex"),
    Some("ring_pip_flex"),
    Some("ring_dip_flex"),
    Some("pinky_mcp_abd"),
    Some("pinky_mcp_flex"),
    Some("pinky_pip_flex"),
    Some("pinky_dip_flex"),
    Some("thumb_cmc_twist"),
    Some("index_mcp_twist"),
    Some("middle_mcp_twist"),
    Some("ring_mcp_twist"),
    Some("pinky_mcp_twist"),
];

/// The original phalanges in `I.txt` order: (our bone name, original name, parent phalange).
const PHALANGES: [(&str, &str, Option<usize>); 18] = [
    ("palm", "Hand", Some(17)),
    ("thumb_1", "HandThumb1", Some(0)),
    ("thumb_2", "HandThumb2", Some(1)),
    ("thumb_3", "HandThumb3", Some(2)),
    ("pinky_1", "HandPinky1", Some(0)),
    ("pinky_2", "HandPinky2", Some(4)),
    ("pinky_3", "HandPinky3", Some(5)),
    ("ring_1", "HandRing1", Some(0)),
    ("ring_2", "HandRing2", Some(7)),
    ("ring_3", "HandRing3", Some(8)),
    ("middle_1", "HandMiddle1", Some(0)),
    ("middle_2", "HandMiddle2", Some(10)),
    ("middle_3", "HandMiddle3", Some(11)),
    ("index_1", "HandIndex1", Some(0)),
    ("index_2", "HandIndex2", Some(13)),
    ("index_3", "HandIndex3", Some(14)),
    ("wrist", "Wrist", Some(0)),
    ("root", "Position", None),
];

/// Our bone order (that of the default template), as phalange indices.
const BONE_ORDER: [usize; 18] = [17, 0, 16, 1, 2, 3, 13, 14, 15, 10, 11, 12, 7, 8, 9, 4, 5, 6];

fn bone_of_phalange(p: usize) -> usize {
    BONE_ORDER.iter().position(|&q| q == p).unwrap_or(0)
}

/// One DOF of the honline layout.
struct DofSpec {
    theta: usize,
    phalange: usize,
    kind: DofKind,
    /// 0 = x, 1 = y, 2 = z.
    axis: usize,
    limits: Option<[f64; 2]>,
}

const fn rot(theta: usize, phalange: usize, axis: usize, lo: f64, hi: f64) -> DofSpec {
    DofSpec {
        theta,
        phalange,
        kind: DofKind::Rotation,
        axis,
        limits: Some([lo, hi]),
    }
}

const fn global(theta: usize, kind: DofKind, axis: usize) -> DofSpec {
    DofSpec {
        theta,
        phalange: 17,
        kind,
        axis,
        limits: None,
    }
}

/// ANCHOR-FACTS §1.3 (honline limits; the hmodel thumb IP limit is patched in `dof_specs`).
const DOFS: [DofSpec; 33] = [
    global(0, DofKind::Translation, 0),
    global(1, DofKind::Translation, 1),
    global(2, DofKind::Translation, 2),
    global(3, DofKind::GlobalRotation, 0),
    global(4, DofKind::GlobalRotation, 1),
    global(5, DofKind::GlobalRotation, 2),
    rot(7, 16, 2, -1.0, 0.2),
    rot(8, 16, 0, -1.0, 1.6),
    rot(9, 1, 2, -0.1, 1.0),
    rot(10, 1, 0, -0.5, 1.0),
    rot(11, 2, 0, -0.9, 0.9),
    rot(12, 3, 0, -1.4, 0.7),
    rot(13, 13, 2, -0.30, 0.35),
    rot(14, 13, 0, -1.3, 1.6),
    rot(15, 14, 0, -0.1, 2.0),
    rot(16, 15, 0, -0.1, 2.0),
    rot(17, 10, 2, -0.30, 0.40),
    rot(18, 10, 0, -1.3, 1.6),
    rot(19, 11, 0, -0.1, 2.0),
    rot(20, 12, 0, -0.1, 2.0),
    rot(21, 7, 2, -0.10, 0.30),
    rot(22, 7, 0, -1.3, 1.6),
    rot(23, 8, 0, -0.1, 2.0),
    rot(24, 9, 0, -0.1, 2.0),
    rot(25, 4, 2, -0.20, 0.65),
    rot(26, 4, 0, -1.3, 1.6),
    rot(27, 5, 0, -0.1, 2.0),
    rot(28, 6, 0, -0.1, 2.0),
    rot(29, 1, 1, -0.40, 0.40),
    rot(30, 13, 1, -0.45, 0.05),
    rot(31, 10, 1, -0.15, 0.05),
    rot(32, 7, 1, -0.10, 0.05),
    rot(33, 4, 1, -0.10, 0.05),
];

/// How a sphere of the original files is placed.
#[derive(Copy, Clone, PartialEq, Eq)]
enum Role {
    /// The phalange's center sphere: at the bone origin.
    Center,
    /// An attachment: a fixed offset in the bone frame.
    Attached,
    /// honline's derived `thumb_membrane_middle`.
    Derived,
}

/// Spheres in file order: (name, phalange, role). Index 33 differs between the variants.
const SPHERES: [(&str, usize, Role); 39] = [
    ("pinky_top", 6, Role::Attached),
    ("pinky_middle", 6, Role::Center),
    ("pinky_bottom", 5, Role::Center),
    ("pinky_base", 4, Role::Center),
    ("ring_top", 9, Role::Attached),
    ("ring_middle", 9, Role::Center),
    ("ring_bottom", 8, Role::Center),
    ("ring_base", 7, Role::Center),
    ("middle_top", 12, Role::Attached),
    ("middle_middle", 12, Role::Center),
    ("middle_bottom", 11, Role::Center),
    ("middle_base", 10, Role::Center),
    ("index_top", 15, Role::Attached),
    ("index_middle", 15, Role::Center),
    ("index_bottom", 14, Role::Center),
    ("index_base", 13, Role::Center),
    ("thumb_top", 3, Role::Attached),
    ("thumb_middle", 3, Role::Center),
    ("thumb_bottom", 2, Role::Center),
    ("thumb_base", 1, Role::Center),
    ("palm_pinky", 0, Role::Attached),
    ("palm_ring", 0, Role::Attached),
    ("palm_middle", 0, Role::Attached),
    ("palm_index", 0, Role::Attached),
    ("palm_thumb", 0, Role::Attached),
    ("palm_back", 0, Role::Center),
    ("palm_right", 0, Role::Attached),
    ("palm_left", 0, Role::Attached),
    ("pinky_membrane", 4, Role::Attached),
    ("ring_membrane", 7, Role::Attached),
    ("middle_membrane", 10, Role::Attached),
    ("index_membrane", 13, Role::Attached),
    ("thumb_additional", 3, Role::Attached),
    ("thumb_membrane_left", 2, Role::Attached),
    ("wrist_top_left", 16, Role::Attached),
    ("wrist_top_right", 16, Role::Attached),
    ("wrist_bottom_left", 16, Role::Attached),
    ("wrist_bottom_right", 16, Role::Attached),
    ("thumb_membrane_middle", 0, Role::Derived),
];

/// hmodel's sphere 33.
const HMODEL_SPHERE_33: (&str, usize, Role) = ("thumb_fold", 1, Role::Attached);

/// Weights of honline's derived `thumb_membrane_middle` (`Model::update_centers`).
const THUMB_MEMBRANE_MIDDLE: [(&str, f64); 3] = [
    ("palm_thumb", 0.4),
    ("thumb_membrane_left", 0.3),
    ("thumb_base", 0.3),
];

/// Block → phalange maps (honline `setup_blockid_to_phalangeid_map`, hmodel
/// `setup_blockid_to_jointid_map` translated to phalange ids).
const HONLINE_BLOCK_PHALANGE: [usize; 31] = [
    6, 5, 4, 9, 8, 7, 12, 11, 10, 15, 14, 13, 3, 2, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 3, 16,
    16, 0,
];
const HMODEL_BLOCK_PHALANGE: [usize; 30] = [
    6, 5, 4, 9, 8, 7, 12, 11, 10, 15, 14, 13, 3, 2, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 3, 16,
    16,
];

fn sphere_table(variant: HmodelVariant) -> Vec<(&'static str, usize, Role)> {
    let mut t: Vec<_> = SPHERES[..variant.num_spheres()].to_vec();
    if variant == HmodelVariant::Hmodel {
        t[33] = HMODEL_SPHERE_33;
    }
    t
}

fn digit_tip(digit: &str) -> &'static str {
    match digit {
        "thumb" => "thumb_additional",
        "index" => "index_top",
        "middle" => "middle_top",
        "ring" => "ring_top",
        _ => "pinky_top",
    }
}

// ------------------------------------------------------------------------------------------------
// Reading the number files.

/// The whitespace/comma separated tokens of one file, read in order.
struct NumberFile<'a> {
    path: PathBuf,
    tokens: Vec<&'a str>,
    pos: usize,
}

fn read_text(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|source| ModelError::Io {
        file: path.to_path_buf(),
        source,
    })
}

impl<'a> NumberFile<'a> {
    fn new(path: PathBuf, text: &'a str) -> Self {
        let tokens = text
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|s| !s.is_empty())
            .collect();
        Self {
            path,
            tokens,
            pos: 0,
        }
    }

    fn err(&self, field: &str, index: Option<usize>, reason: impl Into<String>) -> ModelError {
        ModelError::field(&self.path, field, index, reason)
    }

    /// The leading count.
    fn count(&mut self) -> Result<usize> {
        let Some(tok) = self.tokens.first().copied() else {
            return Err(self.err("count", None, "empty file: expected a count"));
        };
        self.pos = 1;
        tok.parse::<usize>().map_err(|_| {
            self.err(
                "count",
                None,
                format!("`{tok}` is not a valid count (a non-negative integer)"),
            )
        })
    }

    /// Check that `count` entries of `per` numbers follow (no allocation from untrusted counts).
    fn expect_entries(&self, field: &str, count: usize, per: usize) -> Result<()> {
        let remaining = self.tokens.len() - self.pos;
        let needed = count.checked_mul(per);
        match needed {
            Some(n) if n <= remaining => Ok(()),
            _ => Err(self.err(
                field,
                Some(remaining / per),
                format!(
                    "the file ends after {remaining} numbers but its count {count} needs {} (truncated file or wrong count)",
                    needed.map_or_else(|| "more".to_string(), |n| n.to_string())
                ),
            )),
        }
    }

    fn next_token(&mut self, field: &str, index: usize) -> Result<&'a str> {
        let tok = self
            .tokens
            .get(self.pos)
            .copied()
            .ok_or_else(|| self.err(field, Some(index), "unexpected end of file"))?;
        self.pos += 1;
        Ok(tok)
    }

    fn float(&mut self, field: &str, index: usize) -> Result<f64> {
        let tok = self.next_token(field, index)?;
        let v = tok
            .parse::<f64>()
            .map_err(|_| self.err(field, Some(index), format!("`{tok}` is not a number")))?;
        if !v.is_finite() {
            return Err(self.err(
                field,
                Some(index),
                format!("`{tok}` is not a finite number"),
            ));
        }
        Ok(v)
    }

    fn int(&mut self, field: &str, index: usize) -> Result<i64> {
        let tok = self.next_token(field, index)?;
        tok.parse::<i64>().map_err(|_| {
            self.err(
                field,
                Some(index),
                format!("`{tok}` is not an integer sphere index"),
            )
        })
    }

    /// Refuse numbers after the last entry (the count is then wrong).
    fn finish(&self, count: usize) -> Result<()> {
        let extra = self.tokens.len() - self.pos;
        if extra > 0 {
            return Err(self.err(
                "count",
                None,
                format!("the count says {count} but {extra} more numbers follow the last entry (wrong count)"),
            ));
        }
        Ok(())
    }
}

/// The raw contents of an hmodel/honline model folder.
struct RawModel {
    centers: Vec<Vector3<f64>>,
    radii: Vec<f64>,
    /// Blocks; a pill has `None` as third index.
    blocks: Vec<(usize, usize, Option<usize>)>,
    /// The first 18 rest transforms (rotation projected onto SO(3)).
    transforms: Vec<Rigid3>,
}

fn read_centers(path: PathBuf) -> Result<Vec<Vector3<f64>>> {
    let text = read_text(&path)?;
    let mut f = NumberFile::new(path, &text);
    let n = f.count()?;
    f.expect_entries("centers", n, 3)?;
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        out.push(Vector3::new(
            f.float("centers", i)?,
            f.float("centers", i)?,
            f.float("centers", i)?,
        ));
    }
    f.finish(n)?;
    Ok(out)
}

fn read_radii(path: PathBuf) -> Result<Vec<f64>> {
    let text = read_text(&path)?;
    let mut f = NumberFile::new(path, &text);
    let n = f.count()?;
    f.expect_entries("radii", n, 1)?;
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let r = f.float("radii", i)?;
        if r < 0.0 {
            return Err(f.err("radii", Some(i), format!("negative radius {r}")));
        }
        out.push(r);
    }
    f.finish(n)?;
    Ok(out)
}

fn read_blocks(path: PathBuf, num_spheres: usize) -> Result<Vec<(usize, usize, Option<usize>)>> {
    let text = read_text(&path)?;
    let mut f = NumberFile::new(path, &text);
    let n = f.count()?;
    if n == 0 {
        return Err(f.err("count", None, "no blocks"));
    }
    f.expect_entries("blocks", n, 3)?;
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let raw = [
            f.int("blocks", i)?,
            f.int("blocks", i)?,
            f.int("blocks", i)?,
        ];
        let pill = raw[2] == PILL_SENTINEL;
        let used = if pill { &raw[..2] } else { &raw[..] };
        let mut idx = [0usize; 3];
        for (k, &v) in used.iter().enumerate() {
            if v < 0 || v as u64 >= num_spheres as u64 {
                let what = if v == PILL_SENTINEL {
                    " (the pill marker is only allowed third)"
                } else {
                    ""
                };
                return Err(f.err(
                    "blocks",
                    Some(i),
                    format!("sphere index {v} out of range ({num_spheres} spheres){what}"),
                ));
            }
            idx[k] = v as usize;
        }
        let distinct = idx[0] != idx[1] && (pill || (idx[0] != idx[2] && idx[1] != idx[2]));
        if !distinct {
            return Err(f.err("blocks", Some(i), "a block repeats a sphere"));
        }
        out.push((idx[0], idx[1], (!pill).then_some(idx[2])));
    }
    f.finish(n)?;
    Ok(out)
}

/// The closest rotation to `m` (polar decomposition), or `None` when `m` is not close to one.
fn project_rotation(m: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    if (m.transpose() * m - Matrix3::identity()).norm() > 1e-3 || m.determinant() <= 0.0 {
        return None;
    }
    let svd = m.svd(true, true);
    let r = svd.u? * svd.v_t?;
    (r.determinant() > 0.0 && r.iter().all(|x| x.is_finite())).then_some(r)
}

fn read_transforms(path: PathBuf) -> Result<Vec<Rigid3>> {
    let text = read_text(&path)?;
    let mut f = NumberFile::new(path, &text);
    let n = f.count()?;
    if n < PHALANGES.len() {
        return Err(f.err(
            "count",
            None,
            format!(
                "{n} transforms, expected {} (one per phalange; hmodel writes 19)",
                PHALANGES.len()
            ),
        ));
    }
    f.expect_entries("transforms", n, 16)?;
    let mut out = Vec::with_capacity(PHALANGES.len());
    for i in 0..n {
        let mut cols = [0.0; 16];
        for v in &mut cols {
            *v = f.float("transforms", i)?;
        }
        let Some(&(_, phalange, _)) = PHALANGES.get(i) else {
            continue; // hmodel's unused 19th transform
        };
        let m = Matrix4::from_column_slice(&cols);
        let last_row_ok =
            (m[(3, 0)].abs() + m[(3, 1)].abs() + m[(3, 2)].abs() + (m[(3, 3)] - 1.0).abs()) < 1e-6;
        if !last_row_ok {
            return Err(f.err(
                "transforms",
                Some(i),
                format!(
                    "the last row must be (0 0 0 1) in a column-major rigid transform ({phalange})"
                ),
            ));
        }
        let r = m.fixed_view::<3, 3>(0, 0).into_owned();
        let Some(r) = project_rotation(&r) else {
            return Err(f.err(
                "transforms",
                Some(i),
                format!("the rotation part is not a rotation ({phalange})"),
            ));
        };
        out.push(Rigid3::new(r, m.fixed_view::<3, 1>(0, 3).into_owned()));
    }
    f.finish(n)?;
    Ok(out)
}

fn read_raw(dir: &Path) -> Result<RawModel> {
    let centers = read_centers(dir.join("C.txt"))?;
    let c_path = dir.join("C.txt");
    if HmodelVariant::from_sphere_count(centers.len()).is_none() {
        return Err(ModelError::field(
            c_path,
            "count",
            None,
            format!(
                "{} spheres: expected 38 (hmodel) or 39 (honline)",
                centers.len()
            ),
        ));
    }
    let radii = read_radii(dir.join("R.txt"))?;
    if radii.len() != centers.len() {
        return Err(ModelError::field(
            dir.join("R.txt"),
            "count",
            None,
            format!(
                "{} radii for {} centers in C.txt",
                radii.len(),
                centers.len()
            ),
        ));
    }
    let blocks = read_blocks(dir.join("B.txt"), centers.len())?;
    let transforms = read_transforms(dir.join("I.txt"))?;
    Ok(RawModel {
        centers,
        radii,
        blocks,
        transforms,
    })
}

// ------------------------------------------------------------------------------------------------
// Building the template.

/// Build the skeleton of a variant from the 18 rest transforms (phalange order).
fn build_skeleton(
    variant: HmodelVariant,
    transforms: &[Rigid3],
    source: &Path,
) -> Result<Skeleton> {
    let specs: Vec<&DofSpec> = DOFS
        .iter()
        .filter(|d| variant == HmodelVariant::Honline || d.theta < 29)
        .collect();
    let mut bones: Vec<Bone> = BONE_ORDER
        .iter()
        .map(|&p| {
            let (name, _, parent) = PHALANGES[p];
            Bone {
                name: name.to_string(),
                parent: parent.map(bone_of_phalange),
                rest: transforms.get(p).copied().unwrap_or_default(),
                dofs: vec![],
            }
        })
        .collect();
    let mut dofs = Vec::with_capacity(specs.len());
    for s in &specs {
        let mut limits = s.limits;
        if variant == HmodelVariant::Hmodel && s.theta == 12 {
            limits = Some([-0.9, 0.7]);
        }
        dofs.push(Dof {
            name: HONLINE_THETA_DOFS[s.theta].unwrap_or("unused").to_string(),
            bone: bone_of_phalange(s.phalange),
            kind: s.kind,
            axis: Vector3::ith(s.axis, 1.0),
            limits,
        });
    }
    // Application order: the global pass (θ order), then X, then Z, then Y rotations.
    let pass = |s: &DofSpec| match s.kind {
        DofKind::Translation | DofKind::GlobalRotation => 0,
        DofKind::Rotation => [1, 3, 2][s.axis],
    };
    let mut order: Vec<usize> = (0..specs.len()).collect();
    order.sort_by_key(|&d| (pass(specs[d]), specs[d].theta));
    for d in order {
        let b = dofs[d].bone;
        bones[b].dofs.push(d);
    }
    Skeleton::new(bones, dofs, source)
}

/// Lowest common ancestor of a set of bones.
fn common_ancestor(skeleton: &Skeleton, bones: &[usize]) -> usize {
    let mut lca = bones.first().copied().unwrap_or(0);
    for &b in bones.iter().skip(1) {
        while !skeleton.is_ancestor_or_self(lca, b) {
            match skeleton.bones()[lca].parent {
                Some(p) => lca = p,
                None => break,
            }
        }
    }
    lca
}

/// `Model::reindex`: put the sphere with the largest radius first (the original's fixed
/// sequence of five in-place reorderings for wedges, a swap for pills).
fn reindex(block: (usize, usize, Option<usize>), radii: &[f64]) -> Element {
    let r = |i: usize| radii.get(i).copied().unwrap_or(0.0);
    match block {
        (a, b, None) => {
            if r(a) < r(b) {
                Element::Pill([b as u32, a as u32])
            } else {
                Element::Pill([a as u32, b as u32])
            }
        }
        (a, b, Some(c)) => {
            let mut s = [a, b, c];
            let le = |x: usize, y: usize| r(x) <= r(y);
            if le(s[0], s[1]) && le(s[1], s[2]) {
                s = [s[2], s[1], s[0]];
            }
            if le(s[0], s[2]) && le(s[2], s[1]) {
                s = [s[1], s[2], s[0]];
            }
            if le(s[1], s[0]) && le(s[0], s[2]) {
                s = [s[2], s[0], s[1]];
            }
            if le(s[1], s[2]) && le(s[2], s[0]) {
                s = [s[0], s[2], s[1]];
            }
            if le(s[2], s[0]) && le(s[0], s[1]) {
                s = [s[1], s[0], s[2]];
            }
            Element::Wedge(s.map(|i| i as u32))
        }
    }
}

fn build_template(raw: &RawModel, dir: &Path) -> Result<SphereMeshTemplate> {
    let c_path = dir.join("C.txt");
    let variant = HmodelVariant::from_sphere_count(raw.centers.len()).ok_or_else(|| {
        ModelError::field(
            &c_path,
            "count",
            None,
            "expected 38 (hmodel) or 39 (honline) spheres",
        )
    })?;
    let skeleton = build_skeleton(variant, &raw.transforms, &dir.join("I.txt"))?;
    let globals = skeleton.rest_globals();
    let table = sphere_table(variant);
    let index: HashMap<&str, usize> = table.iter().enumerate().map(|(i, s)| (s.0, i)).collect();

    let mut spheres = Vec::with_capacity(table.len());
    for (i, &(name, phalange, role)) in table.iter().enumerate() {
        let bone = bone_of_phalange(phalange);
        let attachment = match role {
            Role::Center => Attachment::Bone {
                bone,
                offset: Vector3::zeros(),
            },
            Role::Attached => {
                let g = &globals[bone];
                Attachment::Bone {
                    bone,
                    offset: g.rotation.transpose() * (raw.centers[i] - g.translation),
                }
            }
            Role::Derived => Attachment::Blend {
                parts: THUMB_MEMBRANE_MIDDLE
                    .iter()
                    .map(|&(n, w)| (index.get(n).copied().unwrap_or(0), w))
                    .collect(),
            },
        };
        let radius = if role == Role::Derived {
            0.0
        } else {
            raw.radii[i]
        };
        spheres.push(SphereDef {
            name: name.to_string(),
            attachment,
            radius,
        });
    }
    if variant == HmodelVariant::Honline {
        // The thumb rewrite of honline's `Model::initialize_offsets` (ANCHOR-FACTS §2.3).
        for name in ["thumb_membrane_left", "thumb_top", "thumb_additional"] {
            if let Some(Attachment::Bone { offset, .. }) =
                index.get(name).map(|&i| &mut spheres[i].attachment)
            {
                if name == "thumb_membrane_left" {
                    *offset = Vector3::new(0.0, 12.0, 0.0);
                } else {
                    offset.x = 0.0;
                }
            }
        }
    }

    // Radii as the posed model has them (the derived sphere's radius is the blend of its parts),
    // for the re-ordering of blocks.
    let radii: Vec<f64> = {
        let mut r: Vec<f64> = spheres.iter().map(|s| s.radius).collect();
        for (i, s) in spheres.iter().enumerate() {
            if let Attachment::Blend { parts } = &s.attachment {
                r[i] = parts.iter().map(|&(p, w)| w * r[p]).sum();
            }
        }
        r
    };
    let sphere_bone = |i: usize| -> Vec<usize> {
        match &spheres[i].attachment {
            Attachment::Bone { bone, .. } => vec![*bone],
            Attachment::Blend { parts } => parts
                .iter()
                .filter_map(|&(p, _)| match spheres[p].attachment {
                    Attachment::Bone { bone, .. } => Some(bone),
                    Attachment::Blend { .. } => None,
                })
                .collect(),
        }
    };
    let map: &[usize] = match variant {
        HmodelVariant::Hmodel => &HMODEL_BLOCK_PHALANGE,
        HmodelVariant::Honline => &HONLINE_BLOCK_PHALANGE,
    };
    let use_map = raw.blocks.len() == variant.num_blocks();
    let mut elements = Vec::with_capacity(raw.blocks.len());
    for (k, &block) in raw.blocks.iter().enumerate() {
        let element = reindex(block, &radii);
        let bone = if use_map {
            bone_of_phalange(map[k])
        } else {
            let bones: Vec<usize> = element
                .spheres()
                .iter()
                .flat_map(|&s| sphere_bone(s as usize))
                .collect();
            common_ancestor(&skeleton, &bones)
        };
        elements.push(ElementDef { element, bone });
    }

    let mut keypoints = Vec::with_capacity(21);
    let bone = |name: &str| skeleton.bone_index(name).unwrap_or(0);
    keypoints.push(KeypointDef::Joint {
        bone: bone("wrist"),
    });
    for digit in ["thumb", "index", "middle", "ring", "pinky"] {
        for k in 1..=3 {
            keypoints.push(KeypointDef::Joint {
                bone: bone(&format!("{digit}_{k}")),
            });
        }
        let sphere = index.get(digit_tip(digit)).copied().unwrap_or(0);
        keypoints.push(KeypointDef::Tip {
            bone: bone(&format!("{digit}_3")),
            sphere,
        });
    }

    let folder = dir
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let template = SphereMeshTemplate {
        name: format!("{} model ({folder})", variant.label()),
        handedness: Handedness::Left,
        skeleton,
        spheres,
        elements,
        keypoints,
    };
    template.validate(dir)?;
    Ok(template)
}

/// Import an original hmodel or honline model folder (`C.txt`, `R.txt`, `B.txt`, `I.txt`) as a
/// **left-hand** template.
///
/// # The files
/// Every file is whitespace-separated text whose first number is a count N:
/// - `C.txt`: N sphere centers (x y z, mm) in the rest pose, model frame. The honline file writes
///   its last center with commas (`24.139700, 32.040798, -12.749390`); commas are treated as
///   separators here, so it parses.
/// - `R.txt`: N radii (mm).
/// - `B.txt`: N blocks of three sphere indices; a third index of [`PILL_SENTINEL`] (32767, MSVC's
///   `RAND_MAX`) marks a pill, anything else a wedge.
/// - `I.txt`: N 4×4 rest transforms (`init_local`, relative to the parent phalange), stored
///   column-major, one per phalange in the original order (Hand, Thumb1..3, Pinky1..3, Ring1..3,
///   Middle1..3, Index1..3, Wrist, Position). hmodel writes 19 (the last one is unused), honline
///   18; only the first 18 are read.
///
/// Two variants are recognized by their sphere count: **hmodel** (38 spheres, 30 blocks; sphere 33
/// is `thumb_fold` on Thumb1) and **honline** (39 spheres, 31 blocks; sphere 33 is
/// `thumb_membrane_left` on Thumb2 and sphere 38 is the derived `thumb_membrane_middle`).
///
/// # What the importer builds (the way the originals initialize the model)
/// - Bones: Position → `root` (carrying the six `global_*` DOFs), Hand → `palm`, Wrist → `wrist`,
///   HandThumb1..3 → `thumb_1..3`, HandIndex1..3 → `index_1..3`, and so on; rest frames are the
///   `I.txt` transforms (rotations projected onto SO(3), which moves nothing by more than
///   ~1e-4 mm for 6-digit files).
/// - DOFs: the honline θ layout with this crate's names ([`HONLINE_THETA_DOFS`]), axes and limits
///   (ANCHOR-FACTS §1.3; for hmodel files the 28 DOFs of θ0..28 without slot 6, with the hmodel
///   thumb IP limit [−0.9, 0.7]; honline adds the five MCP twists). Each bone applies its DOFs in
///   the original pass order: X (flexion), then Z (abduction), then Y (twist), each rotation
///   post-multiplying the rest frame.
/// - Spheres keep the file order and get the honline names. The "center" sphere of each phalange
///   sits at the bone origin (offset 0, as `Model::update_centers` places it); every other sphere
///   is attached with `offset = R_global⁻¹·(c − t_global)` at θ = 0
///   (`Model::initialize_offsets`). No calibration-type adjustments are applied (the NONE
///   setting: palm offsets keep their z, finger bases are not moved 3 mm).
/// - honline only, the thumb rewrite of `initialize_offsets` (§2.3): `thumb_membrane_left`'s
///   offset becomes (0, 12, 0) and the x offsets of `thumb_top` and `thumb_additional` become 0;
///   `thumb_membrane_middle` is the [`Attachment::Blend`] of palm_thumb, thumb_membrane_left and
///   thumb_base with weights 0.4, 0.3, 0.3 (center and radius); its C.txt/R.txt values are
///   ignored.
/// - Elements: blocks re-ordered like `Model::reindex` (largest radius first), each with the bone
///   of the original block → phalange map (§2.4; for hmodel files block 26, the thumb_base /
///   thumb_fold / palm_thumb wedge, maps to Thumb1 as in hmodel's own map). A file whose block
///   count differs from its variant's uses the lowest common ancestor of the spheres' bones,
///   which reproduces the honline map exactly.
/// - Keypoints: wrist = `wrist` bone origin; joints = bone origins; tips = the `<finger>_top`
///   sphere plus its radius along the distal bone's +y. The thumb tip uses `thumb_additional`,
///   whose far surface lies further along the distal thumb axis than `thumb_top`'s (≈ 25.7 mm
///   versus ≈ 21.0 mm past the IP joint in the honline model), matching the default template.
///
/// # Handedness
/// The original files are geometrically **left** hands (index toward +x, palm toward −z); the
/// importer returns them as [`Handedness::Left`] without changing any number, and
/// [`SphereMeshTemplate::mirrored`] gives the right hand.
///
/// # Errors
/// Refused with a [`ModelError`] naming the file, the field and the index: missing or unreadable
/// files, truncated files, counts that disagree with the data or with each other, non-numeric
/// tokens, NaN/infinite values, negative radii, block indices out of range, transforms that are
/// not column-major rigid transforms.
pub fn import_hmodel_dir(dir: impl AsRef<Path>) -> Result<SphereMeshTemplate> {
    let dir = dir.as_ref();
    let raw = read_raw(dir)?;
    build_template(&raw, dir)
}

/// The variant of an original model folder, from the count of its `C.txt`.
pub fn detect_hmodel_variant(dir: impl AsRef<Path>) -> Result<HmodelVariant> {
    let path = dir.as_ref().join("C.txt");
    let text = read_text(&path)?;
    let mut f = NumberFile::new(path.clone(), &text);
    let n = f.count()?;
    HmodelVariant::from_sphere_count(n).ok_or_else(|| {
        ModelError::field(
            path,
            "count",
            None,
            format!("{n} spheres: expected 38 (hmodel) or 39 (honline)"),
        )
    })
}

/// A pose of `template` from an original θ vector (29 hmodel or 34 honline values, the layout
/// of ANCHOR-FACTS §1.3, mapped through [`HONLINE_THETA_DOFS`]). Slot 6 is ignored; a non-zero
/// value for a DOF the template lacks (e.g. a twist on an hmodel import) is an error.
pub fn pose_from_honline_theta(template: &SphereMeshTemplate, theta: &[f64]) -> Result<Pose> {
    if theta.len() != 29 && theta.len() != 34 {
        return Err(ModelError::InvalidArgument {
            name: "theta",
            reason: format!(
                "{} values: expected 29 (hmodel) or 34 (honline)",
                theta.len()
            ),
        });
    }
    let mut pose = Pose::zeros(&template.skeleton);
    for (i, &v) in theta.iter().enumerate() {
        let Some(name) = HONLINE_THETA_DOFS[i] else {
            continue;
        };
        match template.skeleton.dof_index(name) {
            Some(_) => pose.set(&template.skeleton, name, v)?,
            None if v == 0.0 => {}
            None => {
                return Err(ModelError::InvalidArgument {
                    name: "theta",
                    reason: format!("θ{i} = {v} but the template has no DOF `{name}`"),
                })
            }
        }
    }
    Ok(pose)
}

// ------------------------------------------------------------------------------------------------
// Export.

fn fmt_num(out: &mut String, v: f64) {
    use std::fmt::Write;
    let _ = write!(out, "{v}");
}

/// Write a template back to the original `C.txt`, `R.txt`, `B.txt`, `I.txt` format (atomically,
/// file by file) so that the original trackers and [`import_hmodel_dir`] can read it.
///
/// The template needs this crate's bone names and the honline sphere names: with
/// `thumb_membrane_middle` it is written as a honline model (39 spheres, 18 transforms), with
/// `thumb_fold` as an hmodel model (38 spheres, 19 transforms). A right-hand template is mirrored
/// first, since the original files are left hands. Centers are the rest-pose centers (the derived
/// sphere's too); blocks keep the template's element order; DOF axes and limits are not part of
/// the format. Note that the importer puts each phalange's center sphere at its bone origin and,
/// for honline, re-applies the thumb rewrite.
pub fn export_hmodel_dir(template: &SphereMeshTemplate, dir: impl AsRef<Path>) -> Result<()> {
    let dir = dir.as_ref();
    let mirrored;
    let t = if template.handedness == Handedness::Right {
        mirrored = template.mirrored()?;
        &mirrored
    } else {
        template
    };
    let src = Path::new("<template>");
    t.validate(src)?;
    let variant = if t.sphere_index("thumb_membrane_middle").is_some() {
        HmodelVariant::Honline
    } else if t.sphere_index("thumb_fold").is_some() {
        HmodelVariant::Hmodel
    } else {
        return Err(ModelError::field(
            src,
            "spheres",
            None,
            "neither `thumb_membrane_middle` (honline) nor `thumb_fold` (hmodel): not an hmodel/honline topology",
        ));
    };
    let table = sphere_table(variant);
    if t.spheres.len() != table.len() {
        return Err(ModelError::field(
            src,
            "spheres",
            None,
            format!(
                "{} spheres; the {} format holds exactly {}",
                t.spheres.len(),
                variant.label(),
                table.len()
            ),
        ));
    }
    // file index of each template sphere
    let mut file_index = vec![0usize; t.spheres.len()];
    for (fi, &(name, _, _)) in table.iter().enumerate() {
        let ti = t.sphere_index(name).ok_or_else(|| {
            ModelError::field(src, "spheres", None, format!("missing sphere `{name}`"))
        })?;
        file_index[ti] = fi;
    }
    let rest = t.rest_spheres();
    let mut centers = vec![Vector3::zeros(); table.len()];
    let mut radii = vec![0.0; table.len()];
    for (ti, s) in rest.iter().enumerate() {
        centers[file_index[ti]] = s.center;
        radii[file_index[ti]] = s.radius;
    }
    let globals_local: Vec<Rigid3> = PHALANGES
        .iter()
        .map(|&(name, _, _)| {
            t.skeleton
                .bone_index(name)
                .map(|b| t.skeleton.bones()[b].rest)
                .ok_or_else(|| {
                    ModelError::field(src, "bones", None, format!("missing bone `{name}`"))
                })
        })
        .collect::<Result<_>>()?;

    let mut c = format!("{}\n", centers.len());
    for p in &centers {
        for k in 0..3 {
            fmt_num(&mut c, p[k]);
            c.push(' ');
        }
        c.push('\n');
    }
    let mut r = format!("{}\n", radii.len());
    for &v in &radii {
        fmt_num(&mut r, v);
        r.push(' ');
    }
    r.push('\n');
    let mut b = format!("{}\n", t.elements.len());
    for e in &t.elements {
        let idx: Vec<String> = e
            .element
            .spheres()
            .iter()
            .map(|&s| file_index[s as usize].to_string())
            .collect();
        match e.element {
            Element::Pill(_) => b.push_str(&format!("{} {} {PILL_SENTINEL}\n", idx[0], idx[1])),
            Element::Wedge(_) => b.push_str(&format!("{} {} {}\n", idx[0], idx[1], idx[2])),
        }
    }
    let n_transforms = variant.num_transforms();
    let mut i = format!("{n_transforms}\n");
    for k in 0..n_transforms {
        let tr = globals_local.get(k).copied().unwrap_or_default();
        let mut m = Matrix4::<f64>::identity();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&tr.rotation);
        m.fixed_view_mut::<3, 1>(0, 3).copy_from(&tr.translation);
        for v in m.iter() {
            // nalgebra iterates column-major, the order of I.txt
            fmt_num(&mut i, *v);
            i.push(' ');
        }
        i.push('\n');
    }
    std::fs::create_dir_all(dir).map_err(|source| ModelError::Io {
        file: dir.to_path_buf(),
        source,
    })?;
    for (name, text) in [("C.txt", c), ("R.txt", r), ("B.txt", b), ("I.txt", i)] {
        write_atomic(&dir.join(name), text.as_bytes())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicUsize, Ordering};

    use super::*;
    use crate::kinematics::Pose;
    use crate::spheremesh::{default_right_hand, PosedSphereMesh, ShapeBasis};

    const REFERENCE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/reference/");

    fn reference_dir(name: &str) -> Option<PathBuf> {
        let p = Path::new(REFERENCE).join(name);
        if p.is_dir() {
            Some(p)
        } else {
            println!("skipped: {} absent", p.display());
            None
        }
    }

    fn temp_dir(tag: &str) -> PathBuf {
        static N: AtomicUsize = AtomicUsize::new(0);
        let n = N.fetch_add(1, Ordering::Relaxed);
        let d = std::env::temp_dir().join(format!(
            "hands-hmodel-test-{}-{tag}-{n}",
            std::process::id()
        ));
        std::fs::create_dir_all(&d).expect("temp dir");
        d
    }

    fn posed(t: &SphereMeshTemplate, values: &[(&str, f64)]) -> PosedSphereMesh {
        let mut pose = Pose::zeros(&t.skeleton);
        for &(name, v) in values {
            pose.set(&t.skeleton, name, v).expect("known DOF");
        }
        PosedSphereMesh::new(t, &pose)
    }

    fn center(t: &SphereMeshTemplate, p: &PosedSphereMesh, name: &str) -> Vector3<f64> {
        p.spheres[t.sphere_index(name).expect("named sphere")].center
    }

    fn raw(dir: &Path) -> RawModel {
        read_raw(dir).expect("reference files parse")
    }

    /// Rest-pose centers reproduce `C.txt` (except the spheres the honline init rewrites) and
    /// radii reproduce `R.txt`; returns the largest center error.
    fn check_rest_pose(t: &SphereMeshTemplate, raw: &RawModel, skip: &[&str]) -> f64 {
        let rest = t.rest_spheres();
        let mut max_err = 0.0f64;
        for (i, s) in rest.iter().enumerate() {
            let name = t.spheres[i].name.as_str();
            if skip.contains(&name) {
                continue;
            }
            let err = (s.center - raw.centers[i]).norm();
            assert!(
                err < 1e-3,
                "{name}: rest center {:?} vs C.txt {:?}",
                s.center,
                raw.centers[i]
            );
            assert_eq!(s.radius, raw.radii[i], "{name}: radius");
            max_err = max_err.max(err);
        }
        max_err
    }

    #[test]
    fn honline_rest_pose_reproduces_the_files() {
        let Some(dir) = reference_dir("honline-template-anastasia") else {
            return;
        };
        let t = import_hmodel_dir(&dir).expect("imports");
        assert_eq!(detect_hmodel_variant(&dir).unwrap(), HmodelVariant::Honline);
        assert_eq!(t.handedness, Handedness::Left);
        assert_eq!(
            (t.spheres.len(), t.elements.len(), t.skeleton.num_dofs()),
            (39, 31, 33)
        );
        assert_eq!(t.element_counts(), (16, 15));
        let raw = raw(&dir);
        let changed = [
            "thumb_top",
            "thumb_additional",
            "thumb_membrane_left",
            "thumb_membrane_middle",
        ];
        let max_err = check_rest_pose(&t, &raw, &changed);
        println!("honline: max rest-center error vs C.txt {max_err:.2e} mm");
        // The spheres changed by the thumb rewrite, at the values of ANCHOR-FACTS §2.3.
        let rest = t.rest_spheres();
        for (name, expected, r) in [
            ("thumb_top", [26.529, 47.290, -70.882], 7.0311),
            ("thumb_additional", [27.658, 51.179, -76.474], 4.99162),
            ("thumb_membrane_left", [23.472, 28.854, -46.928], 3.0),
            ("thumb_membrane_middle", [21.398, 26.310, -15.704], 6.80481),
        ] {
            let s = rest[t.sphere_index(name).unwrap()];
            let err = (s.center - Vector3::from(expected)).norm();
            assert!(err < 1e-3, "{name}: {:?}", s.center);
            assert!((s.radius - r).abs() < 1e-5, "{name}: radius {}", s.radius);
        }
        // The file's own (stale) values of the derived sphere are ignored.
        let i = t.sphere_index("thumb_membrane_middle").unwrap();
        assert!(
            (raw.centers[i] - Vector3::new(24.1397, 32.040798, -12.74939)).norm() < 1e-6,
            "comma line parsed"
        );
        assert!((rest[i].center - raw.centers[i]).norm() > 1.0);
    }

    #[test]
    fn honline_offsets_match_the_anchor_table() {
        let Some(dir) = reference_dir("honline-template-anastasia") else {
            return;
        };
        let t = import_hmodel_dir(&dir).expect("imports");
        // ANCHOR-FACTS §2.3, attachment offsets after the thumb rewrite (3 decimals).
        let table: [(&str, [f64; 3]); 17] = [
            ("palm_index", [23.937, 45.629, 3.482]),
            ("palm_left", [7.311, 3.093, -0.049]),
            ("palm_middle", [5.558, 45.021, 6.948]),
            ("palm_pinky", [-17.933, 38.572, 3.262]),
            ("palm_right", [-10.008, 1.014, 0.437]),
            ("palm_ring", [-6.554, 42.595, 6.321]),
            ("palm_thumb", [28.597, 41.231, 1.305]),
            ("thumb_membrane_left", [0.0, 12.0, 0.0]),
            ("thumb_top", [0.0, 13.951, 1.210]),
            ("thumb_additional", [0.0, 20.686, 2.733]),
            ("pinky_membrane", [1.352, 18.222, 4.363]),
            ("pinky_top", [-0.189, 12.749, 1.342]),
            ("ring_top", [-0.476, 13.503, 1.556]),
            ("middle_membrane", [0.560, 15.084, 4.734]),
            ("index_top", [-0.830, 12.805, 0.129]),
            ("wrist_bottom_left", [4.058, -48.699, 0.0]),
            ("wrist_top_right", [-8.117, -4.058, 0.0]),
        ];
        for (name, expected) in table {
            let Attachment::Bone { offset, .. } =
                &t.spheres[t.sphere_index(name).unwrap()].attachment
            else {
                panic!("{name} is not bone-attached")
            };
            assert!(
                (offset - Vector3::from(expected)).amax() < 6e-4,
                "{name}: {offset:?}"
            );
        }
    }

    #[test]
    fn hmodel_rest_pose_reproduces_the_files() {
        let Some(dir) = reference_dir("hmodel-template-anastasia") else {
            return;
        };
        let t = import_hmodel_dir(&dir).expect("imports");
        assert_eq!(detect_hmodel_variant(&dir).unwrap(), HmodelVariant::Hmodel);
        assert_eq!(
            (t.spheres.len(), t.elements.len(), t.skeleton.num_dofs()),
            (38, 30, 28)
        );
        // ANCHOR-FACTS §2.2 says 16 pills + 14 wedges; the file holds 15 + 15 (block 14 is a
        // wedge with thumb_fold, block 27 the thumb_top–thumb_additional pill).
        assert_eq!(t.element_counts(), (15, 15));
        assert_eq!(t.spheres[33].name, "thumb_fold");
        assert_eq!(
            t.skeleton.bones()[sphere_bone(&t, "thumb_fold")].name,
            "thumb_1"
        );
        let raw = raw(&dir);
        let max_err = check_rest_pose(&t, &raw, &[]);
        println!("hmodel: max rest-center error vs C.txt {max_err:.2e} mm");
        let ip = t.skeleton.dof_index("thumb_ip_flex").unwrap();
        assert_eq!(t.skeleton.dofs()[ip].limits, Some([-0.9, 0.7]));
        assert!(t.skeleton.dof_index("index_mcp_twist").is_none());
    }

    fn sphere_bone(t: &SphereMeshTemplate, name: &str) -> usize {
        match t.spheres[t.sphere_index(name).unwrap()].attachment {
            Attachment::Bone { bone, .. } => bone,
            Attachment::Blend { .. } => panic!("blend"),
        }
    }

    /// ANCHOR-FACTS §1.3: the honline model at the initial pose of `Worker::initialize`
    /// (θ1 = −50, θ2 = 375, θ9 = 0.7, θ10 = 0.6). Every reference value is reproduced to the
    /// 3 decimals it is given with (largest error ≈ 6e-4 mm, i.e. rounding).
    #[test]
    fn honline_initial_pose_matches_reference_fk() {
        let Some(dir) = reference_dir("honline-template-anastasia") else {
            return;
        };
        let t = import_hmodel_dir(&dir).expect("imports");
        let mut theta = [0.0; 34];
        theta[1] = -50.0;
        theta[2] = 375.0;
        theta[9] = 0.7;
        theta[10] = 0.6;
        let pose = pose_from_honline_theta(&t, &theta).expect("pose");
        let p = PosedSphereMesh::new(&t, &pose);
        let reference: [(&str, [f64; 3]); 9] = [
            ("palm_back", [0.0, -50.0, 375.0]),
            ("thumb_base", [9.726, -46.128, 367.840]),
            ("thumb_bottom", [38.913, -23.529, 363.736]),
            ("thumb_middle", [57.027, -2.051, 359.359]),
            ("thumb_top", [64.995, 8.900, 355.797]),
            ("index_base", [25.396, 0.819, 380.287]),
            ("index_top", [35.159, 70.538, 383.599]),
            ("middle_top", [3.878, 82.340, 387.601]),
            ("pinky_top", [-39.192, 54.429, 372.967]),
        ];
        for (name, expected) in reference {
            let c = center(&t, &p, name);
            let err = (c - Vector3::from(expected)).norm();
            let comp = (c - Vector3::from(expected)).amax();
            println!(
                "{name:>13}: ({:.5}, {:.5}, {:.5})  error {err:.1e} mm (max component {comp:.1e})",
                c.x, c.y, c.z
            );
            assert!(err < 1e-3, "{name}: {c:?} vs {expected:?}");
        }
    }

    /// ANCHOR-FACTS §1.3: positive flexion bends toward the palm (−z), positive index abduction
    /// moves the tip to +x (away from the middle finger) on the left-hand files.
    #[test]
    fn honline_flexion_and_abduction_signs() {
        let Some(dir) = reference_dir("honline-template-anastasia") else {
            return;
        };
        let t = import_hmodel_dir(&dir).expect("imports");
        let rest = center(&t, &posed(&t, &[]), "index_top");
        assert!(
            (rest - Vector3::new(35.2, 120.5, 8.6)).amax() < 0.05,
            "{rest:?}"
        );
        let flexed = center(&t, &posed(&t, &[("index_mcp_flex", 0.5)]), "index_top");
        assert!(
            (flexed - Vector3::new(25.7, 114.7, -24.5)).amax() < 0.05,
            "{flexed:?}"
        );
        let abducted = center(&t, &posed(&t, &[("index_mcp_abd", 0.3)]), "index_top");
        assert!(abducted.x > rest.x + 10.0, "{abducted:?}");
        // The twist turns about the bone axis (+y): the next joint, on the axis, stays; the
        // membrane sphere, off the axis, moves.
        let (twisted, rest_pose) = (posed(&t, &[("index_mcp_twist", 0.3)]), posed(&t, &[]));
        let moved = |name: &str| (center(&t, &twisted, name) - center(&t, &rest_pose, name)).norm();
        assert!(moved("index_bottom") < 1e-9);
        assert!(moved("index_membrane") > 1.0);
    }

    #[test]
    fn element_bones_follow_the_original_block_maps() {
        for (name, map) in [
            ("honline-template-anastasia", &HONLINE_BLOCK_PHALANGE[..]),
            ("hmodel-template-anastasia", &HMODEL_BLOCK_PHALANGE[..]),
        ] {
            let Some(dir) = reference_dir(name) else {
                return;
            };
            let t = import_hmodel_dir(&dir).expect("imports");
            let rest_radii: Vec<f64> = t.rest_spheres().iter().map(|s| s.radius).collect();
            for (k, e) in t.elements.iter().enumerate() {
                assert_eq!(e.bone, bone_of_phalange(map[k]), "{name} block {k}");
                // The lowest common ancestor rule agrees, except hmodel's block 26 (thumb_base,
                // thumb_fold, palm_thumb), which hmodel maps to Thumb1.
                let mut bones = vec![];
                for &s in e.element.spheres() {
                    match &t.spheres[s as usize].attachment {
                        Attachment::Bone { bone, .. } => bones.push(*bone),
                        Attachment::Blend { parts } => bones.extend(
                            parts
                                .iter()
                                .map(|&(p, _)| sphere_bone(&t, &t.spheres[p].name)),
                        ),
                    }
                }
                let lca = common_ancestor(&t.skeleton, &bones);
                if name.starts_with("hmodel") && k == 26 {
                    assert_eq!(t.skeleton.bones()[lca].name, "palm");
                    assert_eq!(t.skeleton.bones()[e.bone].name, "thumb_1");
                } else {
                    assert_eq!(lca, e.bone, "{name} block {k}");
                }
                // Largest radius first (`Model::reindex`).
                let r: Vec<f64> = e
                    .element
                    .spheres()
                    .iter()
                    .map(|&s| rest_radii[s as usize])
                    .collect();
                assert!(r.iter().all(|&x| x <= r[0]), "{name} block {k}: {r:?}");
            }
            // The re-ordered blocks of the ANCHOR-FACTS §2.6 tables.
            let wrist = |k: usize| t.elements[k].element;
            if name.starts_with("honline") {
                assert_eq!(wrist(28), Element::Wedge([36, 35, 34]));
                assert_eq!(wrist(29), Element::Wedge([37, 36, 35]));
                assert_eq!(wrist(30), Element::Wedge([19, 38, 33]));
            } else {
                assert_eq!(wrist(28), Element::Wedge([36, 35, 34]));
                assert_eq!(wrist(29), Element::Wedge([36, 37, 35]));
                assert_eq!(wrist(14), Element::Wedge([19, 18, 33]));
            }
            assert_eq!(t.elements[0].element, Element::Pill([1, 0]));
        }
    }

    #[test]
    fn keypoints_of_the_import() {
        let Some(dir) = reference_dir("honline-template-anastasia") else {
            return;
        };
        let t = import_hmodel_dir(&dir).expect("imports");
        let p = posed(&t, &[]);
        let k = p.keypoints(&t);
        assert_eq!(k[0], Vector3::zeros(), "wrist = wrist bone origin");
        assert!(
            (k[1] - center(&t, &p, "thumb_base")).norm() < 1e-12,
            "thumb CMC"
        );
        assert!(
            (k[5] - center(&t, &p, "index_base")).norm() < 1e-12,
            "index MCP"
        );
        assert!(
            (k[7] - center(&t, &p, "index_middle")).norm() < 1e-12,
            "index DIP"
        );
        // Thumb tip: thumb_additional plus its radius along the distal bone, beyond thumb_top's
        // own far surface.
        let t3 = t.skeleton.bone_index("thumb_3").unwrap();
        let axis = p.skeleton.globals[t3].rotation.column(1).into_owned();
        let ip = p.skeleton.globals[t3].translation;
        let top = &p.spheres[t.sphere_index("thumb_top").unwrap()];
        assert!((k[4] - ip).dot(&axis) > (top.center - ip).dot(&axis) + top.radius);
        assert!(((k[4] - ip).dot(&axis) - 25.68).abs() < 0.01);
        assert!((k[8] - center(&t, &p, "index_top")).norm() - 5.17427 < 1e-9);
    }

    /// The imported files are left hands; `mirrored()` gives the right hand, and posing commutes
    /// with the mirror for any joint angles.
    #[test]
    fn mirrored_import_is_a_right_hand() {
        let Some(dir) = reference_dir("honline-template-anastasia") else {
            return;
        };
        let left = import_hmodel_dir(&dir).expect("imports");
        let right = left.mirrored().expect("mirrors");
        assert_eq!(right.handedness, Handedness::Right);
        let values = [
            ("global_ty", -50.0),
            ("global_tz", 375.0),
            ("thumb_cmc_abd", 0.7),
            ("thumb_cmc_flex", 0.6),
            ("thumb_cmc_twist", 0.2),
            ("index_mcp_abd", 0.2),
            ("index_mcp_flex", 0.9),
            ("middle_pip_flex", 1.1),
            ("pinky_mcp_twist", -0.05),
            ("wrist_abd", -0.4),
            ("wrist_flex", 0.5),
        ];
        let (pl, pr) = (posed(&left, &values), posed(&right, &values));
        let m = Vector3::new(-1.0, 1.0, 1.0);
        for (a, b) in pl.spheres.iter().zip(&pr.spheres) {
            assert!((a.center.component_mul(&m) - b.center).norm() < 1e-9);
        }
        let rest = right.rest_spheres();
        assert!(
            rest[right.sphere_index("thumb_base").unwrap()].center.x < 0.0,
            "thumb toward −x"
        );
        assert!(
            rest[right.sphere_index("index_base").unwrap()].center.x < 0.0,
            "index on the thumb side"
        );
        assert!(rest[right.sphere_index("pinky_base").unwrap()].center.x > 0.0);
    }

    /// The honline shape vector builds on the import; its template values agree with the β̄ table
    /// of ANCHOR-FACTS §2.5 wherever the two define the same quantity. The table's values are
    /// the constants hard-coded in honline's `setup_calibration_type_to_beta_template_map`, not
    /// values measured on the files, and differ for:
    /// - `thumb_top_length` 14.0316: the length of thumb_top's offset *before* the thumb rewrite
    ///   zeroes its x (measured here: 14.0032 after, 14.0316 before);
    /// - the finger-base z values: the file values minus the 3 mm of the FULL calibration (§2.3);
    /// - `wrist_width` 4.02408, `wrist_length` 48.6212, `wrist_width_left` 10.02408: constants that
    ///   match no offset of the files (4.05823, 48.6988, 8.1165);
    /// - `wrist_top_left_radius` 12.9863: the radius of wrist_top_right (sphere 35) in R.txt;
    ///   wrist_top_left (sphere 34) has 12.9.
    #[test]
    fn honline_shape_basis_on_the_import() {
        let Some(dir) = reference_dir("honline-template-anastasia") else {
            return;
        };
        let t = import_hmodel_dir(&dir).expect("imports");
        let basis = ShapeBasis::honline(&t).expect("basis builds");
        assert_eq!(basis.len(), 75);
        #[rustfmt::skip]
        let table: [f64; 75] = [
            37.1409, 28.436, 14.0316, 37.0552, 20.5967, 12.8331, 40.4944, 23.2687, 15.9073,
            37.9263, 23.9032, 13.6011, 31.9997, 19.1319, 12.8207,
            9.72575, 3.87206, -7.16046, 25.3963, 50.8191, 2.28707, 8.13206, 52.8925, 7.5463,
            -5.93253, 49.1046, 7.7991, -18.1006, 44.8872, 3.8978,
            23.9371, 45.629, -17.9329, 38.572, 7.31059, 3.0928, -10.0083, 1.01374, 28.5967, 41.231,
            4.02408, 48.6212, 12.0, 6.7374, 1.52305, 10.02408,
            15.6827, 10.3118, 7.30846, 7.0311, 8.44143, 7.55251, 5.85299, 5.17427,
            7.68834, 7.64302, 5.67621, 5.58432, 7.26768, 6.97092, 5.01217, 4.84959,
            7.84562, 6.22559, 4.77166, 4.18002, 9.50548, 10.726, 10.2172, 8.98482,
            13.2994, 13.6244, 13.4193, 12.9863, 15.4,
        ];
        let ours = basis.template_values();
        let names: Vec<&str> = basis.names().collect();
        let mut differ = vec![];
        for (j, (&a, &b)) in ours.iter().zip(&table).enumerate() {
            if (a - b).abs() > 3e-3 {
                differ.push((names[j], a, b));
            }
        }
        let expected: Vec<&str> = vec![
            "thumb_top_length",
            "index_base_z",
            "middle_base_z",
            "ring_base_z",
            "pinky_base_z",
            "wrist_width",
            "wrist_length",
            "wrist_width_left",
            "wrist_top_left_radius",
        ];
        assert_eq!(
            differ.iter().map(|d| d.0).collect::<Vec<_>>(),
            expected,
            "{differ:?}"
        );
        for (name, a, b) in &differ {
            println!("β {name}: template {a:.5}, §2.5 table {b:.5}");
        }
        for j in [20, 23, 26, 29] {
            assert!((ours[j] - 3.0 - table[j]).abs() < 1e-4, "{}", names[j]);
        }
        // thumb_top_length before the rewrite.
        let raw = raw(&dir);
        let g = t.skeleton.rest_globals()[t.skeleton.bone_index("thumb_3").unwrap()];
        let before = g.rotation.transpose() * (raw.centers[16] - g.translation);
        assert!((before.norm() - 14.0316).abs() < 1e-3, "{}", before.norm());

        // apply / fit round trip on the imported template.
        let mut beta = ours.clone();
        for (j, b) in beta.iter_mut().enumerate() {
            *b *= 1.0 + 0.03 * ((j as f64) * 0.7).sin();
        }
        let shaped = basis.apply(&t, &beta).expect("applies");
        let (fitted, resid) = basis.fit(&t, &shaped).expect("fits");
        let err = fitted
            .iter()
            .zip(&beta)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(
            err < 1e-6 && resid < 1e-6,
            "β error {err}, residual {resid}"
        );
        let (same, resid) = basis.fit(&t, &t).expect("fits");
        assert!(same.iter().zip(&ours).all(|(a, b)| (a - b).abs() < 1e-9) && resid < 1e-9);
    }

    #[test]
    fn export_import_round_trips() {
        let Some(dir) = reference_dir("honline-template-anastasia") else {
            return;
        };
        let t = import_hmodel_dir(&dir).expect("imports");
        let out = temp_dir("honline");
        export_hmodel_dir(&t, &out).expect("exports");
        let back = import_hmodel_dir(&out).expect("re-imports");
        let mut renamed = back.clone();
        renamed.name = t.name.clone();
        let diff = t.max_abs_difference(&renamed).expect("same structure");
        assert!(diff < 1e-9, "{diff}");
        // Right hands are mirrored on export.
        export_hmodel_dir(&t.mirrored().unwrap(), &out).expect("exports");
        let again = import_hmodel_dir(&out).expect("re-imports");
        let rest_a: Vec<_> = t.rest_spheres();
        let rest_b: Vec<_> = again.rest_spheres();
        for (a, b) in rest_a.iter().zip(&rest_b) {
            assert!((a.center - b.center).norm() < 1e-9 && (a.radius - b.radius).abs() < 1e-12);
        }
        let _ = std::fs::remove_dir_all(&out);
    }

    #[test]
    fn hmodel_export_import_round_trips() {
        let Some(dir) = reference_dir("hmodel-template-anastasia") else {
            return;
        };
        let t = import_hmodel_dir(&dir).expect("imports");
        let out = temp_dir("hmodel");
        export_hmodel_dir(&t, &out).expect("exports");
        assert!(std::fs::read_to_string(out.join("I.txt"))
            .unwrap()
            .starts_with("19\n"));
        let back = import_hmodel_dir(&out).expect("re-imports");
        for (a, b) in t.rest_spheres().iter().zip(&back.rest_spheres()) {
            assert!((a.center - b.center).norm() < 1e-9);
        }
        let _ = std::fs::remove_dir_all(&out);
    }

    /// The default right hand has the honline topology: it exports as a (mirrored) honline
    /// folder and imports back to the same geometry.
    #[test]
    fn default_template_exports_as_honline_files() {
        let d = default_right_hand();
        let out = temp_dir("default");
        export_hmodel_dir(&d, &out).expect("exports");
        assert_eq!(detect_hmodel_variant(&out).unwrap(), HmodelVariant::Honline);
        let back = import_hmodel_dir(&out).expect("imports");
        let right = back.mirrored().expect("mirrors");
        for (i, (a, b)) in d
            .rest_spheres()
            .iter()
            .zip(&right.rest_spheres())
            .enumerate()
        {
            assert!((a.center - b.center).norm() < 1e-9, "{}", d.spheres[i].name);
            assert!((a.radius - b.radius).abs() < 1e-12);
        }
        let _ = std::fs::remove_dir_all(&out);
    }

    /// A valid folder written by the exporter, to be corrupted by the tests below.
    fn valid_folder(tag: &str) -> PathBuf {
        let out = temp_dir(tag);
        export_hmodel_dir(&default_right_hand(), &out).expect("exports");
        out
    }

    fn edit(dir: &Path, file: &str, f: impl FnOnce(String) -> String) {
        let p = dir.join(file);
        let text = std::fs::read_to_string(&p).unwrap();
        std::fs::write(&p, f(text)).unwrap();
    }

    fn refused(dir: &Path) -> String {
        let e = import_hmodel_dir(dir)
            .expect_err("bad input refused")
            .to_string();
        let _ = std::fs::remove_dir_all(dir);
        e
    }

    fn replace_token(text: &str, n: usize, with: &str) -> String {
        let mut toks: Vec<String> = text.split_whitespace().map(String::from).collect();
        toks[n] = with.to_string();
        toks.join(" ")
    }

    #[test]
    fn refuses_bad_files() {
        // Truncated centers.
        let d = valid_folder("trunc");
        edit(&d, "C.txt", |t| {
            t.split_whitespace().take(60).collect::<Vec<_>>().join(" ")
        });
        let e = refused(&d);
        assert!(
            e.contains("C.txt") && e.contains("`centers`[19]") && e.contains("truncated"),
            "{e}"
        );
        // Non-numeric token.
        let d = valid_folder("token");
        edit(&d, "I.txt", |t| replace_token(&t, 40, "0.5x"));
        let e = refused(&d);
        assert!(
            e.contains("I.txt") && e.contains("`transforms`[2]") && e.contains("`0.5x`"),
            "{e}"
        );
        // NaN.
        let d = valid_folder("nan");
        edit(&d, "C.txt", |t| replace_token(&t, 1 + 3 * 7 + 2, "nan"));
        let e = refused(&d);
        assert!(
            e.contains("C.txt") && e.contains("`centers`[7]") && e.contains("finite"),
            "{e}"
        );
        // Wrong count: more numbers than the count.
        let d = valid_folder("count");
        edit(&d, "R.txt", |t| replace_token(&t, 0, "38"));
        let e = refused(&d);
        assert!(
            e.contains("R.txt") && e.contains("`count`") && e.contains("wrong count"),
            "{e}"
        );
        // Counts that disagree between files.
        let d = valid_folder("mismatch");
        edit(&d, "R.txt", |t| {
            let toks: Vec<&str> = t.split_whitespace().collect();
            format!("38 {}", toks[1..39].join(" "))
        });
        let e = refused(&d);
        assert!(
            e.contains("R.txt") && e.contains("38 radii for 39 centers"),
            "{e}"
        );
        // Unsupported sphere count.
        let d = valid_folder("spheres");
        edit(&d, "C.txt", |t| {
            let toks: Vec<&str> = t.split_whitespace().collect();
            format!("37 {}", toks[1..1 + 37 * 3].join(" "))
        });
        let e = refused(&d);
        assert!(e.contains("C.txt") && e.contains("37 spheres"), "{e}");
        // Block index out of range.
        let d = valid_folder("block");
        edit(&d, "B.txt", |t| replace_token(&t, 1 + 3 * 5 + 1, "45"));
        let e = refused(&d);
        assert!(
            e.contains("B.txt") && e.contains("`blocks`[5]") && e.contains("45 out of range"),
            "{e}"
        );
        // The pill marker in the wrong place.
        let d = valid_folder("sentinel");
        edit(&d, "B.txt", |t| replace_token(&t, 1, "32767"));
        let e = refused(&d);
        assert!(
            e.contains("`blocks`[0]") && e.contains("only allowed third"),
            "{e}"
        );
        // Negative block index and a block repeating a sphere.
        let d = valid_folder("negative");
        edit(&d, "B.txt", |t| replace_token(&t, 4, "-1"));
        assert!(refused(&d).contains("`blocks`[1]"));
        let d = valid_folder("repeat");
        edit(&d, "B.txt", |t| replace_token(&t, 2, "1"));
        assert!(refused(&d).contains("repeats a sphere"));
        // Negative radius.
        let d = valid_folder("radius");
        edit(&d, "R.txt", |t| replace_token(&t, 4, "-2.5"));
        let e = refused(&d);
        assert!(
            e.contains("R.txt") && e.contains("`radii`[3]") && e.contains("negative"),
            "{e}"
        );
        // A transposed (row-major) transform.
        let d = valid_folder("transposed");
        edit(&d, "I.txt", |t| {
            let mut toks: Vec<String> = t.split_whitespace().map(String::from).collect();
            let m: Vec<String> = toks[1 + 16..1 + 32].to_vec();
            for r in 0..4 {
                for c in 0..4 {
                    toks[1 + 16 + 4 * c + r] = m[4 * r + c].clone();
                }
            }
            toks.join(" ")
        });
        let e = refused(&d);
        assert!(
            e.contains("I.txt") && e.contains("`transforms`[1]") && e.contains("column-major"),
            "{e}"
        );
        // A scaled rotation.
        let d = valid_folder("scaled");
        edit(&d, "I.txt", |t| replace_token(&t, 1 + 16 * 2, "1.5"));
        assert!(refused(&d).contains("not a rotation"));
        // Too few transforms.
        let d = valid_folder("few");
        edit(&d, "I.txt", |t| replace_token(&t, 0, "17"));
        assert!(refused(&d).contains("17 transforms"));
        // Empty and missing files.
        let d = valid_folder("empty");
        edit(&d, "B.txt", |_| String::new());
        assert!(refused(&d).contains("empty file"));
        let d = valid_folder("missing");
        std::fs::remove_file(d.join("I.txt")).unwrap();
        assert!(refused(&d).contains("I.txt"));
        // Count that is not a number, huge count.
        let d = valid_folder("countword");
        edit(&d, "C.txt", |t| replace_token(&t, 0, "thirty-nine"));
        assert!(refused(&d).contains("not a valid count"));
        let d = valid_folder("huge");
        edit(&d, "C.txt", |t| {
            replace_token(&t, 0, "18446744073709551615")
        });
        assert!(refused(&d).contains("truncated"));
    }

    #[test]
    fn commas_are_separators() {
        let d = valid_folder("commas");
        edit(&d, "C.txt", |t| t.replace(' ', ", ").replacen(", ", " ", 1));
        assert!(import_hmodel_dir(&d).is_ok());
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn theta_conversion() {
        let t = default_right_hand();
        let mut theta = vec![0.0; 29];
        theta[6] = 5.0; // unused slot
        theta[14] = 0.4;
        let pose = pose_from_honline_theta(&t, &theta).expect("converts");
        assert_eq!(
            pose.values[t.skeleton.dof_index("index_mcp_flex").unwrap()],
            0.4
        );
        let mut theta = vec![0.0; 34];
        theta[30] = 0.1; // the default template has no twists
        assert!(pose_from_honline_theta(&t, &theta).is_err());
        assert!(pose_from_honline_theta(&t, &[0.0; 10]).is_err());
        theta[30] = 0.0;
        theta[3] = f64::NAN;
        assert!(pose_from_honline_theta(&t, &theta).is_err());
    }
}
