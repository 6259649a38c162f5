//! `hands convert`: copy a sequence between the folder and MCAP formats.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use sensor_io::io::{create_sequence, open_sequence};

/// Convert a sequence between the folder format and MCAP (DESIGN.md "Sequences on disk").
///
/// Example: `hands convert seq/ seq.mcap` (an `.mcap` output writes MCAP, anything else a folder).
#[derive(Args)]
pub struct ConvertArgs {
    /// Input sequence: a folder or an `.mcap` file.
    pub input: PathBuf,
    /// Output: an `.mcap` path writes MCAP, any other path a folder.
    pub output: PathBuf,
}

/// Run the conversion, streaming one frame at a time.
pub fn run(args: ConvertArgs) -> Result<()> {
    let mut reader =
        open_sequence(&args.input).with_context(|| format!("opening {}", args.input.display()))?;
    let camera = reader.camera().clone();
    let mut writer = create_sequence(&args.output, &camera)
        .with_context(|| format!("creating {}", args.output.display()))?;
    let bar = crate::progress::frames_bar(reader.len(), "convert");
    let mut n = 0;
    while let Some(frame) = reader.next_frame() {
        let (frame, record) = frame?;
        writer.write(&frame, record.as_ref())?;
        n += 1;
        bar.inc(1);
    }
    writer.finish()?;
    bar.finish_and_clear();
    eprintln!(
        "converted {n} frames: {} → {}",
        args.input.display(),
        args.output.display()
    );
    Ok(())
}
