//! The versioned JSON template format (`hands.spheremesh`, version 1), documented on
//! [`TEMPLATE_FORMAT`]; see [`SphereMeshTemplate::to_json_string`], [`SphereMeshTemplate::load`]
//! and [`SphereMeshTemplate::save`].

use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use nalgebra::{Matrix3, Vector3};
use serde_json::{Map, Value};

use super::template::{Attachment, ElementDef, SphereDef, SphereMeshTemplate};
use crate::error::{ModelError, Result};
use crate::keypoints::{Handedness, KeypointDef, KEYPOINT_NAMES, NUM_KEYPOINTS};
use crate::kinematics::{Bone, Dof, DofKind, Skeleton};
use crate::math::Rigid3;
use crate::shape::Element;

/// The `format` tag of sphere-mesh template files (`hands.spheremesh`).
///
/// A template file names everything instead of indexing it, so that it can be read and edited
/// by hand:
///
/// ```json
/// {
///   "format": "hands.spheremesh",
///   "version": 1,
///   "name": "hands default right hand",
///   "handedness": "right",
///   "bones": [
///     {"name": "root", "parent": null,
///      "rest": {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "translation": [0, 0, 0]},
///      "dofs": ["global_tx", "global_ty", "global_tz", "global_rx", "global_ry", "global_rz"]},
///     {"name": "palm", "parent": "root", "rest": {...}, "dofs": []}
///   ],
///   "dofs": [
///     {"name": "global_tx", "bone": "root", "kind": "translation", "axis": [1, 0, 0], "limits": null},
///     {"name": "index_mcp_flex", "bone": "index_1", "kind": "rotation", "axis": [1, 0, 0], "limits": [-0.5, 1.6]}
///   ],
///   "spheres": [
///     {"name": "index_base", "bone": "index_1", "center": [-27, 57, 3], "radius": 9.8},
///     {"name": "thumb_membrane_middle", "blend": [["palm_thumb", 0.4], ["thumb_membrane_left", 0.3], ["thumb_base", 0.3]]}
///   ],
///   "elements": [{"pill": ["index_base", "index_bottom"], "bone": "index_1"},
///                {"wedge": ["palm_back", "palm_right", "palm_ring"], "bone": "palm"}],
///   "keypoints": [{"name": "wrist", "joint": "wrist"},
///                 {"name": "index_tip", "tip": "index_top", "bone": "index_3"}]
/// }
/// ```
///
/// - `bones`: parents before children; `rest` is the rest frame relative to the parent
///   (rotation row-major); `dofs` lists the bone's DOFs in application order.
/// - `dofs`: in pose-vector order; `kind` is `translation`, `global_rotation` or `rotation`.
/// - `spheres`: `center` is in the model frame at the rest pose (converted to a bone offset on
///   load); a blend sphere gives `[sphere, weight]` pairs of earlier bone-attached spheres and no
///   radius (it is the blend of the parts' radii).
/// - `elements`: sphere names (integer indices are accepted too).
/// - `keypoints`: exactly the 21 of DESIGN.md, in order, with their names.
///
/// Unknown keys are ignored. Everything else is checked, and a bad file is refused with a
/// [`ModelError`] naming the file, the field and the index.
pub const TEMPLATE_FORMAT: &str = "hands.spheremesh";
/// The current version of the template format.
pub const TEMPLATE_VERSION: u32 = 1;

/// Longest line (in characters) a JSON value is printed on before it is broken up.
const INLINE_WIDTH: usize = 100;

// ------------------------------------------------------------------------------------------------
// Writing.

/// An ordered JSON tree (object keys keep their insertion order).
enum J {
    Null,
    Num(f64),
    Int(u64),
    Str(String),
    Arr(Vec<J>),
    Obj(Vec<(&'static str, J)>),
}

fn num_text(v: f64) -> String {
    // serde_json prints the shortest representation that reads back to the same f64.
    serde_json::to_string(&v).unwrap_or_else(|_| "null".to_string())
}

fn str_text(s: &str) -> String {
    serde_json::to_string(s).unwrap_or_else(|_| "\"\"".to_string())
}

impl J {
    fn vec3(v: &Vector3<f64>) -> J {
        J::Arr(v.iter().map(|&x| J::Num(x)).collect())
    }

    fn str(s: &str) -> J {
        J::Str(s.to_string())
    }

    fn inline(&self) -> String {
        match self {
            J::Null => "null".to_string(),
            J::Num(v) => num_text(*v),
            J::Int(v) => v.to_string(),
            J::Str(s) => str_text(s),
            J::Arr(items) => format!(
                "[{}]",
                items.iter().map(J::inline).collect::<Vec<_>>().join(", ")
            ),
            J::Obj(fields) => format!(
                "{{{}}}",
                fields
                    .iter()
                    .map(|(k, v)| format!("{}: {}", str_text(k), v.inline()))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }

    fn write(&self, indent: usize, out: &mut String) {
        let flat = self.inline();
        if flat.len() + indent <= INLINE_WIDTH {
            out.push_str(&flat);
            return;
        }
        let pad = " ".repeat(indent + 2);
        match self {
            J::Arr(items) => {
                out.push_str("[\n");
                for (i, item) in items.iter().enumerate() {
                    out.push_str(&pad);
                    item.write(indent + 2, out);
                    out.push_str(if i + 1 < items.len() { ",\n" } else { "\n" });
                }
                let _ = write!(out, "{}]", " ".repeat(indent));
            }
            J::Obj(fields) => {
                out.push_str("{\n");
                for (i, (k, v)) in fields.iter().enumerate() {
                    let _ = write!(out, "{pad}{}: ", str_text(k));
                    v.write(indent + 2, out);
                    out.push_str(if i + 1 < fields.len() { ",\n" } else { "\n" });
                }
                let _ = write!(out, "{}}}", " ".repeat(indent));
            }
            _ => out.push_str(&flat),
        }
    }
}

fn kind_text(kind: DofKind) -> &'static str {
    match kind {
        DofKind::Translation => "translation",
        DofKind::GlobalRotation => "global_rotation",
        DofKind::Rotation => "rotation",
    }
}

fn check_finite<'a>(
    src: &Path,
    field: &str,
    index: usize,
    values: impl IntoIterator<Item = &'a f64>,
) -> Result<()> {
    if values.into_iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(ModelError::field(
            src,
            field,
            Some(index),
            "non-finite number (JSON cannot hold it)",
        ))
    }
}

impl SphereMeshTemplate {
    /// The template as a `hands.spheremesh` version-1 JSON document (layout on
    /// [`TEMPLATE_FORMAT`]). Refused: an invalid template or a non-finite number.
    pub fn to_json_string(&self) -> Result<String> {
        self.to_json_with_source(Path::new("<memory>"))
    }

