//! Binary glTF 2.0 (`.glb`) export of a [`TriMesh`], written by hand: the sphere-mesh surface of
//! thesis Fig. 3.4 for web and desktop viewers.
//!
//! Layout: a 12-byte header (`glTF`, version 2, total length), a JSON chunk padded with spaces
//! and a BIN chunk padded with zeros, both to 4 bytes. The BIN chunk holds, in this order and
//! each 4-byte aligned, the positions (`f32` VEC3, accessor with `min`/`max` as glTF requires),
//! the normals (`f32` VEC3, when there is one per vertex) and the indices (`u32` SCALAR), one
//! buffer view each; one mesh with one triangle primitive, one node, one scene.
//!
//! glTF units are metres, so millimetre positions are divided by 1000; axes are kept (the model
//! frame's +y toward the fingertips is glTF's up).

use std::path::Path;

use serde_json::json;

use super::atomic::write_atomic;
use super::mesh::TriMesh;
use crate::error::{ModelError, Result};

/// Magic number `glTF` of the `.glb` header (export of the Fig. 3.4 surface).
pub const GLB_MAGIC: u32 = 0x4654_6C67;
/// Chunk type `JSON` (export of the Fig. 3.4 surface).
pub const CHUNK_JSON: u32 = 0x4E4F_534A;
/// Chunk type `BIN\0` (export of the Fig. 3.4 surface).
pub const CHUNK_BIN: u32 = 0x004E_4942;

const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const TRIANGLES: u32 = 4;

fn push_f32s(bin: &mut Vec<u8>, values: impl Iterator<Item = f32>) {
    for v in values {
        bin.extend_from_slice(&v.to_le_bytes());
    }
}

/// The `.glb` bytes of a sphere-mesh surface mesh (Fig. 3.4) (positions converted from mm to m).
///
/// Errors: a triangle index out of range, a non-finite position, or more than 2 GiB of data. An empty mesh gives a valid
/// file with an empty scene and no buffer.
pub fn encode_glb(mesh: &TriMesh) -> Result<Vec<u8>> {
    let bad = |reason: String| ModelError::InvalidArgument {
        name: "mesh",
        reason,
    };
    let nv = mesh.positions.len();
    if let Some(t) = mesh
        .triangles
        .iter()
        .find(|t| t.iter().any(|&i| i as usize >= nv))
    {
        return Err(bad(format!("triangle {t:?} refers past the {nv} vertices")));
    }
    if mesh.positions.iter().flatten().any(|x| !x.is_finite()) {
        return Err(bad("non-finite vertex position".into()));
    }
    let asset = json!({ "version": "2.0", "generator": "hands hand-model render::glb" });
    if mesh.triangles.is_empty() {
        let doc = json!({ "asset": asset, "scene": 0, "scenes": [{ "nodes": [] }] });
        return Ok(assemble(&doc.to_string(), &[]));
    }
    let positions: Vec<[f32; 3]> = mesh.positions.iter().map(|p| p.map(|x| x * 1e-3)).collect();
    let mut lo = positions[0];
    let mut hi = positions[0];
    for p in &positions {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let with_normals = mesh.normals.len() == nv;
    let mut bin = Vec::with_capacity(nv * 24 + mesh.triangles.len() * 12);
    push_f32s(&mut bin, positions.iter().flatten().copied());
    let pos_len = bin.len();
    if with_normals {
        push_f32s(&mut bin, mesh.normals.iter().flatten().copied());
    }
    let nrm_len = bin.len() - pos_len;
    for i in mesh.triangles.iter().flatten() {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let idx_len = bin.len() - pos_len - nrm_len;

    let mut views = vec![
        json!({ "buffer": 0, "byteOffset": 0, "byteLength": pos_len, "target": ARRAY_BUFFER }),
    ];
    let mut accessors = vec![json!({
        "bufferView": 0, "componentType": FLOAT, "count": nv, "type": "VEC3",
        "min": lo, "max": hi,
    })];
    let mut attributes = json!({ "POSITION": 0 });
    if with_normals {
        views.push(json!({ "buffer": 0, "byteOffset": pos_len, "byteLength": nrm_len, "target": ARRAY_BUFFER }));
        accessors
            .push(json!({ "bufferView": 1, "componentType": FLOAT, "count": nv, "type": "VEC3" }));
        attributes["NORMAL"] = json!(1);
    }
    views.push(json!({
        "buffer": 0, "byteOffset": pos_len + nrm_len, "byteLength": idx_len, "target": ELEMENT_ARRAY_BUFFER,
    }));
    accessors.push(json!({
        "bufferView": views.len() - 1, "componentType": UNSIGNED_INT,
        "count": mesh.triangles.len() * 3, "type": "SCALAR",
    }));
    let doc = json!({
        "asset": asset,
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0, "name": "sphere-mesh" }],
        "meshes": [{
            "name": "sphere-mesh",
            "primitives": [{ "attributes": attributes, "indices": accessors.len() - 1, "mode": TRIANGLES }],
        }],
        "buffers": [{ "byteLength": bin.len() }],
        "bufferViews": views,
        "accessors": accessors,
    });
    if bin.len() > (u32::MAX as usize) / 2 {
        return Err(bad(format!(
            "{} bytes of buffer data do not fit a .glb",
            bin.len()
        )));
    }
    Ok(assemble(&doc.to_string(), &bin))
}

