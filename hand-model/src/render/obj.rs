//! Wavefront OBJ export of a [`TriMesh`] (positions, per-vertex normals, `f a//a b//b c//c`
//! faces), readable by any 3D viewer; the sphere-mesh surface of thesis Fig. 3.4 as a file.

use std::fmt::Write as _;
use std::path::Path;

use super::atomic::write_atomic;
use super::mesh::TriMesh;
use crate::error::Result;

/// The OBJ text of a sphere-mesh surface mesh (Fig. 3.4) (coordinates as given, i.e. millimetres; 1-based indices). Normals
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

/// Write a sphere-mesh surface mesh (Fig. 3.4) as OBJ, atomically (temporary file in the same folder, then rename).
pub fn write_obj(path: &Path, mesh: &TriMesh) -> Result<()> {
    write_atomic(path, encode_obj(mesh).as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::{extract_mesh, MeshOptions};
    use crate::shape::{Element, Sphere};
    use nalgebra::Vector3;

    fn small_mesh() -> TriMesh {
        let spheres = [
            Sphere::new(Vector3::new(0.0, 0.0, 0.0), 8.0),
            Sphere::new(Vector3::new(0.0, 30.0, 2.0), 5.0),
        ];
        extract_mesh(
            &spheres,
            &[Element::Pill([0, 1])],
            &MeshOptions { cell_mm: 2.0 },
        )
        .unwrap()
    }

    #[test]
    fn obj_parses_back() {
        let mesh = small_mesh();
        let dir = std::env::temp_dir().join(format!("hands-obj-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("pill.obj");
        write_obj(&path, &mesh).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let (mut v, mut vn, mut f) = (vec![], vec![], vec![]);
        for line in text.lines() {
            let mut it = line.split_whitespace();
            match it.next() {
                Some("v") => v.push(it.map(|x| x.parse::<f32>().unwrap()).collect::<Vec<_>>()),
                Some("vn") => vn.push(it.map(|x| x.parse::<f32>().unwrap()).collect::<Vec<_>>()),
                Some("f") => f.push(
                    it.map(|x| {
                        let (a, b) = x.split_once("//").unwrap();
                        assert_eq!(a, b);
                        a.parse::<u32>().unwrap() - 1
                    })
                    .collect::<Vec<_>>(),
                ),
                Some("#") | None => {}
                Some(other) => panic!("unexpected record {other}"),
            }
        }
        assert_eq!(v.len(), mesh.positions.len());
        assert_eq!(vn.len(), mesh.normals.len());
        assert_eq!(f.len(), mesh.triangles.len());
        for (a, b) in v.iter().zip(&mesh.positions) {
            assert_eq!(a.as_slice(), b.as_slice());
        }
        for (a, b) in f.iter().zip(&mesh.triangles) {
            assert_eq!(a.as_slice(), b.as_slice());
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
