//! `hands model …`: show and export templates.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Subcommand;
use hand_model::cylinder::{default_right_hand_cylinders, load_htrack_calib, CylinderModel};
use hand_model::keypoints::KEYPOINT_NAMES;
use hand_model::kinematics::{DofKind, Pose, Skeleton};
use hand_model::render::glb::write_glb;
use hand_model::render::obj::write_obj;
use hand_model::render::preview::{write_preview_png, PreviewOptions, ViewSide};
use hand_model::render::{extract_mesh, MeshOptions};
use hand_model::shape::Element;
use hand_model::spheremesh::{
    default_right_hand, import_hmodel_dir, PosedSphereMesh, ShapeBasis, SphereMeshTemplate,
};

/// Template subcommands.
#[derive(Subcommand)]
pub enum ModelCommand {
    /// Print a summary of a template: bones, DOFs with limits, spheres, elements, β.
    ///
    /// Examples: `hands model show default`, `hands model show me.json`,
    /// `hands model show path/to/hmodel-model-dir` (C/R/B/I.txt), `hands model show default.calib`.
    #[command(after_help = "Example: hands model show default")]
    Show {
        /// `default`, `default-left`, `default-cylinders`, a template `.json`, an htrack
        /// `.calib`, or a folder with the original hmodel/honline `C.txt R.txt B.txt I.txt`.
        template: String,
    },
    /// Export a posed sphere-mesh template as a triangle mesh (`.obj` or `.glb`) and/or a PNG
    /// preview rendered by the CPU ray caster.
    ///
    /// Example: `hands model export default --pose fist.json --out hand.glb --png hand.png`
    #[command(
        after_help = "Example: hands model export default --pose fist.json --out hand.glb --png hand.png"
    )]
    Export {
        /// A sphere-mesh template (see `hands model show --help`).
        template: String,
        /// Pose as JSON: `{"index_mcp_flex": 0.8, ...}` or a track/ground-truth line with a
        /// `pose` object; DOFs not named stay 0 (the rest pose).
        #[arg(long)]
        pose: Option<PathBuf>,
        /// Mesh output: `.obj` (Wavefront, with normals) or `.glb` (binary glTF, metres).
        #[arg(long)]
        out: Option<PathBuf>,
        /// PNG preview output.
        #[arg(long)]
        png: Option<PathBuf>,
        /// Which side the preview looks at.
        #[arg(long, value_enum, default_value = "palm")]
        side: Side,
        /// Mesh resolution (mm).
        #[arg(long, default_value_t = 1.5)]
        cell_mm: f64,
    },
}

/// Preview side.
#[derive(Copy, Clone, clap::ValueEnum)]
pub enum Side {
    /// Looking at the palm.
    Palm,
    /// Looking at the back of the hand.
    Back,
}

/// Run a model subcommand.
pub fn run(cmd: ModelCommand) -> Result<()> {
    match cmd {
        ModelCommand::Show { template } => {
            match load_any(&template)? {
                AnyModel::SphereMesh(t) => print!("{}", summary(&t)),
                AnyModel::Cylinders(c) => print!("{}", cylinder_summary(&c)),
            }
            Ok(())
        }
        ModelCommand::Export {
            template,
            pose,
            out,
            png,
            side,
            cell_mm,
        } => export(
            &template,
            pose.as_deref(),
            out.as_deref(),
            png.as_deref(),
            side,
            cell_mm,
        ),
    }
}

/// Read a pose file: a `{dof: value}` object or any object with a `pose` member.
pub fn read_pose(path: &Path, skeleton: &Skeleton) -> Result<Pose> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let v: serde_json::Value = serde_json::from_str(text.lines().next().unwrap_or(""))
        .or_else(|_| serde_json::from_str(&text))
        .with_context(|| format!("{}: not JSON", path.display()))?;
    let obj = v
        .get("pose")
        .unwrap_or(&v)
        .as_object()
        .with_context(|| format!("{}: expected a JSON object of DOF values", path.display()))?;
    let mut named = Vec::new();
    for (k, x) in obj {
        let x = x
            .as_f64()
            .with_context(|| format!("{}: field `{k}` is not a number", path.display()))?;
        named.push((k.as_str(), x));
    }
    Pose::from_named(skeleton, named).with_context(|| format!("{}: invalid pose", path.display()))
}

