//! Triangle meshes and their depth images: a renderer independent of the sphere-mesh one, for
//! data that no model of this project generated — the real hand scans
//! (`hand-scans-tkach/scans/*.obj`) seen by a depth camera.
//!
//! The renderer is a z-buffer rasterizer: every pixel center inside a projected triangle gets
//! the depth of the triangle's plane along that pixel's ray (perspective-correct `1/z`
//! interpolation of the vertices, exact for a planar triangle) when it is nearer than what the
//! pixel holds. The sphere-mesh renderer of `hand_model::render` ray-casts analytic surfaces;
//! this one shares no code with it, so a tracker tested on its images meets another hand
//! rendered by another implementation. Hand-written rather than taken from a crate: the
//! workspace's graphics dependency is wgpu, which is optional and needs a GPU or Mesa, and a
//! CPU z-buffer of a few thousand triangles is a page.

use std::path::Path;

use nalgebra::Vector3;
use sensor_io::Camera;

use crate::error::Result;
use crate::scans::parse_obj_points;
use crate::text::{parse_error, read_text};

/// Triangles closer to the camera than this (mm) are dropped rather than clipped: the scenes
/// rendered here are hundreds of millimetres away.
pub const NEAR_MM: f64 = 10.0;

/// A triangle mesh: vertex positions and triangles as vertex indices.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriangleMesh {
    /// Vertex positions.
    pub vertices: Vec<Vector3<f64>>,
    /// Vertex indices, three per triangle.
    pub triangles: Vec<[u32; 3]>,
}

impl TriangleMesh {
    /// The mesh with every vertex mapped by `f` (the triangles kept).
    pub fn map(&self, f: impl Fn(&Vector3<f64>) -> Vector3<f64>) -> Self {
        Self {
            vertices: self.vertices.iter().map(f).collect(),
            triangles: self.triangles.clone(),
        }
    }
}

/// Read the vertices and faces of an OBJ file ([`parse_obj_mesh`]).
pub fn read_obj_mesh(path: impl AsRef<Path>) -> Result<TriangleMesh> {
    let path = path.as_ref();
    parse_obj_mesh(&read_text(path)?, path)
}

/// The mesh of OBJ text: `v` lines as [`parse_obj_points`] reads them, and `f` lines of three or
/// more vertex references (`i`, `i/t`, `i//n` or `i/t/n`; 1-based, negative counts back from the
/// last vertex defined so far), polygons split into fans. A face referring to a missing vertex,
/// a face of fewer than three vertices, or a file without faces is an error naming `source` and
/// the line.
pub fn parse_obj_mesh(text: &str, source: &Path) -> Result<TriangleMesh> {
    let vertices = parse_obj_points(text, source)?;
    let mut triangles = Vec::new();
    let mut defined = 0usize;
    for (i, line) in text.lines().enumerate() {
        let content = line.split('#').next().unwrap_or("");
        let mut fields = content.split_whitespace();
        match fields.next() {
            Some("v") => defined += 1,
            Some("f") => {
                let err = |reason: String| parse_error(source, Some(i + 1), reason);
                let face = fields
                    .map(|token| face_index(token, defined, vertices.len()).map_err(&err))
                    .collect::<Result<Vec<u32>>>()?;
                if face.len() < 3 {
                    return Err(err(format!(
                        "a face needs at least 3 vertices, got {}",
                        face.len()
                    )));
                }
                triangles.extend(face[1..].windows(2).map(|w| [face[0], w[0], w[1]]));
            }
            _ => {}
        }
    }
    if triangles.is_empty() {
        return Err(parse_error(source, None, "no faces (`f` lines)"));
    }
    Ok(TriangleMesh {
        vertices,
        triangles,
    })
}

/// The 0-based vertex of one `f` token; `defined` vertices precede the line, `total` in all.
fn face_index(token: &str, defined: usize, total: usize) -> std::result::Result<u32, String> {
    let first = token.split('/').next().unwrap_or("");
    let k: i64 = first
        .parse()
        .map_err(|_| format!("`{token}` is not a vertex reference"))?;
    let index = match k {
        1.. => k - 1,
        ..=-1 => defined as i64 + k,
        0 => -1,
    };
    if index < 0 || index >= total as i64 {
        return Err(format!(
            "vertex `{token}` does not exist ({defined} defined so far, {total} in all)"
        ));
    }
    Ok(index as u32)
}