    fn to_json_with_source(&self, src: &Path) -> Result<String> {
        self.validate(src)?;
        let skel = &self.skeleton;
        let bones = skel.bones();
        let dofs = skel.dofs();
        for (i, b) in bones.iter().enumerate() {
            check_finite(
                src,
                "bones.rest",
                i,
                b.rest.rotation.iter().chain(b.rest.translation.iter()),
            )?;
        }
        for (i, d) in dofs.iter().enumerate() {
            check_finite(src, "dofs.axis", i, d.axis.iter())?;
            check_finite(src, "dofs.limits", i, d.limits.iter().flatten())?;
        }
        let globals = skel.rest_globals();
        let mut bones_j = Vec::with_capacity(bones.len());
        for b in bones {
            let r = &b.rest.rotation;
            let rows = (0..3)
                .map(|i| J::Arr((0..3).map(|j| J::Num(r[(i, j)])).collect()))
                .collect();
            bones_j.push(J::Obj(vec![
                ("name", J::str(&b.name)),
                (
                    "parent",
                    b.parent.map_or(J::Null, |p| J::str(&bones[p].name)),
                ),
                (
                    "rest",
                    J::Obj(vec![
                        ("rotation", J::Arr(rows)),
                        ("translation", J::vec3(&b.rest.translation)),
                    ]),
                ),
                (
                    "dofs",
                    J::Arr(b.dofs.iter().map(|&d| J::str(&dofs[d].name)).collect()),
                ),
            ]));
        }
        let dofs_j = dofs
            .iter()
            .map(|d| {
                J::Obj(vec![
                    ("name", J::str(&d.name)),
                    ("bone", J::str(&bones[d.bone].name)),
                    ("kind", J::str(kind_text(d.kind))),
                    ("axis", J::vec3(&d.axis)),
                    (
                        "limits",
                        d.limits
                            .map_or(J::Null, |l| J::Arr(vec![J::Num(l[0]), J::Num(l[1])])),
                    ),
                ])
            })
            .collect();
        let mut spheres_j = Vec::with_capacity(self.spheres.len());
        for (i, s) in self.spheres.iter().enumerate() {
            spheres_j.push(match &s.attachment {
                Attachment::Bone { bone, offset } => {
                    let center = globals[*bone].transform_point(offset);
                    check_finite(src, "spheres.center", i, center.iter())?;
                    check_finite(src, "spheres.radius", i, [s.radius].iter())?;
                    J::Obj(vec![
                        ("name", J::str(&s.name)),
                        ("bone", J::str(&bones[*bone].name)),
                        ("center", J::vec3(&center)),
                        ("radius", J::Num(s.radius)),
                    ])
                }
                Attachment::Blend { parts } => {
                    check_finite(src, "spheres.blend", i, parts.iter().map(|(_, w)| w))?;
                    let parts = parts
                        .iter()
                        .map(|&(p, w)| J::Arr(vec![J::str(&self.spheres[p].name), J::Num(w)]))
                        .collect();
                    J::Obj(vec![("name", J::str(&s.name)), ("blend", J::Arr(parts))])
                }
            });
        }
        let name_of = |s: &u32| J::str(&self.spheres[*s as usize].name);
        let elements_j = self
            .elements
            .iter()
            .map(|e| {
                let (key, list) = match &e.element {
                    Element::Pill(s) => ("pill", s.iter().map(name_of).collect()),
                    Element::Wedge(s) => ("wedge", s.iter().map(name_of).collect()),
                };
                J::Obj(vec![
                    (key, J::Arr(list)),
                    ("bone", J::str(&bones[e.bone].name)),
                ])
            })
            .collect();
        let keypoints_j = self
            .keypoints
            .iter()
            .zip(KEYPOINT_NAMES)
            .map(|(k, name)| match *k {
                KeypointDef::Joint { bone } => J::Obj(vec![
                    ("name", J::str(name)),
                    ("joint", J::str(&bones[bone].name)),
                ]),
                KeypointDef::Tip { bone, sphere } => J::Obj(vec![
                    ("name", J::str(name)),
                    ("tip", J::str(&self.spheres[sphere].name)),
                    ("bone", J::str(&bones[bone].name)),
                ]),
            })
            .collect();
        let handedness = match self.handedness {
            Handedness::Right => "right",
            Handedness::Left => "left",
        };
        let doc = J::Obj(vec![
            ("format", J::str(TEMPLATE_FORMAT)),
            ("version", J::Int(u64::from(TEMPLATE_VERSION))),
            ("name", J::str(&self.name)),
            ("handedness", J::str(handedness)),
            ("bones", J::Arr(bones_j)),
            ("dofs", J::Arr(dofs_j)),
            ("spheres", J::Arr(spheres_j)),
            ("elements", J::Arr(elements_j)),
            ("keypoints", J::Arr(keypoints_j)),
        ]);
        let mut out = String::new();
        doc.write(0, &mut out);
        out.push('\n');
        Ok(out)
    }

