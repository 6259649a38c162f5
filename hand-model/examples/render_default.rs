//! Render the default right hand: palm and back previews (PNG), the surface mesh (OBJ, GLB) and
//! the timing of a 320×240 depth render (thesis §3.3.2).
//!
//! `cargo run -p hand-model --release --example render_default -- [OUT_DIR]` (default `/tmp`).

use std::path::PathBuf;
use std::time::Instant;

use hand_model::kinematics::Pose;
use hand_model::render::glb::write_glb;
use hand_model::render::obj::write_obj;
use hand_model::render::preview::{
    frame_model, render_preview, write_png, PreviewOptions, ViewSide,
};
use hand_model::render::{extract_mesh, DepthRender, DepthRenderer, MeshOptions};
use hand_model::shape::Element;
use hand_model::spheremesh::{default_right_hand, PosedSphereMesh};

fn main() -> hand_model::Result<()> {
    let out = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "/tmp".into()));
    let template = default_right_hand();
    let pose = Pose::zeros(&template.skeleton);

    for (side, name) in [
        (ViewSide::Palm, "preview.png"),
        (ViewSide::Back, "preview_back.png"),
    ] {
        let p = render_preview(
            &template,
            &pose,
            &PreviewOptions {
                side,
                ..Default::default()
            },
        )?;
        write_png(&out.join(name), &p.image)?;
        let frac = p.render.hit_count() as f64 / (p.render.width * p.render.height) as f64;
        println!("{name}: {:.1} % hand pixels", 100.0 * frac);
    }

    let posed = PosedSphereMesh::new(&template, &pose);
    let elements: Vec<Element> = template.elements.iter().map(|e| e.element).collect();
    let t0 = Instant::now();
    let mesh = extract_mesh(&posed.spheres, &elements, &MeshOptions::default())?;
    println!(
        "mesh: {} vertices, {} triangles in {:.0} ms",
        mesh.positions.len(),
        mesh.triangles.len(),
        t0.elapsed().as_secs_f64() * 1e3
    );
    write_obj(&out.join("hand.obj"), &mesh)?;
    write_glb(&out.join("hand.glb"), &mesh)?;

    // 320×240 depth render, the thesis' resolution.
    let framing = frame_model(&posed.spheres, 320, 240, ViewSide::Palm)?;
    let spheres = framing.spheres_in_camera(&posed.spheres);
    let mut renderer = DepthRenderer::new();
    let mut render = DepthRender::default();
    let mut times = vec![];
    for _ in 0..31 {
        let t = Instant::now();
        renderer.render(&framing.intrinsics, &spheres, &elements, &mut render)?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    println!(
        "320×240 depth render: median {:.2} ms (min {:.2}, max {:.2}), {} hand pixels",
        times[times.len() / 2],
        times[0],
        times[times.len() - 1],
        render.hit_count()
    );
    Ok(())
}
