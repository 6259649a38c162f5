//! `hands prior …`: build the project's PCA pose prior (thesis §2.3.2).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Subcommand;
use hand_model::solver::HTRACK_LATENT_DIMS;

/// Pose-prior subcommands.
#[derive(Subcommand)]
pub enum PriorCommand {
    /// Fit the project's PCA pose prior (htrack grouping: thumb 4 DOFs, fingers 16 DOFs, all
    /// components kept) on the authored key poses and library motions, plus the RealSense
    /// recorded poses retargeted to our skeleton when `--animbank` is given, and write it as
    /// JSON (`hands-pca-prior` format).
    ///
    /// The committed `hand-model/data/pose-prior.json` is regenerated from the repository root
    /// with `hands prior build --animbank
    /// ../shared/reference/pose-corpus-realsense/animbank.pose --out
    /// hand-model/data/pose-prior.json`.
    #[command(
        after_help = "Example: hands prior build --animbank ../shared/reference/pose-corpus-realsense/animbank.pose --out hand-model/data/pose-prior.json"
    )]
    Build {
        /// The RealSense `animbank.pose` corpus (17 bones × xyz + quaternion per line).
        #[arg(long)]
        animbank: Option<PathBuf>,
        /// Output JSON file (written atomically).
        #[arg(long, default_value = "pose-prior.json")]
        out: PathBuf,
    },
}

/// Run a prior subcommand.
pub fn run(cmd: PriorCommand) -> Result<()> {
    match cmd {
        PriorCommand::Build { animbank, out } => {
            let (prior, description) = datasets::prior::build_project_prior(animbank.as_deref())
                .context("building the pose prior")?;
            prior
                .save_json(&out, &description)
                .with_context(|| format!("writing {}", out.display()))?;
            println!("{description}");
            for g in &prior.groups {
                println!(
                    "{:8} {:2} DOFs, variances {:.4?}…, {} components explain {:.1} %",
                    g.name,
                    g.num_dofs(),
                    &g.variances[..HTRACK_LATENT_DIMS.min(g.variances.len())],
                    HTRACK_LATENT_DIMS,
                    100.0 * g.explained_variance(HTRACK_LATENT_DIMS)
                );
            }
            println!("wrote {}", out.display());
            Ok(())
        }
    }
}