    /// Write the template to `path` as JSON, atomically (a temporary file in the same folder,
    /// then a rename), so a reader never sees a half-written file.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let text = self.to_json_with_source(path)?;
        write_atomic(path, text.as_bytes())
    }

    /// Read a template from a JSON file (see [`SphereMeshTemplate::from_json_str`]).
    pub fn load(path: impl AsRef<Path>) -> Result<SphereMeshTemplate> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| ModelError::Io {
            file: path.to_path_buf(),
            source,
        })?;
        Self::from_json_str(&text, path)
    }

    /// Parse a `hands.spheremesh` JSON document; `source` names it in error messages.
    ///
    /// Refused with a [`ModelError`] naming the source, the field and the index: invalid JSON,
    /// a wrong `format` tag, an unsupported `version`, missing or mistyped fields, unknown bone,
    /// DOF or sphere names, duplicate names, negative radii, sphere indices out of range, a
    /// keypoint list that is not the 21 of DESIGN.md, and anything [`Skeleton::new`] or
    /// [`SphereMeshTemplate::validate`] refuses.
    pub fn from_json_str(text: &str, source: &Path) -> Result<SphereMeshTemplate> {
        let value: Value = serde_json::from_str(text).map_err(|e| ModelError::Parse {
            file: source.to_path_buf(),
            reason: format!("invalid JSON: {e}"),
        })?;
        Reader { src: source }.template(&value)
    }

    /// The largest absolute difference between the numbers of two templates of the same
    /// structure (rest frames, DOF axes and limits, sphere offsets, radii and blend weights), or
    /// `None` when their structure differs (names, handedness, bone tree, DOF kinds, attachment
    /// bones, elements, keypoints). Used to check round trips through files.
    pub fn max_abs_difference(&self, other: &SphereMeshTemplate) -> Option<f64> {
        if self.name != other.name
            || self.handedness != other.handedness
            || self.elements != other.elements
            || self.keypoints != other.keypoints
            || self.spheres.len() != other.spheres.len()
        {
            return None;
        }
        let (ba, bb) = (self.skeleton.bones(), other.skeleton.bones());
        let (da, db) = (self.skeleton.dofs(), other.skeleton.dofs());
        if ba.len() != bb.len() || da.len() != db.len() {
            return None;
        }
        let mut diff = 0.0f64;
        let mut acc = |x: f64, y: f64| diff = diff.max((x - y).abs());
        for (a, b) in ba.iter().zip(bb) {
            if a.name != b.name || a.parent != b.parent || a.dofs != b.dofs {
                return None;
            }
            a.rest
                .rotation
                .iter()
                .zip(b.rest.rotation.iter())
                .for_each(|(x, y)| acc(*x, *y));
            a.rest
                .translation
                .iter()
                .zip(b.rest.translation.iter())
                .for_each(|(x, y)| acc(*x, *y));
        }
        for (a, b) in da.iter().zip(db) {
            if a.name != b.name
                || a.bone != b.bone
                || a.kind != b.kind
                || a.limits.is_some() != b.limits.is_some()
            {
                return None;
            }
            a.axis
                .iter()
                .zip(b.axis.iter())
                .for_each(|(x, y)| acc(*x, *y));
            if let (Some(la), Some(lb)) = (a.limits, b.limits) {
                acc(la[0], lb[0]);
                acc(la[1], lb[1]);
            }
        }
        for (a, b) in self.spheres.iter().zip(&other.spheres) {
            if a.name != b.name {
                return None;
            }
            acc(a.radius, b.radius);
            match (&a.attachment, &b.attachment) {
                (
                    Attachment::Bone {
                        bone: x,
                        offset: oa,
                    },
                    Attachment::Bone {
                        bone: y,
                        offset: ob,
                    },
                ) if x == y => {
                    oa.iter().zip(ob.iter()).for_each(|(x, y)| acc(*x, *y));
                }
                (Attachment::Blend { parts: pa }, Attachment::Blend { parts: pb })
                    if pa.len() == pb.len() =>
                {
                    for (&(i, wa), &(j, wb)) in pa.iter().zip(pb) {
                        if i != j {
                            return None;
                        }
                        acc(wa, wb);
                    }
                }
                _ => return None,
            }
        }
        Some(diff)
    }
}

/// Write `bytes` to `path` atomically: a uniquely named temporary file in the same folder,
/// flushed to disk, then renamed over `path`. The temporary file is removed on failure.
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let io_err = |source: std::io::Error| ModelError::Io {
        file: path.to_path_buf(),
        source,
    };
    let Some(file_name) = path.file_name() else {
        return Err(io_err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "the path names no file",
        )));
    };
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp = dir.join(format!(
        ".{}.tmp-{}-{n}",
        file_name.to_string_lossy(),
        std::process::id()
    ));
    fn write_then_rename(tmp: &Path, path: &Path, bytes: &[u8]) -> std::io::Result<()> {
        let mut f = std::fs::File::create(tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(tmp, path)
    }
    if let Err(e) = write_then_rename(&tmp, path, bytes) {
        let _ = std::fs::remove_file(&tmp);
        return Err(io_err(e));
    }
    Ok(())
}

