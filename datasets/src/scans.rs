//! Photogrammetry hand scans and the original authors' fitted sphere-meshes: the data side of
//! offline multi-frame calibration (issue 6, thesis §3.4, multi-view case), for the real-data
//! test "calibrate to six scans of one hand and compare to the authors' fit".
//!
//! - [`read_obj_points`]: the vertices of an OBJ scan (a complete point cloud in arbitrary
//!   units);
//! - [`FittedReference`]: the authors' result folder (`fitted/`): the final model in mm, the
//!   per-pose centers in scan units, the blocks, and the sphere names, which the files give only
//!   indirectly (see [`FittedReference::load`]);
//! - [`match_sphere_names`]: which reference sphere is which sphere of a project template;
//! - [`pill_length_scale`] and [`scale_from_extents`]: scan units per millimetre, from a posed
//!   fit (exact up to the fit's own consistency) or from a scan alone (a first guess that the
//!   calibration refines);
//! - [`scan_residual`] and [`locate_fits`]: the distance of a scan to a sphere-mesh (the E_d2m
//!   of thesis Eq. 3.15 on a complete cloud) and which scan each fitted pose belongs to.
//!
//! The similarity alignment itself is [`hand_model::math::fit_similarity`] (Umeyama 1991), kept
//! in `hand-model` so that `eval` can use it without depending on this crate.

use std::collections::HashMap;
use std::path::Path;

use hand_model::query::SphereMeshGeometry;
use hand_model::shape::{Element, Sphere};
use hand_model::spheremesh::SphereMeshTemplate;
use nalgebra::{Matrix3, Matrix4, Vector3, Vector4};
use serde::de::DeserializeOwned;
use serde_json::Value;

use crate::error::{DatasetError, Result};

// ------------------------------------------------------------------------------------------------
// OBJ point clouds.

/// The vertices of a Wavefront OBJ file, in file order and file units.
///
/// Only `v` lines are read (`v x y z`, `v x y z w`, or MeshLab's `v x y z r g b`); faces,
/// normals, texture coordinates, groups and comments are skipped, because the calibration
/// needs the complete surface as a point cloud and the scans' triangulations carry no extra
/// information about the hand. A malformed `v` line, a non-finite coordinate or a file without
/// vertices is an error naming the file and the line.
pub fn read_obj_points(path: impl AsRef<Path>) -> Result<Vec<Vector3<f64>>> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|source| DatasetError::Io {
        file: path.to_path_buf(),
        source,
    })?;
    parse_obj_points(&text, path)
}

/// [`read_obj_points`] on text already in memory; `source` names it in errors.
pub fn parse_obj_points(text: &str, source: &Path) -> Result<Vec<Vector3<f64>>> {
    let mut points = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let content = line.split('#').next().unwrap_or("");
        let mut fields = content.split_whitespace();
        if fields.next() != Some("v") {
            continue;
        }
        let err = |reason: String| DatasetError::Parse {
            file: source.to_path_buf(),
            line: Some(i + 1),
            reason,
        };
        let values: Vec<&str> = fields.collect();
        if !matches!(values.len(), 3 | 4 | 6 | 7) {
            return Err(err(format!(
                "a `v` line needs `x y z`, `x y z w` or `x y z r g b`, got {} values",
                values.len()
            )));
        }
        let mut xyz = [0.0; 3];
        for (k, token) in values.iter().enumerate() {
            let x: f64 = token
                .parse()
                .map_err(|_| err(format!("`{token}` is not a number")))?;
            if !x.is_finite() {
                return Err(err(format!("non-finite value `{token}`")));
            }
            if k < 3 {
                xyz[k] = x;
            }
        }
        points.push(Vector3::from(xyz));
    }
    if points.is_empty() {
        return Err(DatasetError::Parse {
            file: source.to_path_buf(),
            line: None,
            reason: "no vertices (`v x y z` lines)".into(),
        });
    }
    Ok(points)
}

// ------------------------------------------------------------------------------------------------
// The authors' fitted result.