/// A rendered depth image: per pixel (row-major) the depth along the optical axis (mm, 0 where
/// no triangle is seen) and the unit normal of the seen triangle facing the camera (zero where
/// none), the inputs of [`crate::noise::apply_sensor_model`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshDepth {
    /// Depth (mm), 0 = no surface.
    pub depth: Vec<f32>,
    /// Normals facing the camera, zero where no surface.
    pub normals: Vec<Vector3<f32>>,
}

/// Render `mesh` (camera frame, mm) as `camera` sees it (module docs). The normal of a seen
/// triangle is turned toward the camera, so the winding of the mesh does not matter: for a
/// closed surface the visible side is the outer one. Triangles with a vertex nearer than
/// [`NEAR_MM`] or with a non-finite vertex are skipped.
pub fn render_mesh_depth(mesh: &TriangleMesh, camera: &Camera) -> MeshDepth {
    let n = camera.width as usize * camera.height as usize;
    let mut out = MeshDepth {
        depth: vec![0.0; n],
        normals: vec![Vector3::zeros(); n],
    };
    for tri in &mesh.triangles {
        let vertex = |k: usize| mesh.vertices.get(tri[k] as usize).copied();
        if let (Some(a), Some(b), Some(c)) = (vertex(0), vertex(1), vertex(2)) {
            draw_triangle([a, b, c], camera, &mut out);
        }
    }
    out
}

/// Z-buffer one triangle into `out` (the depth itself is the buffer: 0 is empty).
fn draw_triangle(p: [Vector3<f64>; 3], camera: &Camera, out: &mut MeshDepth) {
    if p.iter()
        .any(|v| v.iter().any(|x| !x.is_finite()) || v.z < NEAR_MM)
    {
        return;
    }
    let mut n = (p[1] - p[0]).cross(&(p[2] - p[0]));
    let norm = n.norm();
    if norm == 0.0 {
        return;
    }
    if n.dot(&p[0]) > 0.0 {
        n = -n;
    }
    let normal = (n / norm).cast::<f32>();
    let uv = p.map(|v| camera.project(&v));
    let inv_z = p.map(|v| 1.0 / v.z);
    let area = edge(&uv[0], &uv[1], &uv[2]);
    if area.abs() < 1e-12 {
        return;
    }
    // The pixel centers inside the triangle's bounding box, clamped to the image.
    let range = |c: usize, size: u32| {
        let (lo, hi) = uv
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), q| {
                (lo.min(q[c]), hi.max(q[c]))
            });
        (lo.ceil().max(0.0), hi.floor().min(f64::from(size) - 1.0))
    };
    let ((u0, u1), (v0, v1)) = (range(0, camera.width), range(1, camera.height));
    if u0 > u1 || v0 > v1 {
        return;
    }
    let w = camera.width as usize;
    for y in v0 as usize..=v1 as usize {
        for x in u0 as usize..=u1 as usize {
            let q = nalgebra::Vector2::new(x as f64, y as f64);
            let l = [
                edge(&uv[1], &uv[2], &q) / area,
                edge(&uv[2], &uv[0], &q) / area,
                edge(&uv[0], &uv[1], &q) / area,
            ];
            if l.iter().any(|&x| x < 0.0) {
                continue;
            }
            let z = (1.0 / (l[0] * inv_z[0] + l[1] * inv_z[1] + l[2] * inv_z[2])) as f32;
            let i = y * w + x;
            if out.depth[i] == 0.0 || z < out.depth[i] {
                out.depth[i] = z;
                out.normals[i] = normal;
            }
        }
    }
}