// ------------------------------------------------------------------------------------------------
// Reading.

/// Reads the JSON tree, naming `src`, the field and the index in every error.
struct Reader<'a> {
    src: &'a Path,
}

type Obj = Map<String, Value>;

impl Reader<'_> {
    fn err(&self, field: &str, index: Option<usize>, reason: impl Into<String>) -> ModelError {
        ModelError::field(self.src, field, index, reason)
    }

    fn obj<'v>(&self, v: &'v Value, field: &str, index: Option<usize>) -> Result<&'v Obj> {
        v.as_object().ok_or_else(|| {
            self.err(
                field,
                index,
                format!("expected an object, got {}", type_name(v)),
            )
        })
    }

    fn arr<'v>(&self, v: &'v Value, field: &str, index: Option<usize>) -> Result<&'v Vec<Value>> {
        v.as_array().ok_or_else(|| {
            self.err(
                field,
                index,
                format!("expected an array, got {}", type_name(v)),
            )
        })
    }

    fn get<'v>(
        &self,
        o: &'v Obj,
        key: &str,
        field: &str,
        index: Option<usize>,
    ) -> Result<&'v Value> {
        o.get(key)
            .ok_or_else(|| self.err(field, index, format!("missing `{key}`")))
    }

    fn string<'v>(&self, v: &'v Value, field: &str, index: Option<usize>) -> Result<&'v str> {
        v.as_str().ok_or_else(|| {
            self.err(
                field,
                index,
                format!("expected a string, got {}", type_name(v)),
            )
        })
    }

    fn number(&self, v: &Value, field: &str, index: Option<usize>) -> Result<f64> {
        let x = v.as_f64().ok_or_else(|| {
            self.err(
                field,
                index,
                format!("expected a number, got {}", type_name(v)),
            )
        })?;
        if !x.is_finite() {
            return Err(self.err(field, index, "non-finite number"));
        }
        Ok(x)
    }

    fn numbers<const N: usize>(
        &self,
        v: &Value,
        field: &str,
        index: Option<usize>,
    ) -> Result<[f64; N]> {
        let a = self.arr(v, field, index)?;
        if a.len() != N {
            return Err(self.err(
                field,
                index,
                format!("expected {N} numbers, got {}", a.len()),
            ));
        }
        let mut out = [0.0; N];
        for (o, x) in out.iter_mut().zip(a) {
            *o = self.number(x, field, index)?;
        }
        Ok(out)
    }

    fn vec3(&self, v: &Value, field: &str, index: Option<usize>) -> Result<Vector3<f64>> {
        Ok(Vector3::from(self.numbers::<3>(v, field, index)?))
    }

    /// A name → index map of a list, refusing duplicates and empty names.
    fn names<'v>(&self, items: &[&'v str], field: &str) -> Result<HashMap<&'v str, usize>> {
        let mut map = HashMap::with_capacity(items.len());
        for (i, &name) in items.iter().enumerate() {
            if name.is_empty() {
                return Err(self.err(field, Some(i), "empty name"));
            }
            if map.insert(name, i).is_some() {
                return Err(self.err(field, Some(i), format!("duplicate name `{name}`")));
            }
        }
        Ok(map)
    }

    fn lookup(
        &self,
        map: &HashMap<&str, usize>,
        name: &str,
        what: &str,
        field: &str,
        index: usize,
    ) -> Result<usize> {
        map.get(name).copied().ok_or_else(|| {
            let hint = if what == "bone" {
                " (missing bone)"
            } else {
                ""
            };
            self.err(field, Some(index), format!("unknown {what} `{name}`{hint}"))
        })
    }

    fn template(&self, root: &Value) -> Result<SphereMeshTemplate> {
        let doc = self.obj(root, "<document>", None)?;
        let format = self.string(self.get(doc, "format", "format", None)?, "format", None)?;
        if format != TEMPLATE_FORMAT {
            return Err(self.err(
                "format",
                None,
                format!("expected `{TEMPLATE_FORMAT}`, got `{format}`"),
            ));
        }
        let version = self.get(doc, "version", "version", None)?;
        match version.as_u64() {
            Some(v) if v == u64::from(TEMPLATE_VERSION) => {}
            Some(v) => {
                return Err(self.err(
                    "version",
                    None,
                    format!(
                        "unsupported version {v} (this build reads version {TEMPLATE_VERSION})"
                    ),
                ))
            }
            None => {
                return Err(self.err(
                    "version",
                    None,
                    format!("expected an integer, got {version}"),
                ))
            }
        }
        let name = self
            .string(self.get(doc, "name", "name", None)?, "name", None)?
            .to_string();
        let handedness = match self.string(
            self.get(doc, "handedness", "handedness", None)?,
            "handedness",
            None,
        )? {
            "right" => Handedness::Right,
            "left" => Handedness::Left,
            other => {
                return Err(self.err(
                    "handedness",
                    None,
                    format!("expected `right` or `left`, got `{other}`"),
                ))
            }
        };
        let skeleton = self.skeleton(doc)?;
        let spheres = self.spheres(doc, &skeleton)?;
        let sphere_names: Vec<&str> = spheres.iter().map(|s| s.name.as_str()).collect();
        let sphere_map = self.names(&sphere_names, "spheres.name")?;
        let bone_names: Vec<&str> = skeleton.bones().iter().map(|b| b.name.as_str()).collect();
        let bone_map = self.names(&bone_names, "bones.name")?;
        let elements = self.elements(doc, &sphere_map, &bone_map, spheres.len())?;
        let keypoints = self.keypoints(doc, &sphere_map, &bone_map)?;
        let template = SphereMeshTemplate {
            name,
            handedness,
            skeleton,
            spheres,
            elements,
            keypoints,
        };
        template.validate(self.src)?;
        Ok(template)
    }

    fn skeleton(&self, doc: &Obj) -> Result<Skeleton> {
        let bones_v = self.arr(self.get(doc, "bones", "bones", None)?, "bones", None)?;
        let dofs_v = self.arr(self.get(doc, "dofs", "dofs", None)?, "dofs", None)?;
        let mut bone_objs = Vec::with_capacity(bones_v.len());
        let mut bone_names = Vec::with_capacity(bones_v.len());
        for (i, b) in bones_v.iter().enumerate() {
            let o = self.obj(b, "bones", Some(i))?;
            bone_names.push(self.string(
                self.get(o, "name", "bones.name", Some(i))?,
                "bones.name",
                Some(i),
            )?);
            bone_objs.push(o);
        }
        let bone_map = self.names(&bone_names, "bones.name")?;
        let mut dof_names = Vec::with_capacity(dofs_v.len());
        let mut dofs = Vec::with_capacity(dofs_v.len());
        for (i, d) in dofs_v.iter().enumerate() {
            let o = self.obj(d, "dofs", Some(i))?;
            let name = self.string(
                self.get(o, "name", "dofs.name", Some(i))?,
                "dofs.name",
                Some(i),
            )?;
            dof_names.push(name);
            let bone_name = self.string(
                self.get(o, "bone", "dofs.bone", Some(i))?,
                "dofs.bone",
                Some(i),
            )?;
            let bone = self.lookup(&bone_map, bone_name, "bone", "dofs.bone", i)?;
            let kind = match self.string(
                self.get(o, "kind", "dofs.kind", Some(i))?,
                "dofs.kind",
                Some(i),
            )? {
                "translation" => DofKind::Translation,
                "global_rotation" => DofKind::GlobalRotation,
                "rotation" => DofKind::Rotation,
                other => {
                    return Err(self.err(
                        "dofs.kind",
                        Some(i),
                        format!(
                        "expected `translation`, `global_rotation` or `rotation`, got `{other}`"
                    ),
                    ))
                }
            };
            let axis = self.vec3(
                self.get(o, "axis", "dofs.axis", Some(i))?,
                "dofs.axis",
                Some(i),
            )?;
            let limits = match o.get("limits") {
                None | Some(Value::Null) => None,
                Some(v) => Some(self.numbers::<2>(v, "dofs.limits", Some(i))?),
            };
            dofs.push(Dof {
                name: name.to_string(),
                bone,
                kind,
                axis,
                limits,
            });
        }
        let dof_map = self.names(&dof_names, "dofs.name")?;
        let mut bones = Vec::with_capacity(bone_objs.len());
        for (i, o) in bone_objs.iter().enumerate() {
            let parent = match self.get(o, "parent", "bones.parent", Some(i))? {
                Value::Null => None,
                v => {
                    let p_name = self.string(v, "bones.parent", Some(i))?;
                    let p = self.lookup(&bone_map, p_name, "bone", "bones.parent", i)?;
                    if p >= i {
                        return Err(self.err(
                            "bones.parent",
                            Some(i),
                            format!(
                                "parent `{p_name}` must be listed before bone `{}`",
                                bone_names[i]
                            ),
                        ));
                    }
                    Some(p)
                }
            };
            let rest = self.obj(
                self.get(o, "rest", "bones.rest", Some(i))?,
                "bones.rest",
                Some(i),
            )?;
            let rows = self.arr(
                self.get(rest, "rotation", "bones.rest.rotation", Some(i))?,
                "bones.rest.rotation",
                Some(i),
            )?;
            if rows.len() != 3 {
                return Err(self.err(
                    "bones.rest.rotation",
                    Some(i),
                    format!("expected 3 rows, got {}", rows.len()),
                ));
            }
            let mut rotation = Matrix3::zeros();
            for (r, row) in rows.iter().enumerate() {
                let row = self.numbers::<3>(row, "bones.rest.rotation", Some(i))?;
                for (c, x) in row.into_iter().enumerate() {
                    rotation[(r, c)] = x;
                }
            }
            let translation = self.vec3(
                self.get(rest, "translation", "bones.rest.translation", Some(i))?,
                "bones.rest.translation",
                Some(i),
            )?;
            let dof_list = self.arr(
                self.get(o, "dofs", "bones.dofs", Some(i))?,
                "bones.dofs",
                Some(i),
            )?;
            let mut bone_dofs = Vec::with_capacity(dof_list.len());
            for d in dof_list {
                let d_name = self.string(d, "bones.dofs", Some(i))?;
                bone_dofs.push(self.lookup(&dof_map, d_name, "DOF", "bones.dofs", i)?);
            }
            bones.push(Bone {
                name: bone_names[i].to_string(),
                parent,
                rest: Rigid3::new(rotation, translation),
                dofs: bone_dofs,
            });
        }
        Skeleton::new(bones, dofs, self.src)
    }

    fn spheres(&self, doc: &Obj, skeleton: &Skeleton) -> Result<Vec<SphereDef>> {
        let list = self.arr(self.get(doc, "spheres", "spheres", None)?, "spheres", None)?;
        let bone_names: Vec<&str> = skeleton.bones().iter().map(|b| b.name.as_str()).collect();
        let bone_map = self.names(&bone_names, "bones.name")?;
        let globals = skeleton.rest_globals();
        let mut objs = Vec::with_capacity(list.len());
        let mut names = Vec::with_capacity(list.len());
        for (i, s) in list.iter().enumerate() {
            let o = self.obj(s, "spheres", Some(i))?;
            names.push(self.string(
                self.get(o, "name", "spheres.name", Some(i))?,
                "spheres.name",
                Some(i),
            )?);
            objs.push(o);
        }
        let map = self.names(&names, "spheres.name")?;
        let mut out = Vec::with_capacity(objs.len());
        for (i, o) in objs.iter().enumerate() {
            let (attachment, radius) = if let Some(blend) = o.get("blend") {
                let parts_v = self.arr(blend, "spheres.blend", Some(i))?;
                let mut parts = Vec::with_capacity(parts_v.len());
                for p in parts_v {
                    let pair = self.arr(p, "spheres.blend", Some(i))?;
                    if pair.len() != 2 {
                        return Err(self.err(
                            "spheres.blend",
                            Some(i),
                            "each part must be [sphere name, weight]",
                        ));
                    }
                    let p_name = self.string(&pair[0], "spheres.blend", Some(i))?;
                    let idx = self.lookup(&map, p_name, "sphere", "spheres.blend", i)?;
                    parts.push((idx, self.number(&pair[1], "spheres.blend", Some(i))?));
                }
                (Attachment::Blend { parts }, 0.0)
            } else {
                let bone_name = self.string(
                    self.get(o, "bone", "spheres.bone", Some(i))?,
                    "spheres.bone",
                    Some(i),
                )?;
                let bone = self.lookup(&bone_map, bone_name, "bone", "spheres.bone", i)?;
                let center = self.vec3(
                    self.get(o, "center", "spheres.center", Some(i))?,
                    "spheres.center",
                    Some(i),
                )?;
                let radius = self.number(
                    self.get(o, "radius", "spheres.radius", Some(i))?,
                    "spheres.radius",
                    Some(i),
                )?;
                if radius < 0.0 {
                    return Err(self.err(
                        "spheres.radius",
                        Some(i),
                        format!("negative radius {radius}"),
                    ));
                }
                let offset = globals[bone].inverse().transform_point(&center);
                (Attachment::Bone { bone, offset }, radius)
            };
            out.push(SphereDef {
                name: names[i].to_string(),
                attachment,
                radius,
            });
        }
        Ok(out)
    }

    fn sphere_ref(
        &self,
        v: &Value,
        map: &HashMap<&str, usize>,
        n: usize,
        index: usize,
    ) -> Result<u32> {
        let i = match v {
            Value::String(name) => self.lookup(map, name, "sphere", "elements", index)?,
            Value::Number(_) => match v
                .as_u64()
                .and_then(|i| usize::try_from(i).ok())
                .filter(|&i| i < n)
            {
                Some(i) => i,
                None => {
                    return Err(self.err(
                        "elements",
                        Some(index),
                        format!("sphere index {v} out of range ({n} spheres)"),
                    ))
                }
            },
            other => {
                return Err(self.err(
                    "elements",
                    Some(index),
                    format!("expected a sphere name, got {}", type_name(other)),
                ))
            }
        };
        u32::try_from(i).map_err(|_| self.err("elements", Some(index), "sphere index too large"))
    }

    fn elements(
        &self,
        doc: &Obj,
        spheres: &HashMap<&str, usize>,
        bones: &HashMap<&str, usize>,
        n: usize,
    ) -> Result<Vec<ElementDef>> {
        let list = self.arr(
            self.get(doc, "elements", "elements", None)?,
            "elements",
            None,
        )?;
        let mut out = Vec::with_capacity(list.len());
        for (e, v) in list.iter().enumerate() {
            let o = self.obj(v, "elements", Some(e))?;
            let element = match (o.get("pill"), o.get("wedge")) {
                (Some(p), None) => {
                    let a = self.arr(p, "elements", Some(e))?;
                    if a.len() != 2 {
                        return Err(self.err(
                            "elements",
                            Some(e),
                            format!("a pill joins 2 spheres, got {}", a.len()),
                        ));
                    }
                    Element::Pill([
                        self.sphere_ref(&a[0], spheres, n, e)?,
                        self.sphere_ref(&a[1], spheres, n, e)?,
                    ])
                }
                (None, Some(w)) => {
                    let a = self.arr(w, "elements", Some(e))?;
                    if a.len() != 3 {
                        return Err(self.err(
                            "elements",
                            Some(e),
                            format!("a wedge joins 3 spheres, got {}", a.len()),
                        ));
                    }
                    Element::Wedge([
                        self.sphere_ref(&a[0], spheres, n, e)?,
                        self.sphere_ref(&a[1], spheres, n, e)?,
                        self.sphere_ref(&a[2], spheres, n, e)?,
                    ])
                }
                _ => {
                    return Err(self.err(
                        "elements",
                        Some(e),
                        "expected exactly one of `pill` or `wedge`",
                    ))
                }
            };
            let bone_name = self.string(
                self.get(o, "bone", "elements.bone", Some(e))?,
                "elements.bone",
                Some(e),
            )?;
            let bone = self.lookup(bones, bone_name, "bone", "elements.bone", e)?;
            out.push(ElementDef { element, bone });
        }
        Ok(out)
    }

    fn keypoints(
        &self,
        doc: &Obj,
        spheres: &HashMap<&str, usize>,
        bones: &HashMap<&str, usize>,
    ) -> Result<Vec<KeypointDef>> {
        let list = self.arr(
            self.get(doc, "keypoints", "keypoints", None)?,
            "keypoints",
            None,
        )?;
        if list.len() != NUM_KEYPOINTS {
            return Err(self.err(
                "keypoints",
                None,
                format!("{} keypoints, expected {NUM_KEYPOINTS}", list.len()),
            ));
        }
        let mut out = Vec::with_capacity(NUM_KEYPOINTS);
        for (k, v) in list.iter().enumerate() {
            let o = self.obj(v, "keypoints", Some(k))?;
            let name = self.string(
                self.get(o, "name", "keypoints.name", Some(k))?,
                "keypoints.name",
                Some(k),
            )?;
            if name != KEYPOINT_NAMES[k] {
                return Err(self.err(
                    "keypoints.name",
                    Some(k),
                    format!(
                        "expected `{}` (DESIGN.md order), got `{name}`",
                        KEYPOINT_NAMES[k]
                    ),
                ));
            }
            let bone_of = |key: &str, field: &str| -> Result<usize> {
                let b = self.string(self.get(o, key, field, Some(k))?, field, Some(k))?;
                self.lookup(bones, b, "bone", field, k)
            };
            let def = if o.contains_key("joint") {
                KeypointDef::Joint {
                    bone: bone_of("joint", "keypoints.joint")?,
                }
            } else if let Some(tip) = o.get("tip") {
                let s = self.string(tip, "keypoints.tip", Some(k))?;
                let sphere = self.lookup(spheres, s, "sphere", "keypoints.tip", k)?;
                KeypointDef::Tip {
                    bone: bone_of("bone", "keypoints.bone")?,
                    sphere,
                }
            } else {
                return Err(self.err("keypoints", Some(k), "expected `joint` or `tip`"));
            };
            out.push(def);
        }
        Ok(out)
    }
}