/// The original authors' multi-frame fit of the scans (`hand-scans-tkach/fitted/`): one shape,
/// one set of centers per posed scan.
#[derive(Clone, Debug, PartialEq)]
pub struct FittedReference {
    /// Final model's sphere centers (mm, the authors' model frame: index toward +x).
    pub final_centers: Vec<Vector3<f64>>,
    /// Final model's radii (mm), in the order of the centers.
    pub final_radii: Vec<f64>,
    /// Name of each sphere, in the order of the centers (the hmodel names: `pinky_top`, ...,
    /// `thumb_fold`, `wrist_bottom_right`).
    pub sphere_names: Vec<String>,
    /// `per_pose_centers[k]`: the centers of `fitting_result_{k+1}_centers.json`, in scan
    /// units, same order as the final centers. Which scan each belongs to is not in the files:
    /// see [`locate_fits`].
    pub per_pose_centers: Vec<Vec<Vector3<f64>>>,
    /// The pills and wedges of the fitted model (0-based sphere indices), shared by the final
    /// model and every pose.
    pub blocks: Vec<Element>,
    /// Sphere names of the initial model the fit started from, by its own (different) index.
    pub initialization_names: Vec<String>,
    /// Blocks of the initial model (0-based indices into `initialization_names`).
    pub initialization_blocks: Vec<Vec<usize>>,
}

impl FittedReference {
    /// Reads the folder.
    ///
    /// The sphere names come from `final_phalanges.json`, because it is the only file that
    /// names the spheres of the fitted model: a phalanx's own sphere sits at its global origin
    /// and each of its `rigid_names` at `global · offset`. Those positions are the final
    /// centers up to one unknown factor (the phalanges are stored before the model's `Scale`
    /// node is applied; it measures 1.43 for these files), so the factor is taken as the ratio of
    /// the RMS spreads of the two point sets about their means, which needs no correspondence;
    /// then each named position is paired with its nearest center. The pairing must be a
    /// bijection with every residual below a quarter of the smallest distance between two
    /// centers, otherwise loading fails. Only names that occur in the initialization's named
    /// blocks count as sphere names (this drops the `Pose` and `Scale` nodes).
    ///
    /// The initialization's names come from pairing `fitting_initialization_blocks.json`
    /// (numeric) with `fitting_initialization_named_blocks.json` position by position; each
    /// index must receive one name only. Those indices (40 spheres) are not the fitted model's
    /// (38): the fit dropped `palm_attachment` and `thumb_membrane` and reordered the rest, so
    /// they cannot name the result directly. They serve as the cross-check of
    /// [`blocks_missing_from_initialization`](Self::blocks_missing_from_initialization).
    pub fn load(dir: impl AsRef<Path>) -> Result<Self> {
        let dir = dir.as_ref();
        let final_centers = read_points(&dir.join("final_centers.json"), "centers")?;
        let radii_path = dir.join("final_radii.json");
        let final_radii: Vec<f64> = read_field(&radii_path, "radii")?;
        let n = final_centers.len();
        if final_radii.len() != n {
            return Err(parse_err(
                &radii_path,
                format!("{} radii for {n} centers", final_radii.len()),
            ));
        }
        if let Some(i) = final_radii
            .iter()
            .position(|r| !(r.is_finite() && *r > 0.0))
        {
            return Err(parse_err(
                &radii_path,
                format!("radius {i} is {} (must be positive)", final_radii[i]),
            ));
        }
        let blocks_path = dir.join("fitting_result_blocks.json");
        let blocks = read_blocks(&blocks_path, n)?
            .into_iter()
            .map(|b| match b.as_slice() {
                [a, b] => Element::Pill([*a as u32, *b as u32]),
                _ => Element::Wedge([b[0] as u32, b[1] as u32, b[2] as u32]),
            })
            .collect();

        let mut per_pose_centers = Vec::new();
        for k in 1.. {
            let path = dir.join(format!("fitting_result_{k}_centers.json"));
            if !path.exists() {
                break;
            }
            let centers = read_points(&path, "centers")?;
            if centers.len() != n {
                return Err(parse_err(
                    &path,
                    format!("{} centers, the final model has {n}", centers.len()),
                ));
            }
            per_pose_centers.push(centers);
        }
        if per_pose_centers.is_empty() {
            return Err(parse_err(
                &dir.join("fitting_result_1_centers.json"),
                "missing: no per-pose fit in the folder",
            ));
        }

        let (initialization_names, initialization_blocks) = read_initialization(dir)?;
        let vocabulary: Vec<&str> = initialization_names.iter().map(String::as_str).collect();
        let sphere_names = names_from_phalanges(
            &dir.join("final_phalanges.json"),
            &final_centers,
            &vocabulary,
        )?;
        Ok(Self {
            final_centers,
            final_radii,
            sphere_names,
            per_pose_centers,
            blocks,
            initialization_names,
            initialization_blocks,
        })
    }

