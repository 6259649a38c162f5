//! Progress bars for long jobs.

use indicatif::{ProgressBar, ProgressStyle};

/// A bar over `len` frames (a spinner when the length is unknown), drawn on stderr.
pub fn frames_bar(len: Option<usize>, what: &str) -> ProgressBar {
    let bar = match len {
        Some(n) => ProgressBar::new(n as u64),
        None => ProgressBar::new_spinner(),
    };
    let style =
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} frames {per_sec} eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar());
    bar.set_style(style);
    bar.set_message(what.to_string());
    bar
}
