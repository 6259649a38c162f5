//! `hands model …`: show and export templates.

use std::fmt::Write as _;

use anyhow::{bail, Result};
use clap::Subcommand;
use hand_model::keypoints::KEYPOINT_NAMES;
use hand_model::kinematics::{DofKind, Pose};
use hand_model::shape::Element;
use hand_model::spheremesh::{default_right_hand, PosedSphereMesh, ShapeBasis, SphereMeshTemplate};

/// Template subcommands.
#[derive(Subcommand)]
pub enum ModelCommand {
    /// Print a summary of a template: bones, DOFs with limits, spheres, elements, β.
    ///
    /// Example: `hands model show default`
    Show {
        /// `default` (the embedded right hand) or a template file.
        template: String,
    },
}

/// Run a model subcommand.
pub fn run(cmd: ModelCommand) -> Result<()> {
    match cmd {
        ModelCommand::Show { template } => {
            let t = load_template(&template)?;
            print!("{}", summary(&t));
            Ok(())
        }
    }
}

/// Resolve a template argument.
pub fn load_template(spec: &str) -> Result<SphereMeshTemplate> {
    match spec {
        "default" | "default-right" => Ok(default_right_hand()),
        "default-left" => Ok(default_right_hand().mirrored()?),
        other => bail!("unknown template `{other}` (try `default`)"),
    }
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