    /// The index of the sphere called `name`.
    pub fn sphere_index(&self, name: &str) -> Option<usize> {
        self.sphere_names.iter().position(|n| n == name)
    }

    /// Indices of the fitted blocks whose set of sphere names is not a block of the
    /// initialization: the blocks the fit changed. Measured on the authors' files: only the
    /// wedge `thumb_base, thumb_bottom, thumb_fold` (the initialization had the pill
    /// `palm_left, thumb_base` instead), which is the hmodel C++ template's block 14 as well.
    pub fn blocks_missing_from_initialization(&self) -> Vec<usize> {
        let known: Vec<Vec<&str>> = self
            .initialization_blocks
            .iter()
            .map(|b| sorted_names(b.iter().map(|&i| &self.initialization_names[i])))
            .collect();
        self.blocks
            .iter()
            .enumerate()
            .filter(|(_, b)| {
                let names =
                    sorted_names(b.spheres().iter().map(|&i| &self.sphere_names[i as usize]));
                !known.contains(&names)
            })
            .map(|(i, _)| i)
            .collect()
    }

    /// The fitted model with `centers` (the final ones or one pose's) and the final radii times
    /// `radius_scale` (scan units per mm for a pose), prepared for distance queries.
    pub fn geometry(
        &self,
        centers: &[Vector3<f64>],
        radius_scale: f64,
    ) -> Result<SphereMeshGeometry> {
        if centers.len() != self.final_radii.len() {
            return Err(DatasetError::arg(
                "centers",
                format!(
                    "{} centers for a model of {} spheres",
                    centers.len(),
                    self.final_radii.len()
                ),
            ));
        }
        positive("radius_scale", radius_scale)?;
        let spheres: Vec<Sphere> = centers
            .iter()
            .zip(&self.final_radii)
            .map(|(c, r)| Sphere::new(*c, r * radius_scale))
            .collect();
        Ok(SphereMeshGeometry::new(&spheres, &self.blocks)?)
    }
}

fn sorted_names<'a>(names: impl Iterator<Item = &'a String>) -> Vec<&'a str> {
    let mut v: Vec<&str> = names.map(String::as_str).collect();
    v.sort_unstable();
    v
}

fn positive(name: &'static str, x: f64) -> Result<()> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        Err(DatasetError::arg(
            name,
            format!("{x} is not a positive number"),
        ))
    }
}

fn parse_err(file: &Path, reason: impl Into<String>) -> DatasetError {
    DatasetError::Parse {
        file: file.to_path_buf(),
        line: None,
        reason: reason.into(),
    }
}

fn read_json(path: &Path) -> Result<Value> {
    let text = std::fs::read_to_string(path).map_err(|source| DatasetError::Io {
        file: path.to_path_buf(),
        source,
    })?;
    serde_json::from_str(&text).map_err(|e| DatasetError::Parse {
        file: path.to_path_buf(),
        line: Some(e.line()),
        reason: e.to_string(),
    })
}

fn read_field<T: DeserializeOwned>(path: &Path, field: &str) -> Result<T> {
    let mut json = read_json(path)?;
    let value = json
        .get_mut(field)
        .map(Value::take)
        .ok_or_else(|| parse_err(path, format!("no field `{field}`")))?;
    serde_json::from_value(value).map_err(|e| parse_err(path, format!("field `{field}`: {e}")))
}

fn read_points(path: &Path, field: &str) -> Result<Vec<Vector3<f64>>> {
    let raw: Vec<[f64; 3]> = read_field(path, field)?;
    if raw.is_empty() {
        return Err(parse_err(path, format!("field `{field}` is empty")));
    }
    if let Some(i) = raw.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
        return Err(parse_err(path, format!("`{field}`[{i}] is not finite")));
    }
    Ok(raw.into_iter().map(Vector3::from).collect())
}