/// Twice the signed area of the triangle `a b c` in the image plane.
#[inline]
fn edge(a: &nalgebra::Vector2<f64>, b: &nalgebra::Vector2<f64>, c: &nalgebra::Vector2<f64>) -> f64 {
    (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::DatasetError;

    fn camera() -> Camera {
        Camera::sr300_qvga()
    }

    /// A square of side `s` centered at `c`, spanned by `a` and `b`, as two triangles.
    fn square(c: Vector3<f64>, a: Vector3<f64>, b: Vector3<f64>, s: f64) -> TriangleMesh {
        let h = s / 2.0;
        TriangleMesh {
            vertices: vec![
                c - h * a - h * b,
                c + h * a - h * b,
                c + h * a + h * b,
                c - h * a + h * b,
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        }
    }

    #[test]
    fn a_tilted_plane_has_the_analytic_depth_of_every_ray() {
        let cam = camera();
        let a = Vector3::new(1.0, 0.0, 0.6).normalize();
        let b = Vector3::new(0.0, 1.0, -0.3);
        let b = (b - a * a.dot(&b)).normalize();
        let c = Vector3::new(10.0, -5.0, 400.0);
        let mesh = square(c, a, b, 120.0);
        let out = render_mesh_depth(&mesh, &cam);
        let n = a.cross(&b).normalize();
        let mut seen = 0;
        for v in 0..cam.height {
            for u in 0..cam.width {
                let i = (v * cam.width + u) as usize;
                let ray = cam.backproject(u as f64, v as f64, 1.0);
                let z = n.dot(&c) / n.dot(&ray);
                // Inside the square, by its own coordinates (away from the border by rounding).
                let (x, y) = ((ray * z - c).dot(&a), (ray * z - c).dot(&b));
                let inside = x.abs() < 60.0 - 1e-6 && y.abs() < 60.0 - 1e-6;
                let outside = x.abs() > 60.0 + 1e-6 || y.abs() > 60.0 + 1e-6;
                if inside {
                    seen += 1;
                    assert!(
                        (out.depth[i] as f64 - z).abs() < 1e-3 * z,
                        "{u} {v}: {} vs {z}",
                        out.depth[i]
                    );
                    let nf = out.normals[i].cast::<f64>();
                    assert!((nf.dot(&n).abs() - 1.0).abs() < 1e-6 && nf.dot(&(ray * z)) < 0.0);
                } else if outside {
                    assert_eq!(out.depth[i], 0.0, "{u} {v}");
                }
            }
        }
        assert!(seen > 1000, "{seen} pixels");
    }

    #[test]
    fn the_nearer_surface_hides_the_farther_one_in_either_order() {
        let cam = camera();
        let (a, b) = (Vector3::x(), Vector3::y());
        let near = square(Vector3::new(0.0, 0.0, 300.0), a, b, 40.0);
        let far = square(Vector3::new(0.0, 0.0, 350.0), a, b, 200.0);
        let mut both = far.clone();
        both.triangles
            .extend(near.triangles.iter().map(|t| t.map(|i| i + 4)));
        both.vertices.extend(&near.vertices);
        let mut reversed = both.clone();
        reversed.triangles.reverse();
        let pixel = |p: Vector3<f64>| {
            let q = cam.project(&p);
            (q.y.round() as u32 * cam.width + q.x.round() as u32) as usize
        };
        let (center, beside) = (
            pixel(Vector3::new(0.0, 0.0, 300.0)),
            pixel(Vector3::new(40.0, 0.0, 350.0)),
        );
        for mesh in [both, reversed] {
            let out = render_mesh_depth(&mesh, &cam);
            assert!((out.depth[center] - 300.0).abs() < 1e-3);
            assert!((out.depth[beside] - 350.0).abs() < 1e-3);
        }
    }

    #[test]
    fn triangles_behind_the_near_plane_or_degenerate_are_skipped() {
        let cam = camera();
        let mut mesh = square(Vector3::new(0.0, 0.0, 5.0), Vector3::x(), Vector3::y(), 4.0);
        mesh.vertices.push(Vector3::new(0.0, 0.0, 300.0));
        mesh.vertices.push(Vector3::new(1.0, 1.0, 300.0));
        mesh.vertices.push(Vector3::new(f64::NAN, 1.0, 300.0));
        mesh.triangles.push([4, 5, 4]);
        mesh.triangles.push([4, 5, 6]);
        mesh.triangles.push([4, 5, 99]);
        let out = render_mesh_depth(&mesh, &cam);
        assert!(out.depth.iter().all(|&d| d == 0.0));
    }

    /// The default hand, meshed by `hand_model::render::extract_mesh` and drawn by this
    /// rasterizer, against the same hand ray-cast analytically by `hand_model::render`: two
    /// independent paths from one sphere-mesh to a depth image.
    #[test]
    fn a_meshed_sphere_mesh_has_the_ray_cast_depth() {
        use hand_model::kinematics::Pose;
        use hand_model::render::{extract_mesh, render_depth, Intrinsics, MeshOptions};
        use hand_model::spheremesh::{default_right_hand, PosedSphereMesh};
        let cam = camera();
        let t = default_right_hand();
        let mut pose = Pose::zeros(&t.skeleton);
        pose.set(&t.skeleton, "global_tz", 400.0).unwrap();
        pose.set(&t.skeleton, "index_pip_flex", 0.8).unwrap();
        let posed = PosedSphereMesh::new(&t, &pose);
        let elements: Vec<_> = t.elements.iter().map(|e| e.element).collect();
        let intrinsics = Intrinsics {
            fx: cam.fx,
            fy: cam.fy,
            cx: cam.cx,
            cy: cam.cy,
            width: cam.width,
            height: cam.height,
        };
        let cast = render_depth(&intrinsics, &posed.spheres, &elements).unwrap();
        let tri = extract_mesh(&posed.spheres, &elements, &MeshOptions { cell_mm: 0.5 }).unwrap();
        let mesh = TriangleMesh {
            vertices: tri
                .positions
                .iter()
                .map(|p| Vector3::from(*p).cast())
                .collect(),
            triangles: tri.triangles,
        };
        let drawn = render_mesh_depth(&mesh, &cam);
        let (mut both, mut either, mut diffs) = (0usize, 0usize, Vec::new());
        for (&a, &b) in cast.depth.iter().zip(&drawn.depth) {
            either += usize::from(a > 0.0 || b > 0.0);
            if a > 0.0 && b > 0.0 {
                both += 1;
                diffs.push((a - b).abs());
            }
        }
        diffs.sort_by(f32::total_cmp);
        let (median, p95) = (diffs[diffs.len() / 2], diffs[diffs.len() * 95 / 100]);
        let iou = both as f64 / either as f64;
        println!("{both} pixels, IoU {iou:.4}, |Δz| median {median:.3} p95 {p95:.3} mm");
        assert!(both > 3000, "{both} pixels");
        assert!(
            iou > 0.995 && median < 0.02 && p95 < 0.05,
            "IoU {iou}, |Δz| median {median} p95 {p95}"
        );
    }

    #[test]
    fn obj_faces_with_every_reference_form() {
        let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1 4/1\nf -4//1 -3//1 -2//1\n# c\nf 1 3 4\n";
        let mesh = parse_obj_mesh(text, Path::new("<memory>")).unwrap();
        assert_eq!(mesh.vertices.len(), 4);
        assert_eq!(
            mesh.triangles,
            vec![[0, 1, 2], [0, 2, 3], [0, 1, 2], [0, 2, 3]]
        );
    }

    #[test]
    fn bad_obj_faces_name_the_line() {
        for (text, line) in [
            ("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 4\n", Some(4)),
            ("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2\n", Some(4)),
            ("v 0 0 0\nv 1 0 0\nf -3 1 2\nv 1 1 0\n", Some(3)),
            ("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 0 1 2\n", Some(4)),
            ("v 0 0 0\nv 1 0 0\nv 1 1 0\nf a b c\n", Some(4)),
            ("v 0 0 0\nv 1 0 0\nv 1 1 0\n", None),
        ] {
            match parse_obj_mesh(text, Path::new("<memory>")) {
                Err(DatasetError::Parse { line: l, .. }) => assert_eq!(l, line, "{text}"),
                other => panic!("{text}: {other:?}"),
            }
        }
    }

    /// Every truncation of a valid file, and every byte of it replaced by a troublemaker (a
    /// sign, a huge or non-numeric token, a separator, a line break, a multi-byte character):
    /// an error, or a mesh whose triangles name existing vertices and whose rendering holds
    /// finite depths only. Never a panic.
    #[test]
    fn corrupt_obj_text_is_an_error_or_a_valid_mesh() {
        let good = "v -20 -20 300\nv 20 -20 300\nv -20 20 320\nv 20 20 1e2\nvt 0 1\n\
                    f 1/1 2/1 3/1\nf -3//1 4 -2 # quad corner\n";
        let camera = camera();
        let check = |text: &str| match parse_obj_mesh(text, Path::new("<memory>")) {
            Ok(mesh) => {
                let n = mesh.vertices.len() as u32;
                assert!(mesh.triangles.iter().flatten().all(|&i| i < n), "{text:?}");
                let image = render_mesh_depth(&mesh, &camera);
                assert!(image.depth.iter().all(|d| d.is_finite()), "{text:?}");
            }
            Err(e) => assert!(!e.to_string().is_empty()),
        };
        let mesh = parse_obj_mesh(good, Path::new("<memory>")).unwrap();
        assert_eq!((mesh.vertices.len(), mesh.triangles.len()), (4, 2));
        let seen = render_mesh_depth(&mesh, &camera).depth;
        assert!(seen.iter().filter(|&&d| d > 0.0).count() > 100);
        for n in 0..=good.len() {
            check(&good[..n]);
        }
        for i in 0..good.len() {
            for token in [
                "",
                "-",
                "+",
                "nan",
                "inf",
                "1e999",
                "99999999999",
                "/",
                " ",
                "\n",
                "é",
            ] {
                check(&format!("{}{token}{}", &good[..i], &good[i + 1..]));
            }
        }
    }
}
