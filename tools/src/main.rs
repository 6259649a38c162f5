//! The `hands` command-line interface (DESIGN.md "CLI surface").

mod bench;
mod calibrate;
mod compare;
mod config;
mod convert;
mod demo;
mod evaluate;
mod interrupt;
mod methods;
mod model;
mod overlay;
mod prior;
mod progress;
mod report;
mod scoring;
mod synth;
mod track;
mod trackers;

use clap::{Parser, Subcommand};

/// Real-time generative hand tracking and hand-model personalization from a depth camera.
#[derive(Parser)]
#[command(
    name = "hands",
    version,
    about = "Real-time generative hand tracking and hand-model personalization from a depth camera",
    after_help = "Example: hands demo"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The main job (no input files): synthesize a random subject, track it with every method,
    /// score against the ground truth and write a report.
    #[command(after_help = "Example: hands demo --out demo-report --frames 120 --seed 7")]
    Demo(demo::DemoArgs),
    /// Inspect and export hand templates.
    #[command(subcommand, after_help = "Example: hands model show default")]
    Model(model::ModelCommand),
    /// Convert a sequence between the folder format and MCAP.
    #[command(
        after_help = "Example: hands convert seq/ seq.mcap   (an .mcap output writes MCAP, any other path a folder)"
    )]
    Convert(convert::ConvertArgs),
    /// Render a synthetic depth sequence with exact ground truth.
    #[command(
        after_help = "Example: hands synth --motion teaser --frames 600 --noise tof --seed 7 --out seq.mcap --preview sheet.png"
    )]
    Synth(synth::SynthArgs),
    /// Track a depth sequence and write the per-frame pose, keypoints, energies and timings.
    #[command(
        after_help = "Example: hands track seq.mcap --model spheremesh --out track.jsonl --overlay overlay/"
    )]
    Track(track::TrackArgs),
    /// Score a track file on its sequence: E_d2m/E_m2d, marker errors, plots.
    #[command(
        after_help = "Example: hands eval track.jsonl --sequence seq.mcap --model spheremesh --out eval/"
    )]
    Eval(evaluate::EvalArgs),
    /// Run several methods on one sequence and write one side-by-side report.
    #[command(
        after_help = "Example: hands compare seq.mcap --methods cylinders,spheremesh --out report/"
    )]
    Compare(compare::CompareArgs),
    /// Calibrate the sphere-mesh template to a sequence of the user's hand (thesis §3.4; the
    /// Ch. 4 batch baselines Offline-Hard/Soft of §4.3.4 with `--method`).
    #[command(
        after_help = "Examples:\n  hands calibrate seq.mcap --auto 8 --out me.json --report calib/\n  hands calibrate seq.mcap --method offline-soft --every 20 --out me.json"
    )]
    Calibrate(calibrate::CalibrateArgs),
    /// Write a reproduction report (markdown + SVG plots) from synthetic ground truth.
    #[command(after_help = "Example: hands report ch2 --out docs/ch2 --frames 300")]
    Report(report::ReportArgs),
    /// Build the project's PCA pose prior from its pose corpus.
    #[command(
        subcommand,
        after_help = "Example: hands prior build --animbank animbank.pose --out pose-prior.json"
    )]
    Prior(prior::PriorCommand),
    /// Measure the trackers' speed: per-stage medians on one thread, two cores, point counts.
    #[command(after_help = "Example: hands bench --model all --frames 240 --json bench.json")]
    Bench(bench::BenchArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    interrupt::install();
    match cli.command {
        Command::Demo(args) => demo::run(args),
        Command::Model(cmd) => model::run(cmd),
        Command::Convert(args) => convert::run(args),
        Command::Synth(args) => synth::run(args),
        Command::Track(args) => track::run(args),
        Command::Eval(args) => evaluate::run(args),
        Command::Compare(args) => compare::run(args),
        Command::Calibrate(args) => calibrate::run(args),
        Command::Report(args) => report::run(args),
        Command::Prior(cmd) => prior::run(cmd),
        Command::Bench(args) => bench::run(args),
    }
}