/// 1-based index blocks of 2 or 3 spheres → 0-based, each index below `count`.
fn read_blocks(path: &Path, count: usize) -> Result<Vec<Vec<usize>>> {
    let raw: Vec<Vec<i64>> = read_field(path, "blocks")?;
    raw.iter()
        .enumerate()
        .map(|(b, block)| {
            if !matches!(block.len(), 2 | 3) {
                return Err(parse_err(
                    path,
                    format!("block {b} has {} spheres (2 or 3 expected)", block.len()),
                ));
            }
            block
                .iter()
                .map(|&i| {
                    if i >= 1 && (i as usize) <= count {
                        Ok(i as usize - 1)
                    } else {
                        Err(parse_err(
                            path,
                            format!("block {b} names sphere {i}, outside 1..={count}"),
                        ))
                    }
                })
                .collect()
        })
        .collect()
}

fn read_initialization(dir: &Path) -> Result<(Vec<String>, Vec<Vec<usize>>)> {
    let named_path = dir.join("fitting_initialization_named_blocks.json");
    let named: Vec<Vec<String>> = read_field(&named_path, "named_blocks")?;
    let path = dir.join("fitting_initialization_blocks.json");
    // The count is not stored: bound the indices by the number of block slots.
    let slots = named.iter().map(Vec::len).sum();
    let blocks = read_blocks(&path, slots)?;
    if blocks.len() != named.len() {
        return Err(parse_err(
            &path,
            format!("{} blocks but {} named blocks", blocks.len(), named.len()),
        ));
    }
    let count = blocks.iter().flatten().max().map_or(0, |m| m + 1);
    let mut names: Vec<Option<String>> = vec![None; count];
    for (b, (block, block_names)) in blocks.iter().zip(&named).enumerate() {
        if block.len() != block_names.len() {
            return Err(parse_err(
                &path,
                format!(
                    "block {b} has {} spheres but {} names",
                    block.len(),
                    block_names.len()
                ),
            ));
        }
        for (&i, name) in block.iter().zip(block_names) {
            match &names[i] {
                Some(old) if old != name => {
                    return Err(parse_err(
                        &path,
                        format!("sphere {} is named both `{old}` and `{name}`", i + 1),
                    ))
                }
                _ => names[i] = Some(name.clone()),
            }
        }
    }
    let names = names
        .into_iter()
        .enumerate()
        .map(|(i, n)| n.ok_or_else(|| parse_err(&path, format!("sphere {} is in no block", i + 1))))
        .collect::<Result<Vec<_>>>()?;
    Ok((names, blocks))
}

/// A 4×4 row-major matrix from JSON.
fn matrix4(path: &Path, phalanx: usize, value: Option<&Value>) -> Result<Matrix4<f64>> {
    let rows: Vec<[f64; 4]> = value
        .cloned()
        .map(serde_json::from_value)
        .transpose()
        .ok()
        .flatten()
        .filter(|rows: &Vec<[f64; 4]>| rows.len() == 4)
        .ok_or_else(|| {
            parse_err(
                path,
                format!("phalanx {phalanx}: `global` is not a 4×4 matrix"),
            )
        })?;
    let m = Matrix4::from_fn(|r, c| rows[r][c]);
    if !m.iter().all(|x| x.is_finite()) {
        return Err(parse_err(
            path,
            format!("phalanx {phalanx}: `global` is not finite"),
        ));
    }
    Ok(m)
}

/// `rigid_names` and `offsets` of a phalanx; Matlab's export collapses one-element lists to a
/// bare string / a bare triple, so both shapes are accepted.
fn attachments(path: &Path, phalanx: usize, p: &Value) -> Result<Vec<(String, Vector3<f64>)>> {
    let names: Vec<String> = match p.get("rigid_names") {
        None | Some(Value::Null) => return Ok(vec![]),
        Some(Value::String(s)) => vec![s.clone()],
        Some(v) => serde_json::from_value(v.clone())
            .map_err(|e| parse_err(path, format!("phalanx {phalanx}: `rigid_names`: {e}")))?,
    };
    let offsets_value = p.get("offsets").cloned().unwrap_or(Value::Null);
    let offsets: Vec<[f64; 3]> = serde_json::from_value::<Vec<[f64; 3]>>(offsets_value.clone())
        .or_else(|_| serde_json::from_value::<[f64; 3]>(offsets_value).map(|o| vec![o]))
        .map_err(|e| parse_err(path, format!("phalanx {phalanx}: `offsets`: {e}")))?;
    if offsets.len() != names.len() {
        return Err(parse_err(
            path,
            format!(
                "phalanx {phalanx}: {} rigid names but {} offsets",
                names.len(),
                offsets.len()
            ),
        ));
    }
    Ok(names
        .into_iter()
        .zip(offsets.into_iter().map(Vector3::from))
        .collect())
}