fn export(
    template: &str,
    pose: Option<&Path>,
    out: Option<&Path>,
    png: Option<&Path>,
    side: Side,
    cell_mm: f64,
) -> Result<()> {
    if out.is_none() && png.is_none() {
        bail!("nothing to do: give --out hand.obj|hand.glb and/or --png preview.png");
    }
    let t = load_template(template)?;
    let pose = match pose {
        Some(p) => read_pose(p, &t.skeleton)?,
        None => Pose::zeros(&t.skeleton),
    };
    if let Some(out) = out {
        let posed = PosedSphereMesh::new(&t, &pose);
        let elements: Vec<Element> = t.elements.iter().map(|e| e.element).collect();
        let mesh = extract_mesh(&posed.spheres, &elements, &MeshOptions { cell_mm })?;
        match out.extension().and_then(|e| e.to_str()) {
            Some("obj") => write_obj(out, &mesh)?,
            Some("glb") => write_glb(out, &mesh)?,
            _ => bail!(
                "{}: the mesh output must end in .obj or .glb",
                out.display()
            ),
        }
        eprintln!(
            "wrote {} ({} vertices, {} triangles)",
            out.display(),
            mesh.positions.len(),
            mesh.triangles.len()
        );
    }
    if let Some(png) = png {
        let side = match side {
            Side::Palm => ViewSide::Palm,
            Side::Back => ViewSide::Back,
        };
        write_preview_png(
            png,
            &t,
            &pose,
            &PreviewOptions {
                side,
                ..Default::default()
            },
        )?;
        eprintln!("wrote {}", png.display());
    }
    Ok(())
}

/// A template of either model.
pub enum AnyModel {
    /// A sphere-mesh template (Ch. 3–4).
    SphereMesh(SphereMeshTemplate),
    /// A cylinder model (Ch. 2).
    Cylinders(CylinderModel),
}

/// Resolve a template argument of either model.
pub fn load_any(spec: &str) -> Result<AnyModel> {
    match spec {
        "default" | "default-right" => return Ok(AnyModel::SphereMesh(default_right_hand())),
        "default-left" => return Ok(AnyModel::SphereMesh(default_right_hand().mirrored()?)),
        "default-cylinders" => return Ok(AnyModel::Cylinders(default_right_hand_cylinders())),
        _ => {}
    }
    let path = Path::new(spec);
    if !path.exists() {
        bail!("template `{spec}` is neither a built-in (default, default-left, default-cylinders) nor an existing file or folder");
    }
    if path.is_dir() {
        let t = import_hmodel_dir(path)
            .with_context(|| format!("importing the hmodel/honline files in {}", path.display()))?;
        return Ok(AnyModel::SphereMesh(t));
    }
    match path.extension().and_then(|e| e.to_str()) {
        Some("calib") => Ok(AnyModel::Cylinders(load_htrack_calib(path)?)),
        Some("json") => Ok(AnyModel::SphereMesh(SphereMeshTemplate::load(path)?)),
        _ => bail!(
            "{}: unknown template file type (expected .json, .calib or a folder)",
            path.display()
        ),
    }
}

/// Resolve a sphere-mesh template argument.
pub fn load_template(spec: &str) -> Result<SphereMeshTemplate> {
    match load_any(spec)? {
        AnyModel::SphereMesh(t) => Ok(t),
        AnyModel::Cylinders(_) => {
            bail!("`{spec}` is a cylinder model; this command needs a sphere-mesh template")
        }
    }
}

fn skeleton_summary(s: &mut String, sk: &Skeleton) {
    let _ = writeln!(s, "\nbones (name, parent, rest translation mm)");
    for b in sk.bones() {
        let parent = b.parent.map(|p| sk.bones()[p].name.as_str()).unwrap_or("-");
        let tr = b.rest.translation;
        let _ = writeln!(
            s,
            "  {:<10} {:<10} ({:7.2}, {:7.2}, {:7.2})",
            b.name, parent, tr.x, tr.y, tr.z
        );
    }
    let _ = writeln!(s, "\nDOFs (index, name, bone, kind, limits)");
    for (i, d) in sk.dofs().iter().enumerate() {
        let kind = match d.kind {
            DofKind::Translation => "translation",
            DofKind::GlobalRotation => "global rot",
            DofKind::Rotation => "rotation",
        };
        let lim = d
            .limits
            .map(|[a, b]| format!("[{a:+.2}, {b:+.2}]"))
            .unwrap_or_else(|| "unbounded".into());
        let _ = writeln!(
            s,
            "  {i:2} {:<16} {:<9} {kind:<11} {lim}",
            d.name,
            sk.bones()[d.bone].name
        );
    }
}

