//! The `hands` command-line interface (DESIGN.md "CLI surface").

mod convert;
mod demo;
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
    /// The main job on the embedded default: synthesize, preprocess and score (no input files).
    Demo(demo::DemoArgs),
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
        Command::Demo(args) => demo::run(args),
        Command::Model(cmd) => model::run(cmd),
        Command::Convert(args) => convert::run(args),
        Command::Synth(args) => synth::run(args),
    }
}