fn names_from_phalanges(
    path: &Path,
    centers: &[Vector3<f64>],
    vocabulary: &[&str],
) -> Result<Vec<String>> {
    let phalanges: Vec<Value> = read_field(path, "phalanges")?;
    let mut named: Vec<(String, Vector3<f64>)> = Vec::new();
    for (k, p) in phalanges.iter().enumerate() {
        let global = matrix4(path, k, p.get("global"))?;
        let to_world = |o: &Vector3<f64>| (global * Vector4::new(o.x, o.y, o.z, 1.0)).xyz();
        let name = p
            .get("name")
            .and_then(Value::as_str)
            .ok_or_else(|| parse_err(path, format!("phalanx {k}: no `name`")))?;
        named.push((name.to_string(), to_world(&Vector3::zeros())));
        for (n, offset) in attachments(path, k, p)? {
            named.push((n, to_world(&offset)));
        }
    }
    // Keep sphere names only, once each (a name on two phalanges must be at one place).
    let mut unique: Vec<(String, Vector3<f64>)> = Vec::new();
    for (name, x) in named {
        if !vocabulary.contains(&name.as_str()) {
            continue;
        }
        match unique.iter().find(|(n, _)| *n == name) {
            Some((_, y)) if (x - y).norm() > 1e-6 * (1.0 + y.norm()) => {
                return Err(parse_err(
                    path,
                    format!("sphere `{name}` is placed at two different positions"),
                ))
            }
            Some(_) => {}
            None => unique.push((name, x)),
        }
    }
    if unique.len() != centers.len() {
        return Err(parse_err(
            path,
            format!(
                "the phalanges name {} spheres, the model has {}",
                unique.len(),
                centers.len()
            ),
        ));
    }
    let positions: Vec<Vector3<f64>> = unique.iter().map(|(_, x)| *x).collect();
    let (mean_c, spread_c) = mean_and_rms_spread(centers);
    let (mean_p, spread_p) = mean_and_rms_spread(&positions);
    if !(spread_c > 0.0 && spread_p > 0.0) {
        return Err(parse_err(
            path,
            "all spheres at one point: names undetermined",
        ));
    }
    let factor = spread_c / spread_p;
    let min_gap = (0..centers.len())
        .flat_map(|i| (0..i).map(move |j| (i, j)))
        .map(|(i, j)| (centers[i] - centers[j]).norm())
        .fold(f64::INFINITY, f64::min);
    let mut names: Vec<Option<String>> = vec![None; centers.len()];
    for (name, x) in &unique {
        let predicted = mean_c + factor * (x - mean_p);
        let (j, d) = nearest(centers, &predicted);
        if d > 0.25 * min_gap {
            return Err(parse_err(
                path,
                format!(
                    "sphere `{name}` is {d:.3} from the nearest center, more than a quarter of \
                     the smallest center spacing ({min_gap:.3}): names undetermined"
                ),
            ));
        }
        if let Some(other) = &names[j] {
            return Err(parse_err(
                path,
                format!("spheres `{other}` and `{name}` both fall on center {j}"),
            ));
        }
        names[j] = Some(name.clone());
    }
    // `unique` has as many entries as there are centers and no center was taken twice.
    Ok(names.into_iter().flatten().collect())
}

fn mean_and_rms_spread(points: &[Vector3<f64>]) -> (Vector3<f64>, f64) {
    let n = points.len() as f64;
    let mean = points.iter().sum::<Vector3<f64>>() / n;
    let var = points
        .iter()
        .map(|p| (p - mean).norm_squared())
        .sum::<f64>()
        / n;
    (mean, var.sqrt())
}

fn nearest(points: &[Vector3<f64>], x: &Vector3<f64>) -> (usize, f64) {
    points
        .iter()
        .enumerate()
        .map(|(i, p)| (i, (p - x).norm()))
        .fold((0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a })
}

// ------------------------------------------------------------------------------------------------
// Names of the reference vs the project template.