fn cylinder_summary(c: &CylinderModel) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "cylinder model {}", c.name);
    let _ = writeln!(s, "handedness     {:?}", c.handedness);
    let _ = writeln!(
        s,
        "counts         {} bones, {} DOFs, {} segments",
        c.skeleton.bones().len(),
        c.skeleton.num_dofs(),
        c.segments.len()
    );
    skeleton_summary(&mut s, &c.skeleton);
    let _ = writeln!(s, "\nsegments (index, bone, length, r1, r2, r1y, r2y mm)");
    for (i, g) in c.segments.iter().enumerate() {
        let _ = writeln!(
            s,
            "  {i:2} {:<10} {:7.2} {:6.2} {:6.2} {:6.2} {:6.2}",
            c.skeleton.bones()[g.bone].name,
            g.length,
            g.r1,
            g.r2,
            g.r1y,
            g.r2y
        );
    }
    let rest = c.rest_posed();
    let _ = writeln!(s, "\nkeypoints at the rest pose (mm)");
    for (name, k) in KEYPOINT_NAMES.iter().zip(c.keypoints(&rest)) {
        let _ = writeln!(s, "  {name:<10} ({:7.2}, {:7.2}, {:7.2})", k.x, k.y, k.z);
    }
    s
}

fn summary(t: &SphereMeshTemplate) -> String {
    let sk = &t.skeleton;
    let (pills, wedges) = t.element_counts();
    let mut s = String::new();
    let _ = writeln!(s, "template   {}", t.name);
    let _ = writeln!(s, "handedness {:?}", t.handedness);
    let _ = writeln!(
        s,
        "counts     {} bones, {} DOFs, {} spheres, {} elements ({pills} pills, {wedges} wedges)",
        sk.bones().len(),
        sk.num_dofs(),
        t.spheres.len(),
        t.elements.len()
    );
    skeleton_summary(&mut s, sk);
    let rest = PosedSphereMesh::new(t, &Pose::zeros(sk));
    let _ = writeln!(s, "\nspheres (index, name, rest center mm, radius mm)");
    for (i, (def, sp)) in t.spheres.iter().zip(&rest.spheres).enumerate() {
        let c = sp.center;
        let _ = writeln!(
            s,
            "  {i:2} {:<22} ({:7.2}, {:7.2}, {:7.2})  r {:5.2}",
            def.name, c.x, c.y, c.z, sp.radius
        );
    }
    let _ = writeln!(s, "\nelements (index, kind, spheres, bone)");
    for (i, e) in t.elements.iter().enumerate() {
        let names: Vec<&str> = e
            .element
            .spheres()
            .iter()
            .map(|&k| t.spheres[k as usize].name.as_str())
            .collect();
        let kind = if matches!(e.element, Element::Pill(_)) {
            "pill "
        } else {
            "wedge"
        };
        let _ = writeln!(
            s,
            "  {i:2} {kind} {:<60} {}",
            names.join(", "),
            sk.bones()[e.bone].name
        );
    }
    let _ = writeln!(s, "\nkeypoints at the rest pose (mm)");
    for (name, k) in KEYPOINT_NAMES.iter().zip(rest.keypoints(t)) {
        let _ = writeln!(s, "  {name:<10} ({:7.2}, {:7.2}, {:7.2})", k.x, k.y, k.z);
    }
    match ShapeBasis::honline(t) {
        Ok(basis) => {
            let _ = writeln!(
                s,
                "\nshape β (honline layout, {} entries: name, kind, value, limits)",
                basis.len()
            );
            for (i, p) in basis.params.iter().enumerate() {
                let lim = p
                    .limits
                    .map(|[a, b]| format!("[{a}, {b}]"))
                    .unwrap_or_default();
                let _ = writeln!(
                    s,
                    "  {i:2} {:<28} {:<20} {:8.3} {lim}",
                    p.name,
                    format!("{:?}", p.kind),
                    p.template_value
                );
            }
        }
        Err(e) => {
            let _ = writeln!(s, "\nshape β: not available for this template ({e})");
        }
    }
    s
}
