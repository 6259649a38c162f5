//! The `hands` command-line interface (DESIGN.md "CLI surface").

mod convert;
mod model;
mod progress;
mod synth;

use clap::{Parser, Subcommand};

/// Real-time generative hand tracking and hand-model personalization from a depth camera.
#[derive(Parser)]
#[command(name = "hands", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Inspect and export hand templates.
    #[command(subcommand)]
    Model(model::ModelCommand),
    /// Convert a sequence between the folder format and MCAP.
    Convert(convert::ConvertArgs),
    /// Render a synthetic depth sequence with exact ground truth.
    Synth(synth::SynthArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Model(cmd) => model::run(cmd),
        Command::Convert(args) => convert::run(args),
        Command::Synth(args) => synth::run(args),
    }
}