/// Which reference sphere is which template sphere.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SphereCorrespondence {
    /// `(reference index, template index)` for every name the two share, in reference order.
    pub pairs: Vec<(usize, usize)>,
    /// Reference spheres without a template counterpart.
    pub reference_only: Vec<String>,
    /// Template spheres without a reference counterpart.
    pub template_only: Vec<String>,
}

/// Pairs spheres by equal name. The project template uses the honline names and the authors'
/// fit the hmodel names, which agree except around the thumb web (ANCHOR-FACTS §2.2): hmodel's
/// `thumb_fold` (attached to the thumb's first bone) became honline's `thumb_membrane_left`
/// (on the second bone) plus the derived `thumb_membrane_middle`. `hand_model`'s importer keeps
/// those names apart too, so the three stay unpaired here rather than being forced onto a sphere
/// that moves with another bone.
pub fn match_sphere_names(
    reference_names: &[String],
    template: &SphereMeshTemplate,
) -> SphereCorrespondence {
    let template_index: HashMap<&str, usize> = template
        .spheres
        .iter()
        .enumerate()
        .map(|(i, s)| (s.name.as_str(), i))
        .collect();
    let mut pairs = Vec::new();
    let mut reference_only = Vec::new();
    for (i, name) in reference_names.iter().enumerate() {
        match template_index.get(name.as_str()) {
            Some(&j) => pairs.push((i, j)),
            None => reference_only.push(name.clone()),
        }
    }
    let template_only = template
        .spheres
        .iter()
        .filter(|s| !reference_names.contains(&s.name))
        .map(|s| s.name.clone())
        .collect();
    SphereCorrespondence {
        pairs,
        reference_only,
        template_only,
    }
}

// ------------------------------------------------------------------------------------------------
// Scale.

/// Scan units per millimetre of a posed fit, from its bone lengths.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ScaleEstimate {
    /// Least-squares factor `s` in `posed length ≈ s · reference length` (scan units per mm).
    pub scale: f64,
    /// RMS relative deviation of the per-pill ratios from `s`: 0 when the posed model is exactly
    /// the reference shape, scaled.
    pub relative_spread: f64,
    /// Number of pills used.
    pub pills: usize,
}

/// The scale between a reference model (mm) and a posed copy of it (scan units), from the
/// lengths of its pills.
///
/// A pill joins two spheres of one bone or the centers of two consecutive bones, so its length
/// does not change with the pose; the similarity over all centers would mix scale with the pose
/// difference. `s = Σ dᵢ Dᵢ / Σ Dᵢ²` over pills (length `Dᵢ` in the reference, `dᵢ` posed).
///
/// On the authors' files the per-pose fits share their pill lengths to 0.01 mm, but the final
/// model is not an exact scaled copy of them (fingertip pills 12 % shorter, thumb pills −17 % to
/// +6 %): `relative_spread` is 0.09 there, and `s` = 0.02806 scan units per mm, whereas the
/// similarity over the spheres that stay rigid with `palm_back` gives 0.02843.
pub fn pill_length_scale(
    reference: &[Vector3<f64>],
    posed: &[Vector3<f64>],
    blocks: &[Element],
) -> Result<ScaleEstimate> {
    if reference.len() != posed.len() {
        return Err(DatasetError::arg(
            "posed",
            format!(
                "{} centers vs {} in the reference",
                posed.len(),
                reference.len()
            ),
        ));
    }
    let mut lengths = Vec::new();
    for b in blocks {
        if let Element::Pill([i, j]) = *b {
            let (i, j) = (i as usize, j as usize);
            if i.max(j) >= reference.len() {
                return Err(DatasetError::arg(
                    "blocks",
                    format!("sphere {} out of range", i.max(j)),
                ));
            }
            let big = (reference[i] - reference[j]).norm();
            let small = (posed[i] - posed[j]).norm();
            if !(big.is_finite() && small.is_finite()) {
                return Err(DatasetError::arg("posed", "non-finite center"));
            }
            lengths.push((big, small));
        }
    }
    let den: f64 = lengths.iter().map(|(d, _)| d * d).sum();
    if den <= 0.0 {
        return Err(DatasetError::arg(
            "blocks",
            "no pill of non-zero length: the scale is undetermined",
        ));
    }
    let scale = lengths.iter().map(|(d, e)| d * e).sum::<f64>() / den;
    positive("scale", scale)?;
    let spread = (lengths
        .iter()
        .filter(|(d, _)| *d > 0.0)
        .map(|(d, e)| (e / (d * scale) - 1.0).powi(2))
        .sum::<f64>()
        / lengths.len() as f64)
        .sqrt();
    Ok(ScaleEstimate {
        scale,
        relative_spread: spread,
        pills: lengths.len(),
    })
}