fn type_name(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spheremesh::default_right_hand;

    fn temp_path(tag: &str) -> PathBuf {
        static N: AtomicUsize = AtomicUsize::new(0);
        let n = N.fetch_add(1, Ordering::Relaxed);
        std::env::temp_dir().join(format!(
            "hands-json-test-{}-{tag}-{n}.json",
            std::process::id()
        ))
    }

    fn default_json() -> Value {
        serde_json::from_str(&default_right_hand().to_json_string().expect("serializes"))
            .expect("valid JSON")
    }

    /// Parse an edited document and return the error text.
    fn refuse(doc: &Value) -> String {
        let text = serde_json::to_string(doc).expect("serializes");
        match SphereMeshTemplate::from_json_str(&text, Path::new("edited.json")) {
            Ok(_) => panic!("an invalid document was accepted"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn default_template_round_trips_through_a_file() {
        let t = default_right_hand();
        let path = temp_path("roundtrip");
        t.save(&path).expect("saves");
        let back = SphereMeshTemplate::load(&path).expect("loads");
        let _ = std::fs::remove_file(&path);
        let diff = t.max_abs_difference(&back).expect("same structure");
        assert!(diff < 1e-9, "round trip moved a number by {diff}");
        // No temporary file is left behind.
        let dir = path.parent().unwrap();
        let stem = path.file_name().unwrap().to_string_lossy().into_owned();
        let leftovers = std::fs::read_dir(dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| {
                e.file_name()
                    .to_string_lossy()
                    .starts_with(&format!(".{stem}.tmp"))
            })
            .count();
        assert_eq!(leftovers, 0);
    }

    #[test]
    fn file_is_readable_with_names() {
        let text = default_right_hand().to_json_string().unwrap();
        assert!(text.starts_with("{\n  \"format\": \"hands.spheremesh\",\n  \"version\": 1,"));
        assert!(
            text.contains("\"pill\": [\"index_middle\", \"index_top\"]"),
            "{text}"
        );
        assert!(text.contains("{\"name\": \"wrist\", \"joint\": \"wrist\"}"));
        assert!(text.contains("\"blend\": [[\"palm_thumb\", 0.4], [\"thumb_membrane_left\", 0.3], [\"thumb_base\", 0.3]]"));
    }

    #[test]
    fn element_indices_are_accepted_as_well_as_names() {
        let mut doc = default_json();
        doc["elements"][0]["pill"] = serde_json::json!([1, 0]);
        let t = SphereMeshTemplate::from_json_str(&doc.to_string(), Path::new("x.json"))
            .expect("indices accepted");
        assert_eq!(t.elements[0].element, Element::Pill([1, 0]));
    }

    #[test]
    fn refuses_wrong_format_and_version() {
        let mut doc = default_json();
        doc["format"] = "something.else".into();
        let e = refuse(&doc);
        assert!(e.contains("edited.json") && e.contains("`format`"), "{e}");
        let mut doc = default_json();
        doc["version"] = 2.into();
        let e = refuse(&doc);
        assert!(
            e.contains("`version`") && e.contains("unsupported version 2"),
            "{e}"
        );
        let mut doc = default_json();
        doc.as_object_mut().unwrap().remove("format");
        assert!(refuse(&doc).contains("missing `format`"));
    }

    #[test]
    fn refuses_unknown_names() {
        let mut doc = default_json();
        doc["bones"][4]["parent"] = "no_such_bone".into();
        let e = refuse(&doc);
        assert!(
            e.contains("`bones.parent`[4]") && e.contains("missing bone"),
            "{e}"
        );
        let mut doc = default_json();
        doc["spheres"][3]["bone"] = "nope".into();
        let e = refuse(&doc);
        assert!(
            e.contains("`spheres.bone`[3]") && e.contains("unknown bone"),
            "{e}"
        );
        let mut doc = default_json();
        doc["elements"][15]["wedge"] =
            serde_json::json!(["palm_back", "palm_right", "palm_nowhere"]);
        let e = refuse(&doc);
        assert!(
            e.contains("`elements`[15]") && e.contains("unknown sphere `palm_nowhere`"),
            "{e}"
        );
        let mut doc = default_json();
        doc["bones"][2]["dofs"][0] = "wrist_twist".into();
        assert!(refuse(&doc).contains("`bones.dofs`[2]"));
        let mut doc = default_json();
        doc["keypoints"][8]["tip"] = "index_nail".into();
        assert!(refuse(&doc).contains("`keypoints.tip`[8]"));
        let mut doc = default_json();
        let last = doc["spheres"].as_array().unwrap().len() - 1;
        doc["spheres"][last]["blend"][1][0] = "thumb_web".into();
        assert!(refuse(&doc).contains(&format!("`spheres.blend`[{last}]")));
    }

    #[test]
    fn refuses_bad_values() {
        let mut doc = default_json();
        doc["spheres"][7]["radius"] = (-1.5).into();
        let e = refuse(&doc);
        assert!(
            e.contains("`spheres.radius`[7]") && e.contains("negative radius"),
            "{e}"
        );
        let mut doc = default_json();
        doc["elements"][2]["pill"] = serde_json::json!([0, 39]);
        let e = refuse(&doc);
        assert!(
            e.contains("`elements`[2]") && e.contains("out of range"),
            "{e}"
        );
        let mut doc = default_json();
        doc["spheres"][1]["center"] = serde_json::json!([1.0, "two", 3.0]);
        assert!(refuse(&doc).contains("`spheres.center`[1]"));
        let mut doc = default_json();
        doc["bones"][1]["rest"]["rotation"][0] = serde_json::json!([2.0, 0.0, 0.0]);
        assert!(refuse(&doc).contains("`bones.rest`[1]"));
        let mut doc = default_json();
        doc["dofs"][9]["limits"] = serde_json::json!([1.0, -1.0]);
        assert!(refuse(&doc).contains("`dofs.limits`[9]"));
        let mut doc = default_json();
        doc["handedness"] = "both".into();
        assert!(refuse(&doc).contains("`handedness`"));
    }

    #[test]
    fn refuses_mismatched_counts_and_duplicates() {
        let mut doc = default_json();
        doc["keypoints"].as_array_mut().unwrap().pop();
        let e = refuse(&doc);
        assert!(
            e.contains("`keypoints`") && e.contains("20 keypoints, expected 21"),
            "{e}"
        );
        let mut doc = default_json();
        doc["keypoints"][1]["name"] = "thumb_mcp".into();
        assert!(refuse(&doc).contains("`keypoints.name`[1]"));
        let mut doc = default_json();
        doc["elements"][0]["pill"] =
            serde_json::json!(["pinky_middle", "pinky_top", "pinky_bottom"]);
        assert!(refuse(&doc).contains("a pill joins 2 spheres"));
        let mut doc = default_json();
        doc["spheres"][5]["name"] = doc["spheres"][2]["name"].clone();
        let e = refuse(&doc);
        assert!(
            e.contains("`spheres.name`[5]") && e.contains("duplicate"),
            "{e}"
        );
        let mut doc = default_json();
        doc["bones"][7]["name"] = "index_1".into();
        assert!(refuse(&doc).contains("`bones.name`"));
        let mut doc = default_json();
        doc["dofs"][12]["name"] = "global_tx".into();
        assert!(refuse(&doc).contains("`dofs.name`[12]"));
    }

    #[test]
    fn refuses_non_finite_numbers() {
        // JSON cannot spell NaN or infinity; an overflowing literal is refused while parsing.
        let text = default_right_hand().to_json_string().unwrap().replacen(
            "\"radius\": ",
            "\"radius\": 1e999, \"r0\": ",
            1,
        );
        let e = SphereMeshTemplate::from_json_str(&text, Path::new("big.json"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("big.json") && e.contains("line"), "{e}");
        // And a template holding a NaN is not written.
        let mut t = default_right_hand();
        t.spheres[4].radius = f64::NAN;
        let e = t.to_json_string().unwrap_err().to_string();
        assert!(e.contains("spheres.radius") && e.contains("[4]"), "{e}");
        // Syntax errors name the file and the position.
        let e = SphereMeshTemplate::from_json_str("{\"format\": ", Path::new("cut.json"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("cut.json") && e.contains("line 1"), "{e}");
    }

    #[test]
    fn load_names_missing_file() {
        let e = SphereMeshTemplate::load("/nonexistent/dir/hand.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains("/nonexistent/dir/hand.json"), "{e}");
        let e = default_right_hand()
            .save("/nonexistent/dir/hand.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains("/nonexistent/dir/hand.json"), "{e}");
    }
}