/// Header + JSON chunk (space-padded) + BIN chunk (zero-padded, omitted when empty).
fn assemble(json: &str, bin: &[u8]) -> Vec<u8> {
    let mut json = json.as_bytes().to_vec();
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let mut bin = bin.to_vec();
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + if bin.is_empty() { 0 } else { 8 + bin.len() };
    let mut out = Vec::with_capacity(total);
    for word in [GLB_MAGIC, 2, total as u32, json.len() as u32, CHUNK_JSON] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    out.extend_from_slice(&json);
    if !bin.is_empty() {
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
        out.extend_from_slice(&bin);
    }
    out
}

/// Write a sphere-mesh surface mesh (Fig. 3.4) as `.glb`, atomically (temporary file in the same folder, then rename).
pub fn write_glb(path: &Path, mesh: &TriMesh) -> Result<()> {
    write_atomic(path, &encode_glb(mesh)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::{extract_mesh, MeshOptions};
    use crate::shape::{Element, Sphere};
    use nalgebra::Vector3;
    use serde_json::Value;

    fn u32_at(b: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
    }

    /// A tiny GLB reader: checks the header and chunk layout, returns the JSON and the BIN chunk.
    fn read_glb(bytes: &[u8]) -> (Value, Vec<u8>) {
        assert_eq!(u32_at(bytes, 0), GLB_MAGIC);
        assert_eq!(u32_at(bytes, 4), 2);
        assert_eq!(u32_at(bytes, 8) as usize, bytes.len());
        let json_len = u32_at(bytes, 12) as usize;
        assert_eq!(json_len % 4, 0);
        assert_eq!(u32_at(bytes, 16), CHUNK_JSON);
        let json: Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
        let rest = 20 + json_len;
        if rest == bytes.len() {
            return (json, vec![]);
        }
        let bin_len = u32_at(bytes, rest) as usize;
        assert_eq!(bin_len % 4, 0);
        assert_eq!(u32_at(bytes, rest + 4), CHUNK_BIN);
        assert_eq!(rest + 8 + bin_len, bytes.len());
        (json, bytes[rest + 8..].to_vec())
    }

    fn view_bytes<'a>(json: &Value, bin: &'a [u8], accessor: usize) -> &'a [u8] {
        let acc = &json["accessors"][accessor];
        let view = &json["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
        let off = view["byteOffset"].as_u64().unwrap() as usize;
        let len = view["byteLength"].as_u64().unwrap() as usize;
        assert_eq!(off % 4, 0);
        assert!(off + len <= bin.len());
        &bin[off..off + len]
    }

    fn floats(b: &[u8]) -> Vec<f32> {
        b.chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect()
    }

    #[test]
    fn glb_parses_back() {
        let spheres = [
            Sphere::new(Vector3::new(0.0, 0.0, 0.0), 8.0),
            Sphere::new(Vector3::new(0.0, 30.0, 2.0), 5.0),
        ];
        let mesh = extract_mesh(
            &spheres,
            &[Element::Pill([0, 1])],
            &MeshOptions { cell_mm: 2.0 },
        )
        .unwrap();
        let dir = std::env::temp_dir().join(format!("hands-glb-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("pill.glb");
        write_glb(&path, &mesh).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let (json, bin) = read_glb(&bytes);
        assert_eq!(json["asset"]["version"], "2.0");
        assert_eq!(
            json["buffers"][0]["byteLength"].as_u64().unwrap() as usize,
            bin.len()
        );
        let prim = &json["meshes"][0]["primitives"][0];
        assert_eq!(prim["mode"], 4);
        let (pa, na, ia) = (
            prim["attributes"]["POSITION"].as_u64().unwrap() as usize,
            prim["attributes"]["NORMAL"].as_u64().unwrap() as usize,
            prim["indices"].as_u64().unwrap() as usize,
        );
        let nv = mesh.positions.len();
        assert_eq!(
            json["accessors"][pa]["count"].as_u64().unwrap() as usize,
            nv
        );
        assert_eq!(
            json["accessors"][na]["count"].as_u64().unwrap() as usize,
            nv
        );
        assert_eq!(
            json["accessors"][ia]["count"].as_u64().unwrap() as usize,
            3 * mesh.triangles.len()
        );
        let pos = floats(view_bytes(&json, &bin, pa));
        let nrm = floats(view_bytes(&json, &bin, na));
        let idx: Vec<u32> = view_bytes(&json, &bin, ia)
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        assert_eq!(pos.len(), 3 * nv);
        for (k, p) in mesh.positions.iter().enumerate() {
            for j in 0..3 {
                assert_eq!(pos[3 * k + j], p[j] * 1e-3);
                assert_eq!(nrm[3 * k + j], mesh.normals[k][j]);
            }
        }
        assert_eq!(
            idx,
            mesh.triangles.iter().flatten().copied().collect::<Vec<_>>()
        );
        // Position accessor min/max are the exact bounds of the data.
        for j in 0..3 {
            let col = pos.iter().skip(j).step_by(3);
            let lo = col.clone().copied().fold(f32::INFINITY, f32::min);
            let hi = col.copied().fold(f32::NEG_INFINITY, f32::max);
            assert_eq!(json["accessors"][pa]["min"][j].as_f64().unwrap() as f32, lo);
            assert_eq!(json["accessors"][pa]["max"][j].as_f64().unwrap() as f32, hi);
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn empty_and_invalid_meshes() {
        let (json, bin) = read_glb(&encode_glb(&TriMesh::default()).unwrap());
        assert!(bin.is_empty());
        assert_eq!(json["scenes"][0]["nodes"].as_array().unwrap().len(), 0);
        let bad = TriMesh {
            positions: vec![[0.0; 3]],
            normals: vec![],
            triangles: vec![[0, 0, 1]],
        };
        assert!(encode_glb(&bad).is_err());
        let nan = TriMesh {
            positions: vec![[f32::NAN, 0.0, 0.0]; 3],
            normals: vec![],
            triangles: vec![[0, 1, 2]],
        };
        assert!(encode_glb(&nan).is_err());
        // Without normals: positions and indices only, still valid.
        let tri = TriMesh {
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            normals: vec![],
            triangles: vec![[0, 1, 2]],
        };
        let (json, _) = read_glb(&encode_glb(&tri).unwrap());
        assert!(json["meshes"][0]["primitives"][0]["attributes"]
            .get("NORMAL")
            .is_none());
    }
}