/// The extents of a point set along its principal axes, largest first: `max − min` of the
/// projections on the eigenvectors of the covariance. Errors on fewer than 4 points or
/// non-finite coordinates.
pub fn principal_extents(points: &[Vector3<f64>]) -> Result<Vector3<f64>> {
    let axes = principal_axes(points, "points")?;
    Ok(extents_along(&axes, points.iter().map(|p| (*p, 0.0))))
}

/// [`principal_extents`] of a sphere set, i.e. of the union of the balls: axes from the
/// centers, extents `max(c·a + r) − min(c·a − r)`, which is exact for a sphere-mesh since its
/// extreme points along any direction lie on spheres.
pub fn sphere_principal_extents(spheres: &[Sphere]) -> Result<Vector3<f64>> {
    let centers: Vec<Vector3<f64>> = spheres.iter().map(|s| s.center).collect();
    let axes = principal_axes(&centers, "spheres")?;
    Ok(extents_along(
        &axes,
        spheres.iter().map(|s| (s.center, s.radius)),
    ))
}

fn principal_axes(points: &[Vector3<f64>], name: &'static str) -> Result<Matrix3<f64>> {
    if points.len() < 4 {
        return Err(DatasetError::arg(
            name,
            format!("{} points; at least 4 needed", points.len()),
        ));
    }
    if points.iter().any(|p| !p.iter().all(|x| x.is_finite())) {
        return Err(DatasetError::arg(name, "non-finite coordinate"));
    }
    hand_model::math::principal_axes(points)
        .map(|(_, axes)| axes)
        .ok_or_else(|| DatasetError::arg(name, "no principal axes"))
}

fn extents_along(
    axes: &Matrix3<f64>,
    balls: impl Iterator<Item = (Vector3<f64>, f64)>,
) -> Vector3<f64> {
    let mut lo = Vector3::repeat(f64::INFINITY);
    let mut hi = Vector3::repeat(f64::NEG_INFINITY);
    for (c, r) in balls {
        let x = axes.transpose() * c;
        lo = lo.inf(&x.add_scalar(-r));
        hi = hi.sup(&x.add_scalar(r));
    }
    hi - lo
}

/// A first guess of a scan's units per millimetre from the scan alone, for a calibration that
/// refines it: the geometric mean of the ratios of the three principal extents of the scan and
/// of the template (mm), i.e. the cube root of the ratio of their principal-box volumes.
///
/// Flexing the fingers trades length for thickness, so one extent alone follows the pose; their
/// product changes less. Measured on the five scans with an authors' fit, against their scale
/// ([`pill_length_scale`]) with the authors' final model as template: errors −16 % to +18 %
/// (the largest extent alone: −19 % to +21 %, the middle one: −30 % to +38 %); see the crate's
/// `scans` test.
pub fn scale_from_extents(scan: &Vector3<f64>, template_mm: &Vector3<f64>) -> Result<f64> {
    let s = (scan.x / template_mm.x * scan.y / template_mm.y * scan.z / template_mm.z).cbrt();
    positive("scale", s)?;
    Ok(s)
}

// ------------------------------------------------------------------------------------------------
// Distances of a scan to a model.

/// How well a sphere-mesh explains a complete scan, in millimetres.
#[derive(Clone, Debug, PartialEq)]
pub struct ScanResidual {
    /// Number of scan points.
    pub points: usize,
    /// Mean unsigned distance from the scan points to the model surface `|φ_M(p)|` (E_d2m,
    /// thesis Eq. 3.15, on a complete cloud instead of a depth map).
    pub d2m_mean_mm: f64,
    /// Median of the same distances.
    pub d2m_median_mm: f64,
    /// Fraction of scan points within `near_mm` of the model surface.
    pub near_fraction: f64,
    /// Mean over spheres of the gap between the sphere's surface and its nearest scan point,
    /// `min_p |‖p − c‖ − r|` (spheres buried inside the model show a gap by construction).
    pub sphere_gap_mean_mm: f64,
}

