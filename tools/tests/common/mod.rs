//! Shared by the `hands` CLI test files.

use std::process::Command;

/// Run the `hands` binary; whether it succeeded and its stdout + stderr.
pub fn hands(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_hands"))
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("run hands");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}
