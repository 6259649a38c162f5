//! Wavefront OBJ export of a [`TriMesh`] (positions, per-vertex normals, `f a//a b//b c//c`
//! faces), readable by any 3D viewer; the sphere-mesh surface of thesis Fig. 3.4 as a file.

use std::fmt::Write as _;
use std::path::Path;

use super::atomic::write_atomic;
use super::mesh::TriMesh;
use crate::error::Result;

/// The OBJ text of a mesh (coordinates as given, i.e. millimetres; 1-based indices). Normals
/// are written when there is one per vertex.
pub fn encode_obj(mesh: &TriMesh) -> String {
    let mut s = String::with_capacity(64 * mesh.positions.len() + 32 * mesh.triangles.len() + 128);
    let _ = writeln!(s, "# hands sphere-mesh surface (mm)");
    let _ = writeln!(
        s,
        "# {} vertices, {} triangles",
        mesh.positions.len(),
        mesh.triangles.len()
    );
    for p in &mesh.positions {
        let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
    }
    let with_normals = mesh.normals.len() == mesh.positions.len();
    if with_normals {
        for n in &mesh.normals {
            let _ = writeln!(s, "vn {} {} {}", n[0], n[1], n[2]);
        }
    }
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| i + 1);
        if with_normals {
            let _ = writeln!(s, "f {a}//{a} {b}//{b} {c}//{c}");
        } else {
            let _ = writeln!(s, "f {a} {b} {c}");
        }
    }
    s
}

/// Write a mesh as OBJ, atomically (temporary file in the same folder, then rename).
pub fn write_obj(path: &Path, mesh: &TriMesh) -> Result<()> {
    write_atomic(path, encode_obj(mesh).as_bytes())
}