/// Distances between a scan (scan units) and a sphere-mesh in the same frame and units;
/// `units_per_mm` converts the results to mm, `near_mm` sets the [`ScanResidual::near_fraction`]
/// threshold.
pub fn scan_residual(
    model: &SphereMeshGeometry,
    scan: &[Vector3<f64>],
    units_per_mm: f64,
    near_mm: f64,
) -> Result<ScanResidual> {
    positive("units_per_mm", units_per_mm)?;
    if !(near_mm.is_finite() && near_mm >= 0.0) {
        return Err(DatasetError::arg(
            "near_mm",
            format!("{near_mm} is not a distance"),
        ));
    }
    if scan.is_empty() {
        return Err(DatasetError::arg("scan", "no points"));
    }
    let mut d = Vec::with_capacity(scan.len());
    for (i, p) in scan.iter().enumerate() {
        let phi = model.phi(p).ok_or_else(|| {
            DatasetError::arg(
                "scan",
                format!("point {i} is not finite or the model has no element"),
            )
        })?;
        d.push(phi.abs() / units_per_mm);
    }
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    let near = d.iter().filter(|&&x| x <= near_mm).count() as f64 / d.len() as f64;
    d.sort_by(f64::total_cmp);
    let median = d[d.len() / 2];
    let spheres = model.spheres();
    let gap = spheres
        .iter()
        .map(|s| {
            scan.iter()
                .map(|p| ((p - s.center).norm() - s.radius).abs())
                .fold(f64::INFINITY, f64::min)
        })
        .sum::<f64>()
        / spheres.len().max(1) as f64
        / units_per_mm;
    Ok(ScanResidual {
        points: scan.len(),
        d2m_mean_mm: mean,
        d2m_median_mm: median,
        near_fraction: near,
        sphere_gap_mean_mm: gap,
    })
}

/// Where one of the authors' per-pose fits lies.
#[derive(Clone, Debug, PartialEq)]
pub struct FitLocation {
    /// Index into [`FittedReference::per_pose_centers`].
    pub fit: usize,
    /// Index of the scan it belongs to (the one it explains best).
    pub scan: usize,
    /// Its scale against the final model ([`pill_length_scale`]).
    pub scale: ScaleEstimate,
    /// Its distances to that scan.
    pub residual: ScanResidual,
    /// Mean scan-to-model distance (mm) to every scan, for the record.
    pub d2m_to_each_scan_mm: Vec<f64>,
}

/// Which scan each per-pose fit belongs to: the file names (`fitting_result_k`) do not say, and
/// there are fewer fits than scans. The per-pose centers are stored in the scans' own frame and
/// units, so no alignment is needed: each fit, with the final radii scaled by its
/// [`pill_length_scale`], is compared with every scan by the mean scan-to-model distance, and
/// the scan it explains best is its own. Two fits claiming one scan is an error.
///
/// Measured on the authors' files: `fitting_result_k` belongs to `pose{k}` for k = 1..5 (mean
/// distance 0.94–1.37 mm to its own scan, at least 20 mm to any other); `pose6` has no fit.
pub fn locate_fits(
    reference: &FittedReference,
    scans: &[Vec<Vector3<f64>>],
    near_mm: f64,
) -> Result<Vec<FitLocation>> {
    let mut out: Vec<FitLocation> = Vec::new();
    for (fit, centers) in reference.per_pose_centers.iter().enumerate() {
        let scale = pill_length_scale(&reference.final_centers, centers, &reference.blocks)?;
        let model = reference.geometry(centers, scale.scale)?;
        let residuals = scans
            .iter()
            .map(|scan| scan_residual(&model, scan, scale.scale, near_mm))
            .collect::<Result<Vec<_>>>()?;
        let d2m: Vec<f64> = residuals.iter().map(|r| r.d2m_mean_mm).collect();
        let Some(best) = (0..d2m.len()).min_by(|&a, &b| d2m[a].total_cmp(&d2m[b])) else {
            return Err(DatasetError::arg("scans", "no scans"));
        };
        if let Some(other) = out.iter().find(|l| l.scan == best) {
            return Err(DatasetError::arg(
                "scans",
                format!("fits {} and {fit} both match scan {best} best", other.fit),
            ));
        }
        out.push(FitLocation {
            fit,
            scan: best,
            scale,
            residual: residuals[best].clone(),
            d2m_to_each_scan_mm: d2m,
        });
    }
    Ok(out)
}
